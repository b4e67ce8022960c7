"""
The checkpoints of ``sb3-dtdpg train`` on an env without missions (``Pendulum-v1``, a MuJoCo task, ...), from which
the same command resumes the run as the uninterrupted one would have gone on
(:class:`~sb3_dtdpg.common.checkpoints.ExactCheckpointCallback`), with the record of the options it trains with, so
that a command with other options does not train on from them.

A run named ``<run>`` keeps ``<run>_checkpoints/`` in its output folder while it trains: ``settings.json`` and its
latest checkpoint. Once the trained model is saved as ``<run>.zip``, :func:`remove_checkpoints` removes the folder.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.type_aliases import GymEnv

from sb3_dtdpg.common.checkpoints import ExactCheckpointCallback, checkpoint_files, load_checkpoint
from sb3_dtdpg.common.files import atomic_write
from sb3_dtdpg.experiments.specs import RunMismatchError
from sb3_dtdpg.experiments.storage import DamagedRecordError

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
    :param settings: the options the run trains with, by option name (values JSON writes and reads back as they are)
    :param env: the training env, built as the run's was (:func:`~sb3_dtdpg.common.checkpoints.load_checkpoint`)
    :param algorithm: the model's class
    :raises RunMismatchError: the checkpoint was trained with other options (the message names the first that differs)
    :raises DamagedRecordError: the checkpoint or its settings record cannot be read
    """
    from sb3_dtdpg.baselines import without_n_step_load_warning

    model_file = latest_checkpoint(folder)
    if model_file is None:
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write(folder / SETTINGS_FILE, lambda path: Path(path).write_text(json.dumps(settings, indent=2) + "\n"))
        return None
    recorded = _recorded_settings(folder)
    for option, value in settings.items():
        if option not in recorded or recorded[option] != value:
            was = _shown(recorded[option]) if option in recorded else "not recorded"
            raise RunMismatchError(
                f"{folder} holds a checkpoint of a run with {option} {was}, this command gives {_shown(value)}: give the "
                f"same options to resume it, another --out or --tag for another run, or delete {folder} to train afresh"
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


def _recorded_settings(folder: Path) -> dict[str, Any]:
    path = folder / SETTINGS_FILE
    try:
        recorded = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        raise DamagedRecordError(
            f"{path}: the record of the options of the checkpoint beside it cannot be read ({error}); delete {folder} "
            "to train afresh"
        ) from error
    if not isinstance(recorded, dict):
        raise DamagedRecordError(f"{path}: not a record of options; delete {folder} to train afresh")
    return recorded


def _shown(value: Any) -> str:
    return "(not given)" if value is None else repr(value) if isinstance(value, str) else str(value)
