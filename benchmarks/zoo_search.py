"""
Wall time of a DT-DPG hyperparameter search through the RL Zoo: 2 workers sharing one study vs 1 worker,
the same trials, measured in one run.

The trials are fixed in advance (the DT-DPG sampler on a seeded random sampler) and enqueued in a fresh
JournalFile study for each setup, so both setups train exactly the same hyperparameters; the workers are
``python -m sb3_dtdpg.train --optimize --storage <study.log> --max-total-trials N`` processes.

    python benchmarks/zoo_search.py [--trials 8] [--timesteps 1000] [--seed 0]
"""

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import gymnasium as gym
import optuna

import noma_radiomap  # noqa: F401
from sb3_dtdpg.zoo import sample_dtdpg_params

REPO = Path(__file__).resolve().parents[1]
ENV_ID = "NomaRadioMap-v0"
STUDY = "bench"


def fixed_trials(n_trials: int, seed: int) -> list[dict]:
    """Raw parameters of ``n_trials`` trials of the DT-DPG sampler (seeded random sampling)."""
    n_actions = gym.make(ENV_ID).action_space.shape[0]
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=seed))
    params = []
    for _ in range(n_trials):
        trial = study.ask()
        sample_dtdpg_params(trial, n_actions, 1, {"using_her_replay_buffer": False, "her_kwargs": {}})
        params.append(trial.params)
    return params


def journal(path: Path) -> optuna.storages.JournalStorage:
    return optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(str(path)))


def run_search(n_workers: int, trials: list[dict], timesteps: int, folder: Path) -> tuple[float, float]:
    """
    Enqueue ``trials`` in a new study and run ``n_workers`` zoo workers on it.

    :return: wall time and CPU time (user + system, all workers) in seconds
    """
    folder.mkdir(parents=True)
    storage_path = folder / "study.log"
    study = optuna.create_study(storage=journal(storage_path), study_name=STUDY, direction="maximize")
    for params in trials:
        study.enqueue_trial(params)
    command = [
        sys.executable, "-m", "sb3_dtdpg.train", "--algo", "dtdpg", "--env", ENV_ID,
        "--conf-file", str(REPO / "zoo_configs" / "dtdpg.yml"), "--optimize", "--storage", str(storage_path),
        "--study-name", STUDY, "--max-total-trials", str(len(trials)), "--pruner", "none", "-n", str(timesteps),
        "--n-evaluations", "1", "--eval-episodes", "2", "--no-optim-plots", "--num-threads", "1",
        "-params", "learning_starts:100", "-f", str(folder / "logs"), "--verbose", "0",
    ]  # fmt: skip
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    usage_before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    workers = [
        subprocess.Popen(command, cwd=folder, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        for _ in range(n_workers)
    ]
    for worker in workers:
        _, stderr = worker.communicate()
        if worker.returncode != 0:
            raise RuntimeError(f"worker failed:\n{stderr[-3000:]}")
    elapsed = time.perf_counter() - start
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = usage.ru_utime + usage.ru_stime - usage_before.ru_utime - usage_before.ru_stime
    done = optuna.load_study(storage=journal(storage_path), study_name=STUDY).trials
    complete = [trial for trial in done if trial.state == optuna.trial.TrialState.COMPLETE]
    if sorted(map(str, (t.params for t in complete))) != sorted(map(str, trials)):
        raise RuntimeError(f"the study did not run exactly the enqueued trials: {[t.params for t in done]}")
    return elapsed, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=8, help="number of trials (the same for both setups)")
    parser.add_argument("--timesteps", type=int, default=1000, help="training steps per trial (-n)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sampler that fixes the trials")
    args = parser.parse_args()

    trials = fixed_trials(args.trials, args.seed)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="zoo-search-") as tmp:
        one = run_search(1, trials, args.timesteps, Path(tmp) / "one_worker")
        two = run_search(2, trials, args.timesteps, Path(tmp) / "two_workers")
    print(
        f"{args.trials} trials of {args.timesteps} steps on {ENV_ID} (DT-DPG sampler, seed {args.seed}), {os.cpu_count()} CPUs"
    )
    print(f"1 worker : {one[0]:7.1f} s wall, {one[1]:7.1f} s CPU")
    print(f"2 workers: {two[0]:7.1f} s wall, {two[1]:7.1f} s CPU  (wall-time speed-up {one[0] / two[0]:.2f}x)")
    print(f"load average (1 min) before / after: {load_before:.1f} / {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
