"""Where a run's files live and how they are read and written: results, progress records, checkpoints, locks.

Under an output folder ``<out>``, a run owns ``<out>/runs/<run_id>/``: ``result.json`` (written last,
atomically: its existence means the run is finished), ``progress.json`` while it trains, ``checkpoint.json`` and
``checkpoints/`` when checkpointed, and the saved models; its TensorBoard logs go to ``<out>/tb/<run_id>``
(:func:`tensorboard_folder`, :func:`tensorboard_claim`, :func:`run_logger`). :func:`output_lock` keeps two jobs out
of one folder.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from stable_baselines3.common import logger as sb3_logger
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_dtdpg.common.checks import shortened
from sb3_dtdpg.common.files import atomic_write, write_json
from sb3_dtdpg.common.training_state import TRAINING_STATE
from sb3_dtdpg.common.training_state import save as save_training_state
from sb3_dtdpg.experiments.provenance import made_with, warn_other_versions
from sb3_dtdpg.experiments.specs import RunMismatchError, RunSpec, check_identity, run_identity

__all__ = [
    "FOLDER_LOCK",
    "RUN_RECORDS",
    "TENSORBOARD_OWNER",
    "DamagedRecordError",
    "OutputBusyError",
    "clear_checkpoints",
    "failure_path",
    "hold_lock",
    "load_result",
    "load_results",
    "output_lock",
    "progress_path",
    "read_checkpoint",
    "read_progress",
    "result_path",
    "run_folder",
    "run_lock_name",
    "run_logger",
    "save_checkpoint",
    "tensorboard_claim",
    "tensorboard_folder",
]


#: A run's record of its finished training, written after its ``model.zip`` and before its evaluations
TRAINED_RECORD = "trained.json"

#: The files a run of ``train``/``compare``/``reproduce`` owns in its folder ``<out>/runs/<run id>/`` (written here
#: and by :func:`sb3_dtdpg.experiments.runs.run_one`), besides the curriculum's ``phase_<k>_<name>.zip`` and the
#: ``checkpoints/`` folder
RUN_RECORDS: tuple[str, ...] = (
    "result.json",
    "progress.json",
    "checkpoint.json",
    "failed.json",
    TRAINED_RECORD,
    "model.zip",
    "replay_buffer.pkl",
    TRAINING_STATE,
)


class OutputBusyError(RuntimeError):
    """Another process holds the output folder's lock."""


class DamagedRecordError(ValueError):
    """
    A run's record (``result.json``, ``checkpoint.json``) or the checkpoint it names is damaged, missing or not this
    run's. The harness writes each of them whole (atomically, a checkpoint's files before its record), so this
    means a change from outside. The message names the file and what to delete; nothing is removed for the user.
    """


def run_folder(out: str | Path, spec: RunSpec) -> Path:
    """:return: the folder of a run's files, ``<out>/runs/<run_id>``"""
    return Path(out) / "runs" / spec.run_id


def result_path(out: str | Path, spec: RunSpec) -> Path:
    """:return: the result file of a run (its existence means the run is finished)"""
    return run_folder(out, spec) / "result.json"


def progress_path(out: str | Path, spec: RunSpec) -> Path:
    """:return: the progress file a running run writes (:class:`sb3_dtdpg.experiments.run_callbacks.RunProgress`)"""
    return run_folder(out, spec) / "progress.json"


def _read_record(path: Path) -> dict[str, Any]:
    """
    :param path: a result or checkpoint record (written atomically: unreadable only when damaged from outside)
    :return: its content
    :raises DamagedRecordError: naming the file and the fix when it is not a JSON mapping
    """
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError) as error:
        record = error
    if not isinstance(record, dict):
        reason = f"{type(record).__name__}: {record}" if isinstance(record, Exception) else "not a JSON mapping"
    elif not isinstance(record.get("identity", {}), dict):
        reason = f"its identity is a JSON {type(record['identity']).__name__}, not a mapping"
    else:
        return record
    raise DamagedRecordError(f"{path} is unreadable ({str(reason)[:200]}); delete {path.parent} to run this run again")


def load_result(out: str | Path, spec: RunSpec, identity: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """
    The stored result of a finished run, checked against the run's identity.

    :param out: output folder
    :param spec: the run
    :param identity: the run's :func:`run_identity` (None: computed here)
    :return: the result, or None when the run has not finished
    :raises RunMismatchError: the stored result is another run's (another budget, scenario, hyperparameters ...)
    :raises DamagedRecordError: the result file is damaged
    """
    path = result_path(out, spec)
    if not path.exists():
        return None
    result = _read_record(path)
    check_identity(result, run_identity(spec) if identity is None else identity, path)
    return result


def load_results(
    out: str | Path, specs: Iterable[RunSpec], identities: Iterable[dict[str, Any]] | None = None
) -> dict[str, dict[str, Any] | None]:
    """
    The stored results of many runs (:func:`load_result`), every one checked before any is used, so that a job
    learns of all the stored records that do not fit before it trains anything.

    :param out: output folder
    :param specs: the runs
    :param identities: their :func:`run_identity` (None: computed here)
    :return: each run's result (None: not finished), by run id
    :raises RunMismatchError: some stored results are other runs' (the first named in full, the others' folders listed)
    :raises DamagedRecordError: the same, where the first is a damaged record
    """
    specs = list(specs)
    identities = list(identities) if identities is not None else [None] * len(specs)
    results: dict[str, dict[str, Any] | None] = {}
    problems: list[tuple[RunSpec, ValueError]] = []
    for spec, identity in zip(specs, identities, strict=True):
        try:
            results[spec.run_id] = load_result(out, spec, identity)
        except (RunMismatchError, DamagedRecordError) as error:
            problems.append((spec, error))
    if not problems:
        warn_other_versions(results, out)
        return results
    first = problems[0][1]
    if len(problems) == 1:
        raise first
    others = [str(result_path(out, spec).parent) for spec, _ in problems[1:]]
    raise type(first)(f"{first}; {len(others)} more stored runs do not fit either: {shortened(others, 5)}") from None


def read_progress(out: str | Path, spec: RunSpec) -> dict[str, Any] | None:
    """:return: a running run's last progress record, or None when it has not started"""
    try:
        return json.loads(progress_path(out, spec).read_text())
    except (OSError, ValueError):
        return None


#: The lock file of a whole-folder job (``compare``, ``reproduce``); a run's lock is held with a shared hold of it.
FOLDER_LOCK = ".lock"


def run_lock_name(run_id: str) -> str:
    """:return: the name of a run's lock file in its output folder (held by ``sb3-dtdpg train`` and the distributed workers)"""
    return f".{run_id}.lock"


@contextlib.contextmanager
def hold_lock(path: Path, shared: bool) -> Iterator[bool]:
    """
    Hold an OS lock on ``path``, released when the block ends or the process ends (even when killed).

    :param path: the lock file (created with its folder)
    :param shared: a shared hold (several holders at once) rather than an exclusive one; without ``fcntl``
        (Windows) every hold is exclusive
    :return: (yields) whether the lock was free; a lock that was not is not held
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        import fcntl
    except ImportError:  # no shared locks without fcntl: every hold is exclusive
        from filelock import FileLock, Timeout

        lock = FileLock(path, timeout=0)
        try:
            lock.acquire()
        except Timeout:
            yield False
            return
        try:
            yield True
        finally:
            lock.release()
        return
    fd = _locked_descriptor(path, fcntl.LOCK_SH if shared else fcntl.LOCK_EX)
    if fd is None:
        yield False
        return
    try:
        yield True
    finally:
        try:  # the last holder removes the file, so that no lock file stays behind in the folder
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            path.unlink(missing_ok=True)
        except BlockingIOError:
            pass  # another job shares the lock: it removes the file when it ends
        finally:
            os.close(fd)  # closing the descriptor releases the lock


def _locked_descriptor(path: Path, mode: int) -> int | None:
    """
    :param path: the lock file (created when missing)
    :param mode: ``fcntl.LOCK_SH`` or ``fcntl.LOCK_EX``
    :return: a descriptor of ``path`` holding the lock, or None when another process holds it. A file that its
        last holder removed between our open and our lock is opened again, so two jobs never hold the locks of two
        different files of one name.
    """
    import fcntl

    while True:
        # created readable and writable as the umask allows; opened for writing where it may be (an exclusive flock
        # on NFS needs it), else read-only: a lock file another user of a shared folder left can still be locked
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        except PermissionError:
            fd = os.open(path, os.O_RDONLY)
        try:
            fcntl.flock(fd, mode | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return None
        try:
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                return fd
        except FileNotFoundError:
            pass
        os.close(fd)


@contextlib.contextmanager
def output_lock(out: str | Path, name: str = FOLDER_LOCK) -> Iterator[Path]:
    """
    Hold the lock of an output folder, or of one run in it, for the duration of a job (OS file locks:
    released when the process ends, even when killed).

    A whole-folder job (``compare``, ``reproduce``: ``name`` is :data:`FOLDER_LOCK`) holds the folder's lock
    alone. A job of one run (``train``: ``name`` is the run's lock, e.g. ``.<run_id>.lock``) holds its own lock
    and shares the folder's lock with other runs' jobs, so that runs of other ids may train into the folder at
    the same time, but no whole-folder job while any of them does, and the other way round.

    :param out: the folder
    :param name: the lock file's name in it
    :raises OutputBusyError: another process holds it
    """
    out = Path(out)
    with contextlib.ExitStack() as stack:
        holds = [(out / FOLDER_LOCK, name != FOLDER_LOCK)]
        if name != FOLDER_LOCK:
            holds.append((out / name, False))
        for path, shared in holds:
            if not stack.enter_context(hold_lock(path, shared)):
                raise OutputBusyError(
                    f"{out} is in use by another job (lock {path}); wait for it to end, or use another output folder"
                )
        yield out / name


def tensorboard_folder(out: str | Path, spec: RunSpec, tensorboard_dir: str | Path | None = None) -> Path:
    """:return: a run's TensorBoard folder, ``<tensorboard_dir>/<run_id>`` (default root: ``<out>/tb``)"""
    return (Path(out) / "tb" if tensorboard_dir is None else Path(tensorboard_dir)) / spec.run_id


#: The file in a TensorBoard folder outside the output folder that names the run owning it.
TENSORBOARD_OWNER = ".owner.json"


@contextlib.contextmanager
def tensorboard_claim(tb_dir: Path, out: Path, run_id: str, fresh: bool) -> Iterator[Path]:
    """
    Own a run's TensorBoard folder while the run trains, so that no run deletes or writes into another's logs.

    A folder inside the output folder (the default, ``<out>/tb/<run_id>``) is covered by the output folder's
    lock (:func:`output_lock`). One elsewhere gets a lock of its own for the run's duration and a
    :data:`TENSORBOARD_OWNER` file naming the output folder and run id; a folder that holds logs of another
    output folder's run (its marker, also inside the output folder) or, elsewhere, logs of unknown origin is
    refused, never emptied.

    :param tb_dir: the run's TensorBoard folder (:func:`tensorboard_folder`)
    :param out: the run's output folder
    :param run_id: the run's id
    :param fresh: the run starts afresh: the folder's old logs (this run's) are removed
    :raises OutputBusyError: another process trains into the folder
    :raises RunMismatchError: the folder holds another run's logs
    """
    out = Path(out).resolve()
    owner = {"out": str(out), "run_id": run_id}
    with contextlib.ExitStack() as stack:
        outside = not tb_dir.resolve().is_relative_to(out)
        if outside:
            lock = tb_dir.parent / f".{tb_dir.name}.lock"
            if not stack.enter_context(hold_lock(lock, shared=False)):
                raise OutputBusyError(
                    f"TensorBoard folder {tb_dir} is in use by another run (lock {lock}); wait for it to end, or "
                    "log to another folder"
                )
        marker = tb_dir / TENSORBOARD_OWNER
        # Inside the output folder only a marker says the logs are another's (a run of another folder logged here).
        if tb_dir.is_dir() and (marker.exists() or (outside and any(tb_dir.iterdir()))):
            try:
                stored = json.loads(marker.read_text())
            except (OSError, ValueError):
                stored = None
            if stored != owner:
                whose = "of unknown origin" if stored is None else f"of run {stored.get('run_id')} in {stored.get('out')}"
                raise RunMismatchError(
                    f"TensorBoard folder {tb_dir} holds the logs {whose}, not of run {run_id} in {out}; log to "
                    f"another folder (the default is inside the output folder) or delete {tb_dir}"
                )
        if fresh:
            shutil.rmtree(tb_dir, ignore_errors=True)  # this run's own logs of an interrupted attempt
        if outside:
            write_json(tb_dir / TENSORBOARD_OWNER, owner)
        yield tb_dir


def run_logger(tb_dir: Path, verbose: int = 0, resumed_at: int | None = None) -> sb3_logger.Logger:
    """
    A run's SB3 logger: TensorBoard and ``progress.csv`` in exactly ``tb_dir`` (SB3's own would append ``_1``),
    and stdout when ``verbose``. A run resumed from its checkpoint at step ``T`` keeps its logs up to ``T`` and
    drops those after it, which it trains again: the CSV keeps its rows of steps up to ``T`` (was overwritten),
    and TensorBoard hides the earlier attempt's events of steps after ``T`` (``SummaryWriter``'s ``purge_step``;
    they were shown twice).

    :param tb_dir: the run's TensorBoard folder
    :param verbose: also print the logs
    :param resumed_at: the checkpoint's step count; None: a fresh start
    :return: the logger
    """
    csv_path = tb_dir / "progress.csv"
    kept = _csv_rows_until(csv_path, resumed_at) if resumed_at is not None else None
    tb_dir.mkdir(parents=True, exist_ok=True)
    formats = [sb3_logger.CSVOutputFormat(str(csv_path))]
    if kept is not None:  # the rows the resumed run keeps, under the header SB3 extends as new keys appear
        formats[0].keys = kept[0]
        formats[0].file.writelines([",".join(kept[0]) + "\n", *kept[1]])
        formats[0].file.flush()
    formats.append(
        sb3_logger.TensorBoardOutputFormat(str(tb_dir)) if resumed_at is None else _PurgingTensorBoard(tb_dir, resumed_at + 1)
    )
    if verbose:
        formats.append(sb3_logger.make_output_format("stdout", str(tb_dir)))
    return sb3_logger.Logger(folder=str(tb_dir), output_formats=formats)


class _PurgingTensorBoard(sb3_logger.TensorBoardOutputFormat):
    """SB3's TensorBoard output whose writer hides the events of steps from ``purge_step`` on in the folder's older
    event files (``torch.utils.tensorboard.SummaryWriter(purge_step=...)``)."""

    def __init__(self, folder: Path, purge_step: int) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.writer = SummaryWriter(log_dir=str(folder), purge_step=purge_step)
        self._is_closed = False


def _csv_rows_until(path: Path, step: int) -> tuple[list[str], list[str]] | None:
    """:return: the header and the lines of ``progress.csv`` up to the first row logged after ``step`` (None: no file)"""
    import csv

    try:
        lines = path.read_text().splitlines(keepends=True)
    except (OSError, UnicodeDecodeError):
        return None
    if lines and not lines[-1].endswith("\n"):  # a row cut by a kill (SB3 ends each row before it flushes)
        lines.pop()
    if not lines:
        return None
    header = next(csv.reader(lines[:1]))
    column = header.index("time/total_timesteps") if "time/total_timesteps" in header else None
    rows = []
    for line in lines[1:]:
        cells = next(csv.reader([line]), [])
        if column is not None and column < len(cells) and cells[column]:
            try:
                if float(cells[column]) > step:
                    break
            except ValueError:  # not a step count: a damaged row, and what follows it is not kept either
                break
        rows.append(line)
    return header, rows


def save_checkpoint(
    model: Any,
    run_dir: Path,
    identity: dict[str, Any],
    episodes: int,
    exact: bool = True,
    train_s: float | None = None,
) -> Path:
    """
    Write a checkpoint: model, replay buffer and training state (:mod:`.training_state`) into a fresh
    ``checkpoints/<episodes>`` folder, then ``checkpoint.json`` (atomically) pointing at it, then remove the older
    folders. A kill at any point leaves the previous checkpoint usable.

    :param model: the model, between two iterations of its ``learn`` loop
    :param run_dir: the run's folder
    :param identity: the run's identity, recorded with the checkpoint
    :param episodes: the episodes trained
    :param exact: whether the training so far is the uninterrupted run's (it started afresh, or resumed from
        an exact checkpoint), so that resuming from this one gives the uninterrupted run's training bit for bit
        (recorded so where the training state is kept: the model trains on a ``DummyVecEnv``)
    :param train_s: the wall-clock seconds of the training up to this checkpoint, over all its resumed parts (None:
        not known, the run resumed from a checkpoint that does not record them)
    :return: the checkpoint folder
    """
    folder = run_dir / "checkpoints" / f"episode_{episodes}"
    shutil.rmtree(folder, ignore_errors=True)
    atomic_write(folder / "model.zip", model.save)
    if getattr(model, "replay_buffer", None) is not None:
        atomic_write(folder / "replay_buffer.pkl", model.save_replay_buffer)
    kept = isinstance(model.get_env(), DummyVecEnv)  # the training state keeps a DummyVecEnv's envs only
    if kept:
        atomic_write(folder / TRAINING_STATE, lambda path: save_training_state(model, path))
    pointer = {
        "identity": identity,
        "episodes": episodes,
        "timesteps": int(model.num_timesteps),
        "folder": str(folder.relative_to(run_dir)),
        "same_as_uninterrupted": exact and kept,
        "train_s": train_s,
        "made_with": made_with(),
    }
    write_json(run_dir / "checkpoint.json", pointer, indent=1)
    for other in (run_dir / "checkpoints").iterdir():
        if other != folder:
            shutil.rmtree(other, ignore_errors=True)
    return folder


def read_checkpoint(run_dir: str | Path, identity: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """
    The latest checkpoint of a run, checked against the run's identity.

    :func:`save_checkpoint` writes ``checkpoint.json`` after the checkpoint's files, and :func:`clear_checkpoints`
    removes it before them, so a record whose ``model.zip`` is missing was changed from outside: an error, never a
    silent fresh start (which would delete the run's folder). Checkpoint folders that the record does not name (a
    kill while one was written) are no error: the next checkpoint, or the run's end, removes them.

    :param run_dir: the run's folder
    :param identity: the run's :func:`run_identity` (None: not checked)
    :return: ``checkpoint.json``'s content plus ``path`` (the folder), ``train_s`` None where it records no duration,
        or None when there is no ``checkpoint.json``
    :raises RunMismatchError: the checkpoint is another run's
    :raises DamagedRecordError: the checkpoint record is damaged, or the checkpoint it names has no ``model.zip``
    """
    run_dir = Path(run_dir)
    pointer = run_dir / "checkpoint.json"
    if not pointer.exists():
        return None
    checkpoint = _read_record(pointer)
    if identity is not None:
        check_identity(checkpoint, identity, pointer)
    folder = checkpoint.get("folder")
    counts = [checkpoint.get(name) for name in ("episodes", "timesteps")]
    if (
        not isinstance(folder, str)
        or len(Path(folder).parts) != 2
        or Path(folder).parts[0] != "checkpoints"
        or Path(folder).name in ("..", ".")
        or not all(isinstance(count, int) and not isinstance(count, bool) and count >= 0 for count in counts)
    ):
        raise DamagedRecordError(
            f"{pointer} is not a checkpoint record (folder {str(folder)[:80]!r}, episodes and timesteps "
            f"{str(counts)[:80]}); delete {pointer} to start the run afresh"
        )
    checkpoint["path"] = run_dir / folder
    train_s = checkpoint.get("train_s")
    if not (isinstance(train_s, int | float) and not isinstance(train_s, bool) and 0 <= train_s < math.inf):
        checkpoint["train_s"] = None  # not recorded (a checkpoint of an earlier version), or not a duration
    if not (checkpoint["path"] / "model.zip").is_file():
        raise DamagedRecordError(
            f"{pointer} names the checkpoint {checkpoint['path']}, which has no model.zip (removed from outside?); "
            f"delete {pointer} to start the run afresh"
        )
    return checkpoint


def read_trained(run_dir: str | Path, identity: dict[str, Any]) -> dict[str, Any] | None:
    """
    The record of a run that finished training and was interrupted before its result was written (in its
    evaluations): what the result keeps of the training, so that the run is evaluated without training again.

    :param run_dir: the run's folder
    :param identity: the run's :func:`run_identity`
    :return: the record, or None when there is none (or no ``model.zip`` beside it: removed from outside)
    :raises RunMismatchError: the record is another run's
    :raises DamagedRecordError: the record cannot be read
    """
    path = Path(run_dir) / TRAINED_RECORD
    if not path.exists() or not (path.parent / "model.zip").is_file():
        return None
    record = _read_record(path)
    check_identity(record, identity, path)
    return record


def failure_path(out: str | Path, spec: RunSpec) -> Path:
    """:return: the record of a failed run (:func:`sb3_dtdpg.experiments.runs.run_one` writes it when training diverges)"""
    return run_folder(out, spec) / "failed.json"


def clear_checkpoints(run_dir: Path) -> None:
    """
    Remove a finished run's checkpoints and progress record (its result supersedes them; a replay buffer can be large).
    The checkpoint record goes first, so that a kill part way never leaves a record naming a removed checkpoint.
    """
    (run_dir / "checkpoint.json").unlink(missing_ok=True)
    (run_dir / "progress.json").unlink(missing_ok=True)
    (run_dir / TRAINED_RECORD).unlink(missing_ok=True)
    shutil.rmtree(run_dir / "checkpoints", ignore_errors=True)


def _as_option(key: str, value: Any) -> str:
    """An option and its value as typed on the command line (``--env-kwargs '{"scenario": "small"}'``)."""
    if value is None:
        return f"--{key.replace('_', '-')} (unset)"
    shown = f"'{json.dumps(value)}'" if isinstance(value, dict | list) else str(value)
    return f"--{key.replace('_', '-')} {shown}"


def settings_mismatch(path: str | Path, settings: dict[str, Any]) -> str | None:
    """
    Why the record a benchmark script stored at ``path`` cannot stand for a run with ``settings``: the scripts name
    their record files by a few options only and store the others under the record's ``"settings"``.

    :param path: the run's record file (JSON)
    :param settings: this command's settings of the run, per option (its ``argparse`` dest); compared as the JSON
        record gives them back (tuples as lists)
    :return: the reason, naming each option that differs with both values (or that the record cannot be checked);
        None when no record is stored or it has these settings
    """
    if not os.path.exists(path):
        return None
    try:
        with open(path) as f:
            record = json.load(f)
    except (OSError, ValueError) as error:
        return f"{path} cannot be read ({error}), so its settings cannot be checked"
    stored = record.get("settings") if isinstance(record, dict) else None
    if not isinstance(stored, dict):
        return f"{path} was stored by an older version of this script, without its settings, so they cannot be checked"
    settings = json.loads(json.dumps(settings))
    differ = [key for key in [*settings, *(k for k in stored if k not in settings)] if stored.get(key) != settings.get(key)]
    if not differ:
        return None
    old = ", ".join(_as_option(key, stored.get(key)) for key in differ)
    new = ", ".join(_as_option(key, settings.get(key)) for key in differ)
    return f"{path} was run with {old}; this command asks for {new}"


def reuse_error(runs: Iterable[tuple[str | Path, dict[str, Any]]]) -> str | None:
    """
    :param runs: each run's record file and this command's settings of it (:func:`settings_mismatch`)
    :return: the error of a command that would reuse stored runs of other settings: the first one's reason, how many
        there are, and what to do; None when every stored run can be reused
    """
    reasons = [reason for reason in (settings_mismatch(path, settings) for path, settings in runs) if reason is not None]
    if not reasons:
        return None
    if len(reasons) == 1:
        return f"{reasons[0]}: use another --out, or delete the file to run it again"
    return (
        f"{reasons[0]} ({len(reasons)} stored runs cannot be reused): use another --out, or delete those files to run "
        "them again"
    )
