"""The observation layouts of the mission envs (docs/MODEL.md, observations), one compiled kernel for all of them.

Each layout is named for what it holds; every value is scaled into [-1, 1] from a fixed documented range:

- ``"paper"``: the paper's state, Eq. (24) ``S_t = {D_u(t), g_u(t)}``: per robot its position and its AP channel
  gain in dB, nothing else (``3U`` values). It goes with the paper's task (``task="paper"``), where each robot's
  destination is fixed and the agent finds it through the inducing reward (paper Sec. IV).
- ``"destinations"``: per robot its position, its destination, its gain and an arrived flag (``6U``), for
  tasks that draw one of several destinations per robot.
- ``"goal"`` (the default): the ``"destinations"`` values of every robot, then per robot the unit vector towards
  its destination and ``min(d / distance_scale, 1)`` (``9U``), all 0 once the robot has arrived
  (goal-conditioned).

Per-robot arrays have shape (..., U), so one mission and a batch of N missions go through the same code.
"""

import numpy as np
from gymnasium import spaces

from noma_radiomap import geometry
from noma_radiomap.compiled import compiled

#: The observation layouts and their values per robot.
OBSERVATIONS: dict[str, int] = {"goal": 9, "destinations": 6, "paper": 3}
#: The layout of every entry point when none is given (``gymnasium.make``, the CLI, the zoo files, the examples).
DEFAULT_OBSERVATION = "goal"
#: Channel gains (dB) mapped onto the observation's [-1, 1]. On the free cells of the built-in scenarios the AP
#: gain with the expected fading lies in [-98.9, -46.5] dB (-46.5 dB: LoS at the 2 m antenna offset); Rayleigh
#: fading moves it by -27.5 to +10.9 dB from there at the 0.1 % tails of Exp(1), which the range covers; rarer
#: deep fades are clipped.
GAIN_DB_RANGE: tuple[float, float] = (-130.0, -30.0)
#: Distance in metres at which the goal layout's distance feature saturates at 1.
DISTANCE_SCALE = 10.0


def default_observation(task: str) -> str:
    """
    :param task: the env's task (``"missions"`` or ``"paper"``)
    :return: the layout an env of that task gets without ``observation=``: the paper's state, Eq. (24), on the
        paper's task (fixed destinations), :data:`DEFAULT_OBSERVATION` otherwise
    """
    return "paper" if task == "paper" else DEFAULT_OBSERVATION


def check_observation(observation: str) -> None:
    """:raises ValueError: ``observation`` is not one of :data:`OBSERVATIONS`"""
    if observation not in OBSERVATIONS:
        raise ValueError(f"observation must be one of {tuple(OBSERVATIONS)}, got {observation!r}")


def observation_space(observation: str, n_robots: int) -> spaces.Box:
    """
    The space of a layout: ``Box(-1, 1)`` of :data:`OBSERVATIONS` ``[observation] * n_robots`` float32 values
    (the arrived flags lie in [0, 1]).

    :param observation: a layout
    :param n_robots: the number of robots U
    """
    check_observation(observation)
    return spaces.Box(-1.0, 1.0, (OBSERVATIONS[observation] * n_robots,), dtype=np.float32)


class Observer:
    """
    The observation of one layout for a room: :meth:`__call__` maps the mission state to it.

    :param observation: a layout of :data:`OBSERVATIONS`
    :param room_size: ``(width, depth)`` in metres
    :param gain_db_range: the gains mapped onto -1 and 1
    :param distance_scale: see :data:`DISTANCE_SCALE` (the goal layout)
    """

    def __init__(
        self,
        observation: str,
        room_size: tuple[float, float],
        gain_db_range: tuple[float, float] = GAIN_DB_RANGE,
        distance_scale: float = DISTANCE_SCALE,
    ) -> None:
        check_observation(observation)
        if not np.isfinite(distance_scale) or distance_scale <= 0:
            raise ValueError(f"distance_scale must be a finite number > 0, got {distance_scale!r}")
        self.observation = observation
        self.values_per_robot = OBSERVATIONS[observation]
        width, depth = (float(size) for size in room_size)
        low, high = (float(value) for value in gain_db_range)
        self._constants = (2.0 / width, 2.0 / depth, 2.0 / (high - low), -(high + low) / (high - low))
        self.distance_scale = float(distance_scale)

    def __call__(
        self, positions: np.ndarray, destinations: np.ndarray, gain_db: np.ndarray, arrived: np.ndarray
    ) -> np.ndarray:
        """
        :param positions: robot positions in metres, shape (..., U, 2)
        :param destinations: destinations in metres, shape (..., U, 2)
        :param gain_db: AP channel gains in dB, shape (..., U)
        :param arrived: arrived flags, shape (..., U)
        :return: float32 array of shape (..., values_per_robot * U)
        """
        positions = np.asarray(positions, dtype=np.float64)
        shape = positions.shape[:-1]
        rows = (-1, shape[-1])
        values = self.rows(
            positions.reshape(*rows, 2),
            np.asarray(destinations, dtype=np.float64).reshape(*rows, 2),
            np.asarray(gain_db, dtype=np.float64).reshape(rows),
            np.asarray(arrived, dtype=np.bool_).reshape(rows),
        )
        return values.reshape(*shape[:-1], self.values_per_robot * shape[-1])

    def rows(self, positions: np.ndarray, destinations: np.ndarray, gain_db: np.ndarray, arrived: np.ndarray) -> np.ndarray:
        """:meth:`__call__` of (M, U) robots: float64 (M, U, 2) points, float64 (M, U) gains, bool (M, U) flags."""
        return _observe_rows(
            positions, destinations, gain_db, arrived, *self._constants, self.distance_scale, self.values_per_robot
        )


def goal_features(
    positions: np.ndarray, destinations: np.ndarray, arrived: np.ndarray, distance_scale: float = DISTANCE_SCALE
) -> np.ndarray:
    """
    The goal-conditioned features of the ``"goal"`` layout: per robot the unit vector towards its destination
    and ``min(d / distance_scale, 1)``, all 0 for a robot that has arrived.

    :param positions: robot positions in metres, shape (..., U, 2)
    :param destinations: destinations in metres, shape (..., U, 2)
    :param arrived: arrived flags, shape (..., U)
    :param distance_scale: distance in metres at which the distance feature saturates at 1
    :return: float32 array of shape (..., 3 U)
    """
    positions = np.asarray(positions, dtype=np.float64)
    goal = Observer("goal", (2.0, 2.0), distance_scale=distance_scale)
    features = goal(positions, destinations, np.zeros(positions.shape[:-1]), arrived)
    return features[..., 6 * positions.shape[-2] :]


@compiled
def _observe_rows(
    positions: np.ndarray,
    destinations: np.ndarray,
    gain_db: np.ndarray,
    arrived: np.ndarray,
    scale_x: float,
    scale_y: float,
    gain_scale: float,
    gain_offset: float,
    distance_scale: float,
    per_robot: int,
) -> np.ndarray:
    """The observation of (M, U) robots in one pass: ``per_robot`` 3 (paper), 6 (destinations) or 9 (goal)."""
    n_rows, n_robots = gain_db.shape
    out = np.empty((n_rows, per_robot * n_robots), dtype=np.float32)
    for row in range(n_rows):
        for u in range(n_robots):
            k = (3 if per_robot == 3 else 6) * u
            x, y = positions[row, u, 0], positions[row, u, 1]
            gain = min(max(gain_db[row, u] * gain_scale + gain_offset, -1.0), 1.0)
            out[row, k] = x * scale_x - 1.0
            out[row, k + 1] = y * scale_y - 1.0
            if per_robot == 3:
                out[row, k + 2] = gain
                continue
            gx, gy = destinations[row, u, 0], destinations[row, u, 1]
            out[row, k + 2] = gx * scale_x - 1.0
            out[row, k + 3] = gy * scale_y - 1.0
            out[row, k + 4] = gain
            out[row, k + 5] = 1.0 if arrived[row, u] else 0.0
            if per_robot == 9:
                j = 6 * n_robots + 3 * u  # the goal features follow the destinations layout of every robot
                if arrived[row, u]:
                    out[row, j], out[row, j + 1], out[row, j + 2] = 0.0, 0.0, 0.0
                else:
                    dx, dy = gx - x, gy - y
                    distance = geometry.hypot(dx, dy)
                    length = max(distance, 1e-9)
                    out[row, j] = dx / length
                    out[row, j + 1] = dy / length
                    out[row, j + 2] = min(distance / distance_scale, 1.0)
    return out
