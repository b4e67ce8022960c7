"""What a checkpoint keeps beyond the model and its replay buffer, so that a run resumed from it trains on
exactly as the uninterrupted run would: the training env as it is (the env itself with its random generator and the
mission in progress, the counters of its wrappers and of its ``DummyVecEnv``) and the random generators SB3 draws
from (numpy's global one: replay sampling and the exploration noise; Python's and torch's; the action space's,
which draws the warm-up actions).

A checkpoint is taken between two iterations of SB3's ``learn`` loop (at the start of a rollout), so the model's
``_last_obs`` is the env's current observation and nothing else is half done.

The wrappers are kept as their attributes, not as objects: a resumed run builds its env as the run did and takes
the attributes back (:func:`restore_env`). Pickled whole, a wrapper whose class a library has replaced in its
module (the RL Zoo replaces Gymnasium's ``TimeLimit`` when it is imported) would travel by value and fail in a
process without that replacement.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import cloudpickle
import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.vec_env import DummyVecEnv

__all__ = ["TRAINING_STATE", "capture", "env_state", "load", "restore", "restore_env", "restore_generators", "save"]

#: The file of a checkpoint folder that holds the training state (next to ``model.zip`` and ``replay_buffer.pkl``).
TRAINING_STATE = "training_state.pkl"


def capture(model: Any) -> dict[str, Any]:
    """
    :param model: an SB3 model between two iterations of its ``learn`` loop, training on a ``DummyVecEnv``
    :return: its training env's state (:func:`env_state`) and the random generators' states
    """
    return {
        "env": env_state(model.get_env()),
        "generators": {
            "numpy": np.random.get_state(),
            "python": random.getstate(),
            "torch": th.get_rng_state(),
            "action_space": model.action_space.np_random.bit_generator.state,
        },
    }


def env_state(vec_env: DummyVecEnv) -> dict[str, Any]:
    """
    :param vec_env: a ``DummyVecEnv``
    :return: its attributes but its envs, and per env the attributes of each wrapper (outermost first) and the
        unwrapped env itself
    :raises TypeError: for another kind of vector env
    """
    if not isinstance(vec_env, DummyVecEnv):
        raise TypeError(f"a training state keeps the envs of a DummyVecEnv, not of a {type(vec_env).__name__}")
    envs = []
    for env in vec_env.envs:
        wrappers = []
        while isinstance(env, gym.Wrapper):
            wrappers.append({name: value for name, value in vars(env).items() if name != "env"})
            env = env.env
        envs.append({"wrappers": wrappers, "env": env})
    return {"vec_env": {name: value for name, value in vars(vec_env).items() if name != "envs"}, "envs": envs}


def restore_env(vec_env: DummyVecEnv, state: dict[str, Any]) -> None:
    """
    Put an :func:`env_state` back into a vector env built as the saved one was: each wrapper takes its attributes
    back, the innermost one wraps the saved env.

    :param vec_env: the new ``DummyVecEnv``
    :param state: the ``env`` of :func:`load`
    :raises ValueError: the vector env has another number of envs or of wrappers than the saved one
    """
    saved_envs = state["envs"]
    if not isinstance(vec_env, DummyVecEnv) or len(vec_env.envs) != len(saved_envs):
        raise ValueError(f"the training state holds {len(saved_envs)} envs of a DummyVecEnv; the env to resume is other")
    for index, saved in enumerate(saved_envs):
        wrappers, env = [], vec_env.envs[index]
        while isinstance(env, gym.Wrapper):
            wrappers.append(env)
            env = env.env
        if len(wrappers) != len(saved["wrappers"]):
            raise ValueError(
                f"the training state's env {index} has {len(saved['wrappers'])} wrappers, the env to resume "
                f"{len(wrappers)}: it was built otherwise"
            )
        for wrapper, attributes in zip(wrappers, saved["wrappers"], strict=True):
            vars(wrapper).update(attributes)
        if wrappers:
            wrappers[-1].env = saved["env"]
        else:
            vec_env.envs[index] = saved["env"]
    vars(vec_env).update(state["vec_env"])


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
    :return: the training state: ``env`` (for :func:`restore_env`) and ``generators`` (for
        :func:`restore_generators`)
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


def restore(model: Any, env: Any, state: dict[str, Any]) -> None:
    """
    Give a model loaded without an env (loading with one would seed it) its training env as :func:`capture` found it,
    and the random generators: the env is wrapped as SB3 wraps a training env and takes the saved env's place
    (:func:`restore_env`), the episode in progress goes on. Then ``learn(..., reset_num_timesteps=False)`` trains on
    as the uninterrupted training would.

    :param model: the loaded model
    :param env: an env built as the training env was
    :param state: the training state (:func:`load`)
    """
    model.set_env(env, force_reset=False)
    restore_env(model.get_env(), state["env"])
    restore_generators(model, state["generators"])
