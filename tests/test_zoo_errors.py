"""``python -m sb3_dtdpg.train``: a mistake in the hyperparameters is one error line, before any log folder."""

import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

pytest.importorskip("rl_zoo3")
REPO = Path(__file__).resolve().parents[1]
#: The arguments every command line here starts with
ZOO_TRAIN = ["--algo", "dtdpg", "--env", "Pendulum-v1"]


def _environment() -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "envs"), os.environ.get("PYTHONPATH", "")])}
    env["MPLBACKEND"] = "Agg"
    return env


def zoo_train(tmp_path, *args):
    command = [sys.executable, "-m", "sb3_dtdpg.train", *ZOO_TRAIN, "-f", str(tmp_path / "logs")]
    return subprocess.run([*command, *args], capture_output=True, text=True, env=_environment(), cwd=tmp_path, timeout=300)


#: Entries of a hyperparameter file that the training refuses, and what its error line says
BAD_ENTRIES = [
    ("  learnin_rate: 0.001\n", "unknown hyperparameter 'learnin_rate' for DTDPG (env Pendulum-v1 in "),
    ('  policy_kwargs: "dict(net_arch=[100000, 100000])"\n', "more than the 20,000,000 allowed"),
    ("  learning_starts: 5000\n", "n_timesteps=1000 cannot train: the first gradient step comes after"),
    ("  gamma: 5\n", "or -params): gamma must be a number in [0, 1], got 5"),
    ("  seed: 3\n", "or -params): set it with --seed, not as a hyperparameter"),
    ("  batch_size: 1\n", "batch_size must be at least 2 with batch normalisation"),
    ('  policy_kwargs: "dict(net_arc=[64])"\n', "unknown policy_kwargs key 'net_arc' for DTDPGPolicy"),  # traceback
    ("  policy_kwargs: \"dict(activation_fn='relu')\"\n", "must be a class (e.g. nn.ReLU, unquoted), got the string"),
    (
        "  phases:\n    - {name: dest, n_episodes: 2}\n    - {name: mqi}\n",
        "phases (env Pendulum-v1 in ",  # an env without reward phases
    ),
    ("  env_kwargs: [1, 2]\n", "bad.yml must be a mapping, got [1, 2]"),  # was: a ValueError traceback
    ("  n_envs: 0\n", "n_envs must be an integer >= 1 (env Pendulum-v1 in "),  # was: ZeroDivisionError, logs made
    ("  callback: sb3_dtdpg.MissionLogger\n", "callback 'sb3_dtdpg.MissionLogger' (env Pendulum-v1 in "),
]
#: A zoo file (None: none) and arguments that the zoo's own checks refuse, and what the error line says
BAD_CONFIGS = [
    (None, ["--conf-file", "nonexist.yml"], "--conf-file nonexist.yml: no such file"),  # was: FileNotFoundError
    ("Pendulum-v1:\n", [], "the entry Pendulum-v1 in ok.yml must be a mapping of hyperparameters"),  # was: TypeError
    ("Pendulum-v1: [\n", [], "--conf-file ok.yml is not valid YAML: "),  # was: a yaml ScannerError traceback
    ("Pendulum-v1:\n  learning_starts: 100\n", [], "n_timesteps is missing (env Pendulum-v1 in ok.yml"),  # KeyError
    (None, ["-n", "1000", "-params", "n_envs:-1"], "n_envs must be an integer >= 1 (env Pendulum-v1 in "),
    (None, ["-n", "1000", "-params", "n_envs:1.5"], "n_envs must be an integer >= 1 "),
    (
        None,
        ["-n", "1000", "-params", "callback:'sb3_dtdpg.MissionLogger'"],  # was: an AttributeError traceback
        "does not import: module 'sb3_dtdpg' has no attribute 'MissionLogger'",
    ),
    (
        None,
        ["-n", "1000", "-params", "callback:{'stable_baselines3.common.callbacks.CheckpointCallback':{'sav_freq':9}}"],
        "callback 'stable_baselines3.common.callbacks.CheckpointCallback' (env Pendulum-v1 in ",
    ),
]
BAD_CONFIG_IDS = [
    "missing_file",
    "empty_entry",
    "not_yaml",
    "no_n_timesteps",
    "n_envs_negative",
    "n_envs_float",
    "callback",
    "kwargs",
]
#: An env id and a file of the repository without an entry for it, and the env ids the file has
FILES_WITHOUT_THE_ENV = [
    ("NomaRadioMap-v0", "dtdpg_paper.yml", "NomaRadioMapPaper-v0, NomaRadioMapPaperOMA-v0"),  # the paper's task
    ("NomaRadioMapPaper-v0", "dtdpg.yml", "NomaRadioMap-v0, NomaRadioMapOMA-v0"),
]
#: A hyperparameter file's entry for Pendulum-v1 without learning_starts, and the whole file with it
_ENTRY_HEAD = "Pendulum-v1:\n  n_timesteps: 1000\n  policy: MlpPolicy\n"
_OK_FILE = _ENTRY_HEAD + "  learning_starts: 100\n"


def _error_cases() -> dict[str, tuple[dict[str, str], list[str]]]:
    """The command lines of the error tests: name -> (files to write in its folder, its arguments after ``-f``)."""
    cases = {}
    for entry, _ in BAD_ENTRIES:
        default_start = "" if "learning_starts" in entry else "  learning_starts: 100\n"
        file = _ENTRY_HEAD + default_start + entry
        cases[f"entry {entry}"] = ({"bad.yml": file}, ["--conf-file", "bad.yml"])
    for config, args, _ in BAD_CONFIGS:
        files = {} if config is None else {"ok.yml": config}
        cases[f"config {config!r} {args}"] = (files, args if config is None else ["--conf-file", "ok.yml", *args])
    cases["env_kwargs"] = ({"ok.yml": _OK_FILE}, ["--conf-file", "ok.yml", "--env-kwargs", "foo:1"])
    for env_id, config, _ in FILES_WITHOUT_THE_ENV:
        cases[f"no entry {env_id}"] = ({}, ["--env", env_id, "--conf-file", str(REPO / "zoo_configs" / config)])
    cases["trial_id"] = ({}, ["--trial-id", "0"])
    return cases


@pytest.fixture(scope="module")
def error_runs(tmp_path_factory) -> dict[str, SimpleNamespace]:
    """
    Every command line of :func:`_error_cases`, each in its own folder, run by ``tests/zoo_train_cases.py`` in one
    Python process: name -> its ``returncode``, ``stderr`` and ``folder``.
    """
    root = tmp_path_factory.mktemp("zoo_errors")
    folders, command_lines = {}, []
    for i, (name, (files, args)) in enumerate(_error_cases().items()):
        folders[name] = folder = root / f"case{i}"
        folder.mkdir()
        for file_name, text in files.items():
            (folder / file_name).write_text(text)
        command_lines.append({"cwd": str(folder), "argv": [*ZOO_TRAIN, "-f", str(folder / "logs"), *args]})
    cases, results = root / "cases.json", root / "results.json"
    cases.write_text(json.dumps(command_lines))
    runner = Path(__file__).with_name("zoo_train_cases.py")
    done = subprocess.run(
        [sys.executable, str(runner), str(cases), str(results)],
        capture_output=True,
        text=True,
        env=_environment(),
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    outcomes = json.loads(results.read_text())
    return {name: SimpleNamespace(folder=folders[name], **outcome) for name, outcome in zip(folders, outcomes, strict=True)}


@pytest.mark.parametrize(("entry", "message"), BAD_ENTRIES)
def test_a_bad_hyperparameter_file_is_one_error_line(error_runs, entry, message):
    done = error_runs[f"entry {entry}"]
    assert done.returncode == 2, done.stderr[-2000:]
    assert "Traceback" not in done.stderr
    errors = [line for line in done.stderr.splitlines() if ": error: " in line]
    assert len(errors) == 1 and errors[0].startswith("python -m sb3_dtdpg.train: error: ") and message in errors[0]
    if "learnin_rate" in entry:
        assert "did you mean 'learning_rate'" in errors[0]
    assert not (done.folder / "logs").exists()  # nothing created


@pytest.mark.parametrize(("config", "args", "message"), BAD_CONFIGS, ids=BAD_CONFIG_IDS)
def test_a_bad_config_file_or_zoo_hyperparameter_is_one_error_line(error_runs, config, args, message):
    """The zoo's own hyperparameters and its file: the zoo's errors were tracebacks, some after the log folder was made."""
    done = error_runs[f"config {config!r} {args}"]
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-2000:]
    errors = [line for line in done.stderr.splitlines() if ": error: " in line]
    assert len(errors) == 1 and errors[0].startswith("python -m sb3_dtdpg.train: error: ") and message in errors[0]
    assert not (done.folder / "logs").exists()


def test_bad_env_kwargs_are_one_error_line_before_the_log_folder(error_runs):
    done = error_runs["env_kwargs"]
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-2000:]
    errors = [line for line in done.stderr.splitlines() if ": error: " in line]
    assert len(errors) == 1 and "env_kwargs {'foo': 1}" in errors[0] and "'foo'" in errors[0]
    assert not (done.folder / "logs").exists()


@pytest.mark.parametrize(("env_id", "config", "ids"), FILES_WITHOUT_THE_ENV)
def test_a_file_without_an_entry_for_the_env_id_is_one_error_line(error_runs, env_id, config, ids):
    done = error_runs[f"no entry {env_id}"]
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-2000:]
    errors = [line for line in done.stderr.splitlines() if ": error: " in line]
    assert len(errors) == 1 and f"--env {env_id}: " in errors[0] and f"{config} has no entry for it" in errors[0]
    assert f"(its env ids: {ids}" in errors[0]
    assert not (done.folder / "logs").exists()


def test_trial_id_without_storage_is_one_error_line(error_runs):
    done = error_runs["trial_id"]
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-2000:]
    errors = [line for line in done.stderr.splitlines() if ": error: " in line]
    assert len(errors) == 1 and errors[0].startswith("python -m sb3_dtdpg.train: error: --trial-id 0 needs --storage")
    assert not (done.folder / "logs").exists()


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--algo", "dtdpg"], ["--algo", "dtdpg", "--num-threads", "1"]),
        (["--num-threads", "4"], ["--num-threads", "4"]),
        (["--num-threads=-1"], ["--num-threads=-1"]),
        (["--num-t", "2"], ["--num-t", "2"]),  # argparse's abbreviation of the zoo's flag
        (["--n-trials", "2"], ["--n-trials", "2", "--num-threads", "1"]),
    ],
)
def test_one_torch_thread_unless_the_command_sets_it(argv, expected):
    from sb3_dtdpg.train import with_default_threads

    assert with_default_threads(argv) == expected


def test_a_dtdpg_search_on_an_env_without_reward_phases_is_one_error_line(tmp_path):
    done = zoo_train(tmp_path, "-n", "300", "-params", "learning_starts:50", "-optimize", "--n-trials", "1")
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-2000:]
    errors = [line for line in done.stderr.splitlines() if ": error: " in line]
    assert len(errors) == 1 and "Pendulum-v1 has no reward phases: search on a NomaRadioMap env" in errors[0]


def test_enjoy_without_a_model_is_one_error_line(tmp_path):
    env = _environment()
    command = [sys.executable, "-m", "sb3_dtdpg.enjoy", "--algo", "dtdpg", "--env", "Pendulum-v1", "--no-render"]
    (tmp_path / "empty" / "dtdpg" / "Pendulum-v1_1").mkdir(parents=True)
    for folder, message in (("nowhere", "folder was not found"), ("empty", "No model found for dtdpg on Pendulum-v1")):
        done = subprocess.run(
            [*command, "-f", str(tmp_path / folder), "--exp-id", "0" if folder == "nowhere" else "1", "-n", "5"],
            capture_output=True,
            text=True,
            env=env,
            cwd=tmp_path,
            timeout=300,
        )
        assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-2000:]  # was an AssertionError
        stderr = done.stderr
        assert stderr.startswith("python -m sb3_dtdpg.enjoy: error: ") and message in stderr, stderr


def test_a_search_worker_that_finds_every_trial_taken_ends_without_a_traceback(tmp_path):
    """A worker that joins a shared study whose --max-total-trials are all held by other workers, none finished, has
    nothing to run: the zoo then read ``study.best_trial`` of a study without a completed trial (a ValueError)."""
    import optuna

    storage = str(tmp_path / "study.log")
    study = optuna.create_study(
        storage=optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(storage)),
        study_name="shared",
        direction="maximize",
    )
    study.ask()  # a trial another worker is running
    search = ["--env", "NomaRadioMap-v0", "-optimize", "--storage", storage, "--study-name", "shared"]
    search += ["--max-total-trials", "1", "-n", "300", "-params", "learning_starts:50", "--env-kwargs", "scenario:'small'"]
    done = zoo_train(tmp_path, *search)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr[-2000:]
    assert "has completed yet (1 running) and its --max-total-trials 1 are all taken" in done.stderr

    study.tell(study.trials[0].number, state=optuna.trial.TrialState.PRUNED)
    done = zoo_train(tmp_path, *search)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-2000:]
    assert "error: no trial of the study 'shared' completed (1 pruned): no best trial" in done.stderr


def test_a_trials_own_value_error_is_not_taken_for_a_study_without_a_completed_trial(monkeypatch):
    import rl_zoo3.exp_manager

    from sb3_dtdpg.zoo import ExperimentManager

    def trial_fails(self):
        raise ValueError("the objective's own error")

    monkeypatch.setattr(rl_zoo3.exp_manager.ExperimentManager, "hyperparameters_optimization", trial_fails)
    manager = object.__new__(ExperimentManager)  # only the attributes the search reads before the zoo's
    manager.algo, manager.storage, manager.study_name, manager.max_total_trials = "ddpg", "s.log", "shared", 1
    with pytest.raises(ValueError, match="the objective's own error"):
        manager.hyperparameters_optimization()


def test_a_policy_class_path_that_imports_passes_the_zoo_check():
    from types import SimpleNamespace

    from sb3_dtdpg.overrides import HyperparameterError
    from sb3_dtdpg.zoo import ExperimentManager

    manager = ExperimentManager.__new__(ExperimentManager)  # only what the check reads
    manager.n_timesteps, manager.config, manager.env_name = 100, "x.yml", SimpleNamespace(gym_id="Pendulum-v1")
    manager._check_zoo_hyperparams({"policy": "sb3_dtdpg.dtdpg.policies.DTDPGPolicy"})  # was "missing ... argument"
    with pytest.raises(HyperparameterError, match=r"policy 'sb3_dtdpg\.dtdpg\.policies\.NoSuch' .* does not import"):
        manager._check_zoo_hyperparams({"policy": "sb3_dtdpg.dtdpg.policies.NoSuch"})
