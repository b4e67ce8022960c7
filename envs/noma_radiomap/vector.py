"""N missions stepped at once: :class:`NomaRadioMapVecEnv`, the Gymnasium vector env of the mission ids
(docs/ARCHITECTURE.md, vector env).

Every stage of :meth:`NomaRadioMapEnv.step` runs once per step on arrays over (N, U) through the same
physics functions (motion, channel, downlink, rewards, observation), so mission ``i`` of a vector env whose
missions are seeded ``seed + i`` makes exactly the transitions of a single env seeded ``seed + i``. Each
mission keeps its own random generator (the starts and destinations of its resets, its Rayleigh fading),
which is the only per-mission Python loop of a step, and only in the ``rayleigh`` channel.
"""

from dataclasses import dataclass
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from noma_radiomap import geometry, rewards
from noma_radiomap.actions import check_actions
from noma_radiomap.compiled import compiled
from noma_radiomap.downlink import allocate_power, downlink, in_outage
from noma_radiomap.env import NomaRadioMapEnv, mission_observation
from noma_radiomap.propagation import faded_gain, interference_power, linear_to_db, rayleigh_fading
from noma_radiomap.registration import check_observation
from noma_radiomap.wrappers import RelativeGoalObservation, goal_features


@dataclass
class BatchStep:
    """The outcome of one step of the stepped missions (arrays over the stepped rows)."""

    rows: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    components: dict[str, np.ndarray]
    power_w: np.ndarray
    rate_bps: np.ndarray
    sinr_db: np.ndarray
    decoding_order: np.ndarray
    outage: np.ndarray
    gain_db: np.ndarray


class MissionView:
    """
    One mission of a vector env, seen as a single env by ``env_method`` / ``get_attr`` / ``call``:
    ``set_reward_phase``, ``reward_weights``, ``reward_phase``, ``episode_summary``, the static attributes
    (``scenario``, ``radio_map``, ``REWARD_PHASES``, ...) and the mission state (``positions``, ...).

    :param vec_env: the vector env
    :param index: the mission's index
    """

    def __init__(self, vec_env: "NomaRadioMapVecEnv", index: int) -> None:
        self._vec, self._index = vec_env, index

    def set_reward_phase(self, name: str) -> None:
        self._vec.set_reward_phase(name, indices=[self._index])

    def reward_weights(self, phase: str | None = None) -> dict[str, float]:
        return rewards.phase_weights(self.reward_phase if phase is None else phase)

    @property
    def reward_phase(self) -> str:
        return self._vec.reward_phases[self._index]

    def episode_summary(self) -> dict[str, Any]:
        summary = self._vec.episode_summaries(np.array([self._index]))
        return {
            key: value[0] if key in ("mission_time", "outage_steps") else value[0].item() for key, value in summary.items()
        }

    @property
    def positions(self) -> np.ndarray:
        return self._vec.positions[self._index].copy()

    @property
    def destinations(self) -> np.ndarray:
        return self._vec.destinations[self._index].copy()

    @property
    def arrived(self) -> np.ndarray:
        return self._vec.arrived[self._index].copy()

    @property
    def step_count(self) -> int:
        return int(self._vec.step_counts[self._index])

    @property
    def np_random(self) -> np.random.Generator:
        return self._vec.np_randoms[self._index]

    def __getattr__(self, name: str) -> Any:
        # The static attributes and constants are those of the template env (scenario, radio_map, ...).
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self._vec.template, name)


class NomaRadioMapVecEnv(VectorEnv):
    """
    ``num_envs`` missions of :class:`~noma_radiomap.NomaRadioMapEnv` stepped at once with array operations
    over (N, U): the ``vector_entry_point`` of the registered ids, so
    ``gymnasium.make_vec("NomaRadioMap-v0", num_envs=8)`` builds it. For Stable-Baselines3, use
    :func:`sb3_dtdpg.make_mission_vec_env` (an SB3 ``VecEnv`` over the same engine).

    Observations ``(N, 6U)``, actions ``(N, 3U)``, rewards, terminations and truncations ``(N,)``: those of the
    single env (see its docstring), truncated at ``max_episode_steps`` (default: the scenario's
    ``mission.max_steps``, as the registered ids' ``TimeLimit``). ``reset(seed=s)`` seeds mission ``i`` with
    ``s + i`` (or takes a list of seeds), like Gymnasium's ``SyncVectorEnv``; ``options`` (``starts``,
    ``destinations``, ``reset_mask``) apply to every reset mission. Autoreset follows Gymnasium's default
    ``AutoresetMode.NEXT_STEP``: the step after an episode ends resets that mission (reward 0, its action
    ignored). ``infos`` are Gymnasium's dict of arrays with ``_key`` masks: every key of the single env's
    ``info`` (``reward_components`` a dict of (N,) arrays), and ``is_success``, ``mqi``, ``mission_time``,
    ``outage_steps`` for the missions whose episode ends on the step.

    ``set_reward_phase(name, indices=None)``, ``reward_weights(phase=None)``, ``call(name, ...)`` and
    ``get_attr(name)`` reach every mission (:class:`MissionView`) as ``SyncVectorEnv`` reaches its envs.

    :param num_envs: number of missions N
    :param scenario: see :class:`~noma_radiomap.NomaRadioMapEnv` (also ``multiple_access``, ``channel``,
        ``reward_phase``, ``inducing``)
    :param max_episode_steps: truncation length (None: the scenario's ``mission.max_steps``; at most that)
    :param render_mode: only None (render a single env to see a mission)
    :param observation: ``"paper"`` (the env's own) or ``"goal"`` (as
        :class:`~noma_radiomap.wrappers.RelativeGoalObservation` adds it to a single env)
    """

    metadata: ClassVar[dict[str, Any]] = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        scenario: Any = "mall",
        multiple_access: str = "noma",
        channel: str = "radio_map",
        reward_phase: str = "destination",
        inducing: str = "euclidean",
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        observation: str = "paper",
    ) -> None:
        check_observation(observation)
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if render_mode is not None:
            raise ValueError(f"render_mode: the vector env does not render (use a single env), got {render_mode!r}")
        self.template = NomaRadioMapEnv(scenario, multiple_access, channel, reward_phase, inducing)
        env = self.template
        limit = env.max_steps if max_episode_steps is None else int(max_episode_steps)
        if limit < 1:
            raise ValueError(f"max_episode_steps must be >= 1, got {max_episode_steps!r}")
        self.max_episode_steps = min(limit, env.max_steps)
        self.num_envs = int(num_envs)
        self.render_mode = None
        self.observation = observation
        self._goal = RelativeGoalObservation(env) if observation == "goal" else None  # its space and scale
        self.single_observation_space = env.observation_space if self._goal is None else self._goal.observation_space
        self.single_action_space = env.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(env.action_space, self.num_envs)
        self.n_robots = env.n_robots
        self.max_steps = env.max_steps
        self.REWARD_PHASES = env.REWARD_PHASES
        self.REWARD_COMPONENTS = env.REWARD_COMPONENTS

        n, u = self.num_envs, self.n_robots
        self.np_randoms: list[np.random.Generator] = [seeding.np_random()[0] for _ in range(n)]
        self.reward_phases = [reward_phase] * n
        # The weight of each reward component per mission (the phase may differ between missions)
        self._weights = {name: np.full(n, weight) for name, weight in rewards.phase_weights(reward_phase).items()}
        self.positions = np.zeros((n, u, 2))
        self.destinations = np.zeros((n, u, 2))
        self.arrived = np.zeros((n, u), dtype=bool)
        self.step_counts = np.zeros(n, dtype=np.int64)
        self._arrival_step = np.full((n, u), env.max_steps, dtype=np.int64)
        self._outage_steps = np.zeros((n, u), dtype=np.int64)
        self._gain_db = np.zeros((n, u))
        self._distance_maps = np.zeros((n, u, 0))
        self._autoreset = np.zeros(n, dtype=bool)
        self._all_rows = np.arange(n)

    # --- reward phases and per-mission access -----------------------------------------------------
    def set_reward_phase(self, name: str, indices: Any = None) -> None:
        """
        Switch the reward phase of some missions (takes effect from their next step).

        :param name: one of :attr:`REWARD_PHASES`
        :param indices: the missions (None: all)
        """
        weights = rewards.phase_weights(name)
        rows = self._rows(indices)
        for component, weight in weights.items():
            self._weights[component][rows] = weight
        for i in rows:
            self.reward_phases[i] = name

    def reward_weights(self, phase: str | None = None) -> dict[str, float]:
        """
        Weights of the reward components (see :meth:`NomaRadioMapEnv.reward_weights`).

        :param phase: a reward phase; None: mission 0's current one
        """
        return rewards.phase_weights(self.reward_phases[0] if phase is None else phase)

    def mission(self, index: int) -> MissionView:
        """One mission as a single env (:class:`MissionView`)."""
        if not 0 <= int(index) < self.num_envs:
            raise IndexError(f"mission index must be in [0, {self.num_envs}), got {index!r}")
        return MissionView(self, int(index))

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        results = []
        for i in range(self.num_envs):
            attr = getattr(self.mission(i), name)
            results.append(attr(*args, **kwargs) if callable(attr) else attr)
        return tuple(results)

    def get_attr(self, name: str) -> tuple[Any, ...]:
        return tuple(getattr(self.mission(i), name) for i in range(self.num_envs))

    def _rows(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int | np.integer):
            return [int(indices)]
        return [int(i) for i in indices]

    # --- the batched engine (also driven by the SB3 face) ----------------------------------------
    def reset_missions(
        self, rows: np.ndarray, seeds: list[int | None] | None = None, options: dict | list[dict | None] | None = None
    ) -> None:
        """
        Reset some missions: as :meth:`NomaRadioMapEnv.reset` on each, with its own generator.

        :param rows: the missions to reset
        :param seeds: a seed per row (None entries keep the generator going)
        :param options: the single env's reset options, for every row or one per row
        """
        env = self.template
        for k, i in enumerate(rows):
            seed = None if seeds is None else seeds[k]
            if seed is not None:
                self.np_randoms[i] = seeding.np_random(seed)[0]
            row_options = options[k] if isinstance(options, list) else options
            starts, destinations = env._draw_mission(row_options, self.np_randoms[i])
            self.positions[i], self.destinations[i] = starts, destinations
        self.arrived[rows] = False
        self.step_counts[rows] = 0
        self._arrival_step[rows] = env.max_steps
        self._outage_steps[rows] = 0
        if env.inducing == "geodesic":
            if self._distance_maps.shape[-1] == 0:
                self._distance_maps = np.zeros((self.num_envs, self.n_robots, env.scenario.room.nx * env.scenario.room.ny))
            for i in rows:
                self._distance_maps[i] = np.stack([env.radio_map.distance_field(d).ravel() for d in self.destinations[i]])
        self._channel(rows, self.positions[rows])

    def step_missions(self, actions: np.ndarray, rows: np.ndarray | slice) -> BatchStep:
        """
        One step of some missions: the stages of :meth:`NomaRadioMapEnv.step` over (rows, U).

        :param actions: actions of the stepped rows, (len(rows), 3U) (:func:`~noma_radiomap.actions.check_actions`:
            a wrong shape or a non-finite component raises a ValueError before anything changes)
        :param rows: the missions to step (a slice for all)
        :return: the step's outcome
        """
        env = self.template
        row_indices = self._all_rows[rows]
        action = check_actions(actions, row_indices, self.n_robots)
        active = ~self.arrived[rows]
        positions, at_goal = env._motion.move_batch(self.positions[rows], action[..., :2], self.destinations[rows], active)
        self.positions[rows] = positions
        arriving = at_goal & active
        gain, gain_db, interference = self._channel(rows, positions)
        radio = env.scenario.radio
        power = allocate_power(np.where(active, action[..., 2], -1.0), env._max_power_w)
        result = downlink(power, gain, interference, radio.bandwidth_per_robot_hz, env._noise_w_per_hz, env.multiple_access)
        outage = in_outage(result.rate_bps, radio.qos_rate_bps) & active
        components = rewards.reward_components(
            active, arriving, outage, self._distances(rows), env._d_max, env._reward_constants
        )
        # A weight per row (the phase may differ between missions), summed as the single env sums its floats
        reward = rewards.weighted_reward(components, self._weight_columns(rows))
        terminated, truncated = _record_step(
            row_indices,
            arriving,
            outage,
            self.arrived,
            self.step_counts,
            self._arrival_step,
            self._outage_steps,
            self.max_episode_steps,
        )
        return BatchStep(
            rows=row_indices,
            reward=reward,
            terminated=terminated,
            truncated=truncated,
            components=components,
            power_w=power,
            rate_bps=result.rate_bps,
            sinr_db=result.sinr_db,
            decoding_order=result.decoding_order,
            outage=outage,
            gain_db=gain_db,
        )

    def _channel(self, rows: np.ndarray | slice, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The channel of some missions at their positions: the linear AP gain, the same in dB (also kept for the
        observation) and the interference power, (rows, U) each."""
        env = self.template
        gains = env._gain_table[env.scenario.room.flat_cell_index(positions)]  # (rows, U, transmitters)
        if env.channel == "rayleigh" and len(gains):
            # One draw per mission from its own generator: the single env's draws, in its order
            fading = np.stack([rayleigh_fading(self.np_randoms[i], gains.shape[1:]) for i in self._all_rows[rows]])
            gains = faded_gain(gains, fading)
        gain = gains[..., 0]
        gain_db = linear_to_db(gain)
        self._gain_db[rows] = gain_db
        return gain, gain_db, interference_power(gains[..., 1:], env._interferer_power_w)

    def _weight_columns(self, rows: np.ndarray | slice) -> dict[str, np.ndarray]:
        """The weight of each reward component for the stepped rows."""
        if isinstance(rows, slice) and rows == slice(None):
            return self._weights
        return {name: weights[rows] for name, weights in self._weights.items()}

    def _distances(self, rows: np.ndarray | slice) -> np.ndarray:
        env = self.template
        if env.inducing == "euclidean":
            return geometry.distance(self.positions[rows], self.destinations[rows])
        cells = env.scenario.room.flat_cell_index(self.positions[rows])
        maps = self._distance_maps[rows]
        return np.take_along_axis(maps, cells[..., None], axis=-1)[..., 0]

    def observations(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """The observations of some missions, (rows, 6U) float32 (``observation="goal"``: (rows, 9U))."""
        env = self.template
        paper = mission_observation(
            self.positions[rows],
            self.destinations[rows],
            self._gain_db[rows],
            self.arrived[rows],
            env._room_size,
            env.GAIN_DB_RANGE,
        )
        if self._goal is None:
            return paper
        goal = goal_features(self.positions[rows], self.destinations[rows], self.arrived[rows], self._goal.distance_scale)
        return np.concatenate([paper, goal], axis=-1).astype(np.float32)

    def episode_summaries(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        """:meth:`NomaRadioMapEnv.episode_summary` of some missions, as arrays over the rows."""
        mission = self.template.scenario.mission
        arrived = self.arrived[rows]
        mission_time = np.where(arrived, self._arrival_step[rows], self.max_steps).astype(np.int64)
        outage_steps = self._outage_steps[rows].copy()
        mqi = rewards.mission_quality_indicator(mission.t_total, mission_time, outage_steps, mission.outage_penalty)
        return {
            "is_success": arrived.all(axis=-1),
            "mqi": np.asarray(mqi, dtype=np.float64),
            "mission_time": mission_time,
            "outage_steps": outage_steps,
        }

    # --- Gymnasium VectorEnv API -----------------------------------------------------------------
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict]:
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        rows = np.arange(self.num_envs) if mask is None else np.flatnonzero(np.asarray(mask, dtype=bool))
        if seed is None or isinstance(seed, int | np.integer):
            seeds = [None] * len(rows) if seed is None else [int(seed) + int(i) for i in rows]
        else:
            if len(seed) != self.num_envs:
                raise ValueError(f"seed: expected {self.num_envs} seeds (one per mission), got {len(seed)}")
            seeds = [seed[i] for i in rows]
        self.reset_missions(rows, seeds, options or None)
        self._autoreset[rows] = False
        return self.observations(), {}

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        actions = np.asarray(actions)
        resetting = self._autoreset.copy()
        stepping = np.flatnonzero(~resetting) if resetting.any() else slice(None)
        n = self.num_envs
        reward = np.zeros(n)
        terminated = np.zeros(n, dtype=bool)
        truncated = np.zeros(n, dtype=bool)
        infos: dict[str, Any] = {}
        if not resetting.all():
            self._step_infos(self.step_missions(actions[stepping], stepping), reward, terminated, truncated, infos)
        if resetting.any():
            self.reset_missions(np.flatnonzero(resetting))
        self._autoreset = terminated | truncated
        return self.observations(), reward, terminated, truncated, infos

    def _step_infos(
        self, result: BatchStep, reward: np.ndarray, terminated: np.ndarray, truncated: np.ndarray, infos: dict[str, Any]
    ) -> None:
        """Scatter a step's outcome into the (N,) arrays and Gymnasium's masked infos."""
        n, rows = self.num_envs, result.rows
        reward[rows], terminated[rows], truncated[rows] = result.reward, result.terminated, result.truncated
        mask = np.zeros(n, dtype=bool)
        mask[rows] = True
        components = {}
        for key, value in result.components.items():
            components[key], components[f"_{key}"] = self._full(value, rows, mask), mask
        infos["reward_components"] = components
        infos["_reward_components"] = mask
        for key in ("rate_bps", "sinr_db", "outage", "power_w", "gain_db", "decoding_order"):
            infos[key], infos[f"_{key}"] = self._full(getattr(result, key), rows, mask), mask
        ended = rows[result.terminated | result.truncated]
        if len(ended):
            end_mask = np.zeros(n, dtype=bool)
            end_mask[ended] = True
            for key, value in self.episode_summaries(ended).items():
                infos[key], infos[f"_{key}"] = self._full(value, ended, end_mask), end_mask

    @staticmethod
    def _full(values: np.ndarray, rows: np.ndarray, mask: np.ndarray) -> np.ndarray:
        if mask.all():
            return values
        full = np.zeros((len(mask), *np.shape(values)[1:]), dtype=np.asarray(values).dtype)
        full[rows] = values
        return full

    def close_extras(self, **kwargs: Any) -> None:
        self.template.close()


@compiled
def _record_step(
    rows: np.ndarray,
    arriving: np.ndarray,
    outage: np.ndarray,
    arrived: np.ndarray,
    step_counts: np.ndarray,
    arrival_step: np.ndarray,
    outage_steps: np.ndarray,
    max_episode_steps: int,
) -> tuple[np.ndarray, np.ndarray]:
    """
    The bookkeeping of a step of the missions ``rows`` (the single env's, in one compiled loop): count the
    step, record the arrivals (``arriving``, (rows, U)) and their step, add the outages; in place on the
    (N, ...) state arrays. Returns whether each stepped mission terminated (all robots arrived) and
    reached ``max_episode_steps``.
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
                arrival_step[i, u] = step_counts[i]
            outage_steps[i, u] += outage[k, u]
            all_arrived &= arrived[i, u]
        terminated[k] = all_arrived
        truncated[k] = step_counts[i] >= max_episode_steps
    return terminated, truncated


def make_vec_env(num_envs: int = 1, **kwargs: Any) -> gym.vector.VectorEnv:
    """
    The ``vector_entry_point`` of the registered ids: :class:`NomaRadioMapVecEnv` (``gymnasium.make_vec``
    passes the id's kwargs and ``num_envs``).

    :param num_envs: number of missions
    :param kwargs: the arguments of :class:`NomaRadioMapVecEnv`
    """
    return NomaRadioMapVecEnv(num_envs=num_envs, **kwargs)
