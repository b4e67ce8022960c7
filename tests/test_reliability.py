"""Results never mixed up, jobs never overlapping, workers never orphaned, train resumable, temp files removed."""

import dataclasses
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import yaml

from noma_radiomap import load_scenario
from sb3_dtdpg.cli import main
from sb3_dtdpg.common.files import atomic_write, remove_temp_files, safe_name
from sb3_dtdpg.experiments import pool as pool_module
from sb3_dtdpg.experiments import runs
from sb3_dtdpg.experiments.compare import compare_specs, run_compare
from sb3_dtdpg.experiments.reproduce import reproduce_specs, run_reproduce
from sb3_dtdpg.experiments.runs import (
    BUDGETS,
    RUN_FORMAT_VERSION,
    OutputBusyError,
    RunMismatchError,
    RunSpec,
    load_result,
    output_lock,
    result_path,
    run_identity,
    worker_pool,
)

pytestmark = pytest.mark.filterwarnings("ignore:The inplace keyword:DeprecationWarning", "ignore::FutureWarning")


@pytest.fixture(autouse=True)
def _agg_backend(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")


def _store(out, spec, identity=None, episodes=None):
    """A finished-looking result file for a spec (nothing trained)."""
    path = result_path(out, spec)
    path.parent.mkdir(parents=True, exist_ok=True)
    result = {"spec": dataclasses.asdict(spec), "train": {"episodes": spec.episodes if episodes is None else episodes}}
    if identity is not False:
        result["identity"] = run_identity(spec) if identity is None else identity
    path.write_text(json.dumps(result))
    return path


# ---------------------------------------------------------------------------------------------- run identity
def test_compare_refuses_a_folder_holding_another_budgets_runs(tmp_path):
    """The issue's case: `compare --budget tiny` then `--budget default` into the same folder."""
    for spec in compare_specs(BUDGETS["tiny"], 1):
        _store(tmp_path, spec)
    tiny, default = BUDGETS["tiny"].episodes, BUDGETS["default"].episodes
    with pytest.raises(RunMismatchError, match=rf"same id .*spec\.episodes: {tiny} stored, {default} now"):
        run_compare(tmp_path, budget="default", seeds=1, progress=False)
    assert not (tmp_path / "results.md").exists()


def test_reproduce_reduced_and_small_are_told_apart_even_report_only(tmp_path):
    reduced, small = BUDGETS["reduced"], BUDGETS["small"]
    spec_reduced = reproduce_specs(reduced, 1)["table_ii"][0]
    spec_small = reproduce_specs(small, 1)["table_ii"][0]
    assert spec_reduced.run_id == spec_small.run_id  # same ids ...
    assert run_identity(spec_reduced)["scenario"]["name"] == "small" != run_identity(spec_small)["scenario"]["name"]
    for specs in reproduce_specs(reduced, 1).values():
        for spec in specs:
            _store(tmp_path, spec)
    with pytest.raises(RunMismatchError, match=r"same id \(scenario: 'small' stored, 'mall' now; scenario\."):
        run_reproduce(tmp_path, budget="small", seeds=1, progress=False, train=False)


@pytest.mark.parametrize(
    ("change", "pattern"),
    [
        (lambda spec: dataclasses.replace(spec, episodes=1), r"spec\.episodes: 1 stored, 3 now"),
        (lambda spec: dataclasses.replace(spec, eval_episodes=9), r"spec\.eval_episodes: 9 stored"),
        (
            lambda spec: dataclasses.replace(spec, scenario="mall"),
            r"same id \(scenario: 'mall' stored, 'small' now; scenario\.",
        ),
        (lambda spec: dataclasses.replace(spec, inducing="geodesic"), r"spec\.inducing: 'geodesic' stored, None now"),
    ],
)
def test_a_result_of_another_run_is_refused(tmp_path, change, pattern):
    spec = compare_specs(BUDGETS["_micro"], 1)[0]
    _store(tmp_path, spec, identity=run_identity(change(spec)))
    with pytest.raises(RunMismatchError, match=pattern):
        load_result(tmp_path, spec)


@pytest.mark.parametrize("stored", [{"lean": False, "backprop": False}, {}], ids=["switched_off", "before_they_existed"])
def test_the_lean_step_switches_do_not_make_another_run(tmp_path, stored):
    """lean and backprop give the same weights bit for bit: results stored with them off, or before them, are this run's."""
    spec = RunSpec("dtdpg", "noma", 0, 3, scenario="small")
    identity = run_identity(spec)
    assert identity["hyperparameters"]["lean"] is True and identity["hyperparameters"]["backprop"] is True
    hyperparameters = {k: v for k, v in identity["hyperparameters"].items() if k not in ("lean", "backprop")}
    _store(tmp_path, spec, identity={**identity, "hyperparameters": {**hyperparameters, **stored}})
    assert load_result(tmp_path, spec) is not None
    # any other setting still tells runs apart
    _store(tmp_path, spec, identity={**identity, "hyperparameters": {**hyperparameters, **stored, "tau": 0.5}})
    with pytest.raises(RunMismatchError, match=r"hyperparameters\.tau: 0\.5 stored"):
        load_result(tmp_path, spec)


def test_results_without_identity_or_of_older_format_are_refused(tmp_path):
    spec = compare_specs(BUDGETS["_micro"], 1)[0]
    _store(tmp_path, spec, identity=False)
    with pytest.raises(RunMismatchError, match=rf"format: 1 stored, {RUN_FORMAT_VERSION} now"):
        load_result(tmp_path, spec)


def test_hyperparameters_and_scenario_content_are_part_of_the_identity(tmp_path, monkeypatch):
    from sb3_dtdpg import baselines

    spec = RunSpec("ddpg", "noma", 0, 3, scenario="small", hyperparams="tuned")
    before = run_identity(spec)
    monkeypatch.setitem(baselines.TUNED_KWARGS, "gamma", 0.9)
    assert run_identity(spec)["hyperparameters"]["gamma"] == 0.9 != before["hyperparameters"]["gamma"]
    # what is recorded is what the model trains with: DT-DPG with Table I (recorded lr 1e-3 / batch 128 once)
    paper = run_identity(RunSpec("dtdpg", "noma", 0, 3, scenario="small", hyperparams="paper"))["hyperparameters"]
    assert (paper["learning_rate"], paper["batch_size"], paper["gamma"], paper["tau"]) == (1e-4, 64, 1.0, 0.002)
    assert paper["buffer_size"] == 50_000 and paper["n_steps"] == 1
    # A scenario file edited since the run: same path, other content.
    path = tmp_path / "office.yaml"
    data = load_scenario("small").to_dict()
    path.write_text(yaml.safe_dump(data))
    file_spec = RunSpec("ddpg", "noma", 0, 3, scenario=str(path))
    _store(tmp_path / "out", file_spec)
    assert load_result(tmp_path / "out", file_spec) is not None
    data["ap"]["max_power_dbm"] = 10.0
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(RunMismatchError, match=r"scenario\.ap\.max_power_dbm: 20\.0 stored, 10\.0 now"):
        load_result(tmp_path / "out", file_spec)


# ---------------------------------------------------------------------------------------------- locks
def test_a_second_job_on_a_busy_folder_is_refused(tmp_path):
    with output_lock(tmp_path):
        with pytest.raises(OutputBusyError, match="in use by another job"):
            run_compare(tmp_path, budget="_micro", seeds=1, progress=False)
        with pytest.raises(OutputBusyError):
            run_reproduce(tmp_path, budget="_micro", seeds=1, progress=False)
    with output_lock(tmp_path):  # released
        pass


def test_report_only_of_a_folder_without_finished_runs_is_refused_and_creates_nothing(tmp_path):
    with pytest.raises(
        ValueError, match=r"holds no finished runs of this job \(none of its \d+ runs: budget '_micro', 1 seeds.*train=True"
    ):
        run_reproduce(tmp_path / "none", budget="_micro", seeds=1, progress=False, train=False)
    assert not (tmp_path / "none").exists()


def test_the_lock_of_a_killed_job_is_released(tmp_path):
    code = f"from sb3_dtdpg.experiments.runs import output_lock\nwith output_lock({str(tmp_path)!r}):\n"
    code += "    print('locked', flush=True)\n    import time; time.sleep(60)\n"
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(OutputBusyError):
            with output_lock(tmp_path):
                pass
    finally:
        holder.kill()
        holder.wait()
    with output_lock(tmp_path):
        pass


# ---------------------------------------------------------------------------------------------- workers
PARENT = textwrap.dedent(
    """
    import os, time
    from sb3_dtdpg.experiments.runs import worker_pool

    def pid_after(seconds):
        time.sleep(seconds)
        return os.getpid()

    if __name__ == "__main__":
        pool = worker_pool(2)
        ready = set()
        while len(ready) < 2:  # both workers started (their initialiser has run)
            ready |= {f.result() for f in [pool.submit(pid_after, 1.0) for _ in range(2)]}
        futures = [pool.submit(time.sleep, 120) for _ in range(4)]  # two running, two queued
        time.sleep(0.5)
        print(" ".join(str(pid) for pid in ready), flush=True)
        time.sleep(120)
    """
)


def _alive(pid):
    try:
        with open(f"/proc/{pid}/status") as status:
            return "\nState:\tZ" not in status.read()
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_workers_end_with_their_parent(tmp_path, sig):
    script = tmp_path / "parent.py"
    script.write_text(PARENT)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, env=env)
    try:
        workers = [int(pid) for pid in parent.stdout.readline().split()]
        assert len(workers) == 2 and all(_alive(pid) for pid in workers)
        parent.send_signal(sig)
        parent.wait(timeout=10)
        deadline = time.monotonic() + 10
        while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_alive(pid) for pid in workers)
    finally:
        parent.kill()


def test_run_many_uses_the_pool_that_ends_with_its_parent():
    pool = worker_pool(1)
    try:
        assert pool.submit(os.getppid).result() == os.getpid()
        assert pool._initializer is pool_module._start_worker and pool._initargs[0] == os.getpid()
    finally:
        pool.shutdown()


def _format_warning(*arguments):
    """:return: the warning's text as this process formats it (run in a worker)"""
    import warnings

    return warnings.formatwarning(*arguments)


def test_the_workers_show_warnings_as_the_command_line_does():
    """The command line shows warnings as one line each (``sb3-dtdpg compare: warning: ...``), its job's spawned
    workers too (was: Python's ``<file>:<line>: <Category>: ...`` and the source line, from the workers)."""
    import warnings

    from sb3_dtdpg.common.warning_lines import warnings_as_lines

    arguments = ("runs of other versions", UserWarning, "x.py", 1)
    with warnings_as_lines("sb3-dtdpg compare"):
        pool = worker_pool(1)
        try:
            assert pool.submit(_format_warning, *arguments).result() == (
                "sb3-dtdpg compare: warning: runs of other versions\n"
            )
        finally:
            pool.shutdown()
    pool = worker_pool(1)  # outside the command line: Python's format
    try:
        assert pool.submit(_format_warning, *arguments).result() == warnings.formatwarning(*arguments)
    finally:
        pool.shutdown()


UNGUARDED = textwrap.dedent(
    """
    import collections, sys
    from sb3_dtdpg.experiments.pool import RunReport, run_in_pool

    Job = collections.namedtuple("Job", "run_id")
    report = RunReport()
    run_in_pool(print, [(Job("r0"),)], sys.argv[1], 1, report, progress=False)  # no __main__ guard
    print(report.failed["r0"])
    """
)


def test_a_run_pool_started_from_a_script_without_main_guard_says_so(tmp_path):
    script = tmp_path / "unguarded.py"
    script.write_text(UNGUARDED)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    done = subprocess.run([sys.executable, str(script), str(tmp_path)], capture_output=True, text=True, env=env, timeout=120)
    assert done.stdout.strip().splitlines()[-1].startswith("BrokenProcessPool: ")
    assert 'missing `if __name__ == "__main__":` guard' in done.stdout


# ---------------------------------------------------------------------------------------------- train
TRAIN = [
    "train",
    "--hyperparams",
    "paper",
    "--observation",
    "paper",
    "--scenario",
    "small",
    "--episodes",
    "4",
    "--checkpoint-every",
    "2",
    "--eval-episodes",
    "1",
]


@pytest.mark.parametrize("algo", ["ddpg", "dtdpg"])
def test_train_writes_checkpoints_and_resumes(tmp_path, monkeypatch, capsys, algo):
    original = runs.PeriodicCheckpoint._on_rollout_start

    def interrupt_after_first_checkpoint(self):
        due = self._due
        original(self)
        if due:
            raise KeyboardInterrupt

    argv = [*TRAIN, "--algo", algo, "--out", str(tmp_path), "--tb", str(tmp_path / "tb"), "--no-progress"]
    monkeypatch.setattr(runs.PeriodicCheckpoint, "_on_rollout_start", interrupt_after_first_checkpoint)
    assert main(argv) == 130
    message = capsys.readouterr().err
    run_dir = tmp_path / "runs" / f"{algo}_noma_s0"
    assert "the checkpoint after 2 episodes is in" in message and "run the same command again to resume" in message
    checkpoint = json.loads((run_dir / "checkpoint.json").read_text())
    assert checkpoint["episodes"] == 2 and checkpoint["timesteps"] >= 2
    folder = run_dir / checkpoint["folder"]
    assert (folder / "model.zip").stat().st_size > 0 and (folder / "replay_buffer.pkl").stat().st_size > 0
    assert not result_path(tmp_path, RunSpec(algo, "noma", 0, 4)).exists()
    stale = run_dir / ".model.zip.killed.tmp"  # what a write killed by SIGKILL leaves
    stale.write_bytes(b"")

    monkeypatch.setattr(runs.PeriodicCheckpoint, "_on_rollout_start", original)
    assert main(argv) == 0
    assert "resumed after episode 2" in capsys.readouterr().out
    result = json.loads((run_dir / "result.json").read_text())
    assert result["train"]["episodes"] == 4 and result["train"]["resumed_at_episode"] == 2
    assert result["train"]["timesteps"] > checkpoint["timesteps"]
    if algo == "dtdpg":
        assert result["curriculum_state"]["phase_index"] == 1  # the transfer after episode 2 carried over
        assert (run_dir / "phase_1_mqi.zip").is_file()  # the resumed model saves its phase in the run's folder
    assert not stale.exists() and not (run_dir / "checkpoint.json").exists() and not (run_dir / "checkpoints").exists()
    # Finished: the same command returns the result; other settings in the same folder are refused.
    assert main(argv) == 0
    with pytest.raises(SystemExit) as exit_info:  # another run under the same id: one error line, no traceback
        main([*argv, "--episodes", "5"])
    assert exit_info.value.code == 2 and "spec.episodes: 4 stored, 5 now" in capsys.readouterr().err


def test_a_resumed_train_keeps_its_logs_up_to_the_checkpoint_and_shows_each_step_once(tmp_path, monkeypatch):
    import pandas as pd
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    original = runs.PeriodicCheckpoint._on_rollout_start

    def interrupt_an_episode_after_the_first_checkpoint(self):  # the checkpoint after episode 2, logs to episode 3
        original(self)
        if self.counter.n_episodes >= 3:
            raise KeyboardInterrupt

    argv = [*TRAIN, "--algo", "ddpg", "--episodes", "6", "--out", str(tmp_path), "--no-progress"]
    monkeypatch.setattr(runs.PeriodicCheckpoint, "_on_rollout_start", interrupt_an_episode_after_the_first_checkpoint)
    assert main(argv) == 130
    checkpoint = json.loads((tmp_path / "runs" / "ddpg_noma_s0" / "checkpoint.json").read_text())
    tb = tmp_path / "tb" / "ddpg_noma_s0"
    before = pd.read_csv(tb / "progress.csv")
    assert list(before["episode/number"]) == [1, 2, 3]  # the interrupted attempt logged past its checkpoint (2)
    monkeypatch.setattr(runs.PeriodicCheckpoint, "_on_rollout_start", original)
    assert main(argv) == 0
    after = pd.read_csv(tb / "progress.csv")
    assert list(after["episode/number"]) == [1, 2, 3, 4, 5, 6]  # one row per episode, the third trained again
    kept = before[before["time/total_timesteps"] <= checkpoint["timesteps"]]
    assert len(kept) == 2  # the rows up to the checkpoint are kept
    pd.testing.assert_frame_equal(after[kept.columns][:2], kept, check_dtype=False)
    board = EventAccumulator(str(tb))  # what TensorBoard shows (it honours the purge; tbparse reads every event)
    board.Reload()
    assert [event.step for event in board.Scalars("episode/number")] == [60, 120, 180, 240, 300, 360]


@pytest.mark.parametrize(
    ("written", "kept"),
    [
        ("a,time/total_timesteps\n1,60\n2,120\n3,180\n", "1,60\n2,120\n"),  # the rows after the checkpoint go
        ("a,time/total_timesteps\n1,60\n2,1", "1,60\n"),  # a row cut by a kill is no row
        ('a,time/total_timesteps\n1,60\n2,"x"\n3,90\n', "1,60\n"),  # nor one that is not a step count
        ("", ""),
    ],
)
def test_a_resumed_runs_csv_keeps_its_whole_rows_up_to_the_checkpoint(tmp_path, written, kept):
    from sb3_dtdpg.experiments.storage import run_logger

    (tmp_path / "progress.csv").write_text(written)
    run_logger(tmp_path, resumed_at=120).close()
    text = (tmp_path / "progress.csv").read_text()
    assert text == ("a,time/total_timesteps\n" + kept if written else "")


# ---------------------------------------------------------------------------------------------- files
def test_strict_json_writes_non_finite_numbers_as_null(tmp_path):
    import numpy as np

    from sb3_dtdpg.common.files import write_json

    data = {"a": np.float32("nan"), "b": [1.0, float("inf")], "c": np.array([np.nan, 2.0]), "d": np.int64(3)}
    write_json(tmp_path / "x.json", data, strict=True)
    assert json.loads((tmp_path / "x.json").read_text()) == {"a": None, "b": [1.0, None], "c": [None, 2.0], "d": 3}


def test_atomic_write_leaves_no_temp_file_when_interrupted(tmp_path):
    target = tmp_path / "model.zip"
    target.write_bytes(b"old")

    def killed(path):
        with open(path, "wb") as file:
            file.write(b"par")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write(target, killed)
    assert target.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["model.zip"]
    atomic_write(target, lambda path: open(path, "wb").write(b"new"))
    assert target.read_bytes() == b"new" and sorted(p.name for p in tmp_path.iterdir()) == ["model.zip"]


def test_tables_and_figures_are_replaced_whole_or_not_at_all(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    from noma_radiomap.planners import RandomPlanner
    from sb3_dtdpg.common.files import save_figure
    from sb3_dtdpg.evaluation import evaluate
    from sb3_dtdpg.experiments import tables

    result = evaluate(RandomPlanner(seed=0), "NomaRadioMap-v0", n_episodes=2, env_kwargs={"scenario": "small"})
    summary = pd.DataFrame([tables.planner_row("random", "noma", result)])
    tables.save_tables(summary, pd.DataFrame(), tmp_path, "results", "old")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}

    def interrupted(frame, path, **kwargs):
        Path(path).write_text("algorithm,mult")
        raise KeyboardInterrupt

    monkeypatch.setattr(pd.DataFrame, "to_csv", interrupted)
    with pytest.raises(KeyboardInterrupt):
        tables.save_tables(summary.assign(mqi_mean=1.0), pd.DataFrame(), tmp_path, "results", "new")
    monkeypatch.undo()
    # results.md is the new one (written first), results.csv the old one whole, no temporary file left
    assert (tmp_path / "results.md").read_text().startswith("# new")
    assert (tmp_path / "results.csv").read_bytes() == before["results.csv"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.csv", "results.md"]
    # A figure is written in its extension's format, though the temporary file ends in .tmp.
    figure = plt.figure()
    for name, magic in (("f.png", b"\x89PNG"), ("f.pdf", b"%PDF"), ("f.SVG", b"<?xml")):
        assert save_figure(figure, tmp_path / name).read_bytes().startswith(magic)
    plt.close(figure)


@pytest.mark.parametrize("umask", [0o022, 0o027, 0o077])
def test_atomically_written_files_get_the_mode_of_a_plain_write(tmp_path, umask):
    # mkstemp creates its file 0600: a model or result shared through a group folder would be unreadable to the group
    old = os.umask(umask)
    try:
        (tmp_path / "plain").write_text("x")
        written = atomic_write(tmp_path / "atomic", lambda path: Path(path).write_text("x"))
    finally:
        os.umask(old)
    assert oct(written.stat().st_mode & 0o777) == oct((tmp_path / "plain").stat().st_mode & 0o777) == oct(0o666 & ~umask)


def test_remove_temp_files_keeps_everything_else(tmp_path):
    for name in (".result.json.abc.tmp", ".model.zip.x1.tmp", "model.zip", ".hidden", "notes.tmp"):
        (tmp_path / name).write_bytes(b"")
    removed = remove_temp_files(tmp_path)
    assert sorted(p.name for p in removed) == [".model.zip.x1.tmp", ".result.json.abc.tmp"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [".hidden", "model.zip", "notes.tmp"]


@pytest.mark.parametrize(
    ("name", "expected"),
    [("x/../../escaped", "x_escaped"), ("..", "_"), ("/etc/passwd", "_etc_passwd"), ("a\\b:c", "a_b_c"), ("mall", "mall")],
)
def test_safe_name(name, expected):
    assert safe_name(name) == expected


def test_map_keeps_a_hostile_scenario_name_inside_out(tmp_path):
    data = load_scenario("small").to_dict()
    data["name"] = "x/../../escaped"
    path = tmp_path / "evil.yaml"
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "a" / "b" / "maps"
    assert main(["map", "--scenario", str(path), "--out", str(out)]) == 0
    assert [p.name for p in out.iterdir()] == ["maps_x_escaped.png"]
    assert [p.parent for p in tmp_path.rglob("*.png")] == [out]


def test_curriculum_checkpoints_leave_no_temp_files_and_clean_old_ones(tmp_path):
    import gymnasium as gym

    from sb3_dtdpg import DTDPG

    stale = tmp_path / ".phase_0_train.zip.killed.tmp"  # the one phase of the default curriculum on small
    stale.write_bytes(b"")  # a save killed by SIGKILL
    others = [tmp_path / ".results.csv.tmp", tmp_path / ".results.csv.x1.tmp"]  # another program's, in the user's folder
    for other in others:
        other.write_bytes(b"kept")
    env = gym.make("NomaRadioMap-v0", scenario="small")
    model = DTDPG("MlpPolicy", env, learning_starts=10, curriculum_save_path=str(tmp_path), policy_kwargs={"net_arch": [8]})
    model.learn(1)
    assert not stale.exists()
    assert all(other.read_bytes() == b"kept" for other in others)  # were deleted as leftovers of the curriculum


def test_remove_temp_files_of_named_files_only(tmp_path):
    for name in (".model.zip.x1.tmp", ".other.zip.x2.tmp", ".model.zip2.x3.tmp"):
        (tmp_path / name).write_bytes(b"")
    assert [p.name for p in remove_temp_files(tmp_path, ["model.zip"])] == [".model.zip.x1.tmp"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [".model.zip2.x3.tmp", ".other.zip.x2.tmp"]


def test_the_env_works_without_a_writable_numba_cache():
    # No cache locator available (a read-only install and home folder): the env's loops are compiled in the
    # process, with one warning, instead of failing at import
    import numba.core.config

    env = {**os.environ, "NUMBA_CACHE_LOCATOR_CLASSES": "numba.core.caching.IPythonCacheLocator"}
    # an older numba (e.g. the floor, 0.59) reads no NUMBA_CACHE_LOCATOR_CLASSES: the same locators are set by hand
    by_hand = "from numba.core import caching; caching.CacheImpl._locator_classes = [caching._IPythonCacheLocator]"
    if hasattr(numba.core.config, "CACHE_LOCATOR_CLASSES"):
        by_hand = ""
    code = by_hand + textwrap.dedent(
        """
        import warnings
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            import gymnasium as gym
            import noma_radiomap
            env = gym.make("NomaRadioMap-v0", scenario="small")
            env.reset(seed=0)
            env.step(env.action_space.sample())
        print(sum("no writable cache folder" in str(w.message) for w in caught))
        """
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "1"
