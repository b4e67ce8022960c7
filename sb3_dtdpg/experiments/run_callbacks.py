"""The callbacks of a run: one episode count (:class:`EpisodeCounter`) that the others read.

:class:`EpisodeReturnLogger` counts the finished episodes, logs their returns and stops training at the
run's episode budget; :class:`RunProgress` writes the count for the progress bars of
:func:`sb3_dtdpg.experiments.runs.run_many`; :class:`PeriodicCheckpoint` saves a checkpoint every so many
episodes. Put the counter first in the callback list, so that the others see this step's episodes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

from sb3_dtdpg.common.files import write_json
from sb3_dtdpg.experiments.specs import RunDivergedError
from sb3_dtdpg.experiments.storage import save_checkpoint

__all__ = ["EpisodeCounter", "EpisodeReturnLogger", "PeriodicCheckpoint", "RunProgress", "check_finite"]


class EpisodeCounter(BaseCallback):
    """
    Count the finished episodes (those whose ``info`` has ``Monitor``'s ``"episode"``), and stop training once
    ``max_episodes`` more have finished (SB3's ``StopTrainingOnMaxEpisodes``, counting from ``start``).

    :param start: episodes already trained (a resumed run)
    :param max_episodes: episodes to train in this ``learn`` (None: no limit)
    :param verbose: verbosity level
    """

    def __init__(self, start: int = 0, max_episodes: int | None = None, verbose: int = 0) -> None:
        super().__init__(verbose)
        self.n_episodes = start
        self.stop_at = None if max_episodes is None else start + max_episodes
        self.ended: list[dict[str, Any]] = []  # the infos of the episodes that ended at this step

    def _on_step(self) -> bool:
        self.ended = [info for info in self.locals["infos"] if "episode" in info]
        self.n_episodes += len(self.ended)
        return self.stop_at is None or self.n_episodes < self.stop_at


class EpisodeReturnLogger(EpisodeCounter):
    """
    An :class:`EpisodeCounter` that logs each finished episode's return (from ``Monitor``) as ``episode/return``
    and the episode count as ``episode/number`` (SB3 keeps ``time/episodes`` out of TensorBoard). With
    ``log_interval=1`` every episode gets its own point, unlike SB3's ``rollout/ep_rew_mean`` (a mean over 100
    episodes).
    """

    def _on_step(self) -> bool:
        continue_training = super()._on_step()
        for number, info in enumerate(self.ended, start=self.n_episodes - len(self.ended) + 1):
            self.logger.record_mean("episode/return", float(info["episode"]["r"]))
            self.logger.record("episode/number", number)
        return continue_training

    def _on_training_end(self) -> None:
        # A run stopped by its episode budget ends inside SB3's rollout, before SB3 writes the last episode's
        # values: write what is pending, so the last episode is in the logs (progress.csv, TensorBoard) too.
        if self.logger.name_to_value:
            self.logger.dump(self.num_timesteps)


class RunProgress(BaseCallback):
    """
    Write the run's progress (episodes and timesteps done, and the budget) to a small JSON file at most every
    ``interval`` seconds and at the end, for :func:`sb3_dtdpg.experiments.runs.run_many` to show a bar per
    running run.

    :param path: the progress file (:func:`sb3_dtdpg.experiments.storage.progress_path`)
    :param total: the budget, in ``unit``
    :param counter: the run's episode count
    :param unit: ``"episodes"`` or ``"timesteps"``
    :param interval: seconds between writes
    """

    def __init__(self, path: Path, total: int, counter: EpisodeCounter, unit: str = "episodes", interval: float = 1.0) -> None:
        super().__init__()
        self.path, self.total, self.counter, self.unit, self.interval = path, total, counter, unit, interval
        self._last = -math.inf

    def _write(self) -> None:
        episodes = self.counter.n_episodes
        done = episodes if self.unit == "episodes" else self.num_timesteps
        write_json(self.path, {"done": done, "total": self.total, "unit": self.unit, "episodes": episodes})
        self._last = time.monotonic()

    def _on_step(self) -> bool:
        if time.monotonic() - self._last >= self.interval:
            self._write()
        return True

    def _on_training_end(self) -> None:
        self._write()


class PeriodicCheckpoint(BaseCallback):
    """
    Save the model, its replay buffer and the training state (:mod:`sb3_dtdpg.common.training_state`) every
    ``every`` episodes, for :func:`sb3_dtdpg.experiments.runs.run_one` to resume from. The checkpoint is taken at
    the start of the rollout after the one in which the episode ended: the buffer holds the episode's last
    transition and the gradient steps that followed it are done, so that the resumed ``learn`` starts where the
    uninterrupted one goes on.

    :param run_dir: the run's folder (``checkpoint.json`` and ``checkpoints/`` are written there)
    :param every: episodes between checkpoints
    :param identity: the run's :func:`sb3_dtdpg.experiments.specs.run_identity`, stored with each checkpoint
    :param counter: the run's episode count
    :param exact: whether the training so far is the uninterrupted run's (recorded with each checkpoint)
    :param trained_s: wall-clock seconds the run trained before this ``learn`` call (its checkpoint's; None: not
        known), to which each checkpoint adds this call's, so that a resumed run's training time is its whole
    """

    def __init__(
        self,
        run_dir: Path,
        every: int,
        identity: dict[str, Any],
        counter: EpisodeCounter,
        exact: bool = True,
        trained_s: float | None = 0.0,
    ) -> None:
        super().__init__()
        self.run_dir, self.every, self.identity, self.counter, self.exact = run_dir, every, identity, counter, exact
        self.trained_s = trained_s
        self._due = False
        self._start = time.perf_counter()

    def _on_training_start(self) -> None:
        self._start = time.perf_counter()

    def _on_step(self) -> bool:
        if self.counter.ended:
            # One of the episodes that ended at this step is a multiple of ``every`` (several envs: several ended).
            first = self.counter.n_episodes - len(self.counter.ended) + 1
            self._due = self._due or any(n % self.every == 0 for n in range(first, self.counter.n_episodes + 1))
        return True

    def _on_rollout_start(self) -> None:
        if self._due:
            self._due = False
            check_finite(self.model)  # a diverged model is no checkpoint to resume from
            train_s = None if self.trained_s is None else self.trained_s + time.perf_counter() - self._start
            save_checkpoint(self.model, self.run_dir, self.identity, self.counter.n_episodes, self.exact, train_s)


def non_finite(tensors: Iterable[tuple[str, Any]]) -> list[str]:
    """
    :param tensors: named tensors, e.g. a policy's ``named_parameters()`` or ``state_dict().items()``
    :return: the names of those holding NaN or infinite values
    """
    return [name for name, tensor in tensors if not bool(tensor.isfinite().all())]


def check_finite(model: Any) -> None:
    """
    :param model: an SB3 model
    :raises RunDivergedError: a parameter of its policy is NaN or infinite
    """
    broken = non_finite(model.policy.named_parameters())
    if broken:
        raise RunDivergedError(
            f"training diverged at step {model.num_timesteps}: the policy's {broken[0]} holds non-finite values "
            "(a learning rate or reward constants too large?)"
        )
