"""The run harness under attack: shared TensorBoard folders, jobs on one folder, kills, diverged runs, odd paths."""

import dataclasses
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest

from sb3_dtdpg.cli import main
from sb3_dtdpg.experiments.compare import compare_specs, run_compare
from sb3_dtdpg.experiments.runs import (
    BUDGETS,
    DamagedRecordError,
    OutputBusyError,
    PeriodicCheckpoint,
    RunDivergedError,
    RunMismatchError,
    RunsFailedError,
    RunSpec,
    output_lock,
    prepare_run,
    result_path,
    run_many,
    run_one,
)

pytestmark = pytest.mark.filterwarnings("ignore:The inplace keyword:DeprecationWarning", "ignore::FutureWarning")

SPEC = RunSpec("ddpg", "noma", 0, 3, scenario="small", eval_episodes=1, eval_before_transfer=False, observation="paper")
TRAIN = ["train", "--algo", "ddpg", "--hyperparams", "paper", "--observation", "paper", "--scenario", "small"]
TRAIN += ["--episodes", "3", "--eval-episodes", "1", "--no-progress"]


@pytest.fixture(autouse=True)
def _agg_backend(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")


def _events(folder):
    return sorted(folder.rglob("events.out.tfevents*"))


# ---------------------------------------------------------------------------------------------- TensorBoard
def test_two_trains_with_the_same_settings_keep_both_runs_tensorboard_logs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the default TensorBoard folder is relative
    assert main([*TRAIN, "--out", "a"]) == 0
    assert main([*TRAIN, "--out", "b"]) == 0
    first, second = _events(tmp_path / "a"), _events(tmp_path / "b")
    assert len(first) == 1 and len(second) == 1 and first[0].stat().st_size > 0  # one stream per run, both kept


def test_a_run_never_deletes_another_runs_tensorboard_logs(tmp_path):
    shared = tmp_path / "tb"
    run_one(SPEC, tmp_path / "a", tensorboard_dir=shared)
    kept = _events(shared / SPEC.run_id)
    assert len(kept) == 1
    with pytest.raises(RunMismatchError, match=r"holds the logs of run ddpg_noma_s0 in .*a, not of run"):
        run_one(SPEC, tmp_path / "b", tensorboard_dir=shared)
    assert _events(shared / SPEC.run_id) == kept and not result_path(tmp_path / "b", SPEC).exists()
    run_one(SPEC, tmp_path / "a", tensorboard_dir=shared)  # its own run again: a fresh start replaces its logs
    assert len(_events(shared / SPEC.run_id)) == 1


def test_a_run_inside_its_output_folder_never_deletes_the_logs_another_folders_run_put_there(tmp_path):
    # Run b logs into a's TensorBoard folder (--tb a/tb); a's own run of the same id must not empty it.
    run_one(SPEC, tmp_path / "b", tensorboard_dir=tmp_path / "a" / "tb")
    kept = _events(tmp_path / "a" / "tb" / SPEC.run_id)
    with pytest.raises(RunMismatchError, match=r"holds the logs of run ddpg_noma_s0 in .*b, not of run"):
        run_one(SPEC, tmp_path / "a")
    assert len(kept) == 1 and _events(tmp_path / "a" / "tb" / SPEC.run_id) == kept


def test_a_fresh_start_keeps_the_logs_of_a_run_whose_id_extends_its_own(tmp_path):
    # e.g. a Table I run ``ddpg_noma_s1_<tag>`` and the tuned ``ddpg_noma_s1_<tag>_tuned`` in one reproduce folder
    longer = dataclasses.replace(SPEC, tag="tuned")
    assert longer.run_id.startswith(SPEC.run_id) and longer.run_id != SPEC.run_id
    run_one(longer, tmp_path)
    kept = {path: path.read_bytes() for path in _events(tmp_path / "tb" / longer.run_id)}
    run_one(SPEC, tmp_path)
    result_path(tmp_path, SPEC).unlink()  # its result gone: the next attempt starts afresh, removing its own logs
    run_one(SPEC, tmp_path)
    assert len(kept) == 1 and {path: path.read_bytes() for path in _events(tmp_path / "tb" / longer.run_id)} == kept
    assert len(_events(tmp_path / "tb" / SPEC.run_id)) == 1


def test_a_tensorboard_folder_in_use_is_refused(tmp_path):
    shared = tmp_path / "tb"
    with output_lock(shared, f".{SPEC.run_id}.lock"):  # what another run's claim holds
        with pytest.raises(OutputBusyError, match=r"TensorBoard folder .* is in use by another run"):
            run_one(SPEC, tmp_path / "a", tensorboard_dir=shared)


# ---------------------------------------------------------------------------------------------- locks
def test_compare_and_train_exclude_each_other_on_one_folder(tmp_path):
    with output_lock(tmp_path):  # compare's (and reproduce's) lock
        with pytest.raises(OutputBusyError, match="in use by another job"):
            with output_lock(tmp_path, f".{SPEC.run_id}.lock"):  # train's
                pass
    with output_lock(tmp_path, f".{SPEC.run_id}.lock"):
        with output_lock(tmp_path, ".other_run.lock"):  # trains of other runs share the folder
            pass
        with pytest.raises(OutputBusyError, match="in use by another job"):
            with output_lock(tmp_path, f".{SPEC.run_id}.lock"):  # but not one run
                pass
        with pytest.raises(OutputBusyError, match="in use by another job"):
            run_compare(tmp_path, budget="_micro", seeds=1, progress=False)
    with output_lock(tmp_path):  # all released
        pass
    assert not any(tmp_path.glob("runs/*"))


# ---------------------------------------------------------------------------------------------- diverged runs
def test_a_diverged_run_records_its_failure_and_leaves_no_checkpoint_behind(tmp_path):
    diverging = dataclasses.replace(SPEC, episodes=6, learning_rate=1e30)  # finite: inf is refused at construction
    with pytest.raises(RunDivergedError, match=r"ddpg_noma_s0: training diverged at step \d+: the policy's .* non-finite"):
        run_one(diverging, tmp_path, checkpoint_every=1, resume=True)
    run_dir = tmp_path / "runs" / SPEC.run_id
    assert sorted(p.name for p in run_dir.iterdir()) == ["failed.json"]
    failure = json.loads((run_dir / "failed.json").read_text())
    assert failure["identity"]["spec"]["learning_rate"] == 1e30 and "non-finite" in failure["error"]
    # The folder is not held against other settings: the next run trains (before: RunMismatchError)
    result = run_one(dataclasses.replace(SPEC, episodes=6), tmp_path, checkpoint_every=1, resume=True)
    assert result["train"]["episodes"] == 6 and not (run_dir / "failed.json").exists()


# ---------------------------------------------------------------------------------------------- failed runs
def test_a_job_whose_runs_failed_says_so_in_its_table_and_its_exit_status(tmp_path, capsys):
    job = dict(budget="_micro", seeds=2, algos=["ddpg"], modes=["noma"], n_workers=1, progress=False)
    blocked = compare_specs(BUDGETS["_micro"], 2, algos=("ddpg",), modes=("noma",))[1].run_id
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / blocked).write_text("")  # a file where the run's folder goes: the run fails, the other trains
    with pytest.raises(RunsFailedError, match=rf"1 run failed \({blocked}: FileExistsError") as failure:
        run_compare(tmp_path, **job)
    assert list(failure.value.failed) == [blocked] and blocked == "ddpg_noma_s1_goal"
    assert f"**Incomplete: 1 of 2 runs failed ({blocked});" in (tmp_path / "results.md").read_text()
    runs = pd.read_csv(tmp_path / "results_runs.csv")
    assert list(runs["seed"]) == [0]  # the finished run's row is kept
    # the same job again trains the failed run only, and its table is whole
    (tmp_path / "runs" / blocked).unlink()
    run_compare(tmp_path, **job)
    assert "Incomplete" not in (tmp_path / "results.md").read_text()
    assert " s for 1 run, 1 already done)" in capsys.readouterr().out
    # a run given twice runs once (two workers must never write one run's folder)
    spec = compare_specs(BUDGETS["_micro"], 1, algos=("ddpg",), modes=("noma",))[0]
    assert run_many([spec, spec], tmp_path, progress=False).skipped == [spec.run_id]
    with pytest.raises(ValueError, match=rf"two runs share the id '{spec.run_id}' with other settings"):
        run_many([spec, dataclasses.replace(spec, eval_episodes=9)], tmp_path, progress=False)
    # compare with an algorithm and a mode given twice: one row each (was a pandas error after training)
    summary = run_compare(tmp_path, **{**job, "algos": ["ddpg", "ddpg"], "modes": ["noma", "noma"]})
    assert list(summary["algorithm"]).count("DDPG") == 1


def test_reproduce_reports_the_runs_that_finished_when_others_failed(tmp_path):
    from sb3_dtdpg.experiments.reproduce import reproduce_specs, run_reproduce

    specs = [s for s in reproduce_specs(BUDGETS["_micro"], 1)["ddpg_vs_dtdpg"] if s.multiple_access == "noma"]
    blocked = next(s.run_id for s in specs if s.algo == "ddpg")
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / blocked).write_text("")
    # DT-DPG alone finishes: no contrast has both sides (this once crashed the report after the runs)
    with pytest.raises(RunsFailedError, match=rf"1 run failed \({blocked}: "):
        run_reproduce(
            tmp_path, budget="_micro", seeds=1, progress=False, experiments=["ddpg_vs_dtdpg"], multiple_access=["noma"]
        )
    table = (tmp_path / "ddpg_vs_dtdpg.md").read_text()
    assert f"**Incomplete: 1 of 2 runs failed ({blocked});" in table and "| DT-DPG | NOMA |" in table
    assert "Incomplete" not in (tmp_path / "table_ii.md").read_text()  # its runs (the DT-DPG one) all finished


def test_the_cli_exits_with_status_1_when_runs_failed(tmp_path, capsys):
    (tmp_path / "runs").write_text("")  # no run can make its folder
    command = ["compare", "--budget", "tiny", "--algos", "ddpg", "--multiple-access", "noma", "--no-progress"]
    assert main([*command, "--out", str(tmp_path)]) == 1
    error = capsys.readouterr().err
    assert "sb3-dtdpg compare: error: 2 runs failed (" in error and "hold only the runs that finished" in error


# ---------------------------------------------------------------------------------------------- SIGKILL
COMPARE = "from sb3_dtdpg.experiments.compare import run_compare\n"
COMPARE += "run_compare({out!r}, budget='_micro', seeds=1, algos=['ddpg'], n_workers=1, progress=False)\n"


def _results(out):
    """Each run's result without its timings (the only values that differ between two runs of one spec)."""
    results = {}
    for path in sorted(out.glob("runs/*/result.json")):
        result = json.loads(path.read_text())
        del result["train"]["wall_s"], result["train"]["steps_per_s"]
        results[path.parent.name] = result
    return results


def test_sigkill_of_compare_while_training_then_a_rerun_gives_the_uninterrupted_results(tmp_path):
    killed, reference = tmp_path / "killed", tmp_path / "reference"
    job = subprocess.Popen([sys.executable, "-c", COMPARE.format(out=str(killed))], start_new_session=True)
    deadline = time.monotonic() + 240
    try:
        while not any(killed.glob("runs/*/progress.json")):  # a run is training
            assert job.poll() is None and time.monotonic() < deadline, "compare ended before it was killed"
            time.sleep(0.02)
    finally:
        os.killpg(job.pid, signal.SIGKILL)  # the job and its workers, at once
        job.wait()
    assert not any(killed.glob("runs/*/result.json"))  # killed mid-training: nothing finished
    assert any(killed.glob("tb/*/events.out.tfevents*"))  # and it had started logging
    run_compare(killed, budget="_micro", seeds=1, algos=["ddpg"], n_workers=1, progress=False)
    run_compare(reference, budget="_micro", seeds=1, algos=["ddpg"], n_workers=1, progress=False)
    assert _results(killed) == _results(reference) and sorted(_results(killed)) == ["ddpg_noma_s0_goal", "ddpg_oma_s0_goal"]
    for run_id in _results(killed):
        assert len(_events(killed / "tb" / run_id)) == 1  # one event stream per run: the killed one's is gone
    assert not list(killed.rglob("*.tmp")) and not list(killed.rglob("progress.json"))


# ---------------------------------------------------------------------------------------------- damaged files
@pytest.mark.parametrize("name", ["result.json", "checkpoint.json"])
@pytest.mark.parametrize("content", ["{trunc", "[1, 2]", "", '{"identity": null}', '{"identity": "x"}'])
def test_a_damaged_record_is_a_named_error(tmp_path, name, content):
    run_dir = tmp_path / "runs" / SPEC.run_id
    run_dir.mkdir(parents=True)
    (run_dir / name).write_text(content)
    with pytest.raises(ValueError, match=rf"{run_dir / name} is unreadable .*; delete {run_dir} to run this run again"):
        run_one(SPEC, tmp_path, resume=True, checkpoint_every=1)
    assert (run_dir / name).read_text() == content  # nothing removed behind the user's back


def test_a_damaged_checkpoint_model_is_a_named_error(tmp_path, monkeypatch):
    _stop_after_first_checkpoint(monkeypatch)
    with pytest.raises(KeyboardInterrupt):
        run_one(SPEC, tmp_path, resume=True, checkpoint_every=1)
    monkeypatch.undo()
    run_dir = tmp_path / "runs" / SPEC.run_id
    (model := next(run_dir.glob("checkpoints/*/model.zip"))).write_bytes(b"not a zip")
    with pytest.raises(ValueError, match=rf"checkpoint in {model.parent} cannot be loaded .*delete .*checkpoint\.json"):
        run_one(SPEC, tmp_path, resume=True, checkpoint_every=1)
    (run_dir / "checkpoint.json").unlink()  # the fix the message names
    assert run_one(SPEC, tmp_path, resume=True, checkpoint_every=1)["train"]["resumed_at_episode"] is None


def test_a_checkpoint_of_any_algorithm_records_the_env_it_trains_on(tmp_path, monkeypatch):
    # DDPG's own save records nothing: a checkpoint's model.zip was tested on the default room by evaluate/enjoy
    from stable_baselines3.common.save_util import load_from_zip_file

    _stop_after_first_checkpoint(monkeypatch)
    spec = dataclasses.replace(SPEC, multiple_access="oma")
    with pytest.raises(KeyboardInterrupt):
        run_one(spec, tmp_path, resume=True, checkpoint_every=1)
    (model,) = (tmp_path / "runs" / spec.run_id).glob("checkpoints/*/model.zip")
    data, _, _ = load_from_zip_file(model)
    settings = data["env_settings"]
    assert (settings["scenario"], settings["multiple_access"], settings["observation"]) == ("small", "oma", "paper")


def _stop_after_first_checkpoint(patch):
    """Make training raise ``KeyboardInterrupt`` right after its first checkpoint (``patch``: a monkeypatch)."""
    original = PeriodicCheckpoint._on_rollout_start

    def interrupt_after_first_checkpoint(self):
        due = self._due
        original(self)
        if due:
            raise KeyboardInterrupt

    patch.setattr(PeriodicCheckpoint, "_on_rollout_start", interrupt_after_first_checkpoint)


def _interrupt_after_first_checkpoint(spec, out, monkeypatch):
    """
    Train ``spec`` into ``out`` with a checkpoint every episode, interrupted right after the first one.

    :return: the run's folder and its ``checkpoint.json``
    """
    with monkeypatch.context() as patch:
        _stop_after_first_checkpoint(patch)
        with pytest.raises(KeyboardInterrupt):
            run_one(spec, out, resume=True, checkpoint_every=1)
    run_dir = out / "runs" / spec.run_id
    return run_dir, json.loads((run_dir / "checkpoint.json").read_text())


def _files(folder):
    return {path: path.read_bytes() for path in sorted(folder.rglob("*")) if path.is_file()}


def test_a_checkpoint_model_of_another_algorithm_or_run_is_refused(tmp_path, monkeypatch):
    from stable_baselines3 import TD3

    from sb3_dtdpg.baselines import make_env
    from sb3_dtdpg.experiments.specs import build_model

    dtdpg = dataclasses.replace(SPEC, algo="dtdpg")
    finished = run_one(dtdpg, tmp_path / "other")  # another run's finished model, of the same settings
    for spec, foreign, reason in [
        (dtdpg, "ddpg", r"policy_class: '.*TD3Policy' in the model, '.*DTDPGPolicy' in the run"),  # the hunter's case
        (dtdpg, "finished", rf"num_timesteps: {finished['train']['timesteps']} in the model, \d+ in .*checkpoint\.json"),
        (SPEC, "td3", r"batch_size: 256 in the model, 64 in the run"),  # TD3's policy class is DDPG's
    ]:
        run_dir, checkpoint = _interrupt_after_first_checkpoint(spec, tmp_path / f"{spec.algo}_{foreign}", monkeypatch)
        model = run_dir / checkpoint["folder"] / "model.zip"
        if foreign == "finished":
            shutil.copyfile(tmp_path / "other" / "runs" / dtdpg.run_id / "model.zip", model)
        else:  # at the step count the record names: only the algorithm tells
            env = make_env(spec.algo, spec.env_id, spec.multiple_access, spec.channel, spec.env_kwargs)
            other = build_model(SPEC, env) if foreign == "ddpg" else TD3("MlpPolicy", env, buffer_size=100)
            other.num_timesteps = checkpoint["timesteps"]
            other.save(model)
            env.close()
        kept = _files(run_dir)
        folder, pointer = re.escape(str(model.parent)), re.escape(str(run_dir / "checkpoint.json"))
        match = rf"checkpoint in {folder} is not this run's \(.*{reason}.*; delete {pointer} to start the run afresh"
        with pytest.raises(DamagedRecordError, match=match):
            run_one(spec, tmp_path / f"{spec.algo}_{foreign}", resume=True, checkpoint_every=1)
        assert _files(run_dir) == kept  # nothing removed behind the user's back


@pytest.mark.parametrize("removed", ["folder", "model.zip", "replay_buffer.pkl"])
def test_a_checkpoint_record_whose_checkpoint_is_gone_is_a_named_error(tmp_path, monkeypatch, removed):
    run_dir, checkpoint = _interrupt_after_first_checkpoint(SPEC, tmp_path, monkeypatch)
    folder = run_dir / checkpoint["folder"]
    if removed == "folder":
        shutil.rmtree(folder)
    else:
        (folder / removed).unlink()
    kept = _files(run_dir)
    what = "model.zip" if removed == "folder" else removed
    pointer = run_dir / "checkpoint.json"
    with pytest.raises(
        DamagedRecordError, match=rf"{re.escape(str(folder))}.* has no {what} .*; delete {re.escape(str(pointer))} to start"
    ):
        run_one(SPEC, tmp_path, resume=True, checkpoint_every=1)
    assert _files(run_dir) == kept and run_dir.exists()  # before: the run folder was deleted and the run started afresh
    pointer.unlink()  # the fix the message names
    assert run_one(SPEC, tmp_path, resume=True, checkpoint_every=1)["train"]["resumed_at_episode"] is None


def test_checkpoints_interrupted_while_written_or_removed_are_no_error(tmp_path, monkeypatch):
    # a kill while the next checkpoint was written leaves a partial folder that the record does not name
    run_dir, checkpoint = _interrupt_after_first_checkpoint(SPEC, tmp_path / "a", monkeypatch)
    partial = run_dir / "checkpoints" / f"episode_{checkpoint['episodes'] + 1}"
    partial.mkdir()
    (partial / ".model.zip.killed.tmp").write_bytes(b"par")
    result = run_one(SPEC, tmp_path / "a", resume=True, checkpoint_every=1)
    assert result["train"]["resumed_at_episode"] == checkpoint["episodes"] and not (run_dir / "checkpoints").exists()
    # a kill while a fresh start (compare's runs do not resume) removed the run's folder, checkpoints first
    run_dir, _ = _interrupt_after_first_checkpoint(SPEC, tmp_path / "b", monkeypatch)
    rmtree = shutil.rmtree

    def killed_while_removing(path, *args, **kwargs):
        if os.fspath(path) == os.fspath(run_dir):
            rmtree(run_dir / "checkpoints", ignore_errors=True)  # in the worst order: the checkpoints first
            raise KeyboardInterrupt
        rmtree(path, *args, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(shutil, "rmtree", killed_while_removing)
        with pytest.raises(KeyboardInterrupt):
            run_one(SPEC, tmp_path / "b", checkpoint_every=1)
    assert run_one(SPEC, tmp_path / "b", resume=True, checkpoint_every=1)["train"]["resumed_at_episode"] is None


def test_a_resumed_runs_training_time_counts_its_part_before_the_checkpoint_and_its_rate_the_steps_it_trained(
    tmp_path, monkeypatch
):
    _, checkpoint = _interrupt_after_first_checkpoint(SPEC, tmp_path, monkeypatch)
    assert checkpoint["train_s"] > 0
    pointer = tmp_path / "runs" / SPEC.run_id / "checkpoint.json"
    pointer.write_text(json.dumps({**checkpoint, "train_s": 1000.0}))  # as if the part before took 1000 s
    train = run_one(SPEC, tmp_path, resume=True, checkpoint_every=1)["train"]
    assert train["resumed_at_episode"] == 1 and train["timesteps"] > checkpoint["timesteps"] > 0
    # before: the resumed part's time only
    assert 1000.0 < train["wall_s"] < 1100.0 and train["wall_s_complete"] is True
    resumed_s = train["wall_s"] - 1000.0
    # before: all the run's steps over the resumed part's wall time
    assert train["steps_per_s"] == pytest.approx((train["timesteps"] - checkpoint["timesteps"]) / resumed_s)


def test_a_checkpoint_counts_the_training_time_of_every_part_before_it(tmp_path, monkeypatch):
    _, first = _interrupt_after_first_checkpoint(SPEC, tmp_path, monkeypatch)
    pointer = tmp_path / "runs" / SPEC.run_id / "checkpoint.json"
    pointer.write_text(json.dumps({**first, "train_s": 1000.0}))
    _, second = _interrupt_after_first_checkpoint(SPEC, tmp_path, monkeypatch)  # resumed, then stopped again
    assert second["episodes"] == first["episodes"] + 1 and 1000.0 < second["train_s"] < 1100.0


@pytest.mark.parametrize("recorded", ["absent", "12 s"])
def test_a_checkpoint_without_a_training_time_resumes_and_says_its_time_is_the_resumed_parts(tmp_path, monkeypatch, recorded):
    _, checkpoint = _interrupt_after_first_checkpoint(SPEC, tmp_path, monkeypatch)
    pointer = tmp_path / "runs" / SPEC.run_id / "checkpoint.json"
    record = {k: v for k, v in checkpoint.items() if k != "train_s"}  # as an earlier version wrote it
    pointer.write_text(json.dumps(record if recorded == "absent" else {**record, "train_s": recorded}))
    train = run_one(SPEC, tmp_path, resume=True, checkpoint_every=1)["train"]
    assert train["resumed_at_episode"] == 1 and train["wall_s_complete"] is False
    assert train["steps_per_s"] == pytest.approx((train["timesteps"] - checkpoint["timesteps"]) / train["wall_s"])


def test_a_checkpoint_records_its_versions_and_resuming_one_of_others_is_warned_about(tmp_path, monkeypatch):
    from sb3_dtdpg.experiments.provenance import OtherVersionsWarning, made_with

    _, checkpoint = _interrupt_after_first_checkpoint(SPEC, tmp_path, monkeypatch)
    assert checkpoint["made_with"] == made_with()
    pointer = tmp_path / "runs" / SPEC.run_id / "checkpoint.json"
    pointer.write_text(json.dumps(dict(checkpoint, made_with=dict(checkpoint["made_with"], torch="2.4.0"))))
    with pytest.warns(OtherVersionsWarning, match=r"1 of 1 stored runs .*torch 2\.4\.0.*they are resumed"):
        result = run_one(SPEC, tmp_path, resume=True, checkpoint_every=1)
    assert result["train"]["resumed_at_episode"] == 1
    assert result["made_with"] == made_with()  # the versions that finished the training


@pytest.mark.parametrize("damage", ["truncated replay buffer", "checkpoint folder removed", "result.json"])
def test_a_damaged_run_record_is_one_error_line_of_train(tmp_path, monkeypatch, capsys, damage):
    monkeypatch.chdir(tmp_path)  # the default TensorBoard folder is relative
    argv = [*TRAIN, "--out", str(tmp_path / "o"), "--checkpoint-every", "1"]
    with monkeypatch.context() as patch:
        _stop_after_first_checkpoint(patch)
        assert main(argv) == 130
    (run_dir,) = (tmp_path / "o" / "runs").iterdir()
    pointer = run_dir / "checkpoint.json"
    folder = run_dir / json.loads(pointer.read_text())["folder"]
    if damage == "truncated replay buffer":
        buffer = folder / "replay_buffer.pkl"
        buffer.write_bytes(buffer.read_bytes()[:100])
        message = f"the checkpoint in {folder} cannot be loaded (UnpicklingError"
    elif damage == "checkpoint folder removed":
        shutil.rmtree(folder)
        message = f"delete {pointer} to start the run afresh"
    else:
        (run_dir / "result.json").write_text("{trunc")
        message = f"{run_dir / 'result.json'} is unreadable"
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    printed = capsys.readouterr()
    assert exit_info.value.code == 2 and "Traceback" not in printed.err, printed.err  # before: 35 lines, exit 1
    errors = [line for line in printed.err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and errors[0].startswith("sb3-dtdpg train: error: ") and message in errors[0], printed.err
    assert pointer.exists()  # nothing removed behind the user's back


def test_an_error_of_training_itself_is_no_user_error_of_train(tmp_path, monkeypatch):
    from sb3_dtdpg.experiments import runs

    def broken(*args, **kwargs):
        raise ValueError("a bug in training")

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(runs, "_train", broken)
    with pytest.raises(ValueError, match="a bug in training"):  # a traceback, not one error line of the user's
        main([*TRAIN, "--out", "o"])


def test_a_full_disk_at_the_result_leaves_no_partial_file_and_a_rerun_finishes(tmp_path, monkeypatch):
    from sb3_dtdpg.common import files

    write_text = files.Path.write_text

    def full_disk(self, text, *args, **kwargs):
        if self.name.startswith(".result.json"):
            write_text(self, text[: len(text) // 2])  # part of it written, then the disk is full
            raise OSError(28, "No space left on device")
        return write_text(self, text, *args, **kwargs)

    monkeypatch.setattr(files.Path, "write_text", full_disk)
    with pytest.raises(OSError, match="No space left on device"):
        run_one(SPEC, tmp_path, resume=True)
    monkeypatch.undo()
    run_dir = tmp_path / "runs" / SPEC.run_id
    assert not (run_dir / "result.json").exists() and not list(run_dir.glob("*.tmp"))
    assert run_one(SPEC, tmp_path, resume=True)["train"]["episodes"] == 3
    with output_lock(tmp_path):  # the lock was never held by the run: nothing to release
        pass


def test_a_run_interrupted_in_its_evaluations_is_evaluated_again_not_trained_again(tmp_path, monkeypatch):
    from sb3_dtdpg.experiments import runs

    evaluations = runs._evaluations

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(runs, "_evaluations", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_one(SPEC, tmp_path / "a", resume=True)
    model = tmp_path / "a" / "runs" / SPEC.run_id / "model.zip"
    trained_bytes = model.read_bytes()
    monkeypatch.setattr(runs, "_evaluations", evaluations)
    monkeypatch.setattr(runs, "_train", lambda *args, **kwargs: pytest.fail("trained again"))  # was: all of it again
    resumed = run_one(SPEC, tmp_path / "a", resume=True)
    monkeypatch.undo()
    assert model.read_bytes() == trained_bytes and not (model.parent / "trained.json").exists()
    uninterrupted = run_one(SPEC, tmp_path / "b", resume=True)
    assert resumed["eval"] == uninterrupted["eval"]  # the model as loaded tests as the model in memory did
    assert {k: v for k, v in resumed["train"].items() if k not in ("wall_s", "steps_per_s")} == {
        k: v for k, v in uninterrupted["train"].items() if k not in ("wall_s", "steps_per_s")
    }


class _TrainedAgain(Exception):
    pass


def _assert_trained_again(monkeypatch, spec, out):
    """A ``compare`` worker given ``spec`` trains it (rather than testing what the folder holds)."""
    from sb3_dtdpg.experiments import runs

    def train(*args, **kwargs):
        raise _TrainedAgain

    monkeypatch.setattr(runs, "_train", train)
    with pytest.raises(_TrainedAgain):
        runs._worker(spec, str(out), prepare_run(spec))


def _interrupted_in_its_evaluations(monkeypatch, out, spec=SPEC, test=1):
    """
    Train ``spec`` into ``out`` as a ``compare`` worker does, and interrupt it in its test episodes.

    :param test: the evaluation interrupted (DT-DPG's second tests its network before the transfer)
    :return: the run's folder
    """
    from sb3_dtdpg import evaluation
    from sb3_dtdpg.experiments import runs

    evaluate, calls = evaluation.evaluate, []

    def interrupted(*args, **kwargs):
        calls.append(1)
        if len(calls) == test:
            raise KeyboardInterrupt
        return evaluate(*args, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(evaluation, "evaluate", interrupted)
        with pytest.raises(KeyboardInterrupt):
            runs._worker(spec, str(out), prepare_run(spec))
    assert len(calls) == test
    return out / "runs" / spec.run_id


def test_a_compare_run_interrupted_in_its_evaluations_is_evaluated_again_not_trained_again(tmp_path, monkeypatch):
    from sb3_dtdpg.experiments import runs

    run_dir = _interrupted_in_its_evaluations(monkeypatch, tmp_path / "a")
    trained_bytes = (run_dir / "model.zip").read_bytes()
    with monkeypatch.context() as patch:  # was: trained again from its start
        patch.setattr(runs, "_train", lambda *args, **kwargs: pytest.fail("trained again"))
        runs._worker(SPEC, str(tmp_path / "a"), prepare_run(SPEC))
    retested = json.loads(result_path(tmp_path / "a", SPEC).read_text())
    assert (run_dir / "model.zip").read_bytes() == trained_bytes and not (run_dir / "trained.json").exists()
    uninterrupted = run_one(SPEC, tmp_path / "b")
    assert json.dumps(retested["eval"], sort_keys=True) == json.dumps(uninterrupted["eval"], sort_keys=True)  # NaN CIs
    assert retested["train"]["timesteps"] == uninterrupted["train"]["timesteps"]


@pytest.mark.parametrize(
    "leftover", ["resumed training", "resumed training of an earlier version", "another run's", "unreadable model"]
)
def test_a_compare_run_retrains_leftovers_that_are_not_its_uninterrupted_training(tmp_path, monkeypatch, leftover):
    """Only a training that is the uninterrupted run's is this run's as compare would train it: a record of a
    training resumed from a checkpoint without its training state (``sb3-dtdpg train`` of an earlier version, or
    resumed from such a checkpoint), of another identity, or beside a damaged model is a leftover, trained again
    (not an error, not tested as this run)."""

    run_dir = _interrupted_in_its_evaluations(monkeypatch, tmp_path)
    record = json.loads((run_dir / "trained.json").read_text())
    assert record["train"]["same_as_uninterrupted"] is True
    if leftover == "resumed training":
        record["train"].update(resumed_at_episode=1, same_as_uninterrupted=False)
    elif leftover == "resumed training of an earlier version":  # recorded nothing about it
        record["train"]["resumed_at_episode"] = 1
        del record["train"]["same_as_uninterrupted"]
    elif leftover == "another run's":
        record["identity"]["spec"]["eval_episodes"] = 7
    else:
        (run_dir / "model.zip").write_bytes(b"not a zip")
    (run_dir / "trained.json").write_text(json.dumps(record))

    _assert_trained_again(monkeypatch, SPEC, tmp_path)
    assert not (run_dir / "trained.json").exists()


DTDPG_SPEC = RunSpec("dtdpg", "noma", 0, 12, scenario="small", eval_episodes=1, hyperparams="paper", observation="paper")


def _dtdpg_interrupted_before_transfer_test(monkeypatch, out):
    """Train ``DTDPG_SPEC`` as a ``compare`` worker does; interrupt it in its second test, the network before the transfer."""
    run_dir = _interrupted_in_its_evaluations(monkeypatch, out, DTDPG_SPEC, test=2)
    assert list(run_dir.glob("phase_*_destination.zip"))  # it had a network before the transfer
    return run_dir


def _without_timings(result: dict) -> str:
    train = {k: v for k, v in result["train"].items() if k not in ("wall_s", "steps_per_s")}
    return json.dumps({**result, "train": train}, sort_keys=True)


def test_a_dtdpg_run_interrupted_in_its_test_before_the_transfer_gives_the_uninterrupted_result(tmp_path, monkeypatch):
    from sb3_dtdpg.experiments import runs

    _dtdpg_interrupted_before_transfer_test(monkeypatch, tmp_path / "a")
    with monkeypatch.context() as patch:
        patch.setattr(runs, "_train", lambda *args, **kwargs: pytest.fail("trained again"))
        runs._worker(DTDPG_SPEC, str(tmp_path / "a"), prepare_run(DTDPG_SPEC))
    retested = json.loads(result_path(tmp_path / "a", DTDPG_SPEC).read_text())
    uninterrupted = run_one(DTDPG_SPEC, tmp_path / "b")
    assert "before_transfer" in retested and _without_timings(retested) == _without_timings(uninterrupted)


@pytest.mark.parametrize("damage", ["removed", "not a zip"])
def test_a_dtdpg_run_whose_network_before_the_transfer_is_gone_is_trained_again(tmp_path, monkeypatch, damage):
    """The uninterrupted run evaluates that network too: without it, retesting would give another result (or fail
    on every rerun)."""

    run_dir = _dtdpg_interrupted_before_transfer_test(monkeypatch, tmp_path)
    before = next(run_dir.glob("phase_*_destination.zip"))
    if damage == "removed":
        before.unlink()
    else:
        before.write_bytes(b"not a zip")

    _assert_trained_again(monkeypatch, DTDPG_SPEC, tmp_path)


@pytest.mark.parametrize("job", ["train", "compare"])
def test_a_damaged_network_before_the_transfer_is_a_named_error_when_the_run_is_tested_again(tmp_path, monkeypatch, job):
    """``train`` resumes whatever its folder holds, ``compare`` takes any zip there: a model that cannot be loaded
    from it names the file and what to delete (was: SB3's ValueError, the same on every rerun)."""
    import zipfile

    from sb3_dtdpg.experiments import runs

    run_dir = _dtdpg_interrupted_before_transfer_test(monkeypatch, tmp_path)
    before = next(run_dir.glob("phase_*_destination.zip"))
    with zipfile.ZipFile(before, "w") as damaged:  # a zip, not a model
        damaged.writestr("data", "{")
    trained = run_dir / "trained.json"
    with pytest.raises(
        DamagedRecordError, match=rf"{re.escape(str(before))}, cannot be loaded .*delete {re.escape(str(trained))}"
    ):
        if job == "train":
            run_one(DTDPG_SPEC, tmp_path, resume=True)
        else:
            runs._worker(DTDPG_SPEC, str(tmp_path), prepare_run(DTDPG_SPEC))


@pytest.mark.parametrize("job", ["train", "compare"])
def test_a_retested_run_leaves_no_temporary_file_of_a_killed_write(tmp_path, monkeypatch, job):
    from sb3_dtdpg.experiments import runs

    run_dir = _interrupted_in_its_evaluations(monkeypatch, tmp_path)
    left = run_dir / ".result.json.abc123.tmp"  # what atomic_write leaves when its process is killed
    left.write_text("{")
    if job == "train":  # was: left behind by a resumed train
        run_one(SPEC, tmp_path, resume=True)
    else:
        runs._worker(SPEC, str(tmp_path), prepare_run(SPEC))
    assert result_path(tmp_path, SPEC).exists() and not left.exists()


def test_a_distributed_run_interrupted_in_its_evaluations_is_evaluated_again(tmp_path, monkeypatch):
    pytest.importorskip("optuna")
    from sb3_dtdpg.experiments import runs
    from sb3_dtdpg.experiments.distributed import run_study_worker

    _interrupted_in_its_evaluations(monkeypatch, tmp_path / "out")
    monkeypatch.setattr(runs, "_train", lambda *args, **kwargs: pytest.fail("trained again"))
    assert run_study_worker([SPEC], tmp_path / "out", str(tmp_path / "study.log"), "job") == [SPEC.run_id]
    assert result_path(tmp_path / "out", SPEC).exists()


def test_train_interrupted_in_its_test_episodes_says_the_model_is_saved(tmp_path, monkeypatch, capsys):
    from sb3_dtdpg.experiments import runs

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(runs, "_evaluations", interrupted)
    assert main([*TRAIN, "--out", str(tmp_path)]) == 130
    message = capsys.readouterr().err  # was "nothing saved yet (the first checkpoint comes after 10 episodes)"
    assert "interrupted in the test episodes: training had finished and the model is in" in message
    assert "run the same command again to test it" in message


# ---------------------------------------------------------------------------------------------- paths and HOME
def test_paths_with_spaces_and_symlinks(tmp_path):
    real = tmp_path / "real folder"
    real.mkdir()
    (tmp_path / "link to it").symlink_to(real)
    out = tmp_path / "link to it" / "out put"
    result = run_one(SPEC, out)
    stored = json.loads((real / "out put" / "runs" / SPEC.run_id / "result.json").read_text())
    assert json.dumps(stored, sort_keys=True) == json.dumps(result, sort_keys=True)  # (NaN != NaN: compare texts)
    # A TensorBoard folder reached through a symlink into the output folder is the output folder's
    run_one(SPEC, real / "out put", tensorboard_dir=tmp_path / "link to it" / "out put" / "tb")
    assert not list((real / "out put" / "tb").rglob(".owner.json")) and len(_events(real / "out put" / "tb")) == 1


def test_train_works_without_home(tmp_path):
    env = {key: value for key, value in os.environ.items() if key != "HOME"}
    code = "import sys\nfrom sb3_dtdpg.cli import main\nsys.exit(main(sys.argv[1:]))\n"
    done = subprocess.run(
        [sys.executable, "-c", code, *TRAIN, "--out", "o"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "o" / "runs" / SPEC.run_id / "result.json").exists() and len(_events(tmp_path / "o" / "tb")) == 1


# ---------------------------------------------------------------------------------------------- lock files
def test_no_lock_file_stays_behind_and_a_shared_lock_outlives_its_first_holder(tmp_path):
    with output_lock(tmp_path):
        assert (tmp_path / ".lock").exists()
    assert not list(tmp_path.glob("*.lock")) and not list(tmp_path.glob(".*lock"))
    # two trains of other run ids share the folder's lock: the first to end must not free the folder
    with output_lock(tmp_path, ".a.lock"):
        with output_lock(tmp_path, ".b.lock"):
            pass
        assert (tmp_path / ".lock").exists() and not (tmp_path / ".b.lock").exists()
        with pytest.raises(OutputBusyError):
            with output_lock(tmp_path):
                pass
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    with output_lock(tmp_path):  # and the folder is free again
        pass


def test_the_last_training_episode_is_in_the_logs(tmp_path):
    # the episode budget stops training inside SB3's rollout, before SB3 wrote the last episode's values: the logs
    # (curves, training success, the transfer dip) held one episode fewer than the run trained
    from sb3_dtdpg.experiments.plots import read_scalars

    result = run_one(SPEC, tmp_path)
    scalars = read_scalars(tmp_path / "tb" / SPEC.run_id)
    assert scalars["episode/number"].max() == result["train"]["episodes"] == SPEC.episodes
    assert scalars.index.max() == result["train"]["timesteps"]
