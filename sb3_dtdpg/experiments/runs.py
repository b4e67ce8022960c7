"""One training run (train, save, evaluate, write the result), and many of them in parallel processes.

A run is described by a :class:`RunSpec`; :func:`run_one` trains it with TensorBoard logging under
``<out>/tb/<run_id>``, saves the model and writes ``<out>/runs/<run_id>/result.json`` last, atomically:
a run whose result file exists is finished, which is what makes the experiments resumable and keeps
every finished run when a job is interrupted.
"""

from __future__ import annotations

import dataclasses
import json
import math
import multiprocessing
import os
import shutil
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

__all__ = ["BUDGETS", "Budget", "RunReport", "RunSpec", "check_budget", "load_result", "result_path", "run_many", "run_one"]


@dataclass(frozen=True)
class Budget:
    """
    The scale of an experiment.

    :param name: budget name (``--budget``)
    :param episodes: training episodes per run (the paper: 500)
    :param long_episodes: the longer "reality" training of Table II (the paper: 700)
    :param eval_episodes: test episodes per run (the paper: 20, with Rayleigh fading)
    :param seeds: default number of seeds per configuration
    :param scenario: scenario name (None: the env's default, ``mall``)
    """

    name: str
    episodes: int
    long_episodes: int
    eval_episodes: int
    seeds: int
    scenario: str | None = None


#: ``tiny`` is a smoke run on the ``small`` scenario; ``default`` fits ``compare`` in <= 15 minutes on a
#: 2-core machine (measured, docs/RESULTS.md); ``paper`` is the paper's scale; ``reduced`` is the paper's
#: experiments on the ``small`` scenario with 200/280 episodes instead of 500/700 (what a 2-core machine
#: runs in about an hour, docs/RESULTS.md). ``_micro`` is for the tests.
BUDGETS: dict[str, Budget] = {
    "_micro": Budget("_micro", episodes=3, long_episodes=4, eval_episodes=2, seeds=2, scenario="small"),
    "tiny": Budget("tiny", episodes=20, long_episodes=28, eval_episodes=5, seeds=2, scenario="small"),
    "reduced": Budget("reduced", episodes=200, long_episodes=280, eval_episodes=20, seeds=3, scenario="small"),
    "default": Budget("default", episodes=50, long_episodes=70, eval_episodes=20, seeds=3),
    "small": Budget("small", episodes=200, long_episodes=280, eval_episodes=20, seeds=3),
    "paper": Budget("paper", episodes=500, long_episodes=700, eval_episodes=20, seeds=5),
}


@dataclass(frozen=True)
class RunSpec:
    """
    One training run and its evaluation.

    :param algo: one of :data:`sb3_dtdpg.baselines.ALGORITHMS`
    :param multiple_access: ``"noma"`` or ``"oma"``
    :param seed: training seed
    :param episodes: training budget in episodes
    :param channel: training channel, ``"radio_map"`` (the paper's method) or ``"rayleigh"`` ("reality")
    :param learning_rate: overrides the algorithm's learning rate (None: its default)
    :param destination_episodes: DT-DPG's destination-phase budget (None: 60 % of ``episodes``)
    :param env_id: registered env id
    :param scenario: scenario name or path (None: the env's default)
    :param eval_episodes: number of test episodes
    :param eval_seed: seed of the test episodes, the same for every run so that runs are compared on the
        same missions and fading draws
    :param eval_channel: test channel (the paper tests with Rayleigh fading)
    :param tag: suffix of the run id that tells apart runs of the same algorithm, mode and seed
    :param inducing: the env's inducing reward, ``"euclidean"`` (the paper's) or ``"geodesic"`` (None: the env's default)
    :param eval_before_transfer: DT-DPG only: also evaluate the network saved at the end of the destination
        phase (the "before transfer" trajectories of the paper's Fig. 5b)
    :param hyperparams: hyperparameter set of :func:`sb3_dtdpg.baselines.make_model` (``"paper"`` or ``"tuned"``)
    """

    algo: str
    multiple_access: str
    seed: int
    episodes: int
    channel: str = "radio_map"
    learning_rate: float | None = None
    destination_episodes: int | None = None
    env_id: str = "NomaRadioMap-v0"
    scenario: str | None = None
    eval_episodes: int = 20
    eval_seed: int = 10_000
    eval_channel: str = "rayleigh"
    tag: str = ""
    inducing: str | None = None
    eval_before_transfer: bool = True
    hyperparams: str = "paper"

    @property
    def _suffix(self) -> str:
        return (f"_{self.tag}" if self.tag else "") + (f"_{self.hyperparams}" if self.hyperparams != "paper" else "")

    @property
    def run_id(self) -> str:
        """``<algo>_<mode>_s<seed>[_<tag>][_<hyperparams>]``: the run's folder name under ``tb/`` and ``runs/``."""
        return f"{self.algo}_{self.multiple_access}_s{self.seed}{self._suffix}"

    @property
    def group(self) -> str:
        """The run id without the seed: runs of one group are the seeds of one configuration."""
        return f"{self.algo}_{self.multiple_access}{self._suffix}"

    @property
    def env_kwargs(self) -> dict[str, Any]:
        kwargs = {} if self.scenario is None else {"scenario": self.scenario}
        return kwargs if self.inducing is None else {**kwargs, "inducing": self.inducing}


def result_path(out: str | Path, spec: RunSpec) -> Path:
    """:return: the result file of a run (its existence means the run is finished)"""
    return Path(out) / "runs" / spec.run_id / "result.json"


def load_result(out: str | Path, spec: RunSpec) -> dict[str, Any] | None:
    """:return: the stored result of a finished run, or None"""
    path = result_path(out, spec)
    return json.loads(path.read_text()) if path.exists() else None


def _write_json(path: Path, data: dict[str, Any]) -> None:
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(data, indent=1, default=_json_default))
    os.replace(tmp, path)  # atomic: a result file is complete or absent


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def check_budget(spec: RunSpec) -> None:
    """
    :param spec: a run on a mission env
    :raises ValueError: when its budget cannot train: at most ``episodes x mission.max_steps`` env steps, no more
        than the algorithm's ``learning_starts`` (:func:`sb3_dtdpg.baselines.check_training_budget`)
    """
    import gymnasium as gym

    from noma_radiomap import load_scenario
    from sb3_dtdpg.baselines import check_training_budget, hyperparameter

    scenario = spec.scenario or gym.spec(spec.env_id).kwargs.get("scenario", "mall")
    max_steps = int(load_scenario(scenario).mission.max_steps)
    check_training_budget(
        spec.episodes * max_steps,
        int(hyperparameter(spec.algo, "learning_starts", spec.hyperparams)),
        f"{spec.episodes} episodes of at most {max_steps} steps ({spec.run_id})",
        "train for more episodes (a larger budget)",
    )


def _evaluation_record(result: Any, n_trajectories: int, reward_phase: str) -> dict[str, Any]:
    return {
        "reward_phase": reward_phase,
        "summary": result.summary(),
        "episodes": result.episodes,
        "trajectories": [np.round(t, 3).tolist() for t in result.trajectories[:n_trajectories]],
    }


class EpisodeReturnLogger(BaseCallback):
    """
    Log each finished episode's return (from ``Monitor``) as ``episode/return`` and the episode count as
    ``episode/number`` (SB3 keeps ``time/episodes`` out of TensorBoard). With ``log_interval=1`` every
    episode gets its own point, unlike SB3's ``rollout/ep_rew_mean`` (a mean over 100 episodes).
    """

    def __init__(self, verbose: int = 0) -> None:
        super().__init__(verbose)
        self.n_episodes = 0

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            if "episode" in info:
                self.n_episodes += 1
                self.logger.record_mean("episode/return", float(info["episode"]["r"]))
                self.logger.record("episode/number", self.n_episodes)
        return True


def run_one(spec: RunSpec, out: str | Path, n_trajectories: int = 3) -> dict[str, Any]:
    """
    Train, save and evaluate one run; the result is written to :func:`result_path` last.

    The run is evaluated on the reward phase it finished training on (DT-DPG: its last phase's, ``mqi``; the
    baselines: ``combined``), the network saved before the transfer on the first phase's; the result records
    them (``reward_phases``, and ``reward_phase`` in each evaluation record).

    The model trains for ``spec.episodes`` episodes (``StopTrainingOnMaxEpisodes``), logging to TensorBoard
    in ``<out>/tb/<run_id>`` (SB3's scalars and the ``mission/*`` ones). DT-DPG also saves its network at
    the end of the destination phase (the paper's theta_X), which is evaluated too ("before transfer").

    :param spec: the run
    :param out: output folder
    :param n_trajectories: how many test episodes' trajectories to keep in the result
    :return: the result (as written)
    :raises ValueError: when the budget cannot train (:func:`check_budget`)
    """
    import torch as th
    from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes
    from stable_baselines3.common.logger import configure

    import noma_radiomap  # noqa: F401  (registers the env ids in a spawned worker)
    from sb3_dtdpg.baselines import algorithm_class, make_env, make_model, mission_callbacks
    from sb3_dtdpg.evaluation import evaluate

    check_budget(spec)
    th.set_num_threads(1)  # one core per run: runs are parallel across processes
    out = Path(out)
    run_dir = out / "runs" / spec.run_id
    # Leftovers of an interrupted attempt (no result file): start afresh, or TensorBoard would show both.
    for folder in (run_dir, out / "tb" / spec.run_id):
        shutil.rmtree(folder, ignore_errors=True)
    run_dir.mkdir(parents=True, exist_ok=True)
    env = make_env(spec.algo, spec.env_id, spec.multiple_access, spec.channel, spec.env_kwargs)
    destination_episodes = None
    if spec.algo == "dtdpg":
        destination_episodes = spec.destination_episodes or max(1, round(0.6 * spec.episodes))
    model = make_model(
        spec.algo,
        env,
        seed=spec.seed,
        learning_rate=spec.learning_rate,
        destination_episodes=destination_episodes,
        hyperparams=spec.hyperparams,
        **({"curriculum_save_path": str(run_dir)} if spec.algo == "dtdpg" else {}),
    )
    # A logger of our own, so that the TensorBoard folder is exactly tb/<run_id> (SB3 would append "_1").
    model.set_logger(configure(str(out / "tb" / spec.run_id), ["tensorboard", "csv"]))
    max_steps = int(env.unwrapped.scenario.mission.max_steps)
    stop = StopTrainingOnMaxEpisodes(spec.episodes)
    start = time.perf_counter()
    model.learn(
        total_timesteps=spec.episodes * max_steps,
        callback=[stop, EpisodeReturnLogger(), *mission_callbacks(model)],
        log_interval=1,
    )
    train_s = time.perf_counter() - start
    model.save(run_dir / "model.zip")
    curriculum = getattr(model, "curriculum_state", None)
    if curriculum is not None:
        trained_on = list(dict.fromkeys(entry.get("reward_phase") for entry in curriculum["history"]))
    else:
        trained_on = [env.unwrapped.reward_phase]
    final_reward_phase = env.unwrapped.reward_phase
    env.close()

    def _evaluate(policy: Any, reward_phase: str) -> Any:
        return evaluate(
            policy,
            spec.env_id,
            n_episodes=spec.eval_episodes,
            seed=spec.eval_seed,
            channel=spec.eval_channel,
            multiple_access=spec.multiple_access,
            env_kwargs={**spec.env_kwargs, "reward_phase": reward_phase},
            return_trajectories=True,
        )

    result: dict[str, Any] = {
        "spec": dataclasses.asdict(spec),
        "run_id": spec.run_id,
        "group": spec.group,
        "train": {
            "timesteps": int(model.num_timesteps),
            "episodes": int(stop.n_episodes),
            "wall_s": train_s,
            "steps_per_s": model.num_timesteps / max(train_s, 1e-9),
        },
        "reward_phases": {"trained": trained_on, "evaluated": final_reward_phase},
        "eval": _evaluation_record(_evaluate(model, final_reward_phase), n_trajectories, final_reward_phase),
    }
    before = sorted(run_dir.glob("phase_*_destination.zip"))
    if before and spec.eval_before_transfer:
        load_env = make_env(spec.algo, spec.env_id, spec.multiple_access, spec.channel, spec.env_kwargs)
        phase_1 = algorithm_class(spec.algo).load(before[0], env=load_env, device="cpu")
        phase_1_reward = trained_on[0]
        result["before_transfer"] = _evaluation_record(_evaluate(phase_1, phase_1_reward), n_trajectories, phase_1_reward)
        load_env.close()
    result["curriculum_state"] = curriculum
    _write_json(result_path(out, spec), result)
    return result


def _worker(spec: RunSpec, out: str) -> tuple[str, float]:
    start = time.perf_counter()
    run_one(spec, out)
    return spec.run_id, time.perf_counter() - start


@dataclass
class RunReport:
    """What :func:`run_many` did: run ids finished now, skipped (already finished) and failed (with the error)."""

    finished: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    wall_s: float = math.nan


def run_many(
    specs: Sequence[RunSpec],
    out: str | Path,
    n_workers: int | None = None,
    progress: bool = True,
    on_finish: Callable[[str], None] | None = None,
) -> RunReport:
    """
    Run the unfinished runs of ``specs`` in parallel worker processes (spawned, one torch thread each).

    Runs whose result file exists are skipped (resumable). Each run writes its files as soon as it ends,
    so an interruption loses only the runs in progress.

    :param specs: the runs
    :param out: output folder
    :param n_workers: number of processes (default: the number of CPUs)
    :param progress: show a progress bar
    :param on_finish: called with each run id as it finishes
    :return: the report
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    report = RunReport()
    todo: list[RunSpec] = []
    for spec in specs:
        if result_path(out, spec).exists():
            report.skipped.append(spec.run_id)
        else:
            todo.append(spec)
    n_workers = max(1, min(n_workers or os.cpu_count() or 1, len(todo) or 1))
    start = time.perf_counter()
    columns = (
        TextColumn("[bold]runs"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.description}"),
    )
    with Progress(*columns, disable=not progress) as bar:
        task = bar.add_task("", total=len(todo))
        if todo:
            context = multiprocessing.get_context("spawn")
            executor = ProcessPoolExecutor(max_workers=n_workers, mp_context=context)
            try:
                pending: dict[Future, RunSpec] = {executor.submit(_worker, spec, str(out)): spec for spec in todo}
                while pending:
                    done, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for future in done:
                        spec = pending.pop(future)
                        try:
                            run_id, seconds = future.result()
                            report.finished.append(run_id)
                            bar.update(task, advance=1, description=f"{run_id} done in {seconds:.0f} s")
                            if on_finish is not None:
                                on_finish(run_id)
                        except Exception as error:  # a failed run must not take the others down
                            report.failed[spec.run_id] = f"{type(error).__name__}: {error}"
                            bar.update(task, advance=1, description=f"{spec.run_id} FAILED")
            except KeyboardInterrupt:
                executor.shutdown(wait=False, cancel_futures=True)
                raise
            executor.shutdown()
    report.wall_s = time.perf_counter() - start
    return report
