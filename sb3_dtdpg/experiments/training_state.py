"""What a checkpoint keeps beyond the model and its replay buffer, so that a run resumed from it trains on
exactly as the uninterrupted run would: the training env as it is (its random generator, the mission in
progress, its wrappers' counters) and the random generators SB3 draws from (numpy's global one: replay sampling
and the exploration noise; Python's and torch's; the action space's, which draws the warm-up actions).

A checkpoint is taken between two iterations of SB3's ``learn`` loop (at the start of a rollout), so the model's
``_last_obs`` is the env's current observation and nothing else is half done.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import cloudpickle
import numpy as np
import torch as th

__all__ = ["TRAINING_STATE", "capture", "load", "restore_generators", "save"]

#: The file of a checkpoint folder that holds the training state (next to ``model.zip`` and ``replay_buffer.pkl``).
TRAINING_STATE = "training_state.pkl"


def capture(model: Any) -> dict[str, Any]:
    """
    :param model: an SB3 model between two iterations of its ``learn`` loop
    :return: its training env and the random generators' states
    """
    return {
        "env": model.get_env(),
        "generators": {
            "numpy": np.random.get_state(),
            "python": random.getstate(),
            "torch": th.get_rng_state(),
            "action_space": model.action_space.np_random.bit_generator.state,
        },
    }


def save(model: Any, path: str | Path) -> None:
    """
    Write :func:`capture` of the model to ``path`` (cloudpickle).

    :param model: the model
    :param path: the file
    """
    with open(path, "wb") as file:
        cloudpickle.dump(capture(model), file)


def load(path: str | Path) -> dict[str, Any]:
    """
    :param path: a file written by :func:`save`
    :return: the training state: ``env`` (the training env, to give to the loaded model with ``set_env(env,
        force_reset=False)``) and ``generators`` (for :func:`restore_generators`)
    """
    with open(path, "rb") as file:
        state = cloudpickle.load(file)
    if not isinstance(state, dict) or {"env", "generators"} - set(state):
        raise ValueError(f"{path} is not a training state (a dict with 'env' and 'generators')")
    return state


def restore_generators(model: Any, generators: dict[str, Any]) -> None:
    """
    Put the random generators back where :func:`capture` found them. Call it after loading the model (loading
    seeds them) and before ``learn``.

    :param model: the loaded model
    :param generators: the ``generators`` of :func:`load`
    """
    np.random.set_state(generators["numpy"])
    random.setstate(generators["python"])
    th.set_rng_state(generators["torch"])
    model.action_space.np_random.bit_generator.state = generators["action_space"]
