"""Non-learning reference policies (docs/RESULTS.md): the scale on which the learners' MQI means something.

- :class:`RandomPlanner`: uniformly random actions (the floor).
- :class:`ShortestPathPlanner`: the shortest collision-free path on the occupancy grid, followed at full
  speed, with the AP power split equally between the robots.
- :class:`CommAwarePlanner`: Dijkstra on the grid with an outage-aware cost from the radio map, plus a
  per-step power allocation that minimises the number of robots in outage (NOMA or OMA).

They read the true state of the env (positions, destinations, the radio map), so they follow the
:class:`sb3_dtdpg.evaluation.Planner` protocol: ``reset(env)`` after every ``env.reset`` and
``act(env, observation) -> action``, with ``env`` the unwrapped :class:`NomaRadioMapEnv`.

Path planning uses a cost per metre ``c(cell) = 1 + lambda o(cell)``: a robot moving at ``V_max``
spends one step per ``V_max dt`` metres, and a step costs the MQI 1 (time) plus ``lambda`` when the
robot is in outage (paper Eq. (14)), so the cost of a path is the MQI it loses when ``o`` is the outage
indicator. The shortest-path planner uses ``o = 0``.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
from scipy.sparse.csgraph import dijkstra

from noma_radiomap import geometry
from noma_radiomap.downlink import allocate_power, downlink, in_outage
from noma_radiomap.motion import GridMotion
from noma_radiomap.propagation import dbm_to_watt

__all__ = ["CommAwarePlanner", "GridPlanner", "RandomPlanner", "ShortestPathPlanner", "channel_maps", "grid_costs_to_goal"]


def grid_costs_to_goal(
    blocked: np.ndarray, resolution: float, goal: tuple[int, int], extra_cost: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """
    Dijkstra from ``goal`` over the free cells (the env's 8-connected grid without corner cutting,
    :func:`noma_radiomap.geometry.grid_graph`), with the next cell towards the goal from every cell.

    :param blocked: cells that block motion, bool (nx, ny)
    :param resolution: cell size in metres
    :param goal: the goal cell ``(ix, iy)``
    :param extra_cost: extra cost per metre in each cell (see ``grid_graph``); None: pure distance
    :return: the cost to reach the goal from every cell (metres times the cost factor; ``inf`` when
        unreachable), shape (nx, ny), and the next cell towards the goal as flat indices (negative at
        the goal and where unreachable)
    """
    nx, ny = blocked.shape
    graph = geometry.grid_graph(blocked, resolution, extra_cost)
    # The graph is symmetric, so the predecessors on the tree rooted at the goal point towards the goal.
    costs, predecessors = dijkstra(graph, directed=False, indices=goal[0] * ny + goal[1], return_predecessors=True)
    return costs.reshape(nx, ny), predecessors.reshape(nx, ny)


def channel_maps(env: Any) -> tuple[np.ndarray, np.ndarray]:
    """
    Expected (radio-map) channel of every cell: the linear AP gain and the interference power.

    Both include the expected Rayleigh fading ``E[10 log10 |h|^2]`` (paper Eq. (17)), i.e. they are exactly
    the env's channel in ``channel="radio_map"`` mode and its expectation (in dB) in ``"rayleigh"`` mode.

    :param env: the unwrapped env (its ``radio_map``)
    :return: ``gain`` (linear, nx x ny) and ``interference_w`` (watts over the cluster band, nx x ny)
    """
    return env.radio_map.gain["ap"], env.radio_map.interference_w


def _env_state(env: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (U, 2), destinations (U, 2) and arrived flags (U,) of the robots."""
    positions = np.asarray(env.positions, dtype=np.float64).reshape(-1, 2)
    destinations = np.asarray(env.destinations, dtype=np.float64).reshape(-1, 2)
    return positions, destinations, np.asarray(env.arrived, dtype=bool).reshape(-1)


class RandomPlanner:
    """
    Uniformly random actions: the floor of the MQI scale.

    :param seed: seed of the planner's own random generator (the env's generator is left alone)
    """

    def __init__(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)

    def reset(self, env: Any) -> None:
        pass

    def act(self, env: Any, observation: np.ndarray) -> np.ndarray:
        space = env.action_space
        return self.rng.uniform(space.low, space.high).astype(space.dtype)


class GridPlanner:
    """
    Base of the path-following planners: plan on the occupancy grid, follow the path at full speed,
    allocate power by :meth:`power_actions`.

    Paths are planned cell to cell with :func:`grid_costs_to_goal` (one Dijkstra per destination, cached).
    At each step a robot heads for the farthest of the next ``lookahead`` path points that it can reach
    in a straight line (checked with the env's own motion model) at no more cost than the path itself
    (so the comm-aware planner keeps its detours), and moves ``V_max dt`` towards it: this smooths the
    8-connected staircase into straight lines. A robot that ends a step away from where the planner
    sent it (it slid along a wall) is re-planned from where it is.

    :param lookahead: how many path points ahead a robot may aim at
    """

    def __init__(self, lookahead: int = 8) -> None:
        if lookahead < 1:
            raise ValueError(f"lookahead must be >= 1, got {lookahead!r}")
        self.lookahead = lookahead
        self._paths: list[tuple[np.ndarray, np.ndarray]] = []
        self._expected: np.ndarray | None = None
        self._key: tuple[int, str] | None = None
        self._fields: dict[tuple[float, float], tuple[np.ndarray, np.ndarray]] = {}

    # --- to override -------------------------------------------------------------------------------
    def extra_cost(self, env: Any) -> np.ndarray | None:
        """Extra path cost per metre in each cell (nx, ny), on top of the distance; None: pure distance."""
        return None

    def power_actions(self, env: Any, next_positions: np.ndarray, active: np.ndarray) -> np.ndarray:
        """Power actions in [-1, 1], shape (U,): here an equal split, ``p_u = P_max / U``."""
        n_robots = len(next_positions)
        return np.full(n_robots, 2.0 / n_robots - 1.0)

    # --- planning ----------------------------------------------------------------------------------
    def _setup(self, env: Any) -> None:
        key = (id(env.radio_map), str(getattr(env, "multiple_access", "")))
        if key != self._key:
            self._key = key
            self._fields = {}
            extra = self.extra_cost(env)
            self._extra = extra
            self._cost = 1.0 + (np.zeros(env.radio_map.blocked.shape) if extra is None else extra)
            room = env.scenario.room
            self._motion = GridMotion(
                env.radio_map.blocked,
                room,
                max_step=env.scenario.robot.v_max * env.scenario.mission.time_step,
            )

    def _field(self, env: Any, destination: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = (float(destination[0]), float(destination[1]))
        if key not in self._fields:
            goal = tuple(int(i) for i in env.radio_map.cell_index(np.asarray(destination)))
            self._fields[key] = grid_costs_to_goal(env.radio_map.blocked, env.scenario.room.resolution, goal, self._extra)
        return self._fields[key]

    def _plan(self, env: Any, position: np.ndarray, destination: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The path from ``position`` as points (n, 2) with their cost to go (n,), ending at the destination."""
        costs, next_cell = self._field(env, destination)
        ny = costs.shape[1]
        cell = tuple(int(i) for i in env.radio_map.cell_index(np.asarray(position)))
        if not np.isfinite(costs[cell]):
            raise ValueError(f"destination {list(destination)} is unreachable from position {list(position)}")
        cells = [cell]
        while next_cell[cells[-1]] >= 0:
            cells.append(divmod(int(next_cell[cells[-1]]), ny))
        ix, iy = np.array(cells[1:-1], dtype=int).reshape(-1, 2).T
        points = np.concatenate([np.asarray(env.radio_map.cell_center(ix, iy)).reshape(-1, 2), [destination]])
        cost_to_go = np.array([*(costs[c] for c in cells[1:-1]), 0.0])
        return points, cost_to_go

    def _clear(self, start: np.ndarray, end: np.ndarray) -> bool:
        """Whether the motion model moves a robot straight from ``start`` to ``end`` without sliding."""
        step = self._motion.max_step
        n_chunks = max(1, int(np.ceil(np.linalg.norm(end - start) / step - 1e-9)))
        delta = (end - start) / n_chunks
        position = start[None, :]
        for _ in range(n_chunks):
            target = position + delta
            position, _ = self._motion.move(position, delta[None, :] / step)
            if not np.allclose(position, target, atol=1e-9):
                return False
        return True

    def _chord_cost(self, env: Any, start: np.ndarray, end: np.ndarray) -> float:
        """Path cost of a straight segment, in the units of :func:`grid_costs_to_goal`."""
        resolution = env.scenario.room.resolution
        length = float(np.linalg.norm(end - start))
        n = max(1, int(np.ceil(length / (0.25 * resolution))))
        middles = start + (np.arange(n)[:, None] + 0.5) / n * (end - start)
        ix, iy = env.radio_map.cell_index(middles)
        return float(self._cost[ix, iy].mean() * length)

    def _aim(self, env: Any, u: int, position: np.ndarray) -> np.ndarray:
        points, cost_to_go = self._paths[u]
        costs, _ = self._fields[(float(points[-1][0]), float(points[-1][1]))]
        here = float(costs[tuple(int(i) for i in env.radio_map.cell_index(position))])
        best = 0
        for j in range(min(self.lookahead, len(points))):
            # Half a cell of slack: ``position`` is anywhere in its cell, the costs are at cell centres.
            slack = 0.5 * env.scenario.room.resolution
            if self._clear(position, points[j]) and self._chord_cost(env, position, points[j]) <= here - cost_to_go[j] + slack:
                best = j
        # Points before the one aimed at are behind the robot now.
        self._paths[u] = (points[best:], cost_to_go[best:])
        target = points[best]
        gap = float(np.linalg.norm(target - position))
        return target if gap <= self._motion.max_step else position + (target - position) * (self._motion.max_step / gap)

    def reset(self, env: Any) -> None:
        self._setup(env)
        positions, destinations, _ = _env_state(env)
        self._paths = [self._plan(env, p, d) for p, d in zip(positions, destinations, strict=False)]
        self._expected = positions.copy()

    def act(self, env: Any, observation: np.ndarray) -> np.ndarray:
        positions, destinations, arrived = _env_state(env)
        step = self._motion.max_step
        motion = np.zeros_like(positions)
        next_positions = positions.copy()
        for u in range(len(positions)):
            if arrived[u]:
                continue
            if self._expected is None or not np.allclose(positions[u], self._expected[u], atol=1e-6):
                self._paths[u] = self._plan(env, positions[u], destinations[u])
            next_positions[u] = self._aim(env, u, positions[u])
            motion[u] = (next_positions[u] - positions[u]) / step
        self._expected = next_positions
        power = self.power_actions(env, next_positions, ~arrived)
        return np.concatenate([motion, power[:, None]], axis=1).ravel().astype(np.float32)


class ShortestPathPlanner(GridPlanner):
    """Shortest path on the occupancy grid (Dijkstra, 8-connected), full speed, equal power split."""


class CommAwarePlanner(GridPlanner):
    """
    Communication-aware planner: outage-aware paths and outage-minimising power.

    Path cost (see the module docstring): ``1 + lambda o(cell)`` per step, where ``o(cell)`` estimates
    whether a robot there is in outage from the minimum power ``p_min`` it needs alone on the radio-map
    channel (no other robot's NOMA interference): ``o = 1`` when even ``P_max`` is not enough,
    ``o = 1/2`` when it needs more than the equal share ``P_max / U`` (outage depends on the others'
    needs), else 0.

    Power, at every step: an exhaustive search over a grid of power actions (``levels`` per robot; with
    U robots ``levels^U`` candidates, evaluated at once with the env's own downlink model on the expected
    channel at the robots' next positions) for the fewest robots in outage among those still moving;
    ties go to the largest smallest rate-to-QoS ratio.

    :param levels: number of power levels per robot in the search grid (default: 21 for U <= 2, fewer for
        more robots so that the grid stays below ~2000 candidates)
    :param lookahead: how many path points ahead a robot may aim at
    """

    def __init__(self, levels: int | None = None, lookahead: int = 8) -> None:
        super().__init__(lookahead)
        if levels is not None and levels < 2:
            raise ValueError(f"levels must be >= 2, got {levels!r}")
        self.levels = levels

    def _setup(self, env: Any) -> None:
        key = (id(env.radio_map), str(getattr(env, "multiple_access", "")))
        if key != self._key:
            n_robots = env.scenario.n_robots
            levels = self.levels or max(3, min(21, int(2000 ** (1.0 / n_robots))))
            self._grid = np.array(list(itertools.product(np.linspace(-1.0, 1.0, levels), repeat=n_robots)))
        super()._setup(env)

    def _downlink(self, env: Any, power_w: np.ndarray, gain: np.ndarray, interference: np.ndarray) -> np.ndarray:
        radio = env.scenario.radio
        noise_w_per_hz = float(dbm_to_watt(radio.noise_dbm_per_hz))
        result = downlink(power_w, gain, interference, radio.bandwidth_per_robot_hz, noise_w_per_hz, env.multiple_access)
        return result.rate_bps

    def extra_cost(self, env: Any) -> np.ndarray:
        self._gain, self._interference = channel_maps(env)
        scenario, n_robots = env.scenario, env.scenario.n_robots
        max_power_w = float(dbm_to_watt(scenario.ap.max_power_dbm))
        qos = scenario.radio.qos_rate_bps
        # A robot in each cell, its U - 1 cluster mates given no power (so no NOMA interference): the rate
        # grows with its power, so bisect for the least power that meets the QoS.
        gain = np.repeat(self._gain[..., None], n_robots, axis=-1)
        interference = np.repeat(self._interference[..., None], n_robots, axis=-1)
        mates_off = np.zeros_like(gain)

        def meets_qos(power_w: np.ndarray) -> np.ndarray:
            power = mates_off.copy()
            power[..., 0] = power_w
            return ~in_outage(self._downlink(env, power, gain, interference)[..., 0], qos)

        low, high = np.zeros(self._gain.shape), np.full(self._gain.shape, max_power_w)
        for _ in range(40):
            middle = 0.5 * (low + high)
            ok = meets_qos(middle)
            high, low = np.where(ok, middle, high), np.where(ok, low, middle)
        p_min = np.where(meets_qos(np.full(self._gain.shape, max_power_w)), high, np.inf)
        outage = np.where(p_min > max_power_w, 1.0, np.where(p_min > max_power_w / n_robots, 0.5, 0.0))
        return scenario.mission.outage_penalty * outage

    def power_actions(self, env: Any, next_positions: np.ndarray, active: np.ndarray) -> np.ndarray:
        ix, iy = env.radio_map.cell_index(next_positions)
        gain, interference = self._gain[ix, iy], self._interference[ix, iy]
        power_w = allocate_power(self._grid, float(dbm_to_watt(env.scenario.ap.max_power_dbm)))
        rate = self._downlink(env, power_w, gain[None, :], interference[None, :])
        qos = env.scenario.radio.qos_rate_bps
        n_outage = (in_outage(rate, qos) & active).sum(axis=1)
        margin = np.where(active, rate / qos, np.inf).min(axis=1)
        best = np.lexsort((-margin, n_outage))[0]
        return self._grid[best]
