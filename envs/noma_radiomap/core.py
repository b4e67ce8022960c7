"""The mission engine: N missions of one scenario stepped at once on (N, U) arrays (docs/ARCHITECTURE.md, env).

:class:`MissionCore` is the one implementation of a mission step: motion, channel, power allocation and SIC,
rewards, bookkeeping, observation, episode summary and the ``info`` keys. The single env
(:class:`noma_radiomap.NomaRadioMapEnv`) drives it with N = 1, the vector env
(:class:`noma_radiomap.vector.NomaRadioMapVecEnv`) with N; neither keeps mission state of its own. Each mission
has its own random generator (the starts and destinations of its resets, its Rayleigh fading), so mission ``i``
seeded ``s`` makes the transitions of a single env seeded ``s``.
"""

import os
import reprlib
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from gymnasium.error import ResetNeeded
from gymnasium.utils import seeding

from noma_radiomap import geometry, rewards
from noma_radiomap.compiled import compiled
from noma_radiomap.downlink import (
    MULTIPLE_ACCESS,
    allocate_rows,
    gain_and_sinr_db,
    in_outage,
    shannon_rate,
    signal_band,
    sinr_rows,
)
from noma_radiomap.motion import GridMotion, move_robots
from noma_radiomap.observations import GAIN_DB_RANGE, Observer, check_observation, default_observation
from noma_radiomap.propagation import dbm_to_watt, linear_to_db, rayleigh_fading
from noma_radiomap.radiomap import RadioMap, check_missions_memory
from noma_radiomap.rewards import component_rows, mqi_rows, weighted_rows
from noma_radiomap.sampling import MissionSampler
from noma_radiomap.scenario import Scenario, load_scenario

CHANNELS: tuple[str, ...] = ("radio_map", "rayleigh")
INDUCING: tuple[str, ...] = ("euclidean", "geodesic")
#: The tasks: ``"missions"`` draws each robot's destination from its scenario list every episode; ``"paper"``
#: is the paper's task (docs/MODEL.md, the paper's task): each robot's first listed destination, fixed, the
#: paper's state as the default observation and episodes of :data:`PAPER_MAX_STEPS` steps.
TASKS: tuple[str, ...] = ("missions", "paper")
#: The paper's task: episode cap and MQI budget ``T_total`` (paper Sec. V: "T_total = 1000 is regarded as the
#: maximum score"; the paper gives no other episode length, so a mission may last as long as its budget).
PAPER_MAX_STEPS = 1000
#: The per-robot arrays of every step's ``info`` (arrays of length U in scenario order).
INFO_KEYS: tuple[str, ...] = ("rate_bps", "sinr_db", "outage", "power_w", "gain_db", "decoding_order")
#: The episode summary in every ``info``, as of the step (:meth:`MissionCore.episode_summaries`): the envs cannot see
#: where an outer ``TimeLimit`` ends an episode, and its last ``info`` must have it.
SUMMARY_KEYS: tuple[str, ...] = ("is_success", "mqi", "mission_time", "outage_steps")
RESET_FIRST = "call reset() first"
#: The summary values that are one Python scalar per mission in an ``info``, and their type
_SCALAR_SUMMARIES: dict[str, type] = {"is_success": bool, "mqi": float}
_ALL = slice(None)


@dataclass(slots=True)
class MissionStep:
    """The outcome of one step of the stepped missions (arrays over the stepped rows)."""

    rows: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    component_values: np.ndarray
    """The reward components, (5, rows), in the order of :data:`~noma_radiomap.rewards.REWARD_COMPONENTS`."""
    power_w: np.ndarray
    rate_bps: np.ndarray
    sinr_db: np.ndarray
    decoding_order: np.ndarray
    outage: np.ndarray
    gain_db: np.ndarray
    summary: dict[str, np.ndarray]
    """The episode summaries as of the step (:meth:`MissionCore.episode_summaries`)."""

    @property
    def components(self) -> dict[str, np.ndarray]:
        """The reward components by name, (rows,) each."""
        return dict(zip(rewards.REWARD_COMPONENTS, self.component_values, strict=True))

    def info(self, k: int) -> dict[str, Any]:
        """The ``info`` of the ``k``-th stepped mission: ``reward_components``, :data:`INFO_KEYS` and the episode
        summary as of the step (:data:`SUMMARY_KEYS`), in this order."""
        summary = self.summary
        return {
            "reward_components": dict(zip(rewards.REWARD_COMPONENTS, self.component_values[:, k].tolist(), strict=True)),
            "rate_bps": self.rate_bps[k],
            "sinr_db": self.sinr_db[k],
            "outage": self.outage[k],
            "power_w": self.power_w[k],
            "gain_db": self.gain_db[k],
            "decoding_order": self.decoding_order[k],
            "is_success": bool(summary["is_success"][k]),
            "mqi": float(summary["mqi"][k]),
            "mission_time": summary["mission_time"][k],
            "outage_steps": summary["outage_steps"][k],
        }

    def infos(self) -> list[dict[str, Any]]:
        """
        :meth:`info` of every stepped mission, in row order, the same keys in the same order (a test compares
        them). Both are written as dict displays, the fastest way CPython has to build them: for 16 missions the
        infos cost as much as the step's physics.
        """
        # The five reward components as one dict display per mission too (twice as fast as dict(zip(...)))
        time_key, inducing_key, qos_key, arrival_key, success_key = rewards.REWARD_COMPONENTS
        columns = zip(*self.component_values.tolist(), strict=True)
        summary = self.summary
        return [
            {
                "reward_components": {
                    time_key: c[0],
                    inducing_key: c[1],
                    qos_key: c[2],
                    arrival_key: c[3],
                    success_key: c[4],
                },
                "rate_bps": rate,
                "sinr_db": sinr,
                "outage": outage,
                "power_w": power,
                "gain_db": gain,
                "decoding_order": order,
                "is_success": is_success,
                "mqi": mqi,
                "mission_time": mission_time,
                "outage_steps": outage_steps,
            }
            for c, rate, sinr, outage, power, gain, order, is_success, mqi, mission_time, outage_steps in zip(
                columns,
                self.rate_bps,
                self.sinr_db,
                self.outage,
                self.power_w,
                self.gain_db,
                self.decoding_order,
                summary["is_success"].tolist(),
                summary["mqi"].tolist(),
                summary["mission_time"],
                summary["outage_steps"],
                strict=True,
            )
        ]


def summary_row(summaries: dict[str, np.ndarray], j: int) -> dict[str, Any]:
    """The episode summary of the ``j``-th row of :meth:`MissionCore.episode_summaries`, as one mission's ``info``
    holds it: ``is_success`` a bool, ``mqi`` a float, per-robot arrays for the others."""
    return {key: _SCALAR_SUMMARIES.get(key, _same)(summaries[key][j]) for key in SUMMARY_KEYS}


def _same(value: Any) -> Any:
    return value


def check_max_episode_steps(value: Any) -> None:
    """:raises ValueError: ``value`` is neither None nor an integer >= 1, naming ``max_episode_steps`` and the value"""
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"max_episode_steps must be an integer >= 1 (or None), got {reprlib.repr(value)}")


def _row_options(options: Any, n_rows: int) -> list[dict | None]:
    """
    The reset options of each of ``n_rows`` reset missions.

    :param options: None, one mapping for every row or a list of one mapping (or None) per row
    :raises ValueError: naming ``options`` and what it is
    """
    if options is None or isinstance(options, Mapping):
        return [options] * n_rows  # type: ignore[list-item]
    if not isinstance(options, list):
        raise ValueError(f"options: expected a dict of reset options (or None), got {type(options).__name__}")
    if len(options) != n_rows:
        raise ValueError(f"options: expected one dict per reset mission ({n_rows}), got a list of {len(options)}")
    for k, item in enumerate(options):
        if item is not None and not isinstance(item, Mapping):
            raise ValueError(f"options[{k}]: expected a dict of reset options (or None), got {type(item).__name__}")
    return options


def load(scenario: str | os.PathLike[str] | Scenario) -> Scenario:
    """A scenario from a built-in name, a YAML path or a :class:`Scenario` (validated as a YAML file is)."""
    if isinstance(scenario, Scenario):
        # One built or changed in code (``dataclasses.replace``) has not been through the checks of ``from_dict``;
        # the checked copy is used, its values of the types a YAML file gives (e.g. ``max_steps=np.int64(20)`` an int)
        try:
            checked = Scenario.from_dict(scenario.to_dict())
        except ValueError as error:
            raise ValueError(f"scenario {scenario.name!r} (a Scenario object, as given): {error}") from None
        return replace(checked, source=scenario.source)
    if isinstance(scenario, str | os.PathLike):
        return load_scenario(scenario)
    raise ValueError(f"scenario must be a scenario name, a YAML path or a Scenario, got {scenario!r}")


def task_scenario(scenario: Scenario, task: str) -> Scenario:
    """
    :param scenario: a scenario as loaded
    :param task: one of :data:`TASKS`
    :return: the scenario as the task runs it: the paper's task caps episodes at :data:`PAPER_MAX_STEPS` steps and
        sets ``T_total`` to the same
    """
    if task != "paper":
        return scenario
    return replace(scenario, mission=replace(scenario.mission, max_steps=PAPER_MAX_STEPS, t_total=float(PAPER_MAX_STEPS)))


class MissionCore:
    """
    N missions of one scenario on (N, U) arrays. The arguments are those of :class:`~noma_radiomap.NomaRadioMapEnv`.

    State (read it, do not write it): ``positions`` and ``destinations`` (N, U, 2), ``arrived`` (N, U),
    ``step_counts`` (N,), ``arrival_steps`` and ``outage_steps`` (N, U), ``gain_db`` (N, U), ``np_randoms`` and
    ``reward_phases`` (one per mission). Stepping or summarising a mission before its first reset raises
    Gymnasium's ``ResetNeeded``.

    :param num_missions: N
    :param max_episode_steps: the step at which :meth:`step` reports truncation (None: ``max_steps``; a larger one is
        refused, the missions end there)
    """

    def __init__(
        self,
        num_missions: int,
        scenario: str | os.PathLike[str] | Scenario = "mall",
        multiple_access: str = "noma",
        channel: str = "radio_map",
        reward_phase: str = "destination",
        inducing: str = "euclidean",
        observation: str | None = None,
        task: str = "missions",
        max_episode_steps: int | None = None,
    ) -> None:
        for name, value, allowed in (
            ("multiple_access", multiple_access, MULTIPLE_ACCESS),
            ("channel", channel, CHANNELS),
            ("reward_phase", reward_phase, rewards.REWARD_PHASES),
            ("inducing", inducing, INDUCING),
            ("task", task, TASKS),
        ):
            if value not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, got {value!r}")
        if observation is None:
            observation = default_observation(task)
        check_observation(observation)
        check_max_episode_steps(max_episode_steps)
        n = int(num_missions)
        sc = load(scenario)
        check_missions_memory(n, sc, inducing)  # before the map, the sampler and the missions' arrays are built
        # The map does not depend on the missions: the scenario as loaded hits the map cache
        self.radio_map = RadioMap.for_scenario(sc)
        sc = task_scenario(sc, task)
        self.scenario = sc
        self.multiple_access, self.channel, self.inducing, self.task = multiple_access, channel, inducing, task
        self.observation = observation
        self.n_robots = sc.n_robots
        self.max_steps = sc.mission.max_steps
        if max_episode_steps is not None and max_episode_steps > self.max_steps:
            raise ValueError(
                f"max_episode_steps must be at most mission.max_steps = {self.max_steps} of scenario {sc.name!r} "
                f"(its missions end there), got {max_episode_steps!r}"
            )
        self.max_episode_steps = self.max_steps if max_episode_steps is None else int(max_episode_steps)
        self.motion = GridMotion(
            self.radio_map.blocked,
            sc.room,
            max_step=sc.robot.v_max * sc.mission.time_step,
            arrival_radius=sc.robot.arrival_radius,
        )
        self.observe = Observer(observation, (sc.room.width, sc.room.depth), GAIN_DB_RANGE)
        # One row per cell (flat index ix * ny + iy), one column per transmitter (AP first): a single gather per
        # step. The radio-map channel has the expected fading folded in; the Rayleigh channel draws it.
        gains = self.radio_map.gain if channel == "radio_map" else self.radio_map.path_gain
        table = np.stack([gains[name] for name in sc.transmitter_names])
        self._gain_table = table.reshape(len(table), -1).T.copy()
        self._interferer_power_w = dbm_to_watt(np.array([i.power_dbm for i in sc.interferers], dtype=np.float64))
        self.max_power_w = float(dbm_to_watt(sc.ap.max_power_dbm))
        self._noise_w_per_hz = float(dbm_to_watt(sc.radio.noise_dbm_per_hz))
        self._bandwidth_per_robot_hz = float(sc.radio.bandwidth_per_robot_hz)
        #: The band of each robot's signal (the cluster band in NOMA, its own in OMA), for its rate
        self._signal_band_hz = signal_band(sc.n_robots, self._bandwidth_per_robot_hz, multiple_access == "noma")
        mission = sc.mission
        self.reward_constants = rewards.RewardConstants(
            time_cost=mission.time_cost,
            outage_penalty=mission.outage_penalty,
            arrival_reward=mission.arrival_reward,
            success_reward=mission.success_reward,
        )
        self._d_max = sc.room.d_max
        #: Draws the starts and destinations of a reset (:class:`noma_radiomap.sampling.MissionSampler`)
        self.sampler = MissionSampler(sc, self.radio_map, self.motion, fixed_destinations=task == "paper")

        u = self.n_robots
        self.num_missions = n
        self.np_randoms: list[np.random.Generator] = [seeding.np_random()[0] for _ in range(n)]
        self.reward_phases = [reward_phase] * n
        rewards.phase_weights(reward_phase)  # a ValueError naming an unknown phase
        # The weight of each reward component (rows, in the order of REWARD_COMPONENTS) per mission (column)
        self._weights = np.zeros((len(rewards.REWARD_COMPONENTS), n))
        self.set_reward_phase(reward_phase, list(range(n)))
        self.positions = np.zeros((n, u, 2))
        self.destinations = np.zeros((n, u, 2))
        self.arrived = np.zeros((n, u), dtype=bool)
        self.step_counts = np.zeros(n, dtype=np.int64)
        self.arrival_steps = np.full((n, u), self.max_steps, dtype=np.int64)
        self.outage_steps = np.zeros((n, u), dtype=np.int64)
        self.gain_db = np.zeros((n, u))
        self._distance_maps = np.zeros((n, u, 0))
        self._was_reset = np.zeros(n, dtype=bool)
        self._all_reset = False
        self._all_rows = np.arange(n)

    # --- reward phases -----------------------------------------------------------------------------
    def set_reward_phase(self, name: str, rows: list[int]) -> None:
        """
        Switch the reward phase of some missions (takes effect from their next step).

        :param name: one of :data:`noma_radiomap.rewards.REWARD_PHASES`
        :param rows: the missions
        """
        weights = rewards.phase_weights(name)
        for k, component in enumerate(rewards.REWARD_COMPONENTS):
            self._weights[k, rows] = weights[component]
        for i in rows:
            self.reward_phases[i] = name

    # --- resets ------------------------------------------------------------------------------------
    def reset(
        self,
        rows: np.ndarray,
        seeds: list[int | None] | None = None,
        options: dict | list[dict | None] | None = None,
        rngs: list[np.random.Generator] | None = None,
    ) -> None:
        """
        Reset some missions: draw (or take from ``options``) their starts and destinations. Every mission is drawn
        before any changes: a refused option (a ``ValueError`` naming it) leaves every mission, and its generator,
        as it was.

        :param rows: the missions to reset
        :param seeds: a seed per row (None entries keep the generator going)
        :param options: the reset options (``starts``, ``destinations``), for every row or one per row
        :param rngs: a generator per row to use from now on (the single env passes its ``np_random``)
        """
        row_options = _row_options(options, len(rows))
        generators = [self._generator(i, k, seeds, rngs) for k, i in enumerate(rows)]
        starts, destinations = self._draw(row_options, generators)
        geodesic = self.inducing == "geodesic"
        if geodesic and self._distance_maps.shape[-1] == 0:  # counted by radiomap.check_missions_memory
            cells = self.scenario.room.nx * self.scenario.room.ny
            self._distance_maps = np.zeros((self.num_missions, self.n_robots, cells))
        for k, i in enumerate(rows):
            self.np_randoms[i] = generators[k]
            self.positions[i], self.destinations[i] = starts[k], destinations[k]
        self.arrived[rows] = False
        self.step_counts[rows] = 0
        self.arrival_steps[rows] = self.max_steps
        self.outage_steps[rows] = 0
        if geodesic:
            for i in rows:
                self._distance_maps[i] = np.stack([self.radio_map.distance_field(d).ravel() for d in self.destinations[i]])
        self._reset_channel(rows)
        self._was_reset[rows] = True
        self._all_reset = bool(self._was_reset.all())

    def _generator(
        self, i: int, k: int, seeds: list[int | None] | None, rngs: list[np.random.Generator] | None
    ) -> np.random.Generator:
        """The generator of mission ``i`` (the ``k``-th reset row) from this reset on: given, seeded or its own."""
        if rngs is not None:
            return rngs[k]
        if seeds is not None and seeds[k] is not None:
            return seeding.np_random(seeds[k])[0]
        return self.np_randoms[i]

    def _draw(self, options: list[dict | None], generators: list[np.random.Generator]) -> tuple[np.ndarray, np.ndarray]:
        """The starts and destinations (rows, U, 2) of a reset, drawn with ``generators``; when an option is refused,
        the generators are put back to their states before the draws, and the ``ValueError`` raised."""
        states = [rng.bit_generator.state for rng in generators]
        starts = np.empty((len(generators), self.n_robots, 2))
        destinations = np.empty((len(generators), self.n_robots, 2))
        try:
            for k, rng in enumerate(generators):
                starts[k], destinations[k] = self.sampler.draw(options[k], rng)
        except BaseException:
            for rng, state in zip(generators, states, strict=True):
                rng.bit_generator.state = state
            raise
        return starts, destinations

    def check_reset(self, rows: np.ndarray | slice = slice(None)) -> None:
        """:raises ResetNeeded: a mission of ``rows`` has not been reset yet"""
        if not self._all_reset and not self._was_reset[rows].all():
            raise ResetNeeded(f"the mission has not been reset: {RESET_FIRST}")

    # --- one step ----------------------------------------------------------------------------------
    def step(self, action: np.ndarray, rows: np.ndarray | slice) -> MissionStep:
        """
        One step of some missions.

        :param action: the checked actions of the stepped rows, float64 (len(rows), U, 3)
            (:func:`noma_radiomap.actions.check_action` / :func:`~noma_radiomap.actions.check_actions`)
        :param rows: the missions to step (a slice for all)
        :return: the step's outcome
        """
        self.check_reset(rows)
        row_indices = self._all_rows[rows]
        room, radio, motion = self.scenario.room, self.scenario.radio, self.motion
        noma = self.multiple_access == "noma"
        arriving, active, gain_and_sinr, power, order, bad = _transmission_rows(
            self.positions,
            self.destinations,
            self.arrived,
            row_indices,
            action,
            motion.kernel_constants(),
            self._gain_table,
            room.resolution,
            room.nx,
            room.ny,
            self._fading(row_indices),
            self._interferer_power_w,
            self.max_power_w,
            self._bandwidth_per_robot_hz,
            self._noise_w_per_hz,
            noma,
        )
        if bad >= 0:
            raise motion.position_error(self.positions[rows], bad)
        gain_db, sinr_db = gain_and_sinr_db(gain_and_sinr)
        self.gain_db[rows] = gain_db
        rate_bps = shannon_rate(gain_and_sinr[1], self._signal_band_hz)
        outage = in_outage(rate_bps, radio.qos_rate_bps) & active
        constants, mission = self.reward_constants, self.scenario.mission
        numbers, flags, counts = _outcome_rows(
            row_indices,
            active,
            arriving,
            outage,
            self._distances(rows),
            self._d_max,
            constants.kernel_constants(),
            self._weights,
            self.arrived,
            self.step_counts,
            self.arrival_steps,
            self.outage_steps,
            self.max_episode_steps,
            self.max_steps,
            mission.t_total,
            mission.outage_penalty,
        )
        values, reward, mqi = numbers[:_N_COMPONENTS], numbers[_N_COMPONENTS], numbers[_N_COMPONENTS + 1]
        terminated, truncated, success = flags
        mission_time, outage_steps = counts
        summary = {"is_success": success, "mqi": mqi, "mission_time": mission_time, "outage_steps": outage_steps}
        return MissionStep(
            rows=row_indices,
            reward=reward,
            terminated=terminated,
            truncated=truncated,
            component_values=values,
            power_w=power,
            rate_bps=rate_bps,
            sinr_db=sinr_db,
            decoding_order=order,
            outage=outage,
            gain_db=gain_db,
            summary=summary,
        )

    def _reset_channel(self, rows: np.ndarray) -> None:
        """The channel gains in dB of the missions ``rows`` at their start (for the first observation)."""
        room = self.scenario.room
        gain, _ = _link_rows(
            self.positions[rows],
            self._gain_table,
            room.resolution,
            room.nx,
            room.ny,
            self._fading(self._all_rows[rows]),
            self._interferer_power_w,
        )
        self.gain_db[rows] = linear_to_db(gain)

    def _fading(self, rows: np.ndarray) -> np.ndarray:
        """The Rayleigh channel's fading powers of a step of some missions (rows, U, transmitters): one draw per
        mission from its own generator, in the order of a single env's draws; none on the radio-map channel."""
        if self.channel != "rayleigh" or not len(rows):
            return _NO_FADING
        shape = (self.n_robots, self._gain_table.shape[1])
        if len(rows) == 1:  # the same draws, without np.stack's copy (a single env's step)
            return rayleigh_fading(self.np_randoms[rows[0]], (1, *shape))
        return np.stack([rayleigh_fading(self.np_randoms[i], shape) for i in rows])

    def _distances(self, rows: np.ndarray | slice) -> np.ndarray:
        """Distance of each robot to its destination: Euclidean, or geodesic on the grid (``inducing``)."""
        if self.inducing == "euclidean":
            return geometry.distance_rows(self.positions[rows], self.destinations[rows])
        cells = self.scenario.room.flat_cell_index(self.positions[rows])
        return np.take_along_axis(self._distance_maps[rows], cells[..., None], axis=-1)[..., 0]

    # --- what the envs report ----------------------------------------------------------------------
    def observations(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """The observations of some missions in the core's layout, float32 (rows, values per robot x U)."""
        return self.observe.rows(self.positions[rows], self.destinations[rows], self.gain_db[rows], self.arrived[rows])

    def episode_summaries(self, rows: np.ndarray | slice) -> dict[str, np.ndarray]:
        """
        The end-of-episode figures (paper Eq. (13)-(14)) of some missions, as of their current step, arrays over
        the rows: ``is_success`` (all arrived), ``mqi``, ``mission_time`` (per robot, ``T_u``: steps until arrival,
        ``max_steps`` if not arrived) and ``outage_steps`` (per robot).
        """
        self.check_reset(rows)
        mission = self.scenario.mission
        success, mqi, mission_time, outage_steps = _summary_rows(
            self.arrived[rows],
            self.arrival_steps[rows],
            self.outage_steps[rows],
            self.max_steps,
            mission.t_total,
            mission.outage_penalty,
        )
        return {"is_success": success, "mqi": mqi, "mission_time": mission_time, "outage_steps": outage_steps}


_NO_FADING = np.zeros((0, 0, 0))
_N_COMPONENTS = len(rewards.REWARD_COMPONENTS)


@compiled
def _transmission_rows(
    positions: np.ndarray,
    destinations: np.ndarray,
    arrived: np.ndarray,
    rows: np.ndarray,
    actions: np.ndarray,
    motion_constants: tuple,
    gain_table: np.ndarray,
    resolution: float,
    nx: int,
    ny: int,
    fading: np.ndarray,
    interferer_power_w: np.ndarray,
    max_power_w: float,
    bandwidth_per_robot_hz: float,
    noise_w_per_hz: float,
    noma: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """
    The physics of one step of the missions ``rows`` (checked actions (rows, U, 3)), compiled in one call: the
    robots still on their way move (:func:`~noma_radiomap.motion.move_robots`, the motion's constants from
    :meth:`~noma_radiomap.motion.GridMotion.kernel_constants`), their links at the new positions
    (:func:`_link_rows`), the power allocation (:func:`~noma_radiomap.downlink.allocate_rows`) and the SINRs
    with the decoding order (:func:`~noma_radiomap.downlink.sinr_rows`). Writes the new positions into
    ``positions``. Returns the arriving and the active robots, the AP gains and the SINRs stacked (2, rows, U)
    (for their one dB conversion), the powers, the decoding order and -1, or, when a robot of ``rows`` is not on
    a free point, its flat index in (rows, U) as the last value, having changed nothing.
    """
    n_rows, n_robots = len(rows), arrived.shape[1]
    start = np.empty((n_rows, n_robots, 2))
    goals = np.empty((n_rows, n_robots, 2))
    motion = np.empty((n_rows, n_robots, 2))
    power_actions = np.empty((n_rows, n_robots))
    active = np.empty((n_rows, n_robots), dtype=np.bool_)
    for k in range(n_rows):
        i = rows[k]
        for u in range(n_robots):
            start[k, u, 0], start[k, u, 1] = positions[i, u, 0], positions[i, u, 1]
            goals[k, u, 0], goals[k, u, 1] = destinations[i, u, 0], destinations[i, u, 1]
            motion[k, u, 0], motion[k, u, 1] = actions[k, u, 0], actions[k, u, 1]
            power_actions[k, u] = actions[k, u, 2]
            # Robots that arrived before this step are inactive: no motion, no power, no time cost, no outage.
            active[k, u] = not arrived[i, u]
    moved, at_goal, bad = move_robots(
        start.reshape(-1, 2),
        motion.reshape(-1, 2),
        goals.reshape(-1, 2),
        active.reshape(-1),
        True,
        *motion_constants,
    )
    new = moved.reshape(n_rows, n_robots, 2)
    arriving = at_goal.reshape(n_rows, n_robots) & active
    if bad >= 0:
        empty = np.empty((n_rows, n_robots))
        return arriving, active, np.empty((2, n_rows, n_robots)), empty, np.empty((n_rows, n_robots), dtype=np.int64), bad
    for k in range(n_rows):
        positions[rows[k]] = new[k]
    gain, interference = _link_rows(new, gain_table, resolution, nx, ny, fading, interferer_power_w)
    power = allocate_rows(power_actions, active, max_power_w)
    sinr, order = sinr_rows(power, gain, interference, bandwidth_per_robot_hz, noise_w_per_hz, noma)
    gain_and_sinr = np.empty((2, n_rows, n_robots))  # one array for the one dB conversion of both
    gain_and_sinr[0], gain_and_sinr[1] = gain, sinr
    return arriving, active, gain_and_sinr, power, order, -1


@compiled
def _outcome_rows(
    rows: np.ndarray,
    active: np.ndarray,
    arriving: np.ndarray,
    outage: np.ndarray,
    distance: np.ndarray,
    d_max: float,
    reward_constants: tuple[float, float, float, float],
    weights: np.ndarray,
    arrived: np.ndarray,
    step_counts: np.ndarray,
    arrival_steps: np.ndarray,
    outage_steps: np.ndarray,
    max_episode_steps: int,
    max_steps: int,
    t_total: float,
    mqi_outage_penalty: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    The rest of one step of the missions ``rows``, compiled in one call: the reward components
    (:func:`~noma_radiomap.rewards.component_rows`) and the reward with each mission's phase weights ((5, N)
    ``weights``; :func:`~noma_radiomap.rewards.weighted_rows`), the bookkeeping in place on the (N, ...) state
    (:func:`_record_step`) and the episode summaries as of the step (:func:`_summary_rows`). Returns three arrays
    (each returned array costs a boxing, about as much as the kernel's work for one mission): the numbers, (7,
    rows): the five components, the rewards and the MQIs; the flags, (3, rows): terminated, truncated and all
    arrived; the counts, (2, rows, U): the mission times and the outage counts.
    """
    values = component_rows(active, arriving, outage, distance, d_max, *reward_constants)
    n_rows, n_components = len(rows), values.shape[0]
    row_weights = np.empty((weights.shape[0], n_rows))
    for k in range(n_rows):
        row_weights[:, k] = weights[:, rows[k]]
    numbers = np.empty((n_components + 2, n_rows))
    numbers[:n_components] = values
    numbers[n_components] = weighted_rows(values, row_weights)
    flags = np.empty((3, n_rows), dtype=np.bool_)
    flags[0], flags[1] = _record_step(
        rows, arriving, outage, arrived, step_counts, arrival_steps, outage_steps, max_episode_steps
    )
    success, mqi, mission_time, outage_counts = _summary_rows(
        arrived[rows], arrival_steps[rows], outage_steps[rows], max_steps, t_total, mqi_outage_penalty
    )
    numbers[n_components + 1], flags[2] = mqi, success
    counts = np.empty((2, *mission_time.shape), dtype=np.int64)
    counts[0], counts[1] = mission_time, outage_counts
    return numbers, flags, counts


@compiled
def _summary_rows(
    arrived: np.ndarray,
    arrival_steps: np.ndarray,
    outage_steps: np.ndarray,
    max_steps: int,
    t_total: float,
    outage_penalty: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """
    The episode summaries of (M, U) robots, compiled: all arrived, the MQI of Eq. (14)
    (:func:`~noma_radiomap.rewards.mqi_rows`, its sum over the robots left to right), the mission times and a copy
    of the outage counts.
    """
    n_rows, n_robots = arrived.shape
    success = np.empty(n_rows, dtype=np.bool_)
    mission_time = np.empty((n_rows, n_robots), dtype=np.int64)
    outage = np.empty((n_rows, n_robots), dtype=np.int64)
    for row in range(n_rows):
        all_arrived = True
        for u in range(n_robots):
            mission_time[row, u] = arrival_steps[row, u] if arrived[row, u] else max_steps
            outage[row, u] = outage_steps[row, u]
            all_arrived &= arrived[row, u]
        success[row] = all_arrived
    return success, mqi_rows(t_total, mission_time, outage, outage_penalty), mission_time, outage


@compiled
def _link_rows(
    positions: np.ndarray,
    table: np.ndarray,
    resolution: float,
    nx: int,
    ny: int,
    fading: np.ndarray,
    interferer_power_w: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """
    The links of (M, U) robots at ``positions`` (M, U, 2), compiled: each robot's row of the per-cell gain table
    (AP first, then the interferers; Eq. (17)), times its fading powers (M, U, transmitters; Eq. (4)) unless
    ``fading`` is empty (:func:`~noma_radiomap.propagation.faded_gain`); returns the AP gain and the interference
    ``sum_i P_i g_i`` summed left to right (:func:`~noma_radiomap.propagation.interference_power`), (M, U) each.
    """
    n_rows, n_robots = positions.shape[0], positions.shape[1]
    faded = fading.shape[0] > 0
    gain = np.empty((n_rows, n_robots))
    interference = np.zeros((n_rows, n_robots))
    for row in range(n_rows):
        for u in range(n_robots):
            ix = geometry.axis_cell(positions[row, u, 0], resolution, nx)
            iy = geometry.axis_cell(positions[row, u, 1], resolution, ny)
            cell = ix * ny + iy
            g = table[cell, 0] * fading[row, u, 0] if faded else table[cell, 0]
            gain[row, u] = g
            total = 0.0
            for i in range(len(interferer_power_w)):
                g_i = table[cell, i + 1] * fading[row, u, i + 1] if faded else table[cell, i + 1]
                total = g_i * interferer_power_w[i] if i == 0 else total + g_i * interferer_power_w[i]
            interference[row, u] = total
    return gain, interference


@compiled
def _record_step(
    rows: np.ndarray,
    arriving: np.ndarray,
    outage: np.ndarray,
    arrived: np.ndarray,
    step_counts: np.ndarray,
    arrival_steps: np.ndarray,
    outage_steps: np.ndarray,
    max_episode_steps: int,
) -> tuple[np.ndarray, np.ndarray]:
    """
    The bookkeeping of a step of the missions ``rows``, in place on the (N, ...) state arrays: count the step,
    record the arrivals (``arriving``, (rows, U)) and their step, add the outages. Returns whether each stepped
    mission terminated (all robots arrived) and reached ``max_episode_steps``.
    """
    terminated = np.empty(len(rows), dtype=np.bool_)
    truncated = np.empty(len(rows), dtype=np.bool_)
    for k in range(len(rows)):
        i = rows[k]
        step_counts[i] += 1
        all_arrived = True
        for u in range(arrived.shape[1]):
            if arriving[k, u]:
                arrived[i, u] = True
                arrival_steps[i, u] = step_counts[i]
            outage_steps[i, u] += outage[k, u]
            all_arrived &= arrived[i, u]
        terminated[k] = all_arrived
        truncated[k] = step_counts[i] >= max_episode_steps
    return terminated, truncated
