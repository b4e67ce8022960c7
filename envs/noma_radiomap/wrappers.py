"""Optional observation layouts for NomaRadioMap envs (extensions; the paper's observation is the env's own)."""

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces


def goal_features(
    positions: np.ndarray, destinations: np.ndarray, arrived: np.ndarray, distance_scale: float = 10.0
) -> np.ndarray:
    """
    The goal-conditioned features of :class:`RelativeGoalObservation`: per robot the unit vector towards its
    destination and ``min(d / distance_scale, 1)``, all 0 for a robot that has arrived.

    :param positions: robot positions in metres, shape (..., U, 2)
    :param destinations: destinations in metres, shape (..., U, 2)
    :param arrived: arrived flags, shape (..., U)
    :param distance_scale: distance in metres at which the distance feature saturates at 1
    :return: float32 array of shape (..., 3 U)
    """
    offset = np.asarray(destinations, dtype=np.float64) - np.asarray(positions, dtype=np.float64)
    distance = np.hypot(offset[..., 0], offset[..., 1])
    unit = offset / np.maximum(distance, 1e-9)[..., None]
    features = np.concatenate([unit, np.minimum(distance / distance_scale, 1.0)[..., None]], axis=-1)
    features[np.asarray(arrived, dtype=bool)] = 0.0
    return features.reshape(*features.shape[:-2], -1).astype(np.float32)


class RelativeGoalObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """
    Append, per robot, the direction to its destination and the distance to it to the paper's observation.

    The paper's state holds each robot's position and its destination in room coordinates scaled to [-1, 1]
    (``6U`` values, see :class:`noma_radiomap.NomaRadioMapEnv`); a policy then has to compute the direction
    ``destination - position`` itself, and near the destination (the arrival radius is 1 m of a 55 m room,
    0.036 in observation units) it has to do so very precisely. This wrapper adds, per robot in scenario
    order, the unit vector towards the destination (2 values) and ``min(d / distance_scale, 1)`` (1 value),
    all 0 for a robot that has arrived: ``9U`` values in [-1, 1]. It is an extension (a goal-conditioned
    observation), reported in its own rows of docs/BENCHMARKS.md, not the paper's method.

    :param env: a NomaRadioMap env (or a wrapper of one)
    :param distance_scale: distance in metres at which the distance feature saturates at 1
    """

    def __init__(self, env: gym.Env, distance_scale: float = 10.0) -> None:
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
