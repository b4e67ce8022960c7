"""Ctrl-C and SIGTERM of a job with workers: the workers are gone, and no queued run started, before the job
releases its folder lock (``compare``/``reproduce``: one job per folder, workers end with their job)."""

import contextlib
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from sb3_dtdpg.experiments.storage import OutputBusyError, output_lock

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals and process groups")

# A job as `compare` runs it: the folder's lock around run_in_pool, exit status 130 on Ctrl-C as the CLI's. Each
# run writes started/<run id> holding its worker's pid, then sleeps far longer than the test takes.
JOB = textwrap.dedent(
    """
    import collections, os, sys, time
    from pathlib import Path
    from sb3_dtdpg.experiments.pool import RunReport, run_in_pool
    from sb3_dtdpg.experiments.storage import output_lock

    Job = collections.namedtuple("Job", "run_id")

    def mark_and_sleep(job, out):
        marker = Path(out, "started", job.run_id)
        Path(f"{marker}.tmp").write_text(str(os.getpid()))
        os.replace(f"{marker}.tmp", marker)
        time.sleep(120)
        return job.run_id, 120.0, False

    if __name__ == "__main__":
        out = sys.argv[1]
        with output_lock(out):
            try:
                run_in_pool(mark_and_sleep, [(Job(f"r{i}"), out) for i in range(3)], out, 1, RunReport(), progress=False)
            except KeyboardInterrupt:
                sys.exit(130)
    """
)


def _alive(pid: int) -> bool:
    """:return: whether the process exists (a zombie, not yet waited for by its parent, counts)"""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.parametrize("how", ["ctrl-c", "sigint", "sigterm"])
def test_an_interrupted_job_stops_its_workers_before_it_releases_its_lock(tmp_path, how):
    script, out = tmp_path / "job.py", tmp_path / "out"
    script.write_text(JOB)
    (out / "started").mkdir(parents=True)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    # SIGINT at its default in the job even where the test runs with it ignored (a shell's background job): Python
    # then raises KeyboardInterrupt on it, as in a terminal
    job = subprocess.Popen(
        [sys.executable, str(script), str(out)],
        env=env,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        marker, deadline = out / "started" / "r0", time.monotonic() + 60
        while not marker.exists():
            assert job.poll() is None and time.monotonic() < deadline, "the first run did not start"
            time.sleep(0.05)
        worker = int(marker.read_text())
        if how == "ctrl-c":  # a terminal's Ctrl-C: SIGINT to the job's whole process group, workers included
            os.killpg(job.pid, signal.SIGINT)
        else:
            job.send_signal(signal.SIGINT if how == "sigint" else signal.SIGTERM)
        deadline = time.monotonic() + 20
        while True:  # the moment the lock is free, the worker must be gone
            try:
                with output_lock(out):
                    worker_alive = _alive(worker)
                break
            except OutputBusyError:
                assert time.monotonic() < deadline, "the job still holds its lock"
                time.sleep(0.01)
        assert not worker_alive
        assert job.wait(timeout=10) == (-signal.SIGTERM if how == "sigterm" else 130)
        assert sorted(path.name for path in (out / "started").iterdir()) == ["r0"]  # no queued run started
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(job.pid, signal.SIGKILL)
        job.wait()


def test_a_worker_pool_left_by_an_exception_kills_its_workers_instead_of_finishing_the_queue():
    # The benchmarks' `with worker_pool(n) as pool:` (no run_in_pool around it): Ctrl-C in the block ends it at once.
    from sb3_dtdpg.experiments.pool import worker_pool

    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt), worker_pool(1) as pool:
        for _ in range(3):
            pool.submit(time.sleep, 60)
        workers = list(pool._processes.values())
        raise KeyboardInterrupt
    # the processes are gone (asked of the OS: multiprocessing's is_alive() can report a child reaped elsewhere as alive)
    assert time.monotonic() - start < 30 and workers and not any(_alive(worker.pid) for worker in workers)


def test_a_worker_that_does_not_die_is_left_behind_with_a_message(monkeypatch, capsys):
    # A process in uninterruptible I/O outlives SIGKILL: the stop must not wait for it forever.
    import multiprocessing.process

    from sb3_dtdpg.experiments import pool as pool_module

    monkeypatch.setattr(pool_module, "STOP_TIMEOUT_S", 0.5)
    kill = multiprocessing.process.BaseProcess.kill
    with pool_module.worker_pool(1) as pool:
        pool.submit(time.sleep, 60)
        workers = list(pool._processes.values())
        monkeypatch.setattr(multiprocessing.process.BaseProcess, "kill", lambda self: None)  # an unkillable worker
        start = time.monotonic()
        pool_module._stop_workers(pool)
        assert time.monotonic() - start < 10
        monkeypatch.setattr(multiprocessing.process.BaseProcess, "kill", kill)
        for worker in workers:
            worker.kill()
            worker.join()
    assert f"workers [{workers[0].pid}] did not end within 0.5 s of SIGKILL" in capsys.readouterr().err


def test_a_worker_reaped_by_the_pool_itself_is_not_reported_as_stuck(monkeypatch, capsys):
    # A SIGTERM to the whole process group kills the workers too, and the pool's own thread then waits for them:
    # a worker already waited for elsewhere has ended, although multiprocessing's is_alive() says otherwise.
    from sb3_dtdpg.experiments import pool as pool_module

    monkeypatch.setattr(pool_module, "STOP_TIMEOUT_S", 5.0)
    with pool_module.worker_pool(1) as pool:
        pool.submit(time.sleep, 60)
        (worker,) = pool._processes.values()
        os.kill(worker.pid, signal.SIGKILL)
        with contextlib.suppress(ChildProcessError):  # the pool's own thread may have been first: reaped either way
            os.waitpid(worker.pid, 0)  # as the pool's thread does when one of its workers dies
        start = time.monotonic()
        pool_module._stop_workers(pool)
        assert time.monotonic() - start < 5.0
    assert "did not end" not in capsys.readouterr().err
