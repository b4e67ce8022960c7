"""RL Zoo integration: `python -m sb3_dtdpg.train/enjoy`, the YAML files, the DT-DPG sampler and shared Optuna studies."""

import argparse
import glob
import os
import pwd
import shutil
import socket
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import yaml

rl_zoo3 = pytest.importorskip("rl_zoo3")
optuna = pytest.importorskip("optuna")

from stable_baselines3 import DDPG  # noqa: E402
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator  # noqa: E402

import noma_radiomap  # noqa: E402, F401
from sb3_dtdpg import DTDPG, MissionLoggerCallback  # noqa: E402
from sb3_dtdpg.common.phases import parse_phases  # noqa: E402
from sb3_dtdpg.zoo import (  # noqa: E402
    NET_ARCHS,
    ExperimentManager,
    config_dir,
    convert_dtdpg_params,
    register_dtdpg,
    sample_dtdpg_params,
)

REPO = Path(__file__).resolve().parents[1]
CONFIGS = REPO / "zoo_configs"
ENV_ID = "NomaRadioMap-v0"
NOMA_IDS = ["NomaRadioMap-v0", "NomaRadioMapOMA-v0", "NomaRadioMapReality-v0", "NomaRadioMapOMAReality-v0"]
PAPER_IDS = ["NomaRadioMapPaper-v0", "NomaRadioMapPaperOMA-v0"]  # the paper's task
TIMEOUT = 240
# Tiny budgets: one episode is at most 300 steps, evaluations are one episode
TINY_PARAMS = ["learning_starts:50", "buffer_size:2000"]
# Phase 1 ends after one episode, so a 400-step run crosses a transfer
TWO_SHORT_PHASES = (
    "phases:[dict(name='destination',n_episodes=1,sigma=0.5),dict(name='mqi',sigma=0.4,replay_handling='relabel')]"
)


def run_zoo(script: str, *args: str, cwd: Path, timeout: float = TIMEOUT) -> str:
    """Run ``python -m sb3_dtdpg.<script> ...`` in ``cwd``; fail with its output when it fails."""
    result = subprocess.run(
        [sys.executable, "-m", f"sb3_dtdpg.{script}", *args],
        cwd=cwd,
        env=_subprocess_env(),
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    output = result.stdout + result.stderr
    assert result.returncode == 0, f"sb3_dtdpg.{script} {' '.join(args)} failed:\n{output[-4000:]}"
    return output


def _subprocess_env() -> dict[str, str]:
    return {**os.environ, "PYTHONHASHSEED": "0", "MPLBACKEND": "Agg"}


def start_zoo(script: str, *args: str, cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", f"sb3_dtdpg.{script}", *args],
        cwd=cwd,
        env=_subprocess_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def wait_all(processes: list[subprocess.Popen], timeout: float = TIMEOUT) -> list[str]:
    outputs = []
    try:
        for process in processes:
            output, _ = process.communicate(timeout=timeout)
            outputs.append(output)
            assert process.returncode == 0, f"worker {process.args} failed:\n{output[-4000:]}"
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
                process.communicate()
    return outputs


def optimize_args(storage: str, study_name: str, n_trials: int, seed: int) -> list[str]:
    return [
        "--algo", "dtdpg", "--env", ENV_ID, "--conf-file", str(CONFIGS / "dtdpg.yml"),
        "--optimize", "--storage", storage, "--study-name", study_name, "--n-trials", str(n_trials),
        "--sampler", "random", "--pruner", "none", "--seed", str(seed), "-n", "300", "--n-evaluations", "1",
        "--eval-episodes", "1", "--no-optim-plots", "--num-threads", "1", "-f", "logs",
        "-params", *TINY_PARAMS,
    ]  # fmt: skip


def load_config(run_dir: Path, env_id: str = ENV_ID) -> dict[str, Any]:
    with open(run_dir / env_id / "config.yml") as f:
        return dict(yaml.load(f, Loader=yaml.UnsafeLoader))


def scalars(tb_dir: Path, tag: str) -> list[tuple[int, float]]:
    (event_file,) = glob.glob(str(tb_dir / "events.out.tfevents.*"))
    accumulator = EventAccumulator(event_file)
    accumulator.Reload()
    assert tag in accumulator.Tags()["scalars"], f"{tag} not in {accumulator.Tags()['scalars']}"
    return [(event.step, event.value) for event in accumulator.Scalars(tag)]


def replay_episode(model_path: Path, algo_class: type, env_kwargs: dict[str, Any], seed: int) -> tuple[float, int]:
    """The first episode of ``enjoy --deterministic --seed seed``, replayed in this process."""
    model = algo_class.load(model_path, device="cpu")
    env = gym.make(ENV_ID, **env_kwargs)
    obs, _ = env.reset(seed=seed)
    total, length, done = 0.0, 0, False
    while not done:
        action, _ = model.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, _ = env.step(action)
        total, length, done = total + float(reward), length + 1, terminated or truncated
    return total, length


def enjoy_episode(output: str) -> tuple[float, int]:
    lines = output.splitlines()
    reward = next(float(line.split(":")[1]) for line in lines if line.startswith("Episode Reward:"))
    length = next(int(line.split()[-1]) for line in lines if line.startswith("Episode Length"))
    return reward, length


# ----------------------------------------------------------------------------- YAML files
@pytest.mark.parametrize("name", ["dtdpg", "dtdpg_paper", "ddpg", "ddpg_paper", "td3", "sac", "tqc"])
def test_every_config_builds_its_model_for_every_env_id(name: str, tmp_path: Path) -> None:
    register_dtdpg()
    algo = name.removesuffix("_paper")
    paper_task = name.endswith("_paper")
    with open(CONFIGS / f"{name}.yml") as f:
        entries = yaml.safe_load(f)
    env_ids = PAPER_IDS if paper_task else NOMA_IDS
    assert set(env_ids) <= set(entries)
    for env_id in env_ids:
        manager = ExperimentManager(
            argparse.Namespace(), algo, env_id, str(tmp_path / "logs"), eval_freq=-1, config=str(CONFIGS / f"{name}.yml")
        )
        model, saved = manager.setup_experiment()
        assert type(model) is rl_zoo3.ALGOS[algo]
        # every algorithm gets the same budget: the paper's 500 episodes, of 1000 steps on the paper's task
        assert saved["n_timesteps"] == (5e5 if paper_task else 1.5e5)
        assert model.env.get_attr("task") == ["paper" if paper_task else "missions"]
        # the RL Zoo's `callback` key: every run logs the mission/* scalars
        assert [type(callback) for callback in manager.callbacks] == [MissionLoggerCallback]
        if algo == "dtdpg":
            assert model.phases == parse_phases(entries[env_id]["phases"])
            assert [phase.reward_phase for phase in model.phases] == ["destination", "mqi"]
            assert model.curriculum_save_path == manager.save_path
        else:
            assert manager.env_kwargs == {"reward_phase": "combined", **({} if paper_task else {"observation": "goal"})}
        # every file trains on the goal-conditioned observation (9 values per robot) but the paper's task, whose
        # state is Eq. (24): position and channel gain per robot (3 values)
        assert model.observation_space.shape == ((6,) if paper_task else (18,))
        model.env.close()


def test_paper_config_has_table_one_values() -> None:
    with open(CONFIGS / "dtdpg_paper.yml") as f:
        entry = yaml.safe_load(f)["NomaRadioMapPaper-v0"]
    table_one = {"learning_rate": 1e-4, "batch_size": 64, "tau": 0.002, "buffer_size": 50_000, "gamma": 1.0}
    assert {key: entry[key] for key in table_one} == table_one
    assert [phase["sigma"] for phase in entry["phases"]] == [0.5, 0.4]


def test_plain_ddpg_baseline_is_plain() -> None:
    with open(CONFIGS / "ddpg.yml") as f:
        entry = yaml.safe_load(f)[ENV_ID]
    assert entry["noise_type"] == "ornstein-uhlenbeck"
    assert "phases" not in entry
    assert entry["env_kwargs"] == {"reward_phase": "combined", "observation": "goal"}


# ----------------------------------------------------------------------------- ExperimentManager fixes
def test_yaml_env_kwargs_reach_the_eval_env(tmp_path: Path) -> None:
    def eval_kwargs(**kwargs: Any) -> dict[str, Any]:
        manager = ExperimentManager(
            argparse.Namespace(), "ddpg", ENV_ID, str(tmp_path), config=str(CONFIGS / "ddpg.yml"), **kwargs
        )
        hyperparams, _ = manager.read_hyperparameters()
        manager._preprocess_hyperparams(hyperparams)
        return manager.eval_env_kwargs

    assert eval_kwargs() == {"reward_phase": "combined", "observation": "goal"}
    assert eval_kwargs(eval_env_kwargs={"reward_phase": "mqi"}) == {"reward_phase": "mqi", "observation": "goal"}


def test_env_kwargs_merge_into_the_config_env_kwargs(tmp_path: Path) -> None:
    def kwargs(**manager_kwargs: Any) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
        manager = ExperimentManager(
            argparse.Namespace(), "ddpg", ENV_ID, str(tmp_path), config=str(CONFIGS / "ddpg.yml"), **manager_kwargs
        )
        hyperparams, saved = manager.read_hyperparameters()
        manager._preprocess_hyperparams(hyperparams)
        return manager.env_kwargs, manager.eval_env_kwargs, saved["env_kwargs"]

    oma = {"reward_phase": "combined", "observation": "goal", "multiple_access": "oma"}
    assert kwargs(env_kwargs={"multiple_access": "oma"}) == (oma, oma, oma)  # reward_phase kept, and saved
    mqi = {"reward_phase": "mqi", "observation": "goal"}
    assert kwargs(env_kwargs={"reward_phase": "mqi"})[0] == mqi  # the command line wins
    env, evaluation, _ = kwargs(env_kwargs={"multiple_access": "oma"}, eval_env_kwargs={"channel": "rayleigh"})
    assert env == oma and evaluation == {**oma, "channel": "rayleigh"}
    # args.yml, whose env_kwargs the zoo's enjoy puts in place of config.yml's, holds the merged ones
    manager = ExperimentManager(
        argparse.Namespace(env_kwargs={"multiple_access": "oma"}), "ddpg", ENV_ID, str(tmp_path),
        config=str(CONFIGS / "ddpg.yml"), env_kwargs={"multiple_access": "oma"},
    )  # fmt: skip
    manager.read_hyperparameters()
    manager.params_path = str(tmp_path / "params")
    os.makedirs(manager.params_path)
    manager._save_config({})
    with open(tmp_path / "params" / "args.yml") as f:
        assert yaml.load(f, Loader=yaml.UnsafeLoader)["env_kwargs"] == oma


def test_packaged_configs_are_the_defaults(tmp_path: Path) -> None:
    register_dtdpg()

    def config(algo: str, env_id: str) -> str:
        return ExperimentManager(argparse.Namespace(), algo, env_id, str(tmp_path)).config

    assert config_dir() == CONFIGS  # a source checkout
    assert config("dtdpg", ENV_ID) == config("dtdpg", "Pendulum-v1") == str(CONFIGS / "dtdpg.yml")
    assert config("ddpg", "NomaRadioMapOMA-v0") == str(CONFIGS / "ddpg.yml")
    # the paper's task: the files keyed by its env ids
    assert config("dtdpg", "NomaRadioMapPaper-v0") == str(CONFIGS / "dtdpg_paper.yml")
    assert config("ddpg", "NomaRadioMapPaperOMA-v0") == str(CONFIGS / "ddpg_paper.yml")
    assert Path(config("td3", "NomaRadioMapPaper-v0")).parent == Path(rl_zoo3.__file__).parent / "hyperparams"
    assert Path(config("ddpg", "Pendulum-v1")).parent == Path(rl_zoo3.__file__).parent / "hyperparams"  # the zoo's own
    assert ExperimentManager(argparse.Namespace(), "ddpg", ENV_ID, str(tmp_path), config="my.yml").config == "my.yml"


def test_a_budget_that_cannot_train_is_an_error(tmp_path: Path) -> None:
    manager = ExperimentManager(argparse.Namespace(), "dtdpg", ENV_ID, str(tmp_path), n_timesteps=2000)
    hyperparams, _ = manager.read_hyperparameters()
    with pytest.raises(ValueError, match=r"n_timesteps=2000 cannot train: .* learning_starts=2000"):
        manager._preprocess_hyperparams(hyperparams)
    manager = ExperimentManager(argparse.Namespace(), "sac", ENV_ID, str(tmp_path), n_timesteps=100)
    hyperparams, _ = manager.read_hyperparameters()
    with pytest.raises(ValueError, match="learning_starts=100"):
        manager._preprocess_hyperparams(hyperparams)


def test_trial_id_without_storage_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="--trial-id 3 needs --storage and --study-name"):
        ExperimentManager(argparse.Namespace(), "dtdpg", ENV_ID, str(tmp_path), trial_id=3)


# ----------------------------------------------------------------------------- sampler and converter
def test_sampled_params_build_a_dtdpg_that_learns() -> None:
    env = gym.make(ENV_ID)
    n_actions = env.action_space.shape[0]
    zoo_args = {"using_her_replay_buffer": False, "her_kwargs": {}}
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=0))
    trials: list[Any] = [study.ask() for _ in range(4)]
    sampled = [sample_dtdpg_params(trial, n_actions, 1, zoo_args) for trial in trials]
    # The corners of the search space too: every parameter at its low (then high) end
    for end in (0, -1):
        fixed = {}
        for name, dist in trials[0].distributions.items():
            if isinstance(dist, optuna.distributions.CategoricalDistribution):
                fixed[name] = dist.choices[end]
            else:
                fixed[name] = (dist.low, dist.high)[end]
        trials.append(optuna.trial.FixedTrial(fixed))
        sampled.append(sample_dtdpg_params(trials[-1], n_actions, 1, zoo_args))
    for index, (trial, kwargs) in enumerate(zip(trials, sampled, strict=True)):
        # --trial-id rebuilds the same arguments from the stored raw parameters
        assert convert_dtdpg_params(trial.params) == kwargs
        model = DTDPG("MlpPolicy", env, device="cpu", seed=index, learning_starts=16, **kwargs)
        assert model.learning_rate == trial.params["learning_rate"]
        assert model.batch_size == 2 ** trial.params["batch_size_pow"]
        assert model.gamma == pytest.approx(1 - trial.params["one_minus_gamma"])
        assert model.phases[0].n_episodes == trial.params["phase1_episodes"]
        assert model.phases[0].success_threshold == trial.params["success_threshold"]
        assert model.phases[1].replay_handling == trial.params["replay_handling"]
        assert [phase.sigma for phase in model.phases] == [trial.params["phase1_sigma"], trial.params["phase2_sigma"]]
        if index == 0:
            model.learn(64)
            assert model.num_timesteps == 64


def test_converter_names_bad_parameters() -> None:
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=1))
    trial = study.ask()
    sample_dtdpg_params(trial, 6, 1, {})
    with pytest.raises(ValueError, match=r"unknown DT-DPG search parameter.*'noise_std'"):
        convert_dtdpg_params({**trial.params, "noise_std": 0.1})
    with pytest.raises(ValueError, match="'tau' is missing"):
        convert_dtdpg_params({key: value for key, value in trial.params.items() if key != "tau"})
    with pytest.raises(ValueError, match=r"net_arch must be one of .* got 'huge'"):
        convert_dtdpg_params({**trial.params, "net_arch": "huge"})


# ----------------------------------------------------------------------------- train + enjoy
@pytest.mark.filterwarnings("ignore:`n_steps=3` is ignored")  # SB3's load() of its own n-step DDPG
@pytest.mark.parametrize("algo", ["dtdpg", "ddpg"])
def test_train_then_enjoy(algo: str, tmp_path: Path) -> None:
    extra = [TWO_SHORT_PHASES] if algo == "dtdpg" else []
    run_zoo(
        "train", "--algo", algo, "--env", ENV_ID, "--conf-file", str(CONFIGS / f"{algo}.yml"), "-n", "400",
        "-params", *TINY_PARAMS, *extra, "--eval-freq", "200", "--eval-episodes", "1", "--seed", "3",
        "--num-threads", "1", "-f", "logs", "-tb", "runs", cwd=tmp_path,
    )  # fmt: skip
    run_dir = tmp_path / "logs" / algo / f"{ENV_ID}_1"
    model_path = run_dir / f"{ENV_ID}.zip"
    algo_class = {"dtdpg": DTDPG, "ddpg": DDPG}[algo]
    model = algo_class.load(model_path, device="cpu")
    assert type(model) is algo_class
    assert model.num_timesteps == 400
    assert model.env_settings["observation"] == "goal" and model.env_settings["multiple_access"] == "noma"
    # the zips saved while training (the EvalCallback's best model) record the settings too, for every algorithm
    best = algo_class.load(run_dir / "best_model.zip", device="cpu")
    assert best.env_settings == model.env_settings and best.env_settings["scenario"] == "mall"

    config = load_config(run_dir)
    with open(CONFIGS / f"{algo}.yml") as f:
        yaml_entry = yaml.safe_load(f)[ENV_ID]
    assert config["learning_starts"] == 50 and config["buffer_size"] == 2000  # the -params overrides
    assert config["env_kwargs"] == yaml_entry["env_kwargs"]
    assert config["learning_rate"] == yaml_entry["learning_rate"] == model.lr_schedule(1.0)
    with open(run_dir / ENV_ID / "args.yml") as f:
        args = yaml.load(f, Loader=yaml.UnsafeLoader)
    assert (args["algo"], args["env"], args["seed"]) == (algo, ENV_ID, 3)

    tb_dir = tmp_path / "runs" / ENV_ID / f"{algo.upper()}_1"
    assert [step for step, _ in scalars(tb_dir, "eval/mean_reward")] == [200, 400]
    if algo == "dtdpg":
        assert config["phases"][0]["n_episodes"] == 1
        assert [phase.name for phase in model.phases] == ["destination", "mqi"]
        assert model.curriculum_state["phase_index"] == 1, "the first episode ended phase 1"
        assert scalars(tb_dir, "curriculum/phase")[-1][1] == 1
        # the phase checkpoint lands in the run's folder
        assert DTDPG.load(run_dir / "phase_0_destination.zip", device="cpu").curriculum_state["phase_index"] == 0
    else:
        assert model.action_noise.__class__.__name__ == "OrnsteinUhlenbeckActionNoise"

    output = run_zoo(
        "enjoy", "--algo", algo, "--env", ENV_ID, "-f", "logs", "--no-render", "--deterministic", "-n", "300",
        "--seed", "5", "--num-threads", "1", cwd=tmp_path,
    )  # fmt: skip
    assert f"Loading logs/{algo}/{ENV_ID}_1/{ENV_ID}.zip" in output
    reward, length = enjoy_episode(output)
    # enjoy ran the trained model on the env of the saved config: the same episode replayed here
    expected_reward, expected_length = replay_episode(model_path, algo_class, config["env_kwargs"], seed=5)
    assert length == expected_length
    assert reward == pytest.approx(expected_reward, abs=0.01)


def test_zoo_runs_log_the_mission_scalars(tmp_path: Path) -> None:
    """The shipped files name the mission logger (the zoo's `callback` key): DDPG and DT-DPG runs of the default files
    log the same mission/* scalars side by side."""
    for algo in ("dtdpg", "ddpg"):
        run_zoo(
            "train", "--algo", algo, "--env", ENV_ID, "-n", "300", "-params", *TINY_PARAMS,
            "--env-kwargs", "scenario:'small'", "--eval-freq", "-1", "--seed", "0", "-f", "logs", "-tb", "runs", cwd=tmp_path,
        )  # fmt: skip
        assert load_config(tmp_path / "logs" / algo / f"{ENV_ID}_1")["callback"] == "sb3_dtdpg.MissionLoggerCallback"
    for algo in ("dtdpg", "ddpg"):
        tb_dir = tmp_path / "runs" / ENV_ID / f"{algo.upper()}_1"
        # small's missions last at most 60 steps and SB3 dumps every 4 episodes: at least one dump in 300 steps
        success_rates = scalars(tb_dir, "mission/success_rate")
        assert success_rates and all(0 <= value <= 1 for _, value in success_rates)
        assert all(np.isfinite(value) for _, value in scalars(tb_dir, "mission/mqi"))
        assert all(0 < value <= 60 for _, value in scalars(tb_dir, "mission/mission_time"))
        assert scalars(tb_dir, "mission/outage_steps")


# ----------------------------------------------------------------------------- shared studies
@pytest.fixture(scope="module")
def journal_study(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str, list[str]]:
    """Two --optimize workers started at the same time on one JournalFile storage, 2 trials each (a
    ``curriculum_save_path`` given too: trials save no phase models, which the next trial would refuse)."""
    cwd = tmp_path_factory.mktemp("journal")
    storage = str(cwd / "study.log")
    phases = f"curriculum_save_path:'{cwd / 'phases'}'"
    workers = [
        start_zoo("train", *optimize_args(storage, "shared", n_trials=2, seed=seed), phases, cwd=cwd) for seed in (1, 2)
    ]
    return cwd, storage, wait_all(workers)


def load_journal_study(storage: str, name: str) -> "optuna.Study":
    backend = optuna.storages.journal.JournalFileBackend(storage)
    return optuna.load_study(storage=optuna.storages.JournalStorage(backend), study_name=name)


def test_two_workers_share_one_journal_study(journal_study: tuple[Path, str, list[str]]) -> None:
    cwd, storage, outputs = journal_study
    study = load_journal_study(storage, "shared")
    assert sorted(trial.number for trial in study.trials) == [0, 1, 2, 3]
    assert all(trial.state == optuna.trial.TrialState.COMPLETE for trial in study.trials)
    assert all(np.isfinite(trial.value) for trial in study.trials)
    # each worker ran its own 2 trials: the one that finished last saw all 4
    finished = sorted(
        int(line.split()[-1]) for out in outputs for line in out.splitlines() if "Number of finished trials" in line
    )
    assert finished[-1] == 4 and finished[0] >= 2
    assert all("its trials save no phase models" in out for out in outputs)
    assert not (cwd / "phases").exists()


def test_trial_id_trains_the_stored_trial(journal_study: tuple[Path, str, list[str]]) -> None:
    cwd, storage, _ = journal_study
    study = load_journal_study(storage, "shared")
    trial = study.trials[0]
    expected = convert_dtdpg_params(trial.params)
    with open(CONFIGS / "dtdpg.yml") as f:
        assert yaml.safe_load(f)[ENV_ID]["learning_rate"] != expected["learning_rate"], "the trial must differ from the YAML"
    # trial 0 on purpose: rl_zoo3 2.9 alone would silently train the YAML defaults (see sb3_dtdpg.zoo)
    run_zoo(
        "train", "--algo", "dtdpg", "--env", ENV_ID, "--conf-file", str(CONFIGS / "dtdpg.yml"), "-n", "100",
        "-params", *TINY_PARAMS, "--storage", storage, "--study-name", "shared", "--trial-id", "0",
        "--eval-freq", "-1", "--num-threads", "1", "-f", "trained", cwd=cwd,
    )  # fmt: skip
    run_dir = cwd / "trained" / "dtdpg" / f"{ENV_ID}_1"
    config = load_config(run_dir)
    # (SB3's DDPG adds n_critics=1 to the policy_kwargs dict the zoo then saves)
    assert config.pop("policy_kwargs").items() >= expected.pop("policy_kwargs").items()
    assert {key: config[key] for key in expected} == expected
    model = DTDPG.load(run_dir / f"{ENV_ID}.zip", device="cpu")
    assert (model.lr_schedule(1.0), model.gamma, model.tau, model.batch_size) == tuple(
        expected[key] for key in ("learning_rate", "gamma", "tau", "batch_size")
    )
    assert model.phases == parse_phases(expected["phases"])
    assert model.policy.net_args["net_arch"] == NET_ARCHS[trial.params["net_arch"]]


# ----------------------------------------------------------------------------- PostgreSQL (across machines)
def _postgres_bin() -> Path | None:
    found = shutil.which("pg_ctl")
    candidates = [Path(found).resolve().parent] if found else []
    candidates += sorted(Path(p) for p in glob.glob("/usr/lib/postgresql/*/bin"))
    for directory in candidates:
        if all((directory / tool).exists() for tool in ("initdb", "pg_ctl", "createdb")):
            return directory
    return None


def _run_checked(command: list[str]) -> None:
    result = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, f"{' '.join(command)} failed:\n{result.stdout}{result.stderr}"


@pytest.fixture
def postgres_url():
    """A throwaway PostgreSQL cluster on a loopback port (run as the `postgres` user when we are root)."""
    pytest.importorskip("psycopg", reason="optuna's PostgreSQL storage needs psycopg (the `tests` extra)")
    bin_dir = _postgres_bin()
    if bin_dir is None:
        pytest.skip("no PostgreSQL server binaries (initdb, pg_ctl, createdb; Debian package `postgresql`)")
    prefix: list[str] = []
    owner = None
    if os.geteuid() == 0:
        # PostgreSQL refuses to run as root
        runuser = shutil.which("runuser")
        try:
            owner = pwd.getpwnam("postgres")
        except KeyError:
            owner = None
        if runuser is None or owner is None:
            pytest.skip("running as root, and no `postgres` user and `runuser` to start PostgreSQL with")
        prefix = [runuser, "-u", "postgres", "--"]
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    # Directly under the temp root: pytest's own folders are closed to other users
    with tempfile.TemporaryDirectory(prefix="sb3-dtdpg-pg-") as folder:
        if owner is not None:
            os.chown(folder, owner.pw_uid, owner.pw_gid)
        data = os.path.join(folder, "data")
        _run_checked([*prefix, str(bin_dir / "initdb"), "-D", data, "-U", "optuna", "--auth=trust"])
        pg_ctl = [*prefix, str(bin_dir / "pg_ctl"), "-D", data, "-w"]
        options = f"-p {port} -k {folder} -c listen_addresses=127.0.0.1"
        _run_checked([*pg_ctl, "-l", os.path.join(folder, "server.log"), "-o", options, "start"])
        try:
            _run_checked([str(bin_dir / "createdb"), "-h", "127.0.0.1", "-p", str(port), "-U", "optuna", "optuna"])
            yield f"postgresql://optuna@127.0.0.1:{port}/optuna"
        finally:
            subprocess.run([*pg_ctl, "-m", "immediate", "stop"], capture_output=True, timeout=60)


def test_two_workers_share_one_postgresql_study(postgres_url: str, tmp_path: Path) -> None:
    # As in docs/ZOO.md: create the study (and the database schema) once, before the workers start;
    # workers that all create the schema of an empty database at once collide (optuna/optuna#1092).
    optuna_cli = Path(sys.executable).with_name("optuna")
    _run_checked([str(optuna_cli), "create-study", "--storage", postgres_url, "--study-name", "pg", "--direction", "maximize"])
    workers = []
    for seed in (1, 2):
        cwd = tmp_path / f"machine_{seed}"  # one folder per "machine": only the database is shared
        cwd.mkdir()
        workers.append(start_zoo("train", *optimize_args(postgres_url, "pg", n_trials=1, seed=seed), cwd=cwd))
    wait_all(workers)
    study = optuna.load_study(storage=postgres_url, study_name="pg")
    assert sorted(trial.number for trial in study.trials) == [0, 1]
    assert all(trial.state == optuna.trial.TrialState.COMPLETE for trial in study.trials)


def test_trial_lookups_that_fail_are_named(journal_study: tuple[Path, str, list[str]], tmp_path: Path) -> None:
    from sb3_dtdpg.zoo import ZooOptionError

    _, storage, _ = journal_study
    n_trials = len(load_journal_study(storage, "shared").trials)
    manager = ExperimentManager(argparse.Namespace(), "dtdpg", ENV_ID, str(tmp_path), storage=storage, study_name="shared")
    with pytest.raises(ZooOptionError, match=f"--trial-id 99: the study 'shared' has {n_trials} trials"):
        manager.load_trial(storage, "shared", 99)
    with pytest.raises(ZooOptionError, match="--study-name 'nosuch': no such study in --storage"):
        manager.load_trial(storage, "nosuch", 0)
    with pytest.raises(ZooOptionError, match="--trial-id must be a trial number >= 0, got -1"):
        manager.load_trial(storage, "shared", -1)
    missing = tmp_path / "none.log"
    with pytest.raises(ZooOptionError, match="no such JournalFile"):
        manager.load_trial(str(missing), "shared", 0)
    assert not missing.exists()  # the zoo's own lookup made an empty one
