"""
The checkpoints of ``sb3-dtdpg train`` on an env without missions (``Pendulum-v1``, a MuJoCo task, ...), from which
the same command resumes the run as the uninterrupted one would have gone on
(:class:`~sb3_dtdpg.common.checkpoints.ExactCheckpointCallback`), with the record of the options it trains with, so
that a command with other options does not train on from them.

A run named ``<run>`` keeps ``<run>_checkpoints/`` in its output folder while it trains: ``settings.json`` and its
latest checkpoint. Once the trained model is saved as ``<run>.zip``, :func:`remove_checkpoints` removes the folder.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.type_aliases import GymEnv

from sb3_dtdpg.common.checkpoints import ExactCheckpointCallback, checkpoint_files, load_checkpoint
from sb3_dtdpg.common.files import write_json
from sb3_dtdpg.experiments.specs import RunMismatchError
from sb3_dtdpg.experiments.storage import DamagedRecordError, settings_mismatch

__all__ = ["checkpoint_callback", "checkpoint_folder", "latest_checkpoint", "remove_checkpoints", "resume"]

#: The record of the options a run trains with, in its checkpoint folder.
SETTINGS_FILE = "settings.json"


def checkpoint_folder(out: str | Path, run_name: str) -> Path:
    """:return: the folder of a run's checkpoints in its output folder, ``<out>/<run>_checkpoints``"""
    return Path(out) / f"{run_name}_checkpoints"


def checkpoint_callback(folder: Path, run_name: str, every_steps: int) -> ExactCheckpointCallback:
    """
    :param folder: the run's :func:`checkpoint_folder`
    :param run_name: the run's name (the prefix of its checkpoint files)
    :param every_steps: env steps between two checkpoints (each comes at the end of the next episode)
    :return: the callback that keeps the run's latest checkpoint in ``folder``
    """
    return ExactCheckpointCallback(every_steps, str(folder), name_prefix=run_name, keep_last=1)


def latest_checkpoint(folder: Path) -> Path | None:
    """:return: the model file of the latest whole checkpoint in ``folder``; None where there is none"""
    try:
        return checkpoint_files(folder)[0]
    except FileNotFoundError:
        return None


def resume(folder: Path, settings: dict[str, Any], env: GymEnv, algorithm: type[BaseAlgorithm]) -> BaseAlgorithm | None:
    """
    The model of a run's latest checkpoint, ready to train on, or None where it has none: ``settings`` are then
    recorded for the checkpoints to come.

    :param folder: the run's :func:`checkpoint_folder`
    :param settings: the options the run trains with, by ``argparse`` dest
        (:func:`~sb3_dtdpg.experiments.storage.settings_mismatch` compares them)
    :param env: the training env, built as the run's was (:func:`~sb3_dtdpg.common.checkpoints.load_checkpoint`)
    :param algorithm: the model's class
    :raises RunMismatchError: the checkpoint was trained with other options (the message names each that differs), or
        its record of them cannot be read
    :raises DamagedRecordError: the checkpoint cannot be loaded
    """
    from sb3_dtdpg.baselines import without_n_step_load_warning

    model_file, record = latest_checkpoint(folder), folder / SETTINGS_FILE
    if model_file is None:
        folder.mkdir(parents=True, exist_ok=True)
        write_json(record, {"settings": settings}, indent=2)
        return None
    mismatch = settings_mismatch(record, settings) if record.is_file() else f"{record} is missing"
    if mismatch is not None:
        raise RunMismatchError(
            f"{mismatch}: {folder} holds its checkpoint; give the same options to resume it, another --out or --tag for "
            f"another run, or delete {folder} to train afresh"
        )
    try:
        with without_n_step_load_warning():
            return load_checkpoint(model_file, env, algorithm)
    except Exception as error:  # whatever a damaged zip or pickle raises; an interruption is not caught
        raise DamagedRecordError(
            f"{model_file}: the checkpoint cannot be loaded ({type(error).__name__}: {error}); delete {folder} to train afresh"
        ) from error


def remove_checkpoints(folder: Path) -> None:
    """Remove a run's checkpoint folder, once its trained model is saved."""
    shutil.rmtree(folder, ignore_errors=True)
