"""The NOMA indoor radio-map environment (SPEC 2.7-2.10)."""

import math
import os
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from noma_radiomap import geometry
from noma_radiomap.actions import check_action
from noma_radiomap.downlink import MULTIPLE_ACCESS, single_transmission
from noma_radiomap.motion import GridMotion
from noma_radiomap.propagation import EXPECTED_FADING_DB, db_to_linear, dbm_to_watt
from noma_radiomap.radiomap import RadioMap
from noma_radiomap.scenario import Scenario, load_scenario

CHANNELS: tuple[str, ...] = ("radio_map", "rayleigh")
_TINY = float(np.finfo(np.float64).tiny)
INDUCING: tuple[str, ...] = ("euclidean", "geodesic")


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
    loss with obstacle counting (SPEC 2.2-2.5), plus Rayleigh fading, either at its expectation (the paper's
    radio-map training, deterministic) or drawn fresh every step ("reality").

    ## Action Space

    ``Box(-1, 1, (3U,), float32)``, per robot ``u`` (in scenario order) ``[dx, dy, power]``:

    | Num      | Action                                                       | Min | Max |
    |----------|--------------------------------------------------------------|-----|-----|
    | 3u       | x velocity, scaled by ``V_max time_step`` (metres per step)  | -1  | 1   |
    | 3u + 1   | y velocity; the displacement is clipped to norm ``V_max dt``  | -1  | 1   |
    | 3u + 2   | power: ``p_u = P_max (a + 1) / 2``, all scaled down to sum ``P_max`` if more | -1 | 1 |

    Robots move in sub-steps of at most half a cell and slide along walls (SPEC 2.7); an arrived robot's
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

    Terminates when every robot has arrived (within ``arrival_radius`` of its destination). Truncates after
    the scenario's ``mission.max_steps`` steps (the registered ids also apply a ``TimeLimit`` of 300, the
    ``mall`` value; pass ``max_episode_steps=`` to ``gymnasium.make`` for scenarios with longer missions).

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

    ## Version History

    * v0: Initial release.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    REWARD_PHASES: ClassVar[tuple[str, ...]] = ("destination", "mqi", "combined")
    REWARD_COMPONENTS: ClassVar[tuple[str, ...]] = ("time", "inducing", "qos", "arrival", "success")
    _PHASE_TERMS: ClassVar[dict[str, tuple[str, ...]]] = {
        "destination": ("time", "inducing", "arrival", "success"),
        "mqi": ("time", "qos", "arrival", "success"),
        "combined": ("time", "inducing", "qos", "arrival", "success"),
    }
    #: Constants of the paper's reward (Sec. IV): time cost, arrival and success rewards.
    TIME_COST: ClassVar[float] = -1.0
    ARRIVAL_REWARD: ClassVar[float] = 10.0
    SUCCESS_REWARD: ClassVar[float] = 200.0
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
        if isinstance(scenario, Scenario):
            self.scenario = scenario
        elif isinstance(scenario, str | os.PathLike):
            self.scenario = load_scenario(scenario)
        else:
            raise ValueError(f"scenario must be a scenario name, a YAML path or a Scenario, got {scenario!r}")
        self.multiple_access = multiple_access
        self.channel = channel
        self.reward_phase = reward_phase
        self.inducing = inducing
        self.render_mode = render_mode

        sc = self.scenario
        self.n_robots = sc.n_robots
        self.max_steps = sc.mission.max_steps
        self.radio_map = RadioMap.for_scenario(sc)
        blocked = np.asarray(self.radio_map.blocked, dtype=bool)
        self._resolution = sc.room.resolution
        self._grid_shape = blocked.shape
        self._room = np.array([sc.room.width, sc.room.depth])
        self._d_max = float(np.hypot(sc.room.width, sc.room.depth))
        self._motion = GridMotion(
            blocked,
            sc.room.resolution,
            sc.room.width,
            sc.room.depth,
            max_step=sc.robot.v_max * sc.mission.time_step,
            arrival_radius=sc.robot.arrival_radius,
        )
        self._components = geometry.free_components(blocked)

        # Channel: linear path gains of every transmitter (AP first), with the expected fading folded in
        # for the radio-map channel (SPEC 2.4).
        names = sc.transmitter_names
        path_gain_db = -np.stack([self.radio_map.path_loss_db[name] for name in names])
        if channel == "radio_map":
            path_gain_db = path_gain_db + EXPECTED_FADING_DB
        # One row per cell (flat index ix * ny + iy), one column per transmitter: a single gather per step.
        self._gain_table = db_to_linear(path_gain_db).reshape(len(names), -1).T.copy()
        self._interferer_power_w = dbm_to_watt(np.array([i.power_dbm for i in sc.interferers], dtype=np.float64))
        self._interferer_power_list = self._interferer_power_w.tolist()
        self._max_power_w = float(dbm_to_watt(sc.ap.max_power_dbm))
        self._noise_w_per_hz = float(dbm_to_watt(sc.radio.noise_dbm_per_hz))
        self._bandwidth_hz = sc.radio.bandwidth_per_robot_hz
        self._qos_bps = sc.radio.qos_rate_bps
        self._outage_penalty = sc.mission.outage_penalty
        # Affine maps onto the observation's [-1, 1] (class docstring, Observation Space).
        self._position_scale = 2.0 / self._room
        low, high = self.GAIN_DB_RANGE
        self._gain_scale, self._gain_offset = 2.0 / (high - low), -(high + low) / (high - low)

        # Missions: per robot, its destinations and the free start cells not already at each of them.
        self._mission_choices: list[list[tuple[np.ndarray, np.ndarray]]] = []
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
            self._mission_choices.append(choices)

        self.action_space = spaces.Box(-1.0, 1.0, (3 * self.n_robots,), dtype=np.float32)
        self.observation_space = spaces.Box(-1.0, 1.0, (6 * self.n_robots,), dtype=np.float32)

        self.positions = np.zeros((self.n_robots, 2))
        self.destinations = np.zeros((self.n_robots, 2))
        self.arrived = np.zeros(self.n_robots, dtype=bool)
        self._arrival_step = [self.max_steps] * self.n_robots
        self._outage_steps = [0] * self.n_robots
        self._gain_db = np.zeros(self.n_robots)
        self._destination_obs: list[list[float]] = []
        self._destination_list: list[list[float]] = []
        self._trajectory: list[np.ndarray] = []
        self._distance_maps: list[np.ndarray] = []
        self.step_count = 0
        self._renderer = None

    # --- reward phases ---------------------------------------------------------------------------
    def set_reward_phase(self, name: str) -> None:
        """
        Switch the reward phase (takes effect from the next step).

        :param name: one of :attr:`REWARD_PHASES`
        """
        if name not in self.REWARD_PHASES:
            raise ValueError(f"reward_phase must be one of {self.REWARD_PHASES}, got {name!r}")
        self.reward_phase = name

    def reward_weights(self, phase: str | None = None) -> dict[str, float]:
        """
        Weights of the reward components in a phase: its reward is
        ``sum(weights[k] * info["reward_components"][k])``.

        :param phase: a reward phase; None: the current one
        :return: a weight (0 or 1) for each of :attr:`REWARD_COMPONENTS`
        """
        phase = self.reward_phase if phase is None else phase
        if phase not in self.REWARD_PHASES:
            raise ValueError(f"phase must be one of {self.REWARD_PHASES}, got {phase!r}")
        terms = self._PHASE_TERMS[phase]
        return {name: float(name in terms) for name in self.REWARD_COMPONENTS}

    # --- Gymnasium API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        options = {} if options is None else dict(options)
        unknown = set(options) - {"starts", "destinations"}
        if unknown:
            raise ValueError(f"options: unknown keys {sorted(unknown)}, expected 'starts' and/or 'destinations'")
        destinations = self._option_points(options, "destinations")
        starts = self._option_points(options, "starts")
        if destinations is None:
            destinations = np.empty((self.n_robots, 2))
            for u, choices in enumerate(self._mission_choices):
                destinations[u] = choices[self.np_random.integers(len(choices))][0]
        if starts is None:
            starts = np.empty((self.n_robots, 2))
            for u, choices in enumerate(self._mission_choices):
                candidates = self._start_candidates(u, destinations[u], choices)
                starts[u] = candidates[self.np_random.integers(len(candidates))]
        self._check_mission(starts, destinations)

        self.positions = starts
        self.destinations = destinations
        self.arrived = np.zeros(self.n_robots, dtype=bool)
        self._arrival_step = [self.max_steps] * self.n_robots
        self._outage_steps = [0] * self.n_robots
        self.step_count = 0
        self._trajectory = [starts.copy()]
        if self.inducing == "geodesic":
            self._distance_maps = [self.radio_map.distance_field(d) for d in destinations]
        self._destination_obs = (destinations * self._position_scale - 1.0).tolist()
        self._destination_list = destinations.tolist()
        gain_ap, _ = self._channel(starts.tolist())
        self._gain_db = np.array([10.0 * math.log10(max(g, _TINY)) for g in gain_ap])
        if self.render_mode == "human":
            self.render()
        return self._observation(), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        action = check_action(action, self.n_robots)
        was_arrived = self.arrived
        positions, at_goal = self._motion.move(self.positions, action[:, :2], self.destinations, ~was_arrived)
        self.positions = positions
        self.arrived = was_arrived | at_goal
        self.step_count += 1
        self._trajectory.append(positions)

        # Per-robot work on Python floats: U is small, and numpy calls on arrays of U elements cost more
        # than the arithmetic (the env's speed bar, SPEC 2.7). Robots that arrived before this step are
        # inactive: no power, no time cost, no outage (SPEC 2.7, 2.9).
        points = positions.tolist()
        active = [not a for a in was_arrived.tolist()]
        arriving = [a and b for a, b in zip(at_goal.tolist(), active, strict=True)]
        gain_ap, interference = self._channel(points)
        power_actions = [a if is_active else -1.0 for a, is_active in zip(action[:, 2].tolist(), active, strict=True)]
        power, result = single_transmission(
            power_actions,
            gain_ap,
            interference,
            self._max_power_w,
            self._bandwidth_hz,
            self._noise_w_per_hz,
            self.multiple_access,
        )
        qos = self._qos_bps
        outage_list = [rate < qos and is_active for rate, is_active in zip(result.rate_bps.tolist(), active, strict=True)]
        self._gain_db = np.array([10.0 * math.log10(max(g, _TINY)) for g in gain_ap])  # |h|^2 = 0 has p ~ 2^-53

        n_active, n_arriving, n_outage = sum(active), sum(arriving), sum(outage_list)
        terminated = bool(self.arrived.all())
        inducing = 0.0
        for d, is_active in zip(self._distances(points), active, strict=True):
            if is_active:
                inducing += 1.0 - d / self._d_max
        components = {
            "time": self.TIME_COST * n_active + 0.0,
            "inducing": inducing,
            "qos": 0.0 - self._outage_penalty * n_outage,
            "arrival": self.ARRIVAL_REWARD * n_arriving,
            "success": self.SUCCESS_REWARD if terminated and n_arriving else 0.0,  # once, on the last arrival
        }
        reward = 0.0
        for name in self._PHASE_TERMS[self.reward_phase]:
            reward += components[name]

        for u in range(self.n_robots):
            self._outage_steps[u] += outage_list[u]
            if arriving[u]:
                self._arrival_step[u] = self.step_count
        truncated = not terminated and self.step_count >= self.max_steps
        info: dict[str, Any] = {
            "reward_components": components,
            "rate_bps": result.rate_bps,
            "sinr_db": result.sinr_db,
            "outage": np.array(outage_list, dtype=bool),
            "power_w": power,
            "gain_db": self._gain_db,
            "decoding_order": result.decoding_order,
        }
        if terminated or truncated:
            info.update(self.episode_summary())
        if self.render_mode == "human":
            self.render()
        return self._observation(), reward, terminated, truncated, info

    def episode_summary(self) -> dict[str, Any]:
        """
        The end-of-episode figures (SPEC 2.9), as of the current step.

        :return: ``is_success`` (all arrived), ``mqi``, ``mission_time`` (per robot, ``T_u``: steps until
            arrival, ``max_steps`` if not arrived) and ``outage_steps`` (per robot)
        """
        mission_time = np.where(self.arrived, self._arrival_step, self.max_steps).astype(np.int64)
        outage_steps = np.array(self._outage_steps, dtype=np.int64)
        mqi = self.scenario.mission.t_total - float((mission_time + self._outage_penalty * outage_steps).sum())
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

    # --- internals -------------------------------------------------------------------------------
    def _channel(self, points: list[list[float]]) -> tuple[list[float], list[float]]:
        """Linear AP gain and interference power over the cluster band (U floats each) at the points ``[x, y]``."""
        gains = self._gain_table[[self._flat_cell(x, y) for x, y in points]]  # (U, transmitters), AP first
        if self.channel == "rayleigh":
            gains = gains * self.np_random.exponential(size=gains.shape)
        # Interferers spread their power over the cluster band W (SPEC 2.6).
        interferer_power = self._interferer_power_list
        rows = gains.tolist()
        return [row[0] for row in rows], [sum(p * g for p, g in zip(interferer_power, row[1:], strict=True)) for row in rows]

    def _flat_cell(self, x: float, y: float) -> int:
        """Flat index ``ix * ny + iy`` of the cell of a point of the room."""
        nx, ny = self._grid_shape
        return min(int(x / self._resolution), nx - 1) * ny + min(int(y / self._resolution), ny - 1)

    def _distances(self, points: list[list[float]]) -> list[float]:
        """Distance of each robot to its destination: Euclidean, or geodesic on the grid (``inducing``)."""
        if self.inducing == "euclidean":
            return [math.hypot(x - gx, y - gy) for (x, y), (gx, gy) in zip(points, self._destination_list, strict=True)]
        return [float(field.flat[self._flat_cell(x, y)]) for (x, y), field in zip(points, self._distance_maps, strict=True)]

    def _observation(self) -> np.ndarray:
        # Built from Python floats for the same reason as the bookkeeping in step().
        scale_x, scale_y = self._position_scale.tolist()
        gain_scale, gain_offset = self._gain_scale, self._gain_offset
        values: list[float] = []
        for (x, y), destination, gain_db, arrived in zip(
            self.positions.tolist(), self._destination_obs, self._gain_db.tolist(), self.arrived.tolist(), strict=True
        ):
            gain = min(max(gain_db * gain_scale + gain_offset, -1.0), 1.0)
            values += (x * scale_x - 1.0, y * scale_y - 1.0, *destination, gain, float(arrived))
        return np.array(values, dtype=np.float32)

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
        start_labels = self._components[self.radio_map.cell_index(starts)]
        goal_labels = self._components[self.radio_map.cell_index(destinations)]
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
