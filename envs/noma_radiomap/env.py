"""The NOMA indoor radio-map environment (the paper's Sections II-IV; docs/MODEL.md, docs/ARCHITECTURE.md)."""

import os
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from noma_radiomap import geometry, rewards
from noma_radiomap.actions import check_action
from noma_radiomap.downlink import MULTIPLE_ACCESS, DownlinkResult, in_outage, single_transmission
from noma_radiomap.motion import GridMotion
from noma_radiomap.propagation import (
    dbm_to_watt,
    faded_gain,
    interference_power,
    linear_to_db,
    rayleigh_fading,
)
from noma_radiomap.radiomap import RadioMap
from noma_radiomap.scenario import Scenario, load_scenario

CHANNELS: tuple[str, ...] = ("radio_map", "rayleigh")
INDUCING: tuple[str, ...] = ("euclidean", "geodesic")


def mission_observation(
    positions: np.ndarray,
    destinations: np.ndarray,
    gain_db: np.ndarray,
    arrived: np.ndarray,
    room_size: np.ndarray,
    gain_db_range: tuple[float, float],
) -> np.ndarray:
    """
    The observation of missions (class docstring of :class:`NomaRadioMapEnv`, Observation Space): per robot
    its position and destination scaled onto [-1, 1], its AP gain in dB mapped from ``gain_db_range`` onto
    [-1, 1] (clipped) and its arrived flag.

    :param positions: robot positions in metres, shape (..., U, 2)
    :param destinations: destinations in metres, shape (..., U, 2)
    :param gain_db: AP channel gains in dB, shape (..., U)
    :param arrived: arrived flags, shape (..., U)
    :param room_size: ``(width, depth)`` in metres
    :param gain_db_range: the gains mapped onto -1 and 1
    :return: float32 array of shape (..., 6 U)
    """
    scale = 2.0 / np.asarray(room_size, dtype=np.float64)
    low, high = gain_db_range
    gain_scale, gain_offset = 2.0 / (high - low), -(high + low) / (high - low)
    gain = np.minimum(np.maximum(np.asarray(gain_db) * gain_scale + gain_offset, -1.0), 1.0)
    per_robot = np.concatenate(
        [
            np.asarray(positions) * scale - 1.0,
            np.asarray(destinations) * scale - 1.0,
            gain[..., None],
            np.asarray(arrived, dtype=np.float64)[..., None],
        ],
        axis=-1,
    )
    return per_robot.reshape(*per_robot.shape[:-2], -1).astype(np.float32)


class NomaRadioMapEnv(gym.Env[np.ndarray, np.ndarray]):
    """
    ## Description

    Indoor robots (IRs) cross a room built from "Lego" cuboids to their destinations while one access
    point (AP) serves them in the downlink with NOMA (superposition coding and SIC) or OMA (FDMA), under
    interference from external transmitters (Zhong et al., "Path Design and Resource Management for NOMA
    enhanced Indoor Intelligent Robots"). Each step, the agent moves every robot and splits the AP's power
    between them; a robot whose rate falls below the QoS rate is in outage. The mission quality indicator
    ``MQI = t_total - sum_u (T_u + lambda outage_u)`` rewards short missions with few outage steps.

    The channel comes from a pre-computed radio map (:class:`noma_radiomap.RadioMap`): ITU-R P.1238 path
    loss with obstacle counting (paper Eq. (1)-(4), (17)), plus Rayleigh fading, either at its expectation (the paper's
    radio-map training, deterministic) or drawn fresh every step ("reality").

    ## Action Space

    ``Box(-1, 1, (3U,), float32)``, per robot ``u`` (in scenario order) ``[dx, dy, power]``:

    | Num      | Action                                                       | Min | Max |
    |----------|--------------------------------------------------------------|-----|-----|
    | 3u       | x velocity, scaled by ``V_max time_step`` (metres per step)  | -1  | 1   |
    | 3u + 1   | y velocity; the displacement is clipped to norm ``V_max dt``  | -1  | 1   |
    | 3u + 2   | power: ``p_u = P_max (a + 1) / 2``, all scaled down to sum ``P_max`` if more | -1 | 1 |

    Robots move in sub-steps of at most half a cell and slide along walls (paper Sec. IV-D); an arrived robot's
    actions are ignored and it gets no power. Finite actions outside [-1, 1] are clipped; an action of another
    shape than ``(3U,)``, or with a NaN or infinite component, raises a ``ValueError`` naming the robot and the
    component, and leaves the env's state unchanged (:func:`noma_radiomap.actions.check_action`).

    ## Observation Space

    ``Box(-1, 1, (6U,), float32)``, per robot ``u``:

    | Num      | Observation                                                           | Min | Max |
    |----------|-----------------------------------------------------------------------|-----|-----|
    | 6u, 6u+1 | position ``(x, y)``: ``2 x / width - 1``, ``2 y / depth - 1``           | -1  | 1   |
    | 6u+2, +3 | destination, scaled like the position                                 | -1  | 1   |
    | 6u + 4   | AP channel gain ``g_u`` incl. fading in dB, [-130, -30] dB mapped onto [-1, 1], clipped | -1  | 1   |
    | 6u + 5   | arrived flag: 1 once the robot has arrived, else 0                     | 0   | 1   |

    ## Rewards

    Per step, summed over the robots that had not arrived before the step (paper Sec. IV):
    time cost ``R_c = -1``; inducing reward ``R_i = 1 - d / d_max`` (``d``: distance to the destination,
    Euclidean or geodesic, ``d_max``: the room diagonal); QoS penalty ``R_qos = -lambda`` in outage;
    ``R_d = +10`` on the step a robot arrives; ``R_s = +200`` when all robots have arrived. The reward phase
    picks the terms: ``"destination"`` (phase 1): ``R_c + R_i + R_d + R_s``; ``"mqi"`` (phase 2):
    ``R_c + R_qos + R_d + R_s``; ``"combined"`` (the plain DDPG baseline): all five. Every ``info`` has
    ``reward_components`` (``time``, ``inducing``, ``qos``, ``arrival``, ``success``, summed over robots), so
    ``reward == sum(reward_weights()[k] * info["reward_components"][k])`` and any phase's reward can be
    recomputed; ``set_reward_phase`` switches the phase at run time (also through ``VecEnv.env_method``).

    ``info`` per step (per-robot arrays of length U): ``rate_bps``, ``sinr_db``, ``outage`` (bool, only for
    robots that had not arrived), ``power_w``, ``gain_db`` (incl. fading) and ``decoding_order`` (robot
    indices, weakest to strongest equivalent gain). At the end of an episode also ``is_success``, ``mqi``,
    ``mission_time`` (per robot: steps until arrival, ``max_steps`` if never) and ``outage_steps`` (per robot).

    ## Starting State

    Each robot starts at the centre of a cell drawn uniformly from the free cells of its scenario start
    region (farther than ``arrival_radius`` from its destination), heading to one of its scenario
    destinations drawn uniformly. ``reset(options={"starts": [[x, y], ...], "destinations": [[x, y], ...]})``
    fixes either or both (one ``[x, y]`` per robot, free and mutually reachable).

    ## Episode End

    Terminates when every robot has arrived (within ``arrival_radius`` of its destination). Truncation is left
    to Gymnasium's ``TimeLimit``: the registered ids wrap the env in one of the scenario's ``mission.max_steps``
    steps (:func:`noma_radiomap.registration.make_env`), so ``spec.max_episode_steps`` follows the scenario. The
    end-of-mission figures (``mqi``, ...) come in the ``info`` of the step that terminates or reaches
    ``max_steps``.

    ## Arguments

    ```python
    >>> import gymnasium as gym
    >>> import noma_radiomap
    >>> env = gym.make("NomaRadioMap-v0", multiple_access="oma", channel="rayleigh", reward_phase="mqi")
    ```

    - ``scenario``: a built-in scenario name (``"mall"``), a YAML path or a :class:`Scenario`
    - ``multiple_access``: ``"noma"`` (SIC) or ``"oma"`` (FDMA)
    - ``channel``: ``"radio_map"`` (expected fading, -2.51 dB on every link, deterministic) or ``"rayleigh"``
      (``|h|^2 ~ Exp(1)`` per link per step from the env's seeded generator)
    - ``reward_phase``: ``"destination"``, ``"mqi"`` or ``"combined"``
    - ``inducing``: ``"euclidean"`` or ``"geodesic"`` (obstacle-aware grid distance) for ``R_i``
    - ``render_mode``: ``None``, ``"rgb_array"`` (SINR map with robots and trajectories) or ``"human"``

    ## Attributes

    For planners, evaluation and plots (read-only): ``scenario``, ``radio_map``, ``positions`` (U, 2),
    ``destinations`` (U, 2), ``arrived`` (U,), ``step_count``, ``trajectory`` (steps + 1, U, 2),
    ``reward_phase``; :meth:`reward_weights`, :meth:`set_reward_phase`, :meth:`episode_summary`.

    ## Vector env

    ``gymnasium.make_vec("NomaRadioMap-v0", num_envs=N)`` steps N missions at once
    (:class:`noma_radiomap.vector.NomaRadioMapVecEnv`, the same transitions as N single envs seeded
    ``seed + i``); for Stable-Baselines3, ``sb3_dtdpg.vec_env.make_mission_vec_env`` (docs/SCALING.md).

    ## Version History

    * v0: Initial release.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    REWARD_PHASES: ClassVar[tuple[str, ...]] = rewards.REWARD_PHASES
    REWARD_COMPONENTS: ClassVar[tuple[str, ...]] = rewards.REWARD_COMPONENTS
    #: Channel gains (dB) mapped onto the observation's [-1, 1]. On the free cells of the built-in scenarios
    #: the AP gain with the expected fading lies in [-96, -46.5] dB (-46.5 dB: LoS at the 2 m antenna
    #: offset); Rayleigh fading moves it by -30 to +8.4 dB at the 0.1 % tails of Exp(1), which the range
    #: covers; rarer deep fades are clipped.
    GAIN_DB_RANGE: ClassVar[tuple[float, float]] = (-130.0, -30.0)

    def __init__(
        self,
        scenario: str | os.PathLike[str] | Scenario = "mall",
        multiple_access: str = "noma",
        channel: str = "radio_map",
        reward_phase: str = "destination",
        inducing: str = "euclidean",
        render_mode: str | None = None,
    ) -> None:
        for name, value, allowed in (
            ("multiple_access", multiple_access, MULTIPLE_ACCESS),
            ("channel", channel, CHANNELS),
            ("reward_phase", reward_phase, self.REWARD_PHASES),
            ("inducing", inducing, INDUCING),
        ):
            if value not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, got {value!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.scenario = self._load(scenario)
        self.multiple_access = multiple_access
        self.channel = channel
        self.inducing = inducing
        self.render_mode = render_mode
        self.n_robots = self.scenario.n_robots
        self.max_steps = self.scenario.mission.max_steps
        self.radio_map = RadioMap.for_scenario(self.scenario)
        self._motion = GridMotion(
            self.radio_map.blocked,
            self.scenario.room,
            max_step=self.scenario.robot.v_max * self.scenario.mission.time_step,
            arrival_radius=self.scenario.robot.arrival_radius,
        )
        self._components = geometry.free_components(self.radio_map.blocked)
        self._setup_channel()
        self._setup_rewards(reward_phase)
        self._mission_choices = self._setup_missions()

        self.action_space = spaces.Box(-1.0, 1.0, (3 * self.n_robots,), dtype=np.float32)
        self.observation_space = spaces.Box(-1.0, 1.0, (6 * self.n_robots,), dtype=np.float32)

        self.positions = np.zeros((self.n_robots, 2))
        self.destinations = np.zeros((self.n_robots, 2))
        self.arrived = np.zeros(self.n_robots, dtype=bool)
        self._arrival_step = np.full(self.n_robots, self.max_steps, dtype=np.int64)
        self._outage_steps = np.zeros(self.n_robots, dtype=np.int64)
        self._gain_db = np.zeros(self.n_robots)
        self._trajectory: list[np.ndarray] = []
        self._distance_maps = np.zeros((self.n_robots, 0))
        self.step_count = 0
        self._renderer = None

    @staticmethod
    def _load(scenario: str | os.PathLike[str] | Scenario) -> Scenario:
        if isinstance(scenario, Scenario):
            return scenario
        if isinstance(scenario, str | os.PathLike):
            return load_scenario(scenario)
        raise ValueError(f"scenario must be a scenario name, a YAML path or a Scenario, got {scenario!r}")

    def _setup_channel(self) -> None:
        """Per-cell gain table and the radio constants of the downlink."""
        sc = self.scenario
        # One row per cell (flat index ix * ny + iy), one column per transmitter (AP first): a single gather
        # per step. The radio-map channel has the expected fading folded in; the Rayleigh channel draws it.
        gains = self.radio_map.gain if self.channel == "radio_map" else self.radio_map.path_gain
        table = np.stack([gains[name] for name in sc.transmitter_names])
        self._gain_table = table.reshape(len(table), -1).T.copy()
        self._interferer_power_w = dbm_to_watt(np.array([i.power_dbm for i in sc.interferers], dtype=np.float64))
        self._max_power_w = float(dbm_to_watt(sc.ap.max_power_dbm))
        self._noise_w_per_hz = float(dbm_to_watt(sc.radio.noise_dbm_per_hz))
        self._room_size = np.array([sc.room.width, sc.room.depth])

    def _setup_rewards(self, reward_phase: str) -> None:
        mission = self.scenario.mission
        self._reward_constants = rewards.RewardConstants(
            time_cost=mission.time_cost,
            outage_penalty=mission.outage_penalty,
            arrival_reward=mission.arrival_reward,
            success_reward=mission.success_reward,
        )
        self._d_max = self.scenario.room.d_max
        self.set_reward_phase(reward_phase)

    def _setup_missions(self) -> list[list[tuple[np.ndarray, np.ndarray]]]:
        """Per robot, its destinations and the free start cells not already at each of them."""
        sc = self.scenario
        missions = []
        for u, robot in enumerate(sc.robots):
            centres = (self.radio_map.start_cells(u) + 0.5) * sc.room.resolution
            choices = []
            for destination in robot.destinations:
                goal = np.asarray(destination, dtype=np.float64)
                far = np.hypot(*(centres - goal).T) > sc.robot.arrival_radius
                if not far.any():
                    raise ValueError(
                        f"robots[{u}].start: every free cell of {list(robot.start)} is within arrival_radius of "
                        f"destination {list(destination)}"
                    )
                choices.append((goal, centres[far]))
            missions.append(choices)
        return missions

    # --- reward phases ---------------------------------------------------------------------------
    def set_reward_phase(self, name: str) -> None:
        """
        Switch the reward phase (takes effect from the next step).

        :param name: one of :attr:`REWARD_PHASES`
        """
        self._weights = rewards.phase_weights(name)
        self.reward_phase = name

    def reward_weights(self, phase: str | None = None) -> dict[str, float]:
        """
        Weights of the reward components in a phase: its reward is
        ``sum(weights[k] * info["reward_components"][k])``.

        :param phase: a reward phase; None: the current one
        :return: a weight (0 or 1) for each of :attr:`REWARD_COMPONENTS`
        """
        return rewards.phase_weights(self.reward_phase if phase is None else phase)

    # --- Gymnasium API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        starts, destinations = self._draw_mission(options)
        self.positions = starts
        self.destinations = destinations
        self.arrived = np.zeros(self.n_robots, dtype=bool)
        self._arrival_step = np.full(self.n_robots, self.max_steps, dtype=np.int64)
        self._outage_steps = np.zeros(self.n_robots, dtype=np.int64)
        self.step_count = 0
        self._trajectory = [starts.copy()]
        if self.inducing == "geodesic":
            self._distance_maps = np.stack([self.radio_map.distance_field(d).ravel() for d in destinations])
        self._channel()
        if self.render_mode == "human":
            self.render()
        return self._get_obs(), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        action = check_action(action, self.n_robots)
        # Robots that arrived before this step are inactive: no motion, no power, no time cost, no outage.
        active = ~self.arrived
        arriving = self._move(action[:, :2], active)
        gain, interference = self._channel()
        power, result, outage = self._downlink(action[:, 2], gain, interference, active)
        components = self._rewards(active, arriving, outage)
        reward = self._reward(components)
        terminated = self._is_terminated()
        self._outage_steps += outage
        self._arrival_step[arriving] = self.step_count
        info = self._info(components, power, result, outage, end=terminated or self.step_count >= self.max_steps)
        if self.render_mode == "human":
            self.render()
        # Truncation is the TimeLimit's (registration.make_env), at the scenario's mission.max_steps.
        return self._get_obs(), reward, terminated, False, info

    # --- the stages of a step --------------------------------------------------------------------
    def _move(self, motion: np.ndarray, active: np.ndarray) -> np.ndarray:
        """Motion: move the active robots (sub-steps, wall sliding); return the robots arriving on this step."""
        positions, at_goal = self._motion.move(self.positions, motion, self.destinations, active)
        self.positions = positions
        self.arrived = self.arrived | at_goal
        self.step_count += 1
        self._trajectory.append(positions)
        return at_goal & active

    def _channel(self) -> tuple[np.ndarray, np.ndarray]:
        """Channel at the robots' positions: the linear AP gain and the interference power (U,) each."""
        cells = self.scenario.room.flat_cell_index(self.positions)
        gains = self._gain_table[cells]  # (U, transmitters)
        if self.channel == "rayleigh":
            gains = faded_gain(gains, rayleigh_fading(self.np_random, gains.shape))
        gain = gains[:, 0]
        self._gain_db = linear_to_db(gain)
        return gain, interference_power(gains[:, 1:], self._interferer_power_w)

    def _downlink(
        self, power_actions: np.ndarray, gain: np.ndarray, interference: np.ndarray, active: np.ndarray
    ) -> tuple[np.ndarray, DownlinkResult, np.ndarray]:
        """Downlink: the allocated powers (arrived robots get none), rates and SINRs, and the outage of the active robots."""
        radio = self.scenario.radio
        # single_transmission: allocate_power + downlink on Python floats, the same bits (tests/test_downlink.py)
        power, result = single_transmission(
            np.where(active, power_actions, -1.0).tolist(),
            gain.tolist(),
            interference.tolist(),
            self._max_power_w,
            radio.bandwidth_per_robot_hz,
            self._noise_w_per_hz,
            self.multiple_access,
        )
        return power, result, in_outage(result.rate_bps, radio.qos_rate_bps) & active

    def _distances(self) -> np.ndarray:
        """Distance of each robot to its destination: Euclidean, or geodesic on the grid (``inducing``)."""
        if self.inducing == "euclidean":
            return geometry.distance(self.positions, self.destinations)
        cells = self.scenario.room.flat_cell_index(self.positions)
        return self._distance_maps[np.arange(self.n_robots), cells]

    def _rewards(self, active: np.ndarray, arriving: np.ndarray, outage: np.ndarray) -> dict[str, float]:
        """The named reward components of the step (``info["reward_components"]``)."""
        distance = self._distances()
        components = rewards.reward_components(active, arriving, outage, distance, self._d_max, self._reward_constants)
        return {name: float(value) for name, value in components.items()}

    def _reward(self, components: dict[str, float]) -> float:
        """The reward of the current phase: the weighted sum of the components."""
        return float(rewards.weighted_reward(components, self._weights))

    def _is_terminated(self) -> bool:
        """Every robot has arrived."""
        return bool(self.arrived.all())

    def _info(
        self, components: dict[str, float], power: np.ndarray, result: DownlinkResult, outage: np.ndarray, end: bool
    ) -> dict[str, Any]:
        info: dict[str, Any] = {
            "reward_components": components,
            "rate_bps": result.rate_bps,
            "sinr_db": result.sinr_db,
            "outage": outage,
            "power_w": power,
            "gain_db": self._gain_db,
            "decoding_order": result.decoding_order,
        }
        if end:
            info.update(self.episode_summary())
        return info

    def _get_obs(self) -> np.ndarray:
        return mission_observation(
            self.positions, self.destinations, self._gain_db, self.arrived, self._room_size, self.GAIN_DB_RANGE
        )

    def episode_summary(self) -> dict[str, Any]:
        """
        The end-of-episode figures (paper Eq. (13)-(14)), as of the current step.

        :return: ``is_success`` (all arrived), ``mqi``, ``mission_time`` (per robot, ``T_u``: steps until
            arrival, ``max_steps`` if not arrived) and ``outage_steps`` (per robot)
        """
        mission = self.scenario.mission
        mission_time = np.where(self.arrived, self._arrival_step, self.max_steps).astype(np.int64)
        outage_steps = self._outage_steps.copy()
        mqi = float(rewards.mission_quality_indicator(mission.t_total, mission_time, outage_steps, mission.outage_penalty))
        return {
            "is_success": bool(self.arrived.all()),
            "mqi": mqi,
            "mission_time": mission_time,
            "outage_steps": outage_steps,
        }

    @property
    def trajectory(self) -> np.ndarray:
        """Robot positions since the last reset, shape (steps + 1, U, 2)."""
        return np.stack(self._trajectory)

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn(
                "You are calling render method without specifying any render mode. "
                'You can specify the render_mode at initialization, e.g. gym.make("NomaRadioMap-v0", render_mode="rgb_array")'
            )
            return None
        if self._renderer is None:
            from noma_radiomap.rendering import Renderer

            self._renderer = Renderer(self, human=self.render_mode == "human")
        return self._renderer.render()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None  # matplotlib figures are rebuilt on demand
        return state

    # --- missions --------------------------------------------------------------------------------
    def _draw_mission(
        self, options: dict[str, Any] | None, rng: np.random.Generator | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """
        Starts and destinations (U, 2) each: drawn from the scenario, or given in the reset options.

        :param options: the reset options
        :param rng: the generator to draw from (None: the env's ``np_random``; the vector env passes each
            mission's own)
        """
        rng = self.np_random if rng is None else rng
        options = {} if options is None else dict(options)
        unknown = set(options) - {"starts", "destinations"}
        if unknown:
            raise ValueError(f"options: unknown keys {sorted(unknown)}, expected 'starts' and/or 'destinations'")
        destinations = self._option_points(options, "destinations")
        starts = self._option_points(options, "starts")
        if destinations is None:
            destinations = np.empty((self.n_robots, 2))
            for u, choices in enumerate(self._mission_choices):
                destinations[u] = choices[rng.integers(len(choices))][0]
        if starts is None:
            starts = np.empty((self.n_robots, 2))
            for u, choices in enumerate(self._mission_choices):
                candidates = self._start_candidates(u, destinations[u], choices)
                starts[u] = candidates[rng.integers(len(candidates))]
        self._check_mission(starts, destinations)
        return starts, destinations

    def _start_candidates(self, u: int, destination: np.ndarray, choices: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
        for goal, candidates in choices:
            if np.array_equal(goal, destination):
                return candidates
        # A destination given through the options: any free start cell farther than arrival_radius.
        all_cells = np.concatenate([c for _, c in choices])
        far = np.hypot(*(all_cells - destination).T) > self.scenario.robot.arrival_radius
        if not far.any():
            raise ValueError(
                f"options['destinations'][{u}]: {destination.tolist()} is within arrival_radius of every start cell"
            )
        return all_cells[far]

    def _option_points(self, options: dict[str, Any], key: str) -> np.ndarray | None:
        if key not in options or options[key] is None:
            return None
        try:
            points = np.array(options[key], dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"options[{key!r}]: expected {self.n_robots} points [x, y], got {options[key]!r}") from None
        if points.shape != (self.n_robots, 2) or not np.isfinite(points).all():
            raise ValueError(
                f"options[{key!r}]: expected {self.n_robots} finite points [x, y] (shape ({self.n_robots}, 2)), "
                f"got {options[key]!r}"
            )
        free = self._motion.is_free(points)
        if not free.all():
            u = int(np.flatnonzero(~free)[0])
            raise ValueError(f"options[{key!r}][{u}]: {points[u].tolist()} is outside the room or in a blocked cell")
        return points

    def _check_mission(self, starts: np.ndarray, destinations: np.ndarray) -> None:
        start_labels = self._components[self.scenario.room.cell_index(starts)]
        goal_labels = self._components[self.scenario.room.cell_index(destinations)]
        for u in range(self.n_robots):
            if start_labels[u] != goal_labels[u]:
                raise ValueError(
                    f"options: destination {destinations[u].tolist()} of robot {u} is unreachable from its start "
                    f"{starts[u].tolist()}"
                )
            if np.hypot(*(starts[u] - destinations[u])) <= self.scenario.robot.arrival_radius:
                raise ValueError(
                    f"options: start {starts[u].tolist()} of robot {u} is already within arrival_radius "
                    f"({self.scenario.robot.arrival_radius} m) of its destination {destinations[u].tolist()}"
                )
