"""N missions stepped at once: :class:`NomaRadioMapVecEnv`, the Gymnasium vector env of the mission ids
(docs/ARCHITECTURE.md, vector env).

It drives the mission engine :class:`noma_radiomap.core.MissionCore` with N missions, the engine the single
env drives with one, so mission ``i`` of a vector env whose missions are seeded ``seed + i`` makes exactly the
transitions of a single env seeded ``seed + i``. Each mission keeps its own random generator (the starts and
destinations of its resets, its Rayleigh fading).
"""

import os
import reprlib
from collections.abc import Mapping
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from noma_radiomap import rewards
from noma_radiomap.actions import check_actions
from noma_radiomap.core import INFO_KEYS, SUMMARY_KEYS, MissionCore, MissionStep, summary_row
from noma_radiomap.env import NomaRadioMapEnv
from noma_radiomap.observations import observation_space
from noma_radiomap.scenario import Scenario

__all__ = ["MissionView", "NomaRadioMapVecEnv", "check_num_envs", "make_vec_env"]


#: The attributes of a mission that are the same for every mission: those of the vector env's engine
#: (:class:`~noma_radiomap.core.MissionCore`) ...
_SHARED_ATTRIBUTES: tuple[str, ...] = (
    "scenario",
    "radio_map",
    "multiple_access",
    "channel",
    "inducing",
    "task",
    "observation",
    "n_robots",
    "max_steps",
    "max_episode_steps",
    "reward_constants",
    "motion",
)
#: ... and the constants of the env class
_CLASS_CONSTANTS: tuple[str, ...] = ("REWARD_PHASES", "REWARD_COMPONENTS", "GAIN_DB_RANGE")
#: What to use instead of the single env's attributes that a mission of the vector env does not have
_INSTEAD: dict[str, str] = {
    "trajectory": "the vector env keeps no trajectories: record get_attr('positions') after each step, or use a "
    "single env (gymnasium.make)",
    "render": "the vector env does not render: render a single env (gymnasium.make(..., render_mode='rgb_array'))",
    "reset": "reset the vector env (options={'reset_mask': ...} resets some missions)",
    "step": "step the vector env",
    "close": "close the vector env",
    "core": "the vector env's engine is vec_env.core (every mission)",
}


class MissionView:
    """
    One mission of a vector env, seen as a single env by ``env_method`` / ``get_attr`` / ``call``:
    ``set_reward_phase``, ``reward_weights``, ``reward_phase``, ``episode_summary``, the mission state
    (``positions``, ``destinations``, ``arrived``, ``step_count``, ``np_random``), the spaces, ``render_mode``
    (None), the attributes shared by every mission (``scenario``, ``radio_map``, ... :data:`_SHARED_ATTRIBUTES`)
    and the env's constants (``REWARD_PHASES``, ...). Any other name, the single env's ``trajectory``, ``render``,
    ``reset``, ``step`` included, raises an ``AttributeError`` naming it and what to use instead (so SB3's
    ``has_attr`` says False).

    :param vec_env: the vector env
    :param index: the mission's index
    """

    def __init__(self, vec_env: "NomaRadioMapVecEnv", index: int) -> None:
        self.vec_env, self.index = vec_env, index

    def set_reward_phase(self, name: str) -> None:
        self.vec_env.set_reward_phase(name, indices=[self.index])

    def reward_weights(self, phase: str | None = None) -> dict[str, float]:
        return rewards.phase_weights(self.reward_phase if phase is None else phase)

    @property
    def reward_phase(self) -> str:
        return self.vec_env.core.reward_phases[self.index]

    def episode_summary(self) -> dict[str, Any]:
        return summary_row(self.vec_env.core.episode_summaries(np.array([self.index])), 0)

    @property
    def positions(self) -> np.ndarray:
        return self.vec_env.core.positions[self.index].copy()

    @property
    def destinations(self) -> np.ndarray:
        return self.vec_env.core.destinations[self.index].copy()

    @property
    def arrived(self) -> np.ndarray:
        return self.vec_env.core.arrived[self.index].copy()

    @property
    def step_count(self) -> int:
        return int(self.vec_env.core.step_counts[self.index])

    @property
    def np_random(self) -> np.random.Generator:
        return self.vec_env.core.np_randoms[self.index]

    @property
    def observation_space(self) -> gym.spaces.Box:
        return self.vec_env.single_observation_space

    @property
    def action_space(self) -> gym.spaces.Box:
        return self.vec_env.single_action_space

    @property
    def render_mode(self) -> None:
        return None

    def __getattr__(self, name: str) -> Any:
        # Called for the names the class does not define: the shared attributes and the env's constants
        if name in _SHARED_ATTRIBUTES:
            return getattr(self.vec_env.core, name)
        if name in _CLASS_CONSTANTS:
            return getattr(NomaRadioMapEnv, name)
        if name.startswith("_"):
            raise AttributeError(name)
        hint = _INSTEAD.get(name, f"a mission has {', '.join(_mission_attributes())}")
        raise AttributeError(f"{name!r}: not an attribute of a mission of the vector env; {hint}")


def _mission_attributes() -> list[str]:
    """The public names a :class:`MissionView` answers, sorted."""
    own = [name for name in vars(MissionView) if not name.startswith("_")]
    return sorted({*own, *_SHARED_ATTRIBUTES, *_CLASS_CONSTANTS})


def check_num_envs(value: Any, name: str = "num_envs") -> None:
    """:raises ValueError: ``value`` is not an integer >= 1 (a number of missions), naming ``name`` and the value"""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")


class NomaRadioMapVecEnv(VectorEnv):
    """
    ``num_envs`` missions of :class:`~noma_radiomap.NomaRadioMapEnv` stepped at once with array operations
    over (N, U): the ``vector_entry_point`` of the registered ids, so
    ``gymnasium.make_vec("NomaRadioMap-v0", num_envs=8)`` builds it. For Stable-Baselines3, use
    :func:`sb3_dtdpg.vec_env.make_mission_vec_env` (an SB3 ``VecEnv`` over the same engine).

    Observations ``(N, values per robot x U)`` (the layout of ``observation``), actions ``(N, 3U)``, rewards,
    terminations and truncations ``(N,)``: those of the single env (see its docstring), truncated at
    ``max_episode_steps`` (default: the scenario's ``mission.max_steps``, as the registered ids' ``TimeLimit``).
    ``reset(seed=s)`` seeds mission ``i`` with ``s + i`` (or takes a list of seeds), like Gymnasium's
    ``SyncVectorEnv``; ``options`` (``starts``, ``destinations``, ``reset_mask``) apply to every reset mission.
    Autoreset follows Gymnasium's default ``AutoresetMode.NEXT_STEP``: the step after an episode ends resets that
    mission (reward 0, its action ignored). ``infos`` are Gymnasium's dict of arrays with ``_key`` masks: every key
    of the single env's ``info`` (``reward_components`` a dict of (N,) arrays), and ``is_success``, ``mqi``,
    ``mission_time``, ``outage_steps`` (the episode summary as of the step, as the single env gives it). Stepping or
    summarising a mission before its first reset raises Gymnasium's ``ResetNeeded``.

    ``set_reward_phase(name, indices=None)``, ``reward_weights(phase=None)``, ``call(name, ...)`` and
    ``get_attr(name)`` reach every mission (:class:`MissionView`) as ``SyncVectorEnv`` reaches its envs.

    :param num_envs: number of missions N
    :param scenario: see :class:`~noma_radiomap.NomaRadioMapEnv` (also ``multiple_access``, ``channel``,
        ``reward_phase``, ``inducing``)
    :param max_episode_steps: truncation length (None: the scenario's ``mission.max_steps``; at most that, a larger
        one is refused)
    :param render_mode: only None (render a single env to see a mission)
    :param observation: the observation layout (:mod:`noma_radiomap.observations`; None: ``"goal"``, or
        ``"paper"`` with ``task="paper"``)
    :param task: ``"missions"`` or ``"paper"`` (see :class:`~noma_radiomap.NomaRadioMapEnv`)
    :param power_mapping: only ``"paper"``, the env's own (``"shares"`` wraps the single env:
        :class:`~noma_radiomap.wrappers.PowerShares`)
    """

    metadata: ClassVar[dict[str, Any]] = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    REWARD_PHASES: ClassVar[tuple[str, ...]] = rewards.REWARD_PHASES
    REWARD_COMPONENTS: ClassVar[tuple[str, ...]] = rewards.REWARD_COMPONENTS

    def __init__(
        self,
        num_envs: int = 1,
        scenario: str | os.PathLike[str] | Scenario = "mall",
        multiple_access: str = "noma",
        channel: str = "radio_map",
        reward_phase: str = "destination",
        inducing: str = "euclidean",
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        observation: str | None = None,
        task: str = "missions",
        power_mapping: str = "paper",
    ) -> None:
        if power_mapping != "paper":
            raise ValueError(
                f"power_mapping={power_mapping!r}: the batched env has the paper's mapping only ('shares' wraps the "
                "single env, noma_radiomap.wrappers.PowerShares); use gymnasium.make_vec(..., vectorization_mode='sync') "
                "or one env"
            )
        check_num_envs(num_envs)
        if render_mode is not None:
            raise ValueError(f"render_mode: the vector env does not render (use a single env), got {render_mode!r}")
        #: The mission engine, N missions (:class:`noma_radiomap.core.MissionCore`)
        self.core = MissionCore(
            int(num_envs), scenario, multiple_access, channel, reward_phase, inducing, observation, task, max_episode_steps
        )
        core = self.core
        self.num_envs = int(num_envs)
        self.render_mode = None
        self.observation = core.observation
        self.n_robots = core.n_robots
        self.max_steps = core.max_steps
        self.max_episode_steps = core.max_episode_steps
        self.single_observation_space = observation_space(self.observation, self.n_robots)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (3 * self.n_robots,), dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._rows_all = np.arange(self.num_envs)

    # --- reward phases and per-mission access -----------------------------------------------------
    @property
    def reward_phases(self) -> list[str]:
        """The reward phase of each mission."""
        return list(self.core.reward_phases)

    def set_reward_phase(self, name: str, indices: Any = None) -> None:
        """
        Switch the reward phase of some missions (takes effect from their next step).

        :param name: one of :attr:`REWARD_PHASES`
        :param indices: the missions (None: all; an index or a sequence of indices in ``[0, num_envs)``)
        """
        self.core.set_reward_phase(name, self._rows(indices))

    def reward_weights(self, phase: str | None = None) -> dict[str, float]:
        """
        Weights of the reward components (see :meth:`NomaRadioMapEnv.reward_weights`).

        :param phase: a reward phase; None: mission 0's current one
        """
        return rewards.phase_weights(self.core.reward_phases[0] if phase is None else phase)

    def mission(self, index: int) -> MissionView:
        """One mission as a single env (:class:`MissionView`)."""
        if not 0 <= int(index) < self.num_envs:
            raise IndexError(f"mission index must be in [0, {self.num_envs}), got {index!r}")
        return MissionView(self, int(index))

    def missions(self, indices: Any = None) -> list[MissionView]:
        """
        Some missions as single envs (:class:`MissionView`).

        :param indices: None (every mission), an index or a sequence of indices
        """
        return [self.mission(i) for i in self._rows(indices)]

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        results = []
        for i in range(self.num_envs):
            attr = getattr(self.mission(i), name)
            results.append(attr(*args, **kwargs) if callable(attr) else attr)
        return tuple(results)

    def get_attr(self, name: str) -> tuple[Any, ...]:
        return tuple(getattr(self.mission(i), name) for i in range(self.num_envs))

    def _rows(self, indices: Any) -> list[int]:
        """
        :param indices: None (every mission), an index or a sequence of indices
        :return: the mission indices
        :raises IndexError: an index is not an integer in ``[0, num_envs)`` (a negative one too), naming it
        """
        if indices is None:
            return list(range(self.num_envs))
        items = [indices] if isinstance(indices, int | np.integer) else indices
        try:
            items = list(items)
        except TypeError:
            raise IndexError(
                f"indices: expected None, a mission index or a sequence of them, got {reprlib.repr(indices)}"
            ) from None
        for i in items:
            if isinstance(i, bool) or not isinstance(i, int | np.integer) or not 0 <= i < self.num_envs:
                raise IndexError(f"indices: mission indices must be integers in [0, {self.num_envs}), got {reprlib.repr(i)}")
        return [int(i) for i in items]

    # --- the batched engine (also driven by the SB3 face) ----------------------------------------
    @property
    def positions(self) -> np.ndarray:
        """Robot positions of every mission, (N, U, 2) (read-only view of the engine's state)."""
        return self.core.positions

    @property
    def destinations(self) -> np.ndarray:
        """Destinations of every mission, (N, U, 2)."""
        return self.core.destinations

    @property
    def arrived(self) -> np.ndarray:
        """Arrived flags of every mission, (N, U)."""
        return self.core.arrived

    @property
    def step_counts(self) -> np.ndarray:
        """Steps since each mission's last reset, (N,)."""
        return self.core.step_counts

    @property
    def np_randoms(self) -> list[np.random.Generator]:
        """Each mission's generator."""
        return self.core.np_randoms

    def reset_missions(
        self, rows: np.ndarray, seeds: list[int | None] | None = None, options: dict | list[dict | None] | None = None
    ) -> None:
        """
        Reset some missions: as :meth:`NomaRadioMapEnv.reset` on each, with its own generator.

        :param rows: the missions to reset
        :param seeds: a seed per row (None entries keep the generator going)
        :param options: the single env's reset options, for every row or one per row
        """
        self.core.reset(rows, seeds, options)

    def step_missions(self, actions: np.ndarray, rows: np.ndarray | slice) -> MissionStep:
        """
        One step of some missions (:meth:`noma_radiomap.core.MissionCore.step`).

        :param actions: actions of the stepped rows, (len(rows), 3U) (:func:`~noma_radiomap.actions.check_actions`:
            a wrong shape or a non-finite component raises a ValueError before anything changes)
        :param rows: the missions to step (a slice for all)
        :return: the step's outcome
        :raises ResetNeeded: a stepped mission was never reset
        """
        self.core.check_reset(rows)
        return self.core.step(check_actions(actions, self._rows_all[rows], self.n_robots), rows)

    def observations(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """The observations of some missions, float32 (rows, values per robot x U)."""
        return self.core.observations(rows)

    def episode_summaries(self, rows: np.ndarray) -> dict[str, np.ndarray]:
        """:meth:`NomaRadioMapEnv.episode_summary` of some missions, as arrays over the rows."""
        return self.core.episode_summaries(rows)

    # --- Gymnasium VectorEnv API -----------------------------------------------------------------
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict]:
        """
        Reset every mission, or those of ``options["reset_mask"]`` (a bool per mission). Everything is checked
        before any mission changes: a refused seed, mask or option raises a ``ValueError`` naming it and leaves every
        mission as it was.
        """
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"options: expected a dict of reset options (or None), got {type(options).__name__}")
        options = dict(options or {})
        rows = self._reset_rows(options.pop("reset_mask", None))
        seeds = self._reset_seeds(seed, rows)
        self.core.reset(rows, seeds, options or None)
        self._autoreset[rows] = False
        return self.core.observations(), {}

    def _reset_rows(self, mask: Any) -> np.ndarray:
        """:return: the missions a reset mask selects (None: all); :raises ValueError: not one bool per mission"""
        n = self.num_envs
        if mask is None:
            return np.arange(n)
        try:
            array = np.asarray(mask)
        except (TypeError, ValueError):  # a ragged sequence
            raise ValueError(
                f"options['reset_mask']: expected {n} booleans (one per mission), got a ragged sequence"
            ) from None
        if array.shape != (n,):
            raise ValueError(f"options['reset_mask']: expected {n} booleans (one per mission), got shape {array.shape}")
        if array.dtype != np.bool_:
            raise ValueError(f"options['reset_mask']: expected booleans (dtype bool), got dtype {array.dtype}")
        return np.flatnonzero(array)

    def _reset_seeds(self, seed: Any, rows: np.ndarray) -> list[int | None]:
        """:return: the seed of each reset mission; :raises ValueError: ``seed`` is not an integer (or None), nor
        one per mission"""
        if seed is None:
            return [None] * len(rows)
        if _is_seed(seed):
            return [int(seed) + int(i) for i in rows]
        if not isinstance(seed, list | tuple | np.ndarray):
            raise ValueError(
                f"seed: expected an integer >= 0, a list of {self.num_envs} (one per mission) or None, "
                f"got {reprlib.repr(seed)}"
            )
        if len(seed) != self.num_envs:
            raise ValueError(f"seed: expected {self.num_envs} seeds (one per mission), got {len(seed)}")
        for i, value in enumerate(seed):
            if value is not None and not _is_seed(value):
                raise ValueError(f"seed[{i}]: expected an integer >= 0 or None, got {reprlib.repr(value)}")
        return [None if seed[i] is None else int(seed[i]) for i in rows]

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        self.core.check_reset()
        resetting = self._autoreset.copy()
        stepping: np.ndarray | slice = slice(None)
        if resetting.any():  # the whole batch is checked, as at any step, before the stepped rows are taken from it
            stepping = np.flatnonzero(~resetting)
            checked = check_actions(actions, self._rows_all, self.n_robots)  # (N, U, 3)
            actions = checked[stepping].reshape(len(stepping), 3 * self.n_robots)
        n = self.num_envs
        reward = np.zeros(n)
        terminated = np.zeros(n, dtype=bool)
        truncated = np.zeros(n, dtype=bool)
        infos: dict[str, Any] = {}
        if not resetting.all():
            self._step_infos(self.step_missions(actions, stepping), reward, terminated, truncated, infos)
        if resetting.any():
            self.core.reset(np.flatnonzero(resetting))
        self._autoreset = terminated | truncated
        return self.core.observations(), reward, terminated, truncated, infos

    def _step_infos(
        self, result: MissionStep, reward: np.ndarray, terminated: np.ndarray, truncated: np.ndarray, infos: dict[str, Any]
    ) -> None:
        """Scatter a step's outcome into the (N,) arrays and Gymnasium's masked infos."""
        n, rows = self.num_envs, result.rows
        reward[rows], terminated[rows], truncated[rows] = result.reward, result.terminated, result.truncated
        mask = np.zeros(n, dtype=bool)
        mask[rows] = True
        components = {}
        for key, value in result.components.items():
            components[key], components[f"_{key}"] = _full(value, rows, mask), mask
        infos["reward_components"] = components
        infos["_reward_components"] = mask
        for key in INFO_KEYS:
            infos[key], infos[f"_{key}"] = _full(getattr(result, key), rows, mask), mask
        for key in SUMMARY_KEYS:
            infos[key], infos[f"_{key}"] = _full(result.summary[key], rows, mask), mask

    def close_extras(self, **kwargs: Any) -> None:
        pass


def _is_seed(value: Any) -> bool:
    """Whether ``value`` is a seed: an integer >= 0, not a bool."""
    return not isinstance(value, bool) and isinstance(value, int | np.integer) and value >= 0


def _full(values: np.ndarray, rows: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``values`` of the rows ``rows`` scattered into an array over all missions (zeros elsewhere)."""
    if mask.all():
        return values
    full = np.zeros((len(mask), *np.shape(values)[1:]), dtype=np.asarray(values).dtype)
    full[rows] = values
    return full


def make_vec_env(num_envs: int = 1, **kwargs: Any) -> gym.vector.VectorEnv:
    """
    The ``vector_entry_point`` of the registered ids: :class:`NomaRadioMapVecEnv` (``gymnasium.make_vec``
    passes the id's kwargs and ``num_envs``).

    :param num_envs: number of missions
    :param kwargs: the arguments of :class:`NomaRadioMapVecEnv`
    """
    return NomaRadioMapVecEnv(num_envs=num_envs, **kwargs)
