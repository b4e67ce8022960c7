"""The worker processes of :func:`sb3_dtdpg.experiments.runs.run_many` and its progress display.

Workers are spawned processes (no state inherited from the parent) that end when their parent process ends,
however it ends, so that killing a job never leaves workers running its queued runs. On Ctrl-C or SIGTERM the
parent stops its workers and waits until they are gone before it goes on (and its job releases its folder lock).
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import multiprocessing
import os
import signal
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from multiprocessing.connection import wait as wait_for_ready
from pathlib import Path
from typing import Any

from sb3_dtdpg.common.checks import shortened
from sb3_dtdpg.common.warning_lines import WarningLines
from sb3_dtdpg.experiments.specs import RunSpec
from sb3_dtdpg.experiments.storage import read_progress

__all__ = ["RunBars", "RunReport", "RunsFailedError", "failure_message", "run_in_pool", "worker_pool"]


def _die_with_parent(parent_pid: int) -> None:
    """
    Worker initialiser: end this process when its parent ends, however it ends (SIGTERM, SIGKILL, a crash).
    On Linux the kernel sends SIGKILL (``PR_SET_PDEATHSIG``); elsewhere a thread polls the parent's pid.

    The worker ignores SIGINT: a terminal's Ctrl-C reaches the whole process group, and a worker interrupted in a
    task would go on with the next queued one; the parent stops its workers instead (:func:`run_in_pool`).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # 1 = PR_SET_PDEATHSIG
    if os.getppid() != parent_pid:  # the parent ended before the line above
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def _start_worker(parent_pid: int, formatwarning: WarningLines | None) -> None:
    """
    Worker initialiser: :func:`_die_with_parent`, and the parent's way of showing warnings when it shows them as
    :class:`~sb3_dtdpg.common.warning_lines.WarningLines` (the command line does).
    """
    _die_with_parent(parent_pid)
    if formatwarning is not None:
        warnings.formatwarning = formatwarning  # type: ignore[assignment]


def worker_pool(n_workers: int) -> ProcessPoolExecutor:
    """
    The process pool of :func:`run_in_pool`: spawned processes (no state inherited from the parent) that end when
    the parent process ends, so that killing a job never leaves workers running its queued runs, and show warnings
    as the parent does where it shows them as one line each (:mod:`sb3_dtdpg.common.warning_lines`).

    :param n_workers: number of processes
    :return: the executor (in a ``with`` block left by an exception, its workers are killed and waited for)
    """
    context = multiprocessing.get_context("spawn")
    lines = warnings.formatwarning if isinstance(warnings.formatwarning, WarningLines) else None
    return _WorkerPool(max_workers=n_workers, mp_context=context, initializer=_start_worker, initargs=(os.getpid(), lines))


class _WorkerPool(ProcessPoolExecutor):
    """A process pool whose ``with`` block, left by an exception (Ctrl-C, SIGTERM), kills its workers and waits for
    them (:func:`_stop_workers`) instead of letting them finish the tasks already queued."""

    def __exit__(self, exc_type: Any, exc_value: Any, traceback: Any) -> bool | None:
        if exc_type is not None:
            _stop_workers(self)
            return False
        return super().__exit__(exc_type, exc_value, traceback)


@dataclass
class RunReport:
    """
    What :func:`sb3_dtdpg.experiments.runs.run_many` did: run ids finished now, skipped (already finished) and
    failed (with the error); or, for a job that only reports (:meth:`of_stored`), the runs with a stored result
    (skipped) and those without one (missing).
    """

    finished: list[str] = field(default_factory=list)
    resumed: list[str] = field(default_factory=list)  #: of the finished, those that went on from a checkpoint
    skipped: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    wall_s: float = math.nan
    missing: list[str] = field(default_factory=list)

    @classmethod
    def of_stored(cls, results: Mapping[str, Any]) -> RunReport:
        """
        :param results: per run id, its stored result (None: none)
        :return: the report of a job that trained nothing: the runs without a result are missing
        """
        return cls(
            skipped=[run_id for run_id, result in results.items() if result is not None],
            missing=[run_id for run_id, result in results.items() if result is None],
        )

    def counts(self) -> str:
        """
        :return: e.g. ``"4 runs (1 resumed from its checkpoint), 2 already done, 1 failed"`` (the resumed and the
            failed only when there are some)
        """
        resumed = f" ({self.resumed_count()})" if self.resumed else ""
        failed = f", {len(self.failed)} failed" if self.failed else ""
        runs = f"{len(self.finished)} run{'' if len(self.finished) == 1 else 's'}"
        return f"{runs}{resumed}, {len(self.skipped)} already done{failed}"

    def resumed_count(self) -> str:
        """:return: e.g. ``"2 resumed from their checkpoints"`` (empty when no run resumed)"""
        n_resumed = len(self.resumed)
        return f"{n_resumed} resumed from {'its checkpoint' if n_resumed == 1 else 'their checkpoints'}" if n_resumed else ""

    def incomplete_note(self, run_ids: Iterable[str] | None = None) -> str | None:
        """
        :param run_ids: the runs of one table (None: every run of the job); those the job was not asked for (another
            mode or experiment) are not counted
        :return: the line under a table whose runs failed (None when none of them did)
        """
        ids = None if run_ids is None else set(run_ids)
        failed = [run_id for run_id in self.failed if ids is None or run_id in ids]
        missing = [run_id for run_id in self.missing if ids is None or run_id in ids]
        if not failed and not missing:
            return None
        handled = {*self.finished, *self.skipped, *self.failed, *self.missing}  # the runs this job was asked for
        total = len(handled) if ids is None else len(ids & handled)
        if failed:
            return (
                f"Incomplete: {len(failed)} of {total} runs failed ({', '.join(failed)}); the table holds only the runs "
                "that finished, and the same command again trains the failed ones"
            )
        return (
            f"Incomplete: {len(missing)} of {total} runs have no result yet ({shortened(missing, 3)}); the table "
            "holds only the runs that finished (the same job without --report-only trains the others)"
        )

    def raise_failures(self, out: str | Path) -> None:
        """:raises RunsFailedError: when runs failed"""
        if self.failed:
            raise RunsFailedError(self.failed, out)


class RunsFailedError(RuntimeError):
    """
    Runs of a ``compare`` or ``reproduce`` job failed. The job went on with the others and wrote its tables and
    figures from the runs that finished; the same command again trains the failed runs.

    :param failed: per failed run id, its error
    :param out: the job's output folder
    """

    def __init__(self, failed: dict[str, str], out: str | Path):
        self.failed = dict(failed)
        shown = shortened([f"{run_id}: {error}" for run_id, error in failed.items()], 3, separator="; ")
        runs = "run" if len(failed) == 1 else "runs"
        super().__init__(
            f"{len(failed)} {runs} failed ({shown}); the tables and figures in {out} hold only the runs that finished"
        )


def run_in_pool(
    work: Callable[..., tuple[str, float, bool]],
    jobs: Sequence[tuple[RunSpec, Any]],
    out: str | Path,
    n_workers: int,
    report: RunReport,
    progress: bool = True,
    on_finish: Callable[[str], None] | None = None,
) -> None:
    """
    Run ``work(*job)`` for every job in a :func:`worker_pool`, recording each run in ``report`` as it ends; a
    failed run does not take the others down.

    When the call ends early (Ctrl-C, SIGTERM, an error), the workers are killed and gone before it returns: the
    runs in progress are abandoned (next time they go on from their last checkpoints, or are tested again)
    and no queued run starts, so that the caller releases its folder lock only when nothing writes to the folder
    any more. Ctrl-C raises ``KeyboardInterrupt``; SIGTERM (when it has its default action) then ends the process
    as it would have.

    :param work: a module-level function (it is sent to spawned processes) returning the run id, its seconds and
        whether the run went on from a checkpoint
    :param jobs: the arguments of each call, the run's spec first
    :param out: output folder (where the running runs' progress is read)
    :param n_workers: number of processes
    :param report: where the finished and failed runs are recorded
    :param progress: show a progress bar
    :param on_finish: called with each run id as it finishes
    """
    try:
        with _sigterm_raises(), RunBars(out, len(jobs), enabled=progress) as bars:
            if not jobs:
                return
            with worker_pool(n_workers) as executor:  # left by an exception: its workers are killed first
                pending = {executor.submit(work, *job): job[0] for job in jobs}
                while pending:
                    done, _ = wait(pending, timeout=2.0 if progress else None, return_when=FIRST_COMPLETED)
                    bars.show_running(pending.values())
                    for future in done:
                        spec = pending.pop(future)
                        try:
                            _, seconds, resumed = future.result()
                            report.finished.append(spec.run_id)
                            if resumed:
                                report.resumed.append(spec.run_id)
                            bars.finished(spec.run_id, f"{spec.run_id} done in {seconds:.0f} s")
                            if on_finish is not None:
                                on_finish(spec.run_id)
                        except Exception as error:  # a failed run must not take the others down
                            report.failed[spec.run_id] = failure_message(error)
                            bars.finished(spec.run_id, f"{spec.run_id} FAILED")
    except _Terminated:
        # The workers are gone and the bars closed: now SIGTERM's default action (the handler is restored).
        signal.raise_signal(signal.SIGTERM)
        raise


#: How long :func:`_stop_workers` waits for each killed worker to end
STOP_TIMEOUT_S = 60.0


def _stop_workers(executor: ProcessPoolExecutor) -> None:
    """
    Kill the worker processes of ``executor`` and wait until they are gone. ``shutdown(cancel_futures=True)``
    alone would not stop them: a worker finishes its task and takes the queued ones already sent to it, and the
    interpreter's exit waits for them. A worker still there :data:`STOP_TIMEOUT_S` after its SIGKILL is left
    behind with a message (a process in uninterruptible I/O cannot be killed).
    """
    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if in_main else None  # a second Ctrl-C must not cut it short
    try:
        # ProcessPoolExecutor has no public way to stop its workers before Python 3.14 (kill_workers, which does
        # not wait for them); its pid -> Process map is the same from Python 3.9 to 3.14.
        processes = list((executor._processes or {}).values())
        for process in processes:
            process.kill()
        stuck = []
        for process in processes:
            # Asked of the process's sentinel, which is ready once the process has ended whoever waited for it:
            # the pool's own thread also joins the workers when one dies (a SIGTERM to the whole process group),
            # and a process reaped there looks alive to this thread's join() and is_alive().
            if wait_for_ready([process.sentinel], timeout=STOP_TIMEOUT_S):
                process.join()
            else:  # e.g. in uninterruptible I/O on a hung network disk
                stuck.append(process.pid)
        if stuck:
            print(
                f"workers {stuck} did not end within {STOP_TIMEOUT_S:g} s of SIGKILL: going on without them", file=sys.stderr
            )
        executor.shutdown(wait=not stuck, cancel_futures=True)
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


class _Terminated(BaseException):
    """SIGTERM reached the process while :func:`run_in_pool` ran (see :func:`_sigterm_raises`)."""


@contextlib.contextmanager
def _sigterm_raises() -> Iterator[None]:
    """
    Within the block, SIGTERM raises :class:`_Terminated` in the main thread instead of ending the process at
    once, so that :func:`run_in_pool` stops its workers before the process ends and its folder lock is released.
    Only where SIGTERM has its default action and in the main thread (a program's own handler is left alone).
    """
    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGTERM) != signal.SIG_DFL:
        yield
        return

    def terminated(signum: int, frame: object) -> None:
        raise _Terminated

    signal.signal(signal.SIGTERM, terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def failure_message(error: BaseException) -> str:
    """
    :param error: what a run raised, or what its future raised when its worker died
    :return: the line :attr:`RunReport.failed` records; a dead worker's says what commonly kills one
    """
    message = f"{type(error).__name__}: {error}"
    if isinstance(error, BrokenProcessPool):
        message += (
            " (a worker process died: out of memory, killed, or, when this runs from a script, a missing "
            '`if __name__ == "__main__":` guard around the call, which spawned workers need)'
        )
    return message


class RunBars:
    """
    The progress display of :func:`run_in_pool`: one bar for the runs, and one per run in progress (episodes done,
    elapsed time and ETA, read from the run's :class:`sb3_dtdpg.experiments.run_callbacks.RunProgress` file).
    """

    def __init__(self, out: str | Path, n_runs: int, enabled: bool = True) -> None:
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self.out, self.enabled = out, enabled
        self.progress = Progress(
            TextColumn("{task.fields[name]}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[unit]}"),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            disable=not enabled,
            refresh_per_second=1,  # the bars move by episodes; a faster refresh costs the parent a tenth of a core
        )
        self.runs = self.progress.add_task("", total=n_runs, name="[bold]runs", unit="")
        self.running: dict[str, Any] = {}

    def __enter__(self) -> RunBars:
        self.progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.progress.stop()

    def show_running(self, specs: Iterable[RunSpec]) -> None:
        """Update (or add) the bar of each started run of ``specs``."""
        if not self.enabled:
            return
        for spec in specs:
            record = read_progress(self.out, spec)
            if record is None:
                continue
            if spec.run_id not in self.running:
                self.running[spec.run_id] = self.progress.add_task(
                    "", total=record["total"], name=spec.run_id, unit=record["unit"]
                )
            self.progress.update(self.running[spec.run_id], completed=record["done"])

    def finished(self, run_id: str, message: str) -> None:
        """Remove the run's bar, count it as done and print ``message`` above the bars."""
        if run_id in self.running:
            self.progress.remove_task(self.running.pop(run_id))
        self.progress.update(self.runs, advance=1)
        if self.enabled:
            self.progress.console.print(message)
