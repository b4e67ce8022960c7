"""Non-learning reference policies (docs/RESULTS.md): the scale on which the learners' MQI means something.

- :class:`RandomPlanner`: uniformly random actions (the floor).
- :class:`ShortestPathPlanner`: the shortest collision-free path on the occupancy grid, followed at full
  speed, with the AP power split equally between the robots.
- :class:`CommAwarePlanner`: Dijkstra on the grid with an outage-aware cost from the radio map, plus a
  per-step power allocation that minimises the number of robots in outage (NOMA or OMA).
- :class:`ShortestPathPlanner` with ``power="best"``: the shortest paths with the exact outage-minimising
  power split at every step (:func:`min_outage_power`).
- :class:`ReferencePlanner`: the best planner, a joint search over candidate paths of all robots (the
  shortest paths among them) with the exact power split per step, judged on the radio-map channel; it never
  scores below the shortest-path planner with the best power there. :func:`mqi_upper_bound` bounds the MQI
  of any policy from above (its optimality gap).

They read the true state of the env (positions, destinations, the radio map), so they follow the
:class:`sb3_dtdpg.evaluation.Planner` protocol: ``reset(env)`` after every ``env.reset`` and
``act(env, observation) -> action``, with ``env`` the unwrapped :class:`NomaRadioMapEnv`.

Path planning uses a cost per metre ``c(cell) = 1 + lambda o(cell)``: a robot moving at ``V_max``
spends one step per ``V_max dt`` metres, and a step costs the MQI 1 (time) plus ``lambda`` when the
robot is in outage (paper Eq. (14)), so the cost of a path is the MQI it loses when ``o`` is the outage
indicator. The shortest-path planner uses ``o = 0``.
"""

from __future__ import annotations

import functools
import itertools
from typing import Any

import numpy as np
from scipy.sparse.csgraph import dijkstra

from noma_radiomap import geometry
from noma_radiomap.compiled import compiled
from noma_radiomap.downlink import (
    allocate_power,
    band_and_noise,
    decoding_order,
    downlink,
    equivalent_gain,
    in_outage,
    signal_band,
)
from noma_radiomap.motion import GridMotion
from noma_radiomap.propagation import dbm_to_watt

__all__ = [
    "MAX_CELL_STEPS",
    "MAX_PLANNER_ROBOTS",
    "CommAwarePlanner",
    "GridPlanner",
    "RandomPlanner",
    "ReferencePlanner",
    "ShortestPathPlanner",
    "channel_maps",
    "grid_costs_to_goal",
    "min_outage_power",
    "mqi_upper_bound",
    "outages",
    "rates",
]


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


#: The most robots the exact planners take: they search every subset of the robots for the power split (2^U),
#: the comm-aware planner a grid of power levels (3^U and more) and the best planner every combination of the robots'
#: candidate paths (5^U): 6 robots take seconds per mission, 7 minutes, 200 more memory than a machine has.
MAX_PLANNER_ROBOTS = 6


#: The grid planners check each straight move of a robot one motion step at a time: a step shorter than this
#: fraction of a cell (``time_step: 1e-6`` with ``v_max: 100``) would make each check millions of steps.
MAX_CELL_STEPS = 1_000


def check_planner_robots(n_robots: int, planner: str) -> None:
    """
    :param n_robots: the scenario's robots
    :param planner: what plans, for the message
    :raises ValueError: more robots than :data:`MAX_PLANNER_ROBOTS`
    """
    if n_robots > MAX_PLANNER_ROBOTS:
        raise ValueError(
            f"{planner}: the scenario has {n_robots} robots, more than the {MAX_PLANNER_ROBOTS} its exhaustive search "
            "takes (its cost grows exponentially with the robots); ShortestPathPlanner() (equal power) and "
            "RandomPlanner take any number"
        )


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


def _check_count(name: str, value: Any, low: int) -> int:
    """:return: ``value`` as an int; :raises ValueError: unless it is an integer >= ``low``, naming it"""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


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
        self.lookahead = _check_count("lookahead", lookahead, 1)
        self._paths: list[tuple[np.ndarray, np.ndarray]] = []
        self._expected: np.ndarray | None = None
        # The radio map and mode the fields and costs were built for (the map itself, not its id, which a later map
        # could take once this one is collected)
        self._built_for: tuple[Any, str] | None = None
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
    def _stale(self, env: Any) -> bool:
        """:return: whether the planner was set up for another radio map or mode than the env's"""
        built = self._built_for
        return built is None or built[0] is not env.radio_map or built[1] != str(getattr(env, "multiple_access", ""))

    def _setup(self, env: Any) -> None:
        if self._stale(env):
            self._built_for = (env.radio_map, str(getattr(env, "multiple_access", "")))
            self._fields = {}
            extra = self.extra_cost(env)
            self._extra = extra
            self._cost = 1.0 + (np.zeros(env.radio_map.blocked.shape) if extra is None else extra)
            room = env.scenario.room
            max_step = env.scenario.robot.v_max * env.scenario.mission.time_step
            if room.resolution > MAX_CELL_STEPS * max_step:
                raise ValueError(
                    f"{type(self).__name__}: a robot moves at most {max_step:g} m per step (robot.v_max x "
                    f"mission.time_step), less than 1/{MAX_CELL_STEPS:,} of a cell ({room.resolution:g} m); the grid "
                    "planners check their moves step by step and would take hours per mission"
                )
            self._motion = GridMotion(env.radio_map.blocked, room, max_step=max_step)

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
            # np.allclose(position, target, atol=1e-9), written out (this is the planners' inner loop)
            if not (np.abs(position - target) <= 1e-9 + 1e-5 * np.abs(target)).all():
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
        # The farthest point within the lookahead reached by a clear chord no costlier than the path: searched from
        # the far end, as most chords are clear. Half a cell of slack: ``position`` is anywhere in its cell, the costs
        # are at cell centres.
        slack = 0.5 * env.scenario.room.resolution
        best = 0
        for j in range(min(self.lookahead, len(points)) - 1, 0, -1):
            if self._clear(position, points[j]) and self._chord_cost(env, position, points[j]) <= here - cost_to_go[j] + slack:
                best = j
                break
        if best == 0 and len(points) > 1 and np.allclose(points[0], position, atol=1e-6):
            # Standing on the point aimed at (the cell centre before an off-centre destination, whose last leg the
            # cell-centred costs overrate): aiming at it again would keep the robot there for good
            best = 1
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
    """
    Shortest path on the occupancy grid (Dijkstra, 8-connected), full speed.

    :param power: ``"equal"`` (the AP power split equally, radio-blind) or ``"best"`` (the exact
        outage-minimising split of :func:`min_outage_power` at every step, on the radio-map channel)
    :param lookahead: how many path points ahead a robot may aim at
    """

    def __init__(self, power: str = "equal", lookahead: int = 8) -> None:
        super().__init__(lookahead)
        if power not in ("equal", "best"):
            raise ValueError(f"power must be 'equal' or 'best', got {power!r}")
        self.power = power

    def power_actions(self, env: Any, next_positions: np.ndarray, active: np.ndarray) -> np.ndarray:
        if self.power == "equal":
            return super().power_actions(env, next_positions, active)
        return best_power(env, next_positions[None], active[None])[0][0]


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
        self.levels = None if levels is None else _check_count("levels", levels, 2)

    def _setup(self, env: Any) -> None:
        if self._stale(env):
            n_robots = env.scenario.n_robots
            check_planner_robots(n_robots, "CommAwarePlanner")
            levels = self.levels or max(3, min(21, int(2000 ** (1.0 / n_robots))))
            self._grid = np.array(list(itertools.product(np.linspace(-1.0, 1.0, levels), repeat=n_robots)))
        super()._setup(env)

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
            return ~in_outage(rates(power, gain, interference, scenario, env.multiple_access)[..., 0], qos)

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
        rate = rates(power_w, gain[None, :], interference[None, :], env.scenario, env.multiple_access)
        qos = env.scenario.radio.qos_rate_bps
        n_outage = (in_outage(rate, qos) & active).sum(axis=1)
        margin = np.where(active, rate / qos, np.inf).min(axis=1)
        best = np.lexsort((-margin, n_outage))[0]
        return self._grid[best]


def _noise_w(scenario: Any, multiple_access: str) -> float:
    """The noise power in watts over a robot's band in the mode (NOMA: ``W = U B``, OMA: ``B``;
    :func:`~noma_radiomap.downlink.band_and_noise`, the env's)."""
    radio = scenario.radio
    noise_w_per_hz = float(dbm_to_watt(radio.noise_dbm_per_hz))
    noma = multiple_access == "noma"
    return band_and_noise(scenario.n_robots, radio.bandwidth_per_robot_hz, noise_w_per_hz, noma)[1]


def _qos_sinr(scenario: Any, multiple_access: str) -> float:
    """The SINR a robot needs to meet the QoS rate: ``2^(R / band) - 1`` (NOMA: ``W = U B``, OMA: ``B``)."""
    band = signal_band(scenario.n_robots, scenario.radio.bandwidth_per_robot_hz, multiple_access == "noma")
    return float(2.0 ** (scenario.radio.qos_rate_bps / band) - 1.0)


def _least_powers(
    gain: np.ndarray, interference_w: np.ndarray, served: np.ndarray, scenario: Any, multiple_access: str
) -> np.ndarray:
    """
    The least powers (..., U) that meet the QoS of the ``served`` robots, the others given none.

    NOMA (docs/MODEL.md): with SIC a robot hears the signals of the robots stronger than itself, so the powers
    are set from the strongest served robot down: ``p_u = gamma (g_u P_stronger + I_u + N0 W) / g_u``. OMA:
    ``p_u = gamma (I_u / U + N0 B) / g_u``, each robot on its own band.
    """
    n_robots = scenario.n_robots
    gamma = _qos_sinr(scenario, multiple_access)
    noise_w = _noise_w(scenario, multiple_access)
    if multiple_access == "oma":
        need = gamma * (interference_w / n_robots + noise_w) / gain
        return np.where(served, need, 0.0)
    order = decoding_order(equivalent_gain(gain, interference_w, noise_w))  # weakest first
    power = np.zeros(gain.shape)
    stronger = np.zeros(gain.shape[:-1])
    for rank in range(n_robots - 1, -1, -1):
        u = order[..., rank : rank + 1]
        g, i, s = (np.take_along_axis(a, u, axis=-1)[..., 0] for a in (gain, interference_w, served))
        p = np.where(s, gamma * (g * stronger + i + noise_w) / g, 0.0)
        np.put_along_axis(power, u, p[..., None], axis=-1)
        stronger = stronger + p
    return power


def min_outage_power(
    gain: np.ndarray, interference_w: np.ndarray, active: np.ndarray, scenario: Any, multiple_access: str
) -> tuple[np.ndarray, np.ndarray]:
    """
    The power split that puts the fewest active robots in outage, exactly: over every subset of the active
    robots, the least powers that serve it (:func:`_least_powers`); the largest subset that fits in ``P_max``
    wins (ties: the least total power), and its powers are scaled up to the whole ``P_max`` (every served
    robot's SINR grows with a common factor, in NOMA and OMA alike). Robots not served get no power.

    The outage is then measured with the env's own power mapping and downlink
    (:func:`~noma_radiomap.downlink.allocate_power`, :func:`~noma_radiomap.downlink.downlink`).

    :param gain: linear AP gains, shape (T, U)
    :param interference_w: interference powers, shape (T, U)
    :param active: robots that have not arrived, bool (T, U)
    :param scenario: the scenario (its radio constants, ``P_max``)
    :param multiple_access: ``"noma"`` or ``"oma"``
    :return: the power actions in [-1, 1], shape (T, U), and the number of active robots in outage (T,)
    """
    gain, interference_w = np.asarray(gain, dtype=np.float64), np.asarray(interference_w, dtype=np.float64)
    active = np.asarray(active, dtype=bool)
    n_rows, n_robots = gain.shape
    check_planner_robots(n_robots, "min_outage_power (the best power split)")
    max_power_w = float(dbm_to_watt(scenario.ap.max_power_dbm))
    best_power = np.zeros(gain.shape)
    best_key = np.full(n_rows, np.inf)
    for subset in itertools.product((False, True), repeat=n_robots):
        mask = np.array(subset)
        served = np.broadcast_to(mask, gain.shape) & active
        fits = ~(mask & ~active).any(axis=1)  # the subset's robots are all active
        power = _least_powers(gain, interference_w, served, scenario, multiple_access) * (1.0 + 1e-9)
        total = power.sum(axis=1)
        fits &= total <= max_power_w
        # Fewest in outage first (more served), then the least total power.
        key = -sum(subset) * 2.0 * max_power_w + total
        better = fits & (key < best_key)
        best_key = np.where(better, key, best_key)
        best_power = np.where(better[:, None], power, best_power)
    total = best_power.sum(axis=1, keepdims=True)
    best_power = np.where(total > 0, best_power * (max_power_w / np.maximum(total, 1e-300)), best_power)
    actions = np.clip(np.where(active, 2.0 * best_power / max_power_w - 1.0, -1.0), -1.0, 1.0)
    return actions, outages(allocate_power(actions, max_power_w), gain, interference_w, active, scenario, multiple_access)


def rates(
    power_w: np.ndarray, gain: np.ndarray, interference_w: np.ndarray, scenario: Any, multiple_access: str
) -> np.ndarray:
    """
    The robots' rates with these transmit powers: the env's downlink, :func:`~noma_radiomap.downlink.downlink`, with
    the scenario's radio constants.

    :param power_w: transmit powers, shape (..., U)
    :param gain: linear AP gains, shape (..., U)
    :param interference_w: interference powers, shape (..., U)
    :param scenario: the scenario (its radio constants)
    :param multiple_access: ``"noma"`` or ``"oma"``
    :return: the rates in b/s, shape (..., U)
    """
    radio = scenario.radio
    noise_w_per_hz = float(dbm_to_watt(radio.noise_dbm_per_hz))
    return downlink(power_w, gain, interference_w, radio.bandwidth_per_robot_hz, noise_w_per_hz, multiple_access).rate_bps


def outages(
    power_w: np.ndarray,
    gain: np.ndarray,
    interference_w: np.ndarray,
    active: np.ndarray,
    scenario: Any,
    multiple_access: str,
) -> np.ndarray:
    """
    How many active robots are in outage with these transmit powers (:func:`rates` and
    :func:`~noma_radiomap.downlink.in_outage`).

    :param power_w: transmit powers, shape (T, U)
    :param gain: linear AP gains, shape (T, U)
    :param interference_w: interference powers, shape (T, U)
    :param active: robots that have not arrived, bool (T, U)
    :param scenario: the scenario (its radio constants)
    :param multiple_access: ``"noma"`` or ``"oma"``
    :return: the number of active robots in outage, shape (T,)
    """
    rate = rates(power_w, gain, interference_w, scenario, multiple_access)
    return (in_outage(rate, scenario.radio.qos_rate_bps) & active).sum(axis=1)


def single_outage_maps(env: Any, multiple_access: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """
    Per cell, whether a robot alone (its cluster mates off) is in outage with the whole AP power, and whether
    it needs more than the equal share ``P_max / U``, on the radio-map channel.

    :param env: the unwrapped env
    :param multiple_access: ``"noma"`` or ``"oma"``; None: the env's
    :return: two bool arrays (nx, ny)
    """
    multiple_access = env.multiple_access if multiple_access is None else multiple_access
    gain, interference = channel_maps(env)
    scenario, n_robots = env.scenario, env.scenario.n_robots
    served = np.zeros((gain.size, n_robots), dtype=bool)
    served[:, 0] = True
    stacked = [np.repeat(a.reshape(-1, 1), n_robots, axis=1) for a in (gain, interference)]
    need = _least_powers(stacked[0], stacked[1], served, scenario, multiple_access)[:, 0].reshape(gain.shape)
    max_power_w = float(dbm_to_watt(scenario.ap.max_power_dbm))
    return need > max_power_w, need > max_power_w / n_robots


def _reach_offsets(scenario: Any) -> np.ndarray:
    """Cell offsets a robot can cover in one step, from anywhere in a cell to anywhere in another."""
    resolution = scenario.room.resolution
    reach = scenario.robot.v_max * scenario.mission.time_step + np.sqrt(2.0) * resolution
    n = int(np.floor(reach / resolution))
    offsets = np.array([(i, j) for i in range(-n, n + 1) for j in range(-n, n + 1) if np.hypot(i, j) * resolution <= reach])
    return offsets


@compiled
def _clear_segments(a: np.ndarray, b: np.ndarray, padded: np.ndarray, resolution: float) -> np.ndarray:
    """
    Whether the segments from each point of ``a`` (A, 2) to each of ``b`` (B, 2) stay out of the obstacles'
    interior, sampled every quarter cell. A sample is inside when the four cells around it, a hair away along both
    axes, are blocked (``padded``: the blocked cells with a blocked border, so the room's outside counts as
    blocked), so a segment may run along an obstacle. A segment that only clips an obstacle between two samples
    counts as clear, which can only shorten the distances of :func:`_geodesic_steps` (its bound stays a bound).

    :return: bool (A, B)
    """
    eps = 1e-6 * resolution
    clear = np.ones((a.shape[0], b.shape[0]), dtype=np.bool_)
    for i in range(a.shape[0]):
        for j in range(b.shape[0]):
            dx, dy = b[j, 0] - a[i, 0], b[j, 1] - a[i, 1]
            n = max(2, int(np.ceil(4.0 * max(abs(dx), abs(dy)) / resolution)) + 1)
            for k in range(n):
                t = k / (n - 1)
                x, y = a[i, 0] + t * dx, a[i, 1] + t * dy
                inside = True
                for sx in (-eps, eps):
                    for sy in (-eps, eps):
                        ix = min(max(int(np.floor((x + sx) / resolution)) + 1, 0), padded.shape[0] - 1)
                        iy = min(max(int(np.floor((y + sy) / resolution)) + 1, 0), padded.shape[1] - 1)
                        inside = inside and padded[ix, iy]
                if inside:
                    clear[i, j] = False
                    break
    return clear


#: Most segments :func:`mqi_upper_bound` tests for its shortest paths around the obstacles (corner to corner, cell
#: to corner); a room with more (a large room with many obstacles) gets the grid relaxation alone, a looser bound.
_MAX_SEGMENTS = 20_000_000


def _corners(padded: np.ndarray, resolution: float) -> np.ndarray:
    """
    The corners a shortest path around the obstacles can bend at: a shortest path in the free region (a union of
    grid cells) is a polygonal line bending only at convex corners of the obstacles, grid points where one of the
    four cells meeting there is blocked, or two diagonal ones (a pinch the motion model does not pass; the
    relaxation may).

    :param padded: the blocked cells with a blocked border (the room's outside counts as blocked)
    :return: the corners (C, 2) in metres
    """
    quads = np.stack([padded[:-1, :-1], padded[1:, :-1], padded[:-1, 1:], padded[1:, 1:]])
    count = quads.sum(axis=0)
    pinch = (count == 2) & (quads[0] == quads[3])
    ix, iy = np.nonzero((count == 1) | pinch)
    return np.stack([ix, iy], axis=1).astype(float) * resolution


@functools.lru_cache(maxsize=8)
def _corner_graph(
    blocked_bytes: bytes, shape: tuple[int, int], resolution: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None] | None:
    """
    The corners of :func:`_corners`, their shortest distances to each other along their visibility graph (by
    Dijkstra), and which of them each cell centre sees.

    :return: the corners (C, 2) in metres, their distances (C, C) and the cell centres' sight of them (nx, ny, C;
        None beyond :data:`_MAX_SEGMENTS`), or None when the corners alone are beyond it
    """
    blocked = np.frombuffer(blocked_bytes, dtype=bool).reshape(shape)
    padded = np.pad(blocked, 1, constant_values=True)
    corners = _corners(padded, resolution)
    if len(corners) ** 2 > _MAX_SEGMENTS:
        return None
    lengths = np.hypot(*(corners[:, None, :] - corners[None, :, :]).transpose(2, 0, 1))
    graph = np.where(_clear_segments(corners, corners, padded, resolution), lengths, 0.0)
    sight = None
    if blocked.size * len(corners) <= _MAX_SEGMENTS:
        grid = np.stack(np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij"), axis=-1)
        centres = (grid.reshape(-1, 2) + 0.5) * resolution
        sight = _clear_segments(centres, corners, padded, resolution).reshape(*shape, len(corners))
    return corners, dijkstra(graph, directed=False), sight


def _disc_is_free(blocked: np.ndarray, resolution: float, centre: np.ndarray, radius: float) -> bool:
    """:return: whether no blocked cell (nor the room's outside) meets the disc, so that every point of it sees its
    centre"""
    nx, ny = blocked.shape
    if np.any(centre - radius < 0.0) or centre[0] + radius > nx * resolution or centre[1] + radius > ny * resolution:
        return False
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    gap_x = np.maximum(0.0, np.maximum(ix * resolution - centre[0], centre[0] - (ix + 1) * resolution))
    gap_y = np.maximum(0.0, np.maximum(iy * resolution - centre[1], centre[1] - (iy + 1) * resolution))
    return not bool((blocked & (np.hypot(gap_x, gap_y) <= radius)).any())


def _path_lengths(env: Any, points: np.ndarray, destination: np.ndarray, sight: np.ndarray | None = None) -> np.ndarray:
    """
    Lower bounds on the length of any path from each point (N, 2) into a robot's arrival disc that never enters an
    obstacle. Where the disc is free (every point of it sees the destination), the shortest path around the
    obstacles to the destination (through the corners of :func:`_corner_graph`) less the radius; else the
    shortest path to a corner (or none) plus the straight distance from there to the disc, walls ignored.

    :param sight: which corners each point sees (N, C); None: tested here
    :return: lengths in metres (N,)
    """
    scenario, blocked = env.scenario, env.radio_map.blocked
    resolution = scenario.room.resolution
    graph = _corner_graph(blocked.tobytes(), blocked.shape, resolution)
    if graph is None:  # too many corners: no bound from the paths around them
        return np.zeros(len(np.asarray(points).reshape(-1, 2)))
    corners, between, _ = graph
    radius = scenario.robot.arrival_radius
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    destination = np.asarray(destination, dtype=float)
    padded = np.pad(blocked, 1, constant_values=True)

    def last_legs(origins: np.ndarray) -> np.ndarray:
        """Straight on to the destination: the segment clear where the disc is free, walls ignored elsewhere"""
        straight = np.hypot(*(origins - destination).T)
        if not free_disc:
            return straight
        return np.where(_clear_segments(origins, destination[None, :], padded, resolution)[:, 0], straight, np.inf)

    free_disc = _disc_is_free(blocked, resolution, destination, radius)
    lengths = last_legs(points)
    if len(corners):
        via = (between + last_legs(corners)[None, :]).min(axis=1)  # from each corner, through the others
        if sight is None:
            sight = _clear_segments(points, corners, padded, resolution)
        from_points = np.where(sight, np.hypot(*(points[:, None, :] - corners[None, :, :]).transpose(2, 0, 1)), np.inf)
        lengths = np.minimum(lengths, (from_points + via[None, :]).min(axis=1))
    return np.maximum(0.0, lengths - radius)


def _geodesic_steps(env: Any, start: np.ndarray, destination: np.ndarray) -> int:
    """
    A lower bound on the steps a robot needs to arrive, whatever it does: a step moves it along a path at most
    ``V_max dt`` long that never enters an obstacle (:class:`~noma_radiomap.motion.GridMotion`), so it needs at
    least :func:`_path_lengths` over ``V_max dt`` steps.

    :param env: the unwrapped env
    :param start: the robot's position (2,)
    :param destination: its destination (2,)
    :return: the least number of steps
    """
    scenario = env.scenario
    length = float(_path_lengths(env, np.asarray(start, dtype=float)[None, :], np.asarray(destination, dtype=float))[0])
    return int(np.ceil(length / (scenario.robot.v_max * scenario.mission.time_step) - 1e-9))


def _free_points(env: Any, name: str, points: Any) -> np.ndarray:
    """:return: one point per robot as a float array (U, 2); :raises ValueError: else, or for a point off the floor"""
    try:
        array = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        array = np.empty(0)
    n_robots = env.scenario.n_robots
    if array.shape != (n_robots, 2):
        raise ValueError(f"{name}: expected one point per robot, shape ({n_robots}, 2), got {np.shape(points)}")
    room = env.scenario.room
    free = room.contains(array)  # NaN is outside
    free[free] = ~env.radio_map.blocked[room.cell_index(array[free])]
    for u in np.flatnonzero(~free):
        raise ValueError(f"{name}[{u}]: {array[u].tolist()} is outside the room or in a blocked cell")
    return array


def mqi_upper_bound(env: Any, starts: np.ndarray, destinations: np.ndarray) -> float:
    """
    An upper bound on the MQI of any policy on one mission, on the radio-map channel: a relaxation in which
    each robot is alone with the whole AP power (no NOMA coupling, no power split). Per robot, the larger of two
    lower bounds on its ``steps + lambda x outage steps``: value iteration on the grid, where a robot may move
    from anywhere in its cell to any free cell within ``V_max dt`` plus a cell diagonal per step (walls ignored
    within a step) and arrives within ``arrival_radius`` plus half a cell diagonal, never below the steps that the
    shortest path around the obstacles from anywhere in a cell needs (:func:`_path_lengths`; the grid relaxation
    alone underestimates a path by up to a cell diagonal per step); and its steps alone from its start
    (:func:`_geodesic_steps`). The bound is ``t_total`` minus their sum.

    :param env: the unwrapped env (its scenario, radio map and multiple access)
    :param starts: start points (U, 2)
    :param destinations: destinations (U, 2)
    :return: the bound
    :raises ValueError: a point array of another shape, or a point outside the room or in a blocked cell
    """
    starts, destinations = _free_points(env, "starts", starts), _free_points(env, "destinations", destinations)
    scenario, radio_map = env.scenario, env.radio_map
    mission = scenario.mission
    outage, _ = single_outage_maps(env)
    step_cost = np.where(radio_map.blocked, np.inf, 1.0 + mission.outage_penalty * outage)
    offsets = _reach_offsets(scenario)
    pad = int(np.abs(offsets).max())
    nx, ny = step_cost.shape
    centres = (np.stack(np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij"), axis=-1) + 0.5) * scenario.room.resolution
    arrival = scenario.robot.arrival_radius + scenario.room.resolution / np.sqrt(2)
    total = 0.0
    max_step = scenario.robot.v_max * mission.time_step
    free = ~radio_map.blocked
    graph = _corner_graph(radio_map.blocked.tobytes(), radio_map.blocked.shape, scenario.room.resolution)
    sight = None if graph is None or graph[2] is None else graph[2][free]
    for start, goal in zip(np.asarray(starts, dtype=float), np.asarray(destinations, dtype=float), strict=True):
        near = np.hypot(*(centres - goal).transpose(2, 0, 1)) <= arrival
        # From anywhere in a cell at least the steps of the path length from its centre less half a diagonal
        floor = np.zeros((nx, ny))
        if sight is not None:
            lengths = _path_lengths(env, centres[free], goal, sight) - scenario.room.resolution / np.sqrt(2.0)
            floor[free] = np.ceil(np.maximum(0.0, lengths) / max_step - 1e-9)
        to_go = np.full((nx, ny), np.inf)  # least cost to arrive from each cell, not yet arrived
        for _ in range(int(mission.max_steps)):
            after = step_cost + np.where(near, 0.0, to_go)  # cost of stepping into a cell
            padded = np.pad(after, pad, constant_values=np.inf)
            new = np.full((nx, ny), np.inf)
            for dx, dy in offsets:
                np.minimum(new, padded[pad + dx : pad + dx + nx, pad + dy : pad + dy + ny], out=new)
            np.maximum(new, floor, out=new)
            if np.array_equal(new, to_go):
                break
            to_go = new
        cell = tuple(int(i) for i in radio_map.cell_index(start))
        least = max(float(to_go[cell]), float(_geodesic_steps(env, start, goal)))
        total += min(least, float(mission.max_steps))
    return float(mission.t_total - total)


class _PathFollower(GridPlanner):
    """A :class:`GridPlanner` with a given extra path cost per metre (one candidate of :class:`ReferencePlanner`)."""

    def __init__(self, extra: np.ndarray | None, lookahead: int) -> None:
        super().__init__(lookahead)
        self._given_extra = extra

    def extra_cost(self, env: Any) -> np.ndarray | None:
        return self._given_extra

    def _clear(self, start: np.ndarray, end: np.ndarray) -> bool:
        """Whether the straight segment stays in free cells (sampled every 1/8 cell): a quicker test than the
        base class's, for a candidate only (its rollout uses the env's motion model all the same)."""
        if self._given_extra is None:  # the shortest path: exactly the ShortestPathPlanner's following
            return super()._clear(start, end)
        n = max(2, int(np.ceil(8.0 * np.linalg.norm(end - start) / self._motion.resolution)) + 1)
        points = start + np.linspace(0.0, 1.0, n)[:, None] * (end - start)
        return bool(self._motion.is_free(points).all())


class _Shim:
    """The state a :class:`GridPlanner` reads from an env, for rolling a candidate path out without the env."""

    def __init__(self, env: Any, positions: np.ndarray, destinations: np.ndarray, arrived: np.ndarray) -> None:
        self.radio_map, self.scenario, self.multiple_access = env.radio_map, env.scenario, env.multiple_access
        self.positions, self.destinations, self.arrived = positions, destinations, arrived


class ReferencePlanner:
    """
    The best planner: a joint search over candidate paths of all robots, with the exact outage-minimising power
    split at every step (:func:`min_outage_power`), judged on the radio-map channel (the env's expected channel).

    Candidates per robot: the paths of :class:`GridPlanner` (followed at full speed, the same path following)
    for the path costs ``1 + w lambda o(cell)`` per metre, with ``o`` the robot-alone outage at ``P_max`` or
    the need of more than the equal share ``P_max / U`` (:func:`single_outage_maps`, in NOMA and in OMA: the
    same candidates in both modes) and ``w`` in ``weights``, plus the shortest path (``w = 0``). Each distinct
    candidate is rolled out once with the env's motion model; every combination of one candidate per robot is
    then scored exactly (``sum_u T_u + lambda x outage`` with the robots coupled through the power split, step
    by step) and the best is followed. The shortest paths with
    the best power are one of the combinations (ties go to them), so on the radio-map channel the planner never
    scores below :class:`ShortestPathPlanner` with ``power="best"``.

    With the Rayleigh channel (motion does not depend on the fading, so the rollouts are the same) the
    combinations are scored, and the power split chosen, by the expected number of outages under fading
    (:func:`best_power`). Candidate rollouts are cached per scenario and mission (starts,
    destinations), plans per mode and channel too: one instance evaluated on several modes and channels rolls
    every candidate out once.

    :param weights: the outage weights ``w`` of the candidate paths
    :param lookahead: how many path points ahead a robot may aim at
    """

    def __init__(self, weights: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0, 8.0), lookahead: int = 8) -> None:
        numbers = isinstance(weights, (tuple, list)) and all(
            isinstance(w, (int, float, np.integer, np.floating)) and not isinstance(w, bool) for w in weights
        )
        if not numbers or not weights or any(not np.isfinite(w) or w <= 0 for w in weights):
            raise ValueError(f"weights must be a sequence of positive finite numbers, got {weights!r}")
        self.weights = tuple(float(w) for w in weights)
        self.lookahead = _check_count("lookahead", lookahead, 1)
        self._radio_map: Any = None  # the map and scenario (its task: max_steps) the candidates were rolled out on
        self._scenario: Any = None
        self._plans: dict[tuple[str, bytes], tuple[np.ndarray, np.ndarray, float]] = {}
        self._rollouts: dict[tuple[int, bytes, bytes], list[tuple[np.ndarray, np.ndarray]]] = {}
        self._plan: np.ndarray | None = None
        self._positions: np.ndarray | None = None
        self._step = 0
        #: the planned cost ``sum_u T_u + lambda x outage`` of the current mission on the radio-map channel
        self.planned_cost = float("nan")

    def _setup(self, env: Any) -> None:
        if env.radio_map is self._radio_map and (env.scenario is self._scenario or env.scenario == self._scenario):
            return
        self._radio_map, self._scenario, self._plans, self._rollouts = env.radio_map, env.scenario, {}, {}
        penalty = env.scenario.mission.outage_penalty
        self._followers = [_PathFollower(None, self.lookahead)]
        # The same candidates in both modes (a mode's outage map is a useful proxy in the other one).
        for mode in ("noma", "oma"):
            for o in single_outage_maps(env, mode):
                for w in self.weights:
                    self._followers.append(_PathFollower(w * penalty * o.astype(float), self.lookahead))
        self._motion = GridMotion(
            env.radio_map.blocked,
            env.scenario.room,
            max_step=env.scenario.robot.v_max * env.scenario.mission.time_step,
            arrival_radius=env.scenario.robot.arrival_radius,
        )

    def _candidates(
        self, env: Any, u: int, positions: np.ndarray, destinations: np.ndarray
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """Robot ``u``'s distinct candidate rollouts (motion actions and positions), cached per mission."""
        key = (u, positions.tobytes(), destinations.tobytes())
        if key not in self._rollouts:
            seen: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
            planned: set[bytes] = set()
            for follower in self._followers:
                follower._setup(env)
                points = follower._plan(env, positions[u], destinations[u])[0].tobytes()
                if points in planned:  # the same grid path: the same rollout
                    continue
                planned.add(points)
                motions, path = self._rollout(env, follower, u, positions, destinations)
                seen.setdefault(path.tobytes(), (motions, path))
            self._rollouts[key] = list(seen.values())
        return self._rollouts[key]

    def _rollout(
        self, env: Any, follower: GridPlanner, u: int, positions: np.ndarray, destinations: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Robot ``u`` alone following a candidate: its motion actions (T, 2) and positions after each step (T, 2)."""
        arrived = np.ones(len(positions), dtype=bool)
        arrived[u] = False
        shim = _Shim(env, positions.copy(), destinations, arrived)
        follower.reset(shim)
        motions, path = [], []
        for _ in range(int(env.scenario.mission.max_steps)):
            action = follower.act(shim, None).reshape(-1, 3)
            shim.positions, at_goal = self._motion.move(shim.positions, action[:, :2], destinations, ~shim.arrived)
            shim.arrived = shim.arrived | at_goal
            motions.append(action[u, :2])
            path.append(shim.positions[u].copy())
            if shim.arrived[u]:
                break
        return np.array(motions), np.array(path)

    def _search(self, env: Any, positions: np.ndarray, destinations: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        n_robots = len(positions)
        check_planner_robots(n_robots, "ReferencePlanner")
        candidates = [self._candidates(env, u, positions, destinations) for u in range(n_robots)]
        penalty = env.scenario.mission.outage_penalty
        best: tuple[float, tuple[int, ...]] | None = None
        for combo in itertools.product(*(range(len(c)) for c in candidates)):
            paths = [candidates[u][k][1] for u, k in enumerate(combo)]
            arrival = np.array([len(p) for p in paths])
            horizon = int(arrival.max())
            steps = np.arange(horizon)
            at = np.stack([p[np.minimum(steps, len(p) - 1)] for p in paths], axis=1)  # (T, U, 2)
            active = steps[:, None] < arrival[None, :]
            _, n_outage = best_power(env, at, active)
            # A robot that never arrives is active until max_steps: its path is max_steps long.
            cost = float(arrival.sum() + penalty * n_outage.sum())
            if best is None or cost < best[0] - 1e-9:
                best = (cost, combo)
        assert best is not None
        cost, combo = best
        horizon = max(len(candidates[u][k][0]) for u, k in enumerate(combo))
        motion = np.zeros((horizon, n_robots, 2))
        for u, k in enumerate(combo):
            motions = candidates[u][k][0]
            motion[: len(motions), u] = motions
        path = np.stack(
            [candidates[u][k][1][np.minimum(np.arange(horizon), len(candidates[u][k][1]) - 1)] for u, k in enumerate(combo)],
            axis=1,
        )
        return motion, path, cost

    def reset(self, env: Any) -> None:
        self._setup(env)
        positions, destinations, _ = _env_state(env)
        key = (
            f"{env.multiple_access}/{getattr(env, 'channel', 'radio_map')}",
            np.concatenate([positions, destinations]).tobytes(),
        )
        if key not in self._plans:
            self._plans[key] = self._search(env, positions, destinations)
        self._plan, self._path, self.planned_cost = self._plans[key]
        self._step = 0

    def act(self, env: Any, observation: np.ndarray) -> np.ndarray:
        positions, _, arrived = _env_state(env)
        expected = self._path[self._step - 1] if self._step > 0 else None
        if (
            self._plan is None
            or self._step >= len(self._plan)
            or (expected is not None and not np.allclose(positions[~arrived], expected[~arrived], atol=1e-9))
        ):
            self.reset(env)  # off the plan (not reset after env.reset, or moved by someone else): plan from here
        motion = self._plan[self._step]
        power, _ = best_power(env, self._path[self._step][None], (~arrived)[None])
        self._step += 1
        return np.concatenate([motion, power[0][:, None]], axis=1).ravel().astype(np.float32)


def _power_splits(n_robots: int, levels: int) -> np.ndarray:
    """Every split of the whole power into ``levels - 1`` equal parts over the robots: fractions (K, U) summing to 1."""
    parts = levels - 1
    splits = [c for c in itertools.product(range(parts + 1), repeat=n_robots) if sum(c) == parts]
    return np.array(splits, dtype=np.float64) / parts


def rayleigh_success(
    power_w: np.ndarray, gain: np.ndarray, interferer_w: np.ndarray, scenario: Any, multiple_access: str
) -> np.ndarray:
    """
    Probability that each robot meets the QoS under Rayleigh fading (every link ``|h|^2 ~ Exp(1)``, independent),
    for powers ``power_w`` (..., K, U): for a robot whose SINR must beat ``gamma`` against noise ``N`` and interferers
    of mean received powers ``m_i``, ``P = exp(-gamma N / S) prod_i 1 / (1 + gamma m_i / S)`` with ``S`` its mean useful
    power. NOMA: ``S = g (p_u - gamma P_stronger)`` (the stronger robots' signals share the robot's fading), the order
    being that of the mean equivalent gains (the fading may reorder it at a step; this is the planning model).
    OMA: ``S = g p_u`` against ``N0 B`` and ``m_i / U``.

    :param power_w: powers, shape (..., K, U)
    :param gain: mean AP gains (the path gain, no fading), shape (..., U)
    :param interferer_w: mean interference power from each interferer, shape (..., U, I)
    :param scenario: the scenario (radio constants)
    :param multiple_access: ``"noma"`` or ``"oma"``
    :return: the probabilities, shape (..., K, U)
    """
    n_robots = scenario.n_robots
    gamma = _qos_sinr(scenario, multiple_access)
    noise = _noise_w(scenario, multiple_access)
    g = gain[..., None, :]
    m = interferer_w[..., None, :, :]
    if multiple_access == "oma":
        useful, m = g * power_w, m / n_robots
    else:
        order = decoding_order(equivalent_gain(gain, interferer_w.sum(axis=-1), noise))  # weakest first
        rank = np.argsort(order, axis=-1)[..., None, :]  # each robot's place in the order
        # The power of the robots stronger than each robot: those with a higher rank.
        stronger = ((rank[..., None, :] > rank[..., :, None]) * power_w[..., None, :]).sum(axis=-1)
        useful = g * (power_w - gamma * stronger)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(useful > 0, gamma / np.where(useful > 0, useful, 1.0), np.inf)
        probability = np.exp(-ratio * noise) / np.prod(1.0 + ratio[..., None] * m, axis=-1)
    return np.where(useful > 0, probability, 0.0)


def rayleigh_power(
    gain: np.ndarray,
    interferer_w: np.ndarray,
    active: np.ndarray,
    scenario: Any,
    multiple_access: str,
    levels: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """
    The power split with the fewest expected outages under Rayleigh fading (:func:`rayleigh_success`), searched over
    the splits of the whole ``P_max`` on a grid (:func:`_power_splits`); robots that arrived get no power.

    :param gain: mean AP gains (path gains), shape (T, U)
    :param interferer_w: mean interference power from each interferer, shape (T, U, I)
    :param active: robots that have not arrived, bool (T, U)
    :param scenario: the scenario
    :param multiple_access: ``"noma"`` or ``"oma"``
    :param levels: grid levels per robot (default: 41 for two robots, fewer for more)
    :return: the power actions (T, U) and the expected number of active robots in outage (T,)
    """
    n_robots = scenario.n_robots
    levels = levels or max(3, min(41, int(4000 ** (1.0 / max(1, n_robots - 1)))))
    max_power_w = float(dbm_to_watt(scenario.ap.max_power_dbm))
    active = np.asarray(active, dtype=bool)
    power = _power_splits(n_robots, levels)[None] * active[:, None, :]  # (T, K, U)
    total = power.sum(axis=-1, keepdims=True)
    power = np.where(total > 0, power / np.where(total > 0, total, 1.0), 0.0) * max_power_w
    success = rayleigh_success(power, gain, interferer_w, scenario, multiple_access)
    expected = ((1.0 - success) * active[:, None, :]).sum(axis=-1)  # (T, K)
    best = np.argmin(expected, axis=1)
    rows = np.arange(len(best))
    actions = np.clip(2.0 * power[rows, best] / max_power_w - 1.0, -1.0, 1.0)
    return np.where(active, actions, -1.0), expected[rows, best]


def best_power(env: Any, positions: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """
    The best power split of every row of robot positions for the env's channel: exact on the radio-map channel
    (:func:`min_outage_power`), the fewest expected outages on the Rayleigh channel (:func:`rayleigh_power`).

    :param env: the unwrapped env (its scenario, radio map, mode and channel)
    :param positions: robot positions, shape (T, U, 2)
    :param active: robots that have not arrived, bool (T, U)
    :return: power actions (T, U) and the (expected) number of active robots in outage (T,)
    """
    ix, iy = env.radio_map.cell_index(np.asarray(positions))
    if getattr(env, "channel", "radio_map") == "rayleigh":
        radio_map, scenario = env.radio_map, env.scenario
        gain = radio_map.path_gain["ap"][ix, iy]
        powers = dbm_to_watt(np.array([i.power_dbm for i in scenario.interferers], dtype=np.float64))
        gains = [radio_map.path_gain[i.name][ix, iy] for i in scenario.interferers]
        interferer = (np.stack(gains, axis=-1) if gains else np.zeros((*gain.shape, 0))) * powers  # none: a room alone
        return rayleigh_power(gain, interferer, active, scenario, env.multiple_access)
    gain, interference = channel_maps(env)
    return min_outage_power(gain[ix, iy], interference[ix, iy], active, env.scenario, env.multiple_access)
