"""The goal features of the ``"goal"`` observation as a wrapper, for an env built with another layout."""

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from noma_radiomap.observations import DISTANCE_SCALE, goal_features

__all__ = ["RelativeGoalObservation", "goal_features"]


class RelativeGoalObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """
    Append, per robot, the direction to its destination and the distance to it to an env's observation.

    ``NomaRadioMapEnv(observation="goal")`` (the default) computes the same values inside the env; this wrapper
    gives them to an env built with another layout (e.g. ``"destinations"``: then the result is the ``"goal"``
    layout): per robot in scenario order, the unit vector towards the destination (2 values) and
    ``min(d / distance_scale, 1)`` (1 value), all 0 for a robot that has arrived.

    :param env: a NomaRadioMap env (or a wrapper of one)
    :param distance_scale: distance in metres at which the distance feature saturates at 1
    """

    def __init__(self, env: gym.Env, distance_scale: float = DISTANCE_SCALE) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, distance_scale=distance_scale)
        gym.ObservationWrapper.__init__(self, env)
        if not np.isfinite(distance_scale) or distance_scale <= 0:
            raise ValueError(f"distance_scale must be a finite number > 0, got {distance_scale!r}")
        self.distance_scale = float(distance_scale)
        self.n_robots = int(env.unwrapped.n_robots)
        low = np.concatenate([env.observation_space.low, -np.ones(3 * self.n_robots, dtype=np.float32)])
        high = np.concatenate([env.observation_space.high, np.ones(3 * self.n_robots, dtype=np.float32)])
        self.observation_space = spaces.Box(low, high, dtype=np.float32)

    def goal_features(self) -> np.ndarray:
        """Per robot: unit vector to the destination and scaled distance (0 once arrived), shape (3U,)."""
        base: Any = self.env.unwrapped
        return goal_features(base.positions, base.destinations, base.arrived, self.distance_scale)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return np.concatenate([observation, self.goal_features()]).astype(np.float32)
