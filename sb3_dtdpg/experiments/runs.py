"""One training run (train, save, evaluate, write the result), and many of them in parallel processes.

A run is described by a :class:`RunSpec`; :func:`run_one` trains it with TensorBoard logging under
``<out>/tb/<run_id>``, saves the model and writes ``<out>/runs/<run_id>/result.json`` last, atomically:
a run whose result file exists is finished, which is what makes the experiments resumable and keeps
every finished run when a job is interrupted.

A result file records the run's identity (:func:`run_identity`): the spec, the scenario's full content, the
hyperparameters the algorithm is built with and :data:`RUN_FORMAT_VERSION`. A stored result is used only
when its identity is the one asked for; otherwise the run is refused loudly (:class:`RunMismatchError`)
instead of reporting another experiment's result under this one's name. :func:`output_lock` keeps two jobs
out of one folder, and the worker processes of :func:`run_many` end when their parent process ends.
"""

from __future__ import annotations

import contextlib
import ctypes
import dataclasses
import inspect
import json
import math
import multiprocessing
import os
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from sb3_dtdpg.common.files import atomic_write, remove_temp_files

__all__ = [
    "BUDGETS",
    "PUBLIC_BUDGETS",
    "RUN_FORMAT_VERSION",
    "Budget",
    "OutputBusyError",
    "RunMismatchError",
    "RunReport",
    "RunSpec",
    "check_budget",
    "get_budget",
    "load_result",
    "output_lock",
    "result_path",
    "run_identity",
    "run_many",
    "run_one",
    "worker_pool",
]

#: Version of what a run is and what its result file holds; results of another version are not reused.
RUN_FORMAT_VERSION = 2


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
    "tiny": Budget("tiny", episodes=36, long_episodes=50, eval_episodes=5, seeds=2, scenario="small"),
    "reduced": Budget("reduced", episodes=200, long_episodes=280, eval_episodes=20, seeds=3, scenario="small"),
    "default": Budget("default", episodes=250, long_episodes=350, eval_episodes=20, seeds=1),
    "small": Budget("small", episodes=200, long_episodes=280, eval_episodes=20, seeds=3),
    "paper": Budget("paper", episodes=500, long_episodes=700, eval_episodes=20, seeds=5),
}


#: The budgets a user picks by name (``_micro`` is for the tests).
PUBLIC_BUDGETS: tuple[str, ...] = tuple(name for name in BUDGETS if not name.startswith("_"))


def get_budget(budget: str | Budget) -> Budget:
    """
    :param budget: a name of :data:`BUDGETS` or a :class:`Budget`
    :return: the budget
    :raises ValueError: naming the known budgets when the name is unknown
    """
    if isinstance(budget, Budget):
        return budget
    if budget not in BUDGETS:
        raise ValueError(f"budget must be one of {', '.join(PUBLIC_BUDGETS)}, got {budget!r}")
    return BUDGETS[budget]


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
    :param timesteps: train for this many timesteps instead of ``episodes`` episodes (None: by episodes)
    :param observation: the env's observation, ``"paper"`` (the paper's state) or ``"goal"`` (the goal-conditioned
        extension, :class:`noma_radiomap.wrappers.RelativeGoalObservation`)
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
    timesteps: int | None = None
    observation: str = "paper"

    @property
    def _suffix(self) -> str:
        return (
            (f"_{self.tag}" if self.tag else "")
            + (f"_{self.hyperparams}" if self.hyperparams != "paper" else "")
            + (f"_{self.observation}" if self.observation != "paper" else "")
        )

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
        kwargs: dict[str, Any] = {} if self.scenario is None else {"scenario": self.scenario}
        if self.inducing is not None:
            kwargs["inducing"] = self.inducing
        if self.observation != "paper":
            kwargs["observation"] = self.observation
        return kwargs


class RunMismatchError(ValueError):
    """A stored result or checkpoint belongs to another run than the one asked for (same run id, other identity)."""


class OutputBusyError(RuntimeError):
    """Another process holds the output folder's lock."""


def result_path(out: str | Path, spec: RunSpec) -> Path:
    """:return: the result file of a run (its existence means the run is finished)"""
    return Path(out) / "runs" / spec.run_id / "result.json"


def _hyperparameters(spec: RunSpec) -> dict[str, Any]:
    """What :func:`sb3_dtdpg.baselines.make_model` builds the algorithm with: the class defaults and the set's values."""
    from sb3_dtdpg import baselines

    cls = baselines.algorithm_class(spec.algo)
    values: dict[str, Any] = {
        name: repr(parameter.default)
        for name, parameter in inspect.signature(cls).parameters.items()
        if parameter.default is not inspect.Parameter.empty
    }
    if spec.algo == "ddpg":
        values.update(baselines.DDPG_KWARGS, ou_sigma=baselines.DDPG_OU_SIGMA)
    elif spec.algo == "td3":
        values["noise_sigma"] = baselines.TD3_NOISE_SIGMA
    if spec.hyperparams == "tuned":
        values.update(baselines.TUNED_KWARGS)
    return values


def run_identity(spec: RunSpec) -> dict[str, Any]:
    """
    Everything that determines a run's result, as stored in its result file: :data:`RUN_FORMAT_VERSION`, the
    spec (algorithm, mode, seed, budget in episodes, channel, evaluation, ...), the full content of the
    scenario (a scenario file edited since is another run) and the hyperparameters of the algorithm.

    :param spec: the run
    :return: a JSON-ready mapping (lists, not tuples: compare it with a stored one as is)
    """
    import gymnasium as gym

    import noma_radiomap
    from sb3_dtdpg.baselines import check_hyperparams

    check_hyperparams(spec.algo, spec.hyperparams)
    scenario = spec.scenario
    if scenario is None:
        scenario = gym.spec(spec.env_id).kwargs.get("scenario", "mall")
    identity = {
        "format": RUN_FORMAT_VERSION,
        "spec": dataclasses.asdict(spec),
        "scenario": noma_radiomap.load_scenario(scenario).to_dict(),
        "hyperparameters": _hyperparameters(spec),
    }
    return json.loads(json.dumps(identity, default=_json_default))


def _differences(stored: Any, expected: Any, path: str = "") -> list[str]:
    if isinstance(stored, dict) and isinstance(expected, dict):
        found = []
        order = ("format", "spec", "scenario", "hyperparameters")  # the telling differences first
        keys = sorted(set(stored) | set(expected), key=lambda k: (order.index(k) if k in order else len(order), str(k)))
        for key in keys:
            where = f"{path}.{key}" if path else str(key)
            if key not in stored or key not in expected:
                found.append(
                    f"{where}: {'missing' if key not in stored else repr(stored[key])[:60]} stored, "
                    f"{'missing' if key not in expected else repr(expected[key])[:60]} now"
                )
            else:
                found.extend(_differences(stored[key], expected[key], where))
        return found
    if stored != expected:
        return [f"{path}: {repr(stored)[:60]} stored, {repr(expected)[:60]} now"]
    return []


def _check_identity(stored: dict[str, Any], expected: dict[str, Any], what: Path) -> None:
    differences = _differences(stored.get("identity", {"format": 1}), expected)
    if differences:
        shown = "; ".join(differences[:4]) + (f"; and {len(differences) - 4} more" if len(differences) > 4 else "")
        raise RunMismatchError(
            f"{what} belongs to another run with the same id ({shown}). Use another output folder "
            f"or delete {what.parent} to run this one"
        )


def load_result(out: str | Path, spec: RunSpec, identity: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """
    The stored result of a finished run, checked against the run's identity.

    :param out: output folder
    :param spec: the run
    :param identity: the run's :func:`run_identity` (None: computed here)
    :return: the result, or None when the run has not finished
    :raises RunMismatchError: the stored result is another run's (another budget, scenario, hyperparameters ...)
    """
    path = result_path(out, spec)
    if not path.exists():
        return None
    result = json.loads(path.read_text())
    _check_identity(result, run_identity(spec) if identity is None else identity, path)
    return result


@contextlib.contextmanager
def output_lock(out: str | Path, name: str = ".lock") -> Iterator[Path]:
    """
    Hold the lock of an output folder for the duration of a job (an OS file lock: released when the process
    ends, even when killed).

    :param out: the folder
    :param name: the lock file's name in it
    :raises OutputBusyError: another process holds it
    """
    from filelock import FileLock, Timeout

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / name
    lock = FileLock(path, timeout=0)
    try:
        lock.acquire()
    except Timeout:
        raise OutputBusyError(
            f"{out} is in use by another job (lock {path}); wait for it to end, or use another output folder"
        ) from None
    try:
        yield path
    finally:
        lock.release()


def _write_json(path: Path, data: dict[str, Any]) -> None:
    text = json.dumps(data, indent=1, default=_json_default)
    atomic_write(path, lambda tmp: Path(tmp).write_text(text))  # a result file is complete or absent


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def check_budget(spec: RunSpec) -> None:
    """
    :param spec: a run on a mission env
    :raises ValueError: when its budget cannot train: at most ``episodes x mission.max_steps`` env steps (or
        ``timesteps``), no more than the algorithm's ``learning_starts`` (:func:`sb3_dtdpg.baselines.check_training_budget`)
    """
    import gymnasium as gym

    from noma_radiomap import load_scenario
    from sb3_dtdpg.baselines import check_training_budget, hyperparameter

    learning_starts = int(hyperparameter(spec.algo, "learning_starts", spec.hyperparams))
    if spec.timesteps is not None:
        check_training_budget(spec.timesteps, learning_starts, f"{spec.timesteps} env steps ({spec.run_id})")
        return
    scenario = spec.scenario or gym.spec(spec.env_id).kwargs.get("scenario", "mall")
    max_steps = int(load_scenario(scenario).mission.max_steps)
    check_training_budget(
        spec.episodes * max_steps,
        learning_starts,
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

    def __init__(self, verbose: int = 0, start: int = 0) -> None:
        super().__init__(verbose)
        self.n_episodes = start

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            if "episode" in info:
                self.n_episodes += 1
                self.logger.record_mean("episode/return", float(info["episode"]["r"]))
                self.logger.record("episode/number", self.n_episodes)
        return True


class RunProgress(BaseCallback):
    """
    Write the run's progress (episodes and timesteps done, and the budget) to a small JSON file at most every
    ``interval`` seconds and at the end, for :func:`run_many` to show a bar per running run.

    :param path: the progress file (``<run dir>/progress.json``)
    :param total: the budget, in ``unit``
    :param unit: ``"episodes"`` or ``"timesteps"``
    :param start: episodes already trained (a resumed run)
    :param interval: seconds between writes
    """

    def __init__(self, path: Path, total: int, unit: str = "episodes", start: int = 0, interval: float = 1.0) -> None:
        super().__init__()
        self.path, self.total, self.unit, self.interval = path, total, unit, interval
        self.n_episodes, self._last = start, -math.inf

    def _write(self) -> None:
        done = self.n_episodes if self.unit == "episodes" else self.num_timesteps
        text = json.dumps({"done": done, "total": self.total, "unit": self.unit, "episodes": self.n_episodes})
        atomic_write(self.path, lambda tmp: Path(tmp).write_text(text))  # read while written by run_many
        self._last = time.monotonic()

    def _on_step(self) -> bool:
        self.n_episodes += sum("episode" in info for info in self.locals["infos"])
        if time.monotonic() - self._last >= self.interval:
            self._write()
        return True

    def _on_training_end(self) -> None:
        self._write()


def read_progress(out: str | Path, spec: RunSpec) -> dict[str, Any] | None:
    """:return: a running run's last :class:`RunProgress` record, or None when it has not started"""
    try:
        return json.loads((Path(out) / "runs" / spec.run_id / "progress.json").read_text())
    except (OSError, ValueError):
        return None


class PeriodicCheckpoint(BaseCallback):
    """
    Save the model and its replay buffer every ``every`` episodes (at the end of the rollout in which the
    episode ended, so the buffer holds its last transition), for :func:`run_one` to resume from.

    :param run_dir: the run's folder (``checkpoint.json`` and ``checkpoints/`` are written there)
    :param every: episodes between checkpoints
    :param identity: the run's :func:`run_identity`, stored with each checkpoint
    :param start: episodes already trained (a resumed run)
    """

    def __init__(self, run_dir: Path, every: int, identity: dict[str, Any], start: int = 0) -> None:
        super().__init__()
        self.run_dir, self.every, self.identity = run_dir, every, identity
        self.n_episodes, self._due = start, False

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            if "episode" in info:
                self.n_episodes += 1
                self._due = self._due or self.n_episodes % self.every == 0
        return True

    def _on_rollout_end(self) -> None:
        if self._due:
            self._due = False
            save_checkpoint(self.model, self.run_dir, self.identity, self.n_episodes)


def save_checkpoint(model: Any, run_dir: Path, identity: dict[str, Any], episodes: int) -> Path:
    """
    Write a checkpoint: model and replay buffer into a fresh ``checkpoints/<episodes>`` folder, then
    ``checkpoint.json`` (atomically) pointing at it, then remove the older folders. A kill at any point leaves
    the previous checkpoint usable.

    :return: the checkpoint folder
    """
    folder = run_dir / "checkpoints" / f"episode_{episodes}"
    shutil.rmtree(folder, ignore_errors=True)
    atomic_write(folder / "model.zip", model.save)
    if getattr(model, "replay_buffer", None) is not None:
        atomic_write(folder / "replay_buffer.pkl", model.save_replay_buffer)
    pointer = {
        "identity": identity,
        "episodes": episodes,
        "timesteps": int(model.num_timesteps),
        "folder": str(folder.relative_to(run_dir)),
    }
    _write_json(run_dir / "checkpoint.json", pointer)
    for other in (run_dir / "checkpoints").iterdir():
        if other != folder:
            shutil.rmtree(other, ignore_errors=True)
    return folder


def read_checkpoint(run_dir: str | Path, identity: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """
    The latest checkpoint of a run, checked against the run's identity.

    :param run_dir: the run's folder
    :param identity: the run's :func:`run_identity` (None: not checked)
    :return: ``checkpoint.json``'s content plus ``path`` (the folder), or None when there is none
    :raises RunMismatchError: the checkpoint is another run's
    """
    run_dir = Path(run_dir)
    pointer = run_dir / "checkpoint.json"
    if not pointer.exists():
        return None
    checkpoint = json.loads(pointer.read_text())
    if identity is not None:
        _check_identity(checkpoint, identity, pointer)
    checkpoint["path"] = run_dir / checkpoint["folder"]
    return checkpoint if (checkpoint["path"] / "model.zip").exists() else None


def run_one(
    spec: RunSpec,
    out: str | Path,
    n_trajectories: int = 3,
    *,
    tensorboard_dir: str | Path | None = None,
    checkpoint_every: int | None = None,
    resume: bool = False,
    threads: int | None = 1,
    progress_bar: bool = False,
    verbose: int = 0,
) -> dict[str, Any]:
    """
    Train, save and evaluate one run; the result is written to :func:`result_path` last.

    The run is evaluated on the reward phase it finished training on (DT-DPG: its last phase's, ``mqi``; the
    baselines: ``combined``), the network saved before the transfer on the first phase's; the result records
    them (``reward_phases``, and ``reward_phase`` in each evaluation record).

    The model trains for ``spec.episodes`` episodes (``StopTrainingOnMaxEpisodes``; or ``spec.timesteps``
    timesteps), logging to TensorBoard in ``<tensorboard_dir>/<run_id>`` (SB3's scalars and the ``mission/*``
    ones). DT-DPG also saves its network at the end of the destination phase (the paper's theta_X), which is
    evaluated too ("before transfer").

    Without ``resume``, leftovers of an interrupted attempt are removed and the run starts afresh (so that a
    run's result depends on its seed only). With ``resume``, a finished run's result is returned as is and an
    interrupted one continues from its last checkpoint (model, replay buffer, action noise and curriculum
    state; not the environment's random state, so a resumed run is not bit-identical to an uninterrupted one).

    :param spec: the run
    :param out: output folder
    :param n_trajectories: how many test episodes' trajectories to keep in the result
    :param tensorboard_dir: TensorBoard root folder (None: ``<out>/tb``)
    :param checkpoint_every: save a checkpoint every this many episodes (None: none)
    :param resume: reuse a finished result or the last checkpoint (both checked against :func:`run_identity`)
    :param threads: torch threads (None: torch's default; 1 in parallel workers)
    :param progress_bar: show SB3's progress bar
    :param verbose: SB3 verbosity
    :return: the result (as written)
    :raises RunMismatchError: with ``resume``, a stored result or checkpoint is another run's
    :raises ValueError: when the budget cannot train (:func:`check_budget`)
    """
    import torch as th
    from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes
    from stable_baselines3.common.logger import configure

    import noma_radiomap  # noqa: F401  (registers the env ids in a spawned worker)
    from sb3_dtdpg.baselines import algorithm_class, make_env, make_model, mission_callbacks
    from sb3_dtdpg.evaluation import evaluate

    check_budget(spec)
    if threads is not None:
        th.set_num_threads(threads)  # one core per run: runs are parallel across processes
    out = Path(out)
    run_dir = out / "runs" / spec.run_id
    tb_dir = (out / "tb" if tensorboard_dir is None else Path(tensorboard_dir)) / spec.run_id
    identity = run_identity(spec)
    checkpoint = None
    if resume:
        finished = load_result(out, spec, identity)
        if finished is not None:
            return finished
        checkpoint = read_checkpoint(run_dir, identity)
    if checkpoint is None:
        # Leftovers of an interrupted attempt (no result file): start afresh, or TensorBoard would show both.
        for folder in (run_dir, tb_dir):
            shutil.rmtree(folder, ignore_errors=True)
    remove_temp_files(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    env = make_env(spec.algo, spec.env_id, spec.multiple_access, spec.channel, spec.env_kwargs)
    done_episodes = 0
    if checkpoint is not None:
        model = algorithm_class(spec.algo).load(checkpoint["path"] / "model.zip", env=env, device="cpu", verbose=verbose)
        if (checkpoint["path"] / "replay_buffer.pkl").exists():
            model.load_replay_buffer(checkpoint["path"] / "replay_buffer.pkl")
        done_episodes = int(checkpoint["episodes"])
    else:
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
            verbose=verbose,
            **({"curriculum_save_path": str(run_dir)} if spec.algo == "dtdpg" else {}),
        )
    # A logger of our own, so that the TensorBoard folder is exactly tb/<run_id> (SB3 would append "_1").
    model.set_logger(configure(str(tb_dir), ["tensorboard", "csv", *(["stdout"] if verbose else [])]))
    max_steps = int(env.unwrapped.scenario.mission.max_steps)
    episode_logger = EpisodeReturnLogger(start=done_episodes)
    callbacks: list[BaseCallback] = [episode_logger, *mission_callbacks(model)]
    if spec.timesteps is None:
        remaining = spec.episodes - done_episodes
        total_timesteps = remaining * max_steps
        callbacks.insert(0, StopTrainingOnMaxEpisodes(remaining))
        callbacks.append(RunProgress(run_dir / "progress.json", spec.episodes, "episodes", done_episodes))
    else:
        total_timesteps = spec.timesteps - model.num_timesteps
        callbacks.append(RunProgress(run_dir / "progress.json", spec.timesteps, "timesteps", done_episodes))
    if checkpoint_every:
        callbacks.append(PeriodicCheckpoint(run_dir, checkpoint_every, identity, start=done_episodes))
    start = time.perf_counter()
    try:
        if total_timesteps > 0:
            model.learn(
                total_timesteps=total_timesteps,
                callback=callbacks,
                log_interval=1,
                reset_num_timesteps=checkpoint is None,
                progress_bar=progress_bar,
            )
    finally:
        model.logger.close()  # flush and close the CSV and TensorBoard files, also on an interruption
    train_s = time.perf_counter() - start
    atomic_write(run_dir / "model.zip", model.save)
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
        "identity": identity,
        "spec": dataclasses.asdict(spec),
        "run_id": spec.run_id,
        "group": spec.group,
        "train": {
            "timesteps": int(model.num_timesteps),
            "episodes": int(episode_logger.n_episodes),
            "resumed_at_episode": done_episodes if checkpoint is not None else None,
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
    # The result supersedes the checkpoints (the replay buffer can be large).
    (run_dir / "checkpoint.json").unlink(missing_ok=True)
    (run_dir / "progress.json").unlink(missing_ok=True)
    shutil.rmtree(run_dir / "checkpoints", ignore_errors=True)
    return result


def _die_with_parent(parent_pid: int) -> None:
    """
    Worker initialiser: end this process when its parent ends, however it ends (SIGTERM, SIGKILL, a crash).
    On Linux the kernel sends SIGKILL (``PR_SET_PDEATHSIG``); elsewhere a thread polls the parent's pid.
    """
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


def worker_pool(n_workers: int) -> ProcessPoolExecutor:
    """
    The process pool of :func:`run_many`: spawned processes (no state inherited from the parent) that end when
    the parent process ends, so that killing a job never leaves workers running its queued runs.

    :param n_workers: number of processes
    :return: the executor
    """
    context = multiprocessing.get_context("spawn")
    return ProcessPoolExecutor(
        max_workers=n_workers, mp_context=context, initializer=_die_with_parent, initargs=(os.getpid(),)
    )


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

    Runs whose result file exists are skipped (resumable), after checking that the stored result is this run's
    (:func:`run_identity`). Each run writes its files as soon as it ends, so an interruption loses only the
    runs in progress (they start afresh next time). Hold :func:`output_lock` around a job that calls this.

    :param specs: the runs
    :param out: output folder
    :param n_workers: number of processes (default: the number of CPUs)
    :param progress: show a progress bar
    :param on_finish: called with each run id as it finishes
    :return: the report
    :raises RunMismatchError: a stored result is another run's (checked for every run before any starts)
    :raises ValueError: a run's budget cannot train (:func:`check_budget`, for every run before any starts)
    """
    for spec in specs:
        check_budget(spec)  # every run's budget before any run starts
    report = RunReport()
    todo: list[RunSpec] = []
    for spec in specs:
        if load_result(out, spec) is not None:
            report.skipped.append(spec.run_id)
        else:
            todo.append(spec)
    # Longest runs first (the budget is the proxy for their length), so that no long run starts last and runs alone
    todo.sort(key=lambda spec: spec.timesteps or spec.episodes, reverse=True)
    n_workers = max(1, min(n_workers or os.cpu_count() or 1, len(todo) or 1))
    start = time.perf_counter()
    with _RunBars(out, len(todo), enabled=progress) as bars:
        if todo:
            executor = worker_pool(n_workers)
            try:
                pending = {executor.submit(_worker, spec, str(out)): spec for spec in todo}
                while pending:
                    done, _ = wait(pending, timeout=2.0 if progress else None, return_when=FIRST_COMPLETED)
                    bars.show_running(pending.values())
                    for future in done:
                        spec = pending.pop(future)
                        try:
                            _, seconds = future.result()
                            report.finished.append(spec.run_id)
                            bars.finished(spec.run_id, f"{spec.run_id} done in {seconds:.0f} s")
                            if on_finish is not None:
                                on_finish(spec.run_id)
                        except Exception as error:  # a failed run must not take the others down
                            report.failed[spec.run_id] = f"{type(error).__name__}: {error}"
                            bars.finished(spec.run_id, f"{spec.run_id} FAILED")
            except KeyboardInterrupt:
                executor.shutdown(wait=False, cancel_futures=True)
                raise
            executor.shutdown()
    report.wall_s = time.perf_counter() - start
    return report


class _RunBars:
    """
    The progress display of :func:`run_many`: one bar for the runs, and one per run in progress (episodes done,
    elapsed time and ETA, read from the run's :class:`RunProgress` file).
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

    def __enter__(self) -> _RunBars:
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
