"""Where a run's files live and how they are read and written: results, progress records, checkpoints, locks.

Under an output folder ``<out>``, a run owns ``<out>/runs/<run_id>/``: ``result.json`` (written last,
atomically: its existence means the run is finished), ``progress.json`` while it trains, ``checkpoint.json`` and
``checkpoints/`` when checkpointed, and the saved models. :func:`output_lock` keeps two jobs out of one folder.
"""

from __future__ import annotations

import contextlib
import json
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from sb3_dtdpg.common.files import atomic_write, write_json
from sb3_dtdpg.experiments.specs import RunSpec, check_identity, run_identity

__all__ = [
    "OutputBusyError",
    "clear_checkpoints",
    "load_result",
    "output_lock",
    "progress_path",
    "read_checkpoint",
    "read_progress",
    "result_path",
    "run_folder",
    "save_checkpoint",
]


class OutputBusyError(RuntimeError):
    """Another process holds the output folder's lock."""


def run_folder(out: str | Path, spec: RunSpec) -> Path:
    """:return: the folder of a run's files, ``<out>/runs/<run_id>``"""
    return Path(out) / "runs" / spec.run_id


def result_path(out: str | Path, spec: RunSpec) -> Path:
    """:return: the result file of a run (its existence means the run is finished)"""
    return run_folder(out, spec) / "result.json"


def progress_path(out: str | Path, spec: RunSpec) -> Path:
    """:return: the progress file a running run writes (:class:`sb3_dtdpg.experiments.run_callbacks.RunProgress`)"""
    return run_folder(out, spec) / "progress.json"


def load_result(out: str | Path, spec: RunSpec, identity: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """
    The stored result of a finished run, checked against the run's identity.

    :param out: output folder
    :param spec: the run
    :param identity: the run's :func:`run_identity` (None: computed here)
    :return: the result, or None when the run has not finished
    :raises RunMismatchError: the stored result is another run's (another budget, scenario, hyperparameters ...)
    """
    path = result_path(out, spec)
    if not path.exists():
        return None
    result = json.loads(path.read_text())
    check_identity(result, run_identity(spec) if identity is None else identity, path)
    return result


def read_progress(out: str | Path, spec: RunSpec) -> dict[str, Any] | None:
    """:return: a running run's last progress record, or None when it has not started"""
    try:
        return json.loads(progress_path(out, spec).read_text())
    except (OSError, ValueError):
        return None


@contextlib.contextmanager
def output_lock(out: str | Path, name: str = ".lock") -> Iterator[Path]:
    """
    Hold the lock of an output folder for the duration of a job (an OS file lock: released when the process
    ends, even when killed).

    :param out: the folder
    :param name: the lock file's name in it
    :raises OutputBusyError: another process holds it
    """
    from filelock import FileLock, Timeout

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / name
    lock = FileLock(path, timeout=0)
    try:
        lock.acquire()
    except Timeout:
        raise OutputBusyError(
            f"{out} is in use by another job (lock {path}); wait for it to end, or use another output folder"
        ) from None
    try:
        yield path
    finally:
        lock.release()


def save_checkpoint(model: Any, run_dir: Path, identity: dict[str, Any], episodes: int) -> Path:
    """
    Write a checkpoint: model and replay buffer into a fresh ``checkpoints/<episodes>`` folder, then
    ``checkpoint.json`` (atomically) pointing at it, then remove the older folders. A kill at any point leaves
    the previous checkpoint usable.

    :return: the checkpoint folder
    """
    folder = run_dir / "checkpoints" / f"episode_{episodes}"
    shutil.rmtree(folder, ignore_errors=True)
    atomic_write(folder / "model.zip", model.save)
    if getattr(model, "replay_buffer", None) is not None:
        atomic_write(folder / "replay_buffer.pkl", model.save_replay_buffer)
    pointer = {
        "identity": identity,
        "episodes": episodes,
        "timesteps": int(model.num_timesteps),
        "folder": str(folder.relative_to(run_dir)),
    }
    write_json(run_dir / "checkpoint.json", pointer, indent=1)
    for other in (run_dir / "checkpoints").iterdir():
        if other != folder:
            shutil.rmtree(other, ignore_errors=True)
    return folder


def read_checkpoint(run_dir: str | Path, identity: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """
    The latest checkpoint of a run, checked against the run's identity.

    :param run_dir: the run's folder
    :param identity: the run's :func:`run_identity` (None: not checked)
    :return: ``checkpoint.json``'s content plus ``path`` (the folder), or None when there is none
    :raises RunMismatchError: the checkpoint is another run's
    """
    run_dir = Path(run_dir)
    pointer = run_dir / "checkpoint.json"
    if not pointer.exists():
        return None
    checkpoint = json.loads(pointer.read_text())
    if identity is not None:
        check_identity(checkpoint, identity, pointer)
    checkpoint["path"] = run_dir / checkpoint["folder"]
    return checkpoint if (checkpoint["path"] / "model.zip").exists() else None


def clear_checkpoints(run_dir: Path) -> None:
    """Remove a finished run's checkpoints and progress record (its result supersedes them; a replay buffer can be large)."""
    (run_dir / "checkpoint.json").unlink(missing_ok=True)
    (run_dir / "progress.json").unlink(missing_ok=True)
    shutil.rmtree(run_dir / "checkpoints", ignore_errors=True)
