"""The distributed workers (sb3_dtdpg.experiments.distributed) with stub runs: a run in training is never handed to a
second worker, an interrupted run or one whose worker died is taken again, and workers and whole-folder jobs keep
out of each other's folder."""

import json
import os
import threading

import pytest

from sb3_dtdpg.experiments import distributed
from sb3_dtdpg.experiments.budgets import CHECKPOINT_EVERY
from sb3_dtdpg.experiments.distributed import run_study_worker, study_specs
from sb3_dtdpg.experiments.runs import (
    OutputBusyError,
    RunMismatchError,
    output_lock,
    result_path,
    run_folder,
    run_identity,
)

optuna = pytest.importorskip("optuna")

SPECS = study_specs("compare", "tiny", seeds=1)
IDS = sorted(spec.run_id for spec in SPECS)


def _finish(spec, out):
    """What a run leaves when it ends: its result file, with the run's identity."""
    path = result_path(out, spec)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"identity": run_identity(spec)}))


def _recorder(ran, raise_on=None, error=None):
    """:return: a stub run that records its run id and finishes it; raises ``error`` on its call number ``raise_on``"""

    def run(spec, out):
        ran.append(spec.run_id)
        if len(ran) == raise_on:
            raise error
        _finish(spec, out)

    return run


def _study(storage):
    backend = optuna.storages.journal.JournalFileBackend(storage)
    return optuna.load_study(study_name="job", storage=optuna.storages.JournalStorage(backend))


def test_a_run_in_training_is_never_handed_to_a_second_worker(tmp_path):
    """A worker that finds every run left in training by another worker ends (bug: it trained it afresh, deleting the
    other worker's folder); while a worker trains, a whole-folder job and a train of the same run are refused."""
    out, storage = tmp_path / "out", str(tmp_path / "study.log")
    started, release, first_ran, first_done, errors = threading.Event(), threading.Event(), [], [], []

    def slow_run(spec, out):
        first_ran.append(spec.run_id)
        (run_folder(out, spec) / "progress.json").parent.mkdir(parents=True, exist_ok=True)
        (run_folder(out, spec) / "progress.json").write_text("{}")
        started.set()
        assert release.wait(60)
        _finish(spec, out)

    def first_worker():
        try:
            first_done.extend(run_study_worker(SPECS, out, storage, "job", run=slow_run))
        except BaseException as error:  # reported by the test thread
            errors.append(error)

    thread = threading.Thread(target=first_worker)
    thread.start()
    try:
        assert started.wait(60)
        busy = first_ran[0]
        second_ran = []
        second = run_study_worker(SPECS, out, storage, "job", run=_recorder(second_ran))
        assert sorted(second) == sorted(second_ran) == [run_id for run_id in IDS if run_id != busy]
        spec = next(spec for spec in SPECS if spec.run_id == busy)
        assert (run_folder(out, spec) / "progress.json").exists() and not result_path(out, spec).exists()
        for lock in (".lock", f".{busy}.lock"):  # compare / reproduce, and train of the run in training
            with pytest.raises(OutputBusyError, match="is in use by another job"), output_lock(out, lock):
                pass
        with output_lock(out, ".another_run.lock"):  # train of another run may share the folder
            pass
    finally:
        release.set()
        thread.join(60)
    assert errors == [] and first_ran == first_done == [busy]  # then nothing was left for the first worker
    with output_lock(out):  # both workers gone: the folder is free, and no lock file stays behind
        pass
    assert sorted(path.name for path in out.iterdir()) == ["runs"]


def test_an_interrupted_run_is_taken_again_by_the_next_worker(tmp_path):
    """Optuna marks the trial of a Ctrl-C'd run failed; the run has no result, so the next worker trains it (bug: it
    counted as done and was never trained)."""
    out, storage = tmp_path / "out", str(tmp_path / "study.log")
    first = []
    with pytest.raises(KeyboardInterrupt):
        run_study_worker(SPECS, out, storage, "job", run=_recorder(first, raise_on=2, error=KeyboardInterrupt()))
    states = [trial.state for trial in _study(storage).trials]
    assert states == [optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.FAIL]
    second = []
    assert run_study_worker(SPECS, out, storage, "job", run=_recorder(second)) == second
    assert sorted(second) == [run_id for run_id in IDS if run_id != first[0]] and first[1] in second
    assert run_study_worker(SPECS, out, storage, "job", run=_recorder([])) == []


def test_a_run_whose_worker_died_is_taken_again(tmp_path):
    """A killed worker leaves its trial running and its lock file behind, but no process holds the lock: the run is
    taken again (once the runs no trial took are handed out), and the stale lock file is removed."""
    out, storage = tmp_path / "out", str(tmp_path / "study.log")
    indices = list(range(len(SPECS)))
    study = optuna.create_study(
        storage=optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(storage)),
        study_name="job",
        sampler=optuna.samplers.GridSampler({"run": indices}, seed=0),
    )
    dead = SPECS[study.ask().suggest_categorical("run", indices)]  # the dead worker's run: its trial stays RUNNING
    out.mkdir()
    (out / f".{dead.run_id}.lock").touch()
    ran = []
    assert run_study_worker(SPECS, out, storage, "job", run=_recorder(ran)) == ran
    assert sorted(ran) == IDS and ran[-1] == dead.run_id
    assert not (out / f".{dead.run_id}.lock").exists()


def test_a_run_that_train_trains_is_left_to_it(tmp_path):
    out, storage = tmp_path / "out", str(tmp_path / "study.log")
    ran = []
    with output_lock(out, f".{SPECS[0].run_id}.lock"):  # what sb3-dtdpg train holds while it trains that run
        assert run_study_worker(SPECS, out, storage, "job", run=_recorder(ran)) == ran
    assert sorted(ran) == [run_id for run_id in IDS if run_id != SPECS[0].run_id]


def test_a_run_that_failed_with_an_error_is_not_taken_again(tmp_path):
    """A run that raised (a divergence, say) would fail again: the other workers leave it, and say so."""
    out, storage = tmp_path / "out", str(tmp_path / "study.log")
    first = []
    with pytest.raises(RuntimeError, match="no memory"):
        run_study_worker(SPECS, out, storage, "job", run=_recorder(first, raise_on=1, error=RuntimeError("no memory")))
    assert [trial.user_attrs.get("error") for trial in _study(storage).trials] == ["RuntimeError: no memory"]
    second = []
    assert run_study_worker(SPECS, out, storage, "job", run=_recorder(second)) == second
    assert sorted(second) == [run_id for run_id in IDS if run_id != first[0]]


def test_a_worker_is_refused_while_a_folder_job_holds_the_folder(tmp_path, capsys):
    out, storage = tmp_path / "out", str(tmp_path / "study.log")
    ran = []
    with output_lock(out):  # sb3-dtdpg compare / reproduce on the folder
        with pytest.raises(OutputBusyError, match="is in use by another job"):
            run_study_worker(SPECS, out, storage, "job", run=_recorder(ran))
        options = ["--budget", "tiny", "--n-seeds", "1", "--out", str(out), "--storage", storage, "--study-name", "job"]
        with pytest.raises(SystemExit) as exit_info:
            distributed.main(["compare", *options])
    assert ran == [] and exit_info.value.code == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if ": error: " in line]
    assert len(errors) == 1 and "is in use by another job" in errors[0]


def test_the_worker_says_what_is_left_and_ends_an_interruption_in_one_line(tmp_path, monkeypatch, capsys):
    options = ["--budget", "tiny", "--n-seeds", "1", "--out", str(tmp_path), "--storage", "s.log", "--study-name", "job"]

    def worker(specs, out, *args):
        _finish(specs[0], out)
        return [specs[0].run_id]

    monkeypatch.setattr(distributed, "run_study_worker", worker)
    distributed.main(["compare", *options])
    printed = capsys.readouterr().out.strip()
    assert printed.startswith("1 runs of 4 done by this worker; 3 not finished (training in other workers, or failed")

    def interrupted(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(distributed, "run_study_worker", interrupted)
    with pytest.raises(SystemExit) as exit_info:
        distributed.main(["compare", *options])
    assert exit_info.value.code == 130
    assert capsys.readouterr().err.strip() == (
        f"interrupted: when a worker takes the run again, it goes on from its last checkpoint (every {CHECKPOINT_EVERY} "
        "episodes), or is only tested again if it was in its test episodes"
    )


def test_a_stored_run_of_other_settings_is_refused_before_anything_trains(tmp_path, capsys):
    # the worker treated any result.json as finished: it trained the other runs, said it was done, and the report
    # then refused the folder (or, with another budget of the same run ids, trained nothing at all)
    out, ran = tmp_path / "out", []
    for spec in SPECS[:2]:  # results written before run identities (no identity): another run's for this job
        result_path(out, spec).parent.mkdir(parents=True)
        result_path(out, spec).write_text('{"spec": {}}')
    with pytest.raises(RunMismatchError, match=r"belongs to another run .*; 1 more stored runs do not fit either: "):
        run_study_worker(SPECS, out, str(tmp_path / "study.log"), "job", run=_recorder(ran))
    assert ran == []
    with pytest.raises(SystemExit):
        distributed.main(
            [
                "compare",
                "--budget",
                "tiny",
                "--n-seeds",
                "1",
                "--out",
                str(out),
                "--storage",
                str(tmp_path / "s.log"),
                "--study-name",
                "j",
            ]
        )
    assert "error: " in capsys.readouterr().err


def test_a_study_of_another_run_list_is_refused(tmp_path):
    # the run indices of the study's trials would name other runs (or a raw "dynamic value space" error)
    storage, ran = str(tmp_path / "study.log"), []
    run_study_worker(SPECS, tmp_path / "a", storage, "job", run=_recorder(ran))
    other = study_specs("compare", "tiny", seeds=2)
    with pytest.raises(
        distributed.StudyError, match=r"--study-name job: the study hands out the runs of another job \(4 runs"
    ):
        run_study_worker(other, tmp_path / "b", storage, "job", run=_recorder(ran))
    assert sorted(ran) == IDS  # the first job only
    # the same run ids with another budget (run ids do not name it) are another job too
    other_budget = study_specs("compare", "small", seeds=1)
    assert [s.run_id for s in other_budget] == [s.run_id for s in SPECS]
    with pytest.raises(distributed.StudyError, match=r"the study hands out the runs of another job"):
        run_study_worker(other_budget, tmp_path / "c", storage, "job", run=_recorder(ran))
    assert run_study_worker(SPECS, tmp_path / "a", storage, "job", run=_recorder(ran)) == []  # the same job joins


def test_a_reproduce_worker_takes_the_runs_of_reproduce_with_the_same_options(tmp_path, monkeypatch):
    from sb3_dtdpg.experiments.reproduce import job_specs
    from sb3_dtdpg.experiments.runs import get_budget

    taken = []
    monkeypatch.setattr(distributed, "run_study_worker", lambda specs, *args: taken.append(specs) or [])
    options = ["--budget", "tiny", "--experiments", "paper_task", "--out", str(tmp_path), "--storage", "s.log"]
    tiny = get_budget("tiny")
    for preset, presets in ((None, None), ("paper", ["paper"]), ("tuned", ["tuned"])):
        distributed.main(["reproduce", *options, "--study-name", "job", *(["--preset", preset] if preset else [])])
        expected = job_specs(tiny, tiny.seeds, preset or "tuned", "goal", ["paper_task"], paper_task_presets=presets)
        assert taken[-1] == expected
        assert {s.hyperparams for s in taken[-1]} == set(presets or ["paper", "tuned"])
    with pytest.raises(ValueError, match="paper_task_presets: only the reproduce job has paper task presets"):
        study_specs("compare", "tiny", seeds=1, paper_task_presets=["paper"])


@pytest.mark.parametrize("storage", ["missing_folder/study.log", "sqlite-typo:///study.db"])
def test_a_storage_that_cannot_be_opened_is_one_error_line(tmp_path, capsys, storage):
    argv = ["compare", "--budget", "tiny", "--n-seeds", "1", "--out", str(tmp_path / "out"), "--study-name", "j"]
    with pytest.raises(SystemExit) as exit_info:
        distributed.main([*argv, "--storage", str(tmp_path / storage) if storage.endswith(".log") else storage])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and "Traceback" not in err and "--storage" in err and "cannot open it" in err


def test_lock_files_are_shared_as_the_umask_allows(tmp_path):
    # created 0644 whatever the umask: another user of a group-writable folder could not lock it (PermissionError)
    previous = os.umask(0o002)
    try:
        with output_lock(tmp_path):
            mode = (tmp_path / ".lock").stat().st_mode & 0o777
    finally:
        os.umask(previous)
    assert mode == 0o664
