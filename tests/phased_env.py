"""A tiny, fast env with reward phases for the curriculum tests.

It mirrors the interface of ``noma_radiomap.NomaRadioMapEnv`` (docs/ARCHITECTURE.md):
``REWARD_PHASES``, ``reward_phase``, ``set_reward_phase``, ``reward_weights(phase=None)``,
``info["reward_components"]`` at every step and ``is_success``, ``mqi``, ``mission_time``,
``outage_steps`` at episode end, with a toy physics: point robots in the unit square, no obstacles,
and a robot is in outage when its power share is below its x coordinate.
"""

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

PHASE_WEIGHTS: dict[str, dict[str, float]] = {
    "destination": {"time": 1.0, "inducing": 1.0, "qos": 0.0, "arrival": 1.0, "success": 1.0},
    "mqi": {"time": 1.0, "inducing": 0.0, "qos": 1.0, "arrival": 1.0, "success": 1.0},
    "combined": {"time": 1.0, "inducing": 1.0, "qos": 1.0, "arrival": 1.0, "success": 1.0},
}


class PhasedPointEnv(gym.Env):
    """
    Point robots that must reach their destinations in the unit square.

    Action: per robot (dx, dy, power) in [-1, 1]. Observation: per robot position (2) and destination (2)
    scaled to [-1, 1], channel gain scaled to [-1, 1], arrived flag. Episodes end when every robot has
    arrived (terminated) or after ``max_steps`` steps (truncated).

    :param n_robots: Number of robots U
    :param max_steps: Episode length limit
    :param v_max: Largest move per step
    :param arrival_radius: Distance to the destination at which a robot has arrived
    :param outage_penalty: lambda of the QoS penalty and of the MQI
    :param t_total: T_total of the MQI
    :param starts: Fixed start positions (U, 2); None: drawn at every reset
    :param destinations: Fixed destinations (U, 2); None: drawn at every reset
    :param reward_phase: Initial reward phase
    """

    metadata: dict[str, Any] = {"render_modes": []}
    REWARD_PHASES: tuple[str, ...] = tuple(PHASE_WEIGHTS)

    def __init__(
        self,
        n_robots: int = 1,
        max_steps: int = 20,
        v_max: float = 0.2,
        arrival_radius: float = 0.1,
        outage_penalty: float = 2.0,
        t_total: float = 100.0,
        starts: Any = None,
        destinations: Any = None,
        reward_phase: str = "destination",
    ) -> None:
        super().__init__()
        self.n_robots = n_robots
        self.max_steps = max_steps
        self.v_max = v_max
        self.arrival_radius = arrival_radius
        self.outage_penalty = outage_penalty
        self.t_total = t_total
        self._fixed_starts = None if starts is None else np.asarray(starts, dtype=np.float64).reshape(n_robots, 2)
        self._fixed_destinations = (
            None if destinations is None else np.asarray(destinations, dtype=np.float64).reshape(n_robots, 2)
        )
        self.action_space = spaces.Box(-1.0, 1.0, (3 * n_robots,), dtype=np.float32)
        self.observation_space = spaces.Box(-1.0, 1.0, (6 * n_robots,), dtype=np.float32)
        self.reward_phase = "destination"
        self.set_reward_phase(reward_phase)
        self._d_max = np.sqrt(2.0)

    def set_reward_phase(self, name: str) -> None:
        if name not in PHASE_WEIGHTS:
            raise ValueError(f"reward_phase must be one of {self.REWARD_PHASES}, got {name!r}")
        self.reward_phase = name

    def reward_weights(self, phase: str | None = None) -> dict[str, float]:
        phase = self.reward_phase if phase is None else phase
        if phase not in PHASE_WEIGHTS:
            raise ValueError(f"phase must be one of {self.REWARD_PHASES}, got {phase!r}")
        return dict(PHASE_WEIGHTS[phase])

    def _gain(self) -> np.ndarray:
        return 1.0 - self._pos[:, 0]  # in [0, 1]: worse to the right

    def _obs(self) -> np.ndarray:
        per_robot = np.concatenate(
            [
                self._pos * 2 - 1,
                self._dest * 2 - 1,
                (self._gain() * 2 - 1)[:, None],
                self._arrived[:, None].astype(np.float64),
            ],
            axis=1,
        )
        return per_robot.reshape(-1).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        options = options or {}
        shape = (self.n_robots, 2)
        starts = options.get("starts", self._fixed_starts)
        dests = options.get("destinations", self._fixed_destinations)
        self._pos = (
            self.np_random.uniform(0, 1, shape) if starts is None else np.array(starts, dtype=np.float64).reshape(shape)
        )
        self._dest = self.np_random.uniform(0, 1, shape) if dests is None else np.array(dests, dtype=np.float64).reshape(shape)
        self._arrived = np.linalg.norm(self._pos - self._dest, axis=1) <= self.arrival_radius
        self._steps = 0
        self._arrival_step = np.where(self._arrived, 0, self.max_steps)
        self._outage_steps = np.zeros(self.n_robots, dtype=np.int64)
        return self._obs(), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        action = np.clip(np.asarray(action, dtype=np.float64).reshape(self.n_robots, 3), -1, 1)
        active = ~self._arrived
        self._steps += 1
        move = action[:, :2] * self.v_max
        self._pos = np.where(active[:, None], np.clip(self._pos + move, 0, 1), self._pos)
        power = (action[:, 2] + 1) / 2
        share = power / max(power.sum(), 1e-9)
        outage = active & (share < self._pos[:, 0])
        dist = np.linalg.norm(self._pos - self._dest, axis=1)
        arrived_now = active & (dist <= self.arrival_radius)
        self._arrived |= arrived_now
        self._arrival_step[arrived_now] = self._steps
        self._outage_steps += outage
        terminated = bool(self._arrived.all())
        components = {
            "time": -float(active.sum()),
            "inducing": float(np.sum((1 - dist / self._d_max)[active])),
            "qos": -self.outage_penalty * float(outage.sum()),
            "arrival": 10.0 * float(arrived_now.sum()),
            "success": 200.0 if terminated else 0.0,
        }
        weights = PHASE_WEIGHTS[self.reward_phase]
        reward = sum(weights[key] * value for key, value in components.items())
        truncated = not terminated and self._steps >= self.max_steps
        info: dict[str, Any] = {"reward_components": components, "outage": outage}
        if terminated or truncated:
            info["is_success"] = terminated
            info["mission_time"] = self._arrival_step.copy()  # per robot: T_u, max_steps if never arrived
            info["outage_steps"] = self._outage_steps.copy()
            info["mqi"] = self.t_total - float(np.sum(self._arrival_step + self.outage_penalty * self._outage_steps))
        return self._obs(), float(reward), terminated, truncated, info
