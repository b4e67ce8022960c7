"""Wrappers of a NomaRadioMap env: the goal features of the ``"goal"`` observation for an env built with another
layout (:class:`RelativeGoalObservation`), and the power actions read as shares of the AP's power
(:class:`PowerShares`, ``gymnasium.make(..., power_mapping="shares")``)."""

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from noma_radiomap.actions import check_action
from noma_radiomap.observations import DISTANCE_SCALE, goal_features

__all__ = ["PowerShares", "RelativeGoalObservation", "goal_features", "power_shares"]


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
        real = isinstance(distance_scale, int | float | np.integer | np.floating) and not isinstance(distance_scale, bool)
        if not real or not np.isfinite(distance_scale) or distance_scale <= 0:
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


def power_shares(power_actions: np.ndarray, active: np.ndarray) -> np.ndarray:
    """
    The power actions that give the robots under way shares of the whole ``P_max`` under the env's own mapping
    (``p_u = P_max (a_u + 1) / 2``, docs/MODEL.md): each active robot asks for ``w_u = (a_u + 1) / 2`` (``a_u``
    clipped to [-1, 1]) and gets ``P_max w_u / sum_v w_v``; when every active robot asks for nothing (all -1), or
    none is active, all get nothing.

    :param power_actions: the power actions ``a_u``, shape (U,)
    :param active: the robots that have not arrived, bool (U,)
    :return: the power actions for the env, shape (U,): ``2 w_u / sum_v w_v - 1`` (-1 for the others)
    """
    wish = (np.clip(np.asarray(power_actions, dtype=np.float64), -1.0, 1.0) + 1.0) / 2.0 * np.asarray(active, dtype=bool)
    total = wish.sum()
    return 2.0 * wish / total - 1.0 if total > 0.0 else np.full(wish.shape, -1.0)


class PowerShares(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """
    Read each robot's power action as its share of the AP's whole power.

    Under the env's own mapping (paper Eq. (15e), docs/MODEL.md) ``p_u = P_max (a_u + 1) / 2`` is scaled down when
    the robots ask for more than ``P_max`` in total, never up: a policy must learn to ask for all of it. Here the
    robots under way always share the whole ``P_max`` in the ratio of their ``(a_u + 1) / 2``
    (:func:`power_shares`), unless all ask for nothing; the motion components pass unchanged. The env itself is
    unchanged: the wrapper hands it the power actions that give these powers. Built by
    ``gymnasium.make("NomaRadioMap-v0", power_mapping="shares")``, and recorded as a model's ``power_mapping``
    setting (a policy trained with one mapping means something else under the other).

    :param env: a NomaRadioMap env (or a wrapper of one)
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ActionWrapper.__init__(self, env)
        self.n_robots = int(env.unwrapped.n_robots)

    def action(self, action: np.ndarray) -> np.ndarray:
        """
        :param action: the agent's action, shape (3U,)
        :return: the action for the env: the motion unchanged, the powers as shares (:func:`power_shares`)
        :raises ValueError: as the env's own check (:func:`~noma_radiomap.actions.check_action`): a wrong shape, a
            non-real dtype or a NaN/inf component (a NaN power must not become "no power")
        :raises ResetNeeded: before the first reset, as the env
        """
        base: Any = self.env.unwrapped
        base.core.check_reset()  # the env's order: not reset, then a bad action
        values = check_action(action, self.n_robots).reshape(-1)
        values[2::3] = power_shares(values[2::3], ~np.asarray(base.arrived, dtype=bool))
        return values
