"""The mission env's (``noma_radiomap``) curricula and logging, defined next to the mission they train.

The algorithm (:class:`sb3_dtdpg.DTDPG`, :mod:`sb3_dtdpg.common`) knows no env: it trains through any list of
:class:`~sb3_dtdpg.common.phases.Phase` objects, the env's own ``default_curriculum`` or a single phase. The
names of the mission's reward phases (``"destination"``, ``"mqi"``), the noise scales of the paper's two
phases and the mission's ``info`` figures (``mqi``, ...) live here; the named settings sets that use these
curricula are in :mod:`sb3_dtdpg.presets`.
"""

from collections import deque

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from sb3_dtdpg.common.phases import Phase, ReplayHandling, parse_phases

__all__ = ["PAPER_EPISODES", "MissionLoggerCallback", "default_phases", "paper_phases"]

#: The paper's training budget in episodes (Table II: radio-map training, 500 episodes).
PAPER_EPISODES = 500


def default_phases(
    destination_episodes: int = 500,
    success_threshold: float | None = 0.95,
    success_window: int = 20,
    replay_handling: ReplayHandling = "relabel",
) -> list[Phase]:
    """
    The mission's curriculum of the tuned settings (:func:`sb3_dtdpg.presets.preset` ``"tuned"``): the paper's two
    phases (Section IV-E), destination training then MQI training, with an early transfer and relabelling.

    OU noise scales are the paper's (0.5 then 0.4, Table I / Section V). The paper gives no final scale;
    we decay linearly to 0.1 and 0.05. Phase 1 ends after ``destination_episodes`` episodes, or earlier
    once the robots reach their destinations in ``success_threshold`` of the last ``success_window``
    episodes. Phase 2 lasts until ``learn()`` ends.

    :param destination_episodes: Episode budget of the destination phase (default: the paper's 500 training
        episodes, over which its noise decays; the early transfer ends it sooner with the goal-conditioned
        observation, docs/BENCHMARKS.md).
    :param success_threshold: Early-transfer threshold of the destination phase (``None``: off). Measured
        against 0.8 and no early transfer in docs/BENCHMARKS.md, "The early-transfer rule".
    :param success_window: Window K of the early-transfer rule.
    :param replay_handling: Replay handling when entering the MQI phase. ``"relabel"`` (the default) trained
        best in ``benchmarks/learning.py`` (docs/BENCHMARKS.md, "Replay handling at the transfer"); it needs an env
        with ``reward_weights`` and reward components.
    :return: The two phases.
    """
    return parse_phases(
        [
            Phase(
                "destination",
                n_episodes=destination_episodes,
                sigma=0.5,
                final_sigma=0.1,
                success_threshold=success_threshold,
                success_window=success_window,
            ),
            Phase("mqi", sigma=0.4, final_sigma=0.05, decay_episodes=300, replay_handling=replay_handling),
        ]
    )


def paper_phases(destination_episodes: int = 300) -> list[Phase]:
    """
    The mission's curriculum of the paper's settings (:func:`sb3_dtdpg.presets.preset` ``"paper"``, docs/ZOO.md,
    "Presets"): the two phases of Algorithm 1 with the OU scales of Section V, 0.5 then 0.4, each
    decayed linearly. Where the paper is silent: the destination phase lasts ``destination_episodes`` (default
    300 of the paper's 500 episodes) with no early transfer and its noise decays to 0.1 over the phase; the MQI
    phase's noise decays to 0.05 over 200 episodes (the rest of the paper's 500, whatever ``destination_episodes``
    is); the replay buffer is kept at the transfer (Algorithm 1 re-uses its memory buffer).

    :param destination_episodes: Episode budget of the destination phase.
    :return: The two phases.
    """
    return parse_phases(
        [
            Phase("destination", n_episodes=destination_episodes, sigma=0.5, final_sigma=0.1),
            Phase("mqi", sigma=0.4, final_sigma=0.05, decay_episodes=PAPER_EPISODES - 300, replay_handling="keep"),
        ]
    )


class MissionLoggerCallback(BaseCallback):
    """
    Log the mission figures of finished episodes from the env's ``info`` under ``mission/``:
    ``success_rate`` (over the last ``stats_window_size`` episodes, from ``is_success``), and the means over the
    episodes since the last log dump of ``success`` (1 when all robots arrived, the definition of the test
    success rate), ``mqi``, ``outage_steps`` (summed over robots) and ``mission_time`` (the largest over
    robots: steps until the last robot arrived, ``max_steps`` if one never did). With ``log_interval=1``
    an off-policy algorithm dumps after every episode, so these are per-episode values.
    Keys absent from an env's infos are skipped.

    Opt-in for every SB3 algorithm, :class:`~sb3_dtdpg.DTDPG` included (``sb3_dtdpg.baselines.mission_callbacks``
    gives it to every algorithm on a mission env)::

        import gymnasium as gym
        import noma_radiomap  # registers the env ids
        from stable_baselines3 import DDPG
        from sb3_dtdpg import MissionLoggerCallback

        env = gym.make("NomaRadioMap-v0", reward_phase="combined")  # both phases' reward terms at once
        model = DDPG("MlpPolicy", env, tensorboard_log="runs")
        model.learn(30_000, callback=MissionLoggerCallback(), log_interval=1, tb_log_name="ddpg")

    :param stats_window_size: Window of the success rate (None: the model's ``stats_window_size``).
    :param verbose: Verbosity level.
    """

    def __init__(self, stats_window_size: int | None = None, verbose: int = 0):
        super().__init__(verbose=verbose)
        window = stats_window_size
        if window is not None and (isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1):
            raise ValueError(f"stats_window_size must be a positive integer or None, got {stats_window_size!r}")
        self.stats_window_size = None if window is None else int(window)
        self.successes: deque[bool] = deque(maxlen=self.stats_window_size or 100)

    def _init_callback(self) -> None:
        window = self.stats_window_size or getattr(self.model, "_stats_window_size", 100)
        if self.successes.maxlen != window:
            self.successes = deque(self.successes, maxlen=window)

    def _on_step(self) -> bool:
        for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
            if not done:
                continue
            if "is_success" in info:
                self.successes.append(bool(info["is_success"]))
                self.logger.record_mean("mission/success", float(info["is_success"]))
                self.logger.record("mission/success_rate", float(np.mean(self.successes)))
            if "mqi" in info:
                self.logger.record_mean("mission/mqi", float(info["mqi"]))
            if "outage_steps" in info:
                self.logger.record_mean("mission/outage_steps", float(np.sum(info["outage_steps"])))
            if "mission_time" in info:
                # Per robot: the squad's mission time is the last arrival.
                self.logger.record_mean("mission/mission_time", float(np.max(info["mission_time"])))
        return True
