"""The batched mission env for Stable-Baselines3: :class:`MissionVecEnv`, an SB3 ``VecEnv`` over
:class:`noma_radiomap.vector.NomaRadioMapVecEnv` (SB3 does not take Gymnasium vector envs).

It behaves as SB3's ``DummyVecEnv`` of N single envs (``gymnasium.make(env_id)``) seeded ``seed + i``, with
the same transitions, only faster: rewards (float32), dones, ``terminal_observation`` and
``TimeLimit.truncated`` in the infos, auto-reset on the step an episode ends, ``env_method`` / ``get_attr``
on each mission (``set_reward_phase``, ``reward_weights``, ...). :func:`make_mission_vec_env` is its
``make_vec_env``: it adds SB3's ``VecMonitor`` (``info["episode"]`` with ``r``, ``l``, ``t`` and
``is_success`` for the logger), as ``make_vec_env`` adds a ``Monitor`` to each env.
"""

import copy
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecMonitor
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvObs, VecEnvStepReturn

import noma_radiomap  # noqa: F401  (registers the ids)
from noma_radiomap.core import MissionStep
from noma_radiomap.vector import MissionView, NomaRadioMapVecEnv, check_num_envs


class MissionVecEnv(VecEnv):
    """
    N missions of the NOMA radio-map env as an SB3 ``VecEnv``, stepped at once (:class:`NomaRadioMapVecEnv`).

    :param num_envs: number of missions N
    :param env_kwargs: the keyword arguments of :class:`~noma_radiomap.NomaRadioMapEnv` (``scenario``,
        ``multiple_access``, ``channel``, ``reward_phase``, ``inducing``, ``observation``, ``task``) and
        ``max_episode_steps``
    """

    def __init__(self, num_envs: int = 1, **env_kwargs: Any) -> None:
        self.vec_env = NomaRadioMapVecEnv(num_envs=num_envs, **env_kwargs)
        super().__init__(num_envs, self.vec_env.single_observation_space, self.vec_env.single_action_space)
        self._actions: np.ndarray | None = None
        self._clear_next_reset()

    @classmethod
    def from_id(cls, env_id: str, num_envs: int = 1, **kwargs: Any) -> "MissionVecEnv":
        """
        The vector env of a registered mission id with the id's kwargs (e.g. ``NomaRadioMapOMAReality-v0``).

        :param env_id: a registered id of :mod:`noma_radiomap`
        :param num_envs: number of missions
        :param kwargs: overrides of the id's kwargs
        """
        spec = gym.spec(env_id)
        if spec.vector_entry_point != "noma_radiomap.vector:make_vec_env":
            raise ValueError(f"env_id: {env_id!r} is not a mission id of noma_radiomap")
        return cls(num_envs, **{**spec.kwargs, **kwargs})

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """
        Seed the missions at the next :meth:`reset`: mission ``i`` gets ``seed + i``, as SB3's ``VecEnv.seed``.

        :param seed: seed of mission 0 (None: drawn from NumPy's global generator, as SB3 draws it)
        :return: the seed of each mission
        """
        if seed is None:
            seed = int(np.random.randint(0, np.iinfo(np.uint32).max, dtype=np.uint32))
        elif isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:  # failed at the next reset
            raise ValueError(f"seed must be an integer >= 0 or None, got {seed!r}")
        self._next_seeds = [int(seed) + i for i in range(self.num_envs)]
        return list(self._next_seeds)

    def set_options(self, options: list[dict] | dict | None = None) -> None:
        """
        Reset options of the missions at the next :meth:`reset`, as SB3's ``VecEnv.set_options``.

        :param options: the single env's reset options (``starts``, ``destinations``), one dict for every mission
            or one per mission (copied); None: none
        """
        if options is None or isinstance(options, dict):
            options = [options or {}] * self.num_envs
        self._next_options = copy.deepcopy(list(options))

    def _clear_next_reset(self) -> None:
        # The seeds and options of :meth:`seed` / :meth:`set_options` serve one reset, as in SB3; they are kept
        # here rather than in SB3's private attributes.
        self._next_seeds: list[int | None] = [None] * self.num_envs
        self._next_options: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]

    def reset(self) -> VecEnvObs:
        seeds, options = self._next_seeds, [opt or None for opt in self._next_options]
        self._clear_next_reset()  # they serve this reset, also one that refuses them (the next reset draws anew)
        self.vec_env.reset_missions(np.arange(self.num_envs), seeds, options)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return self.vec_env.observations()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        vec = self.vec_env
        result = vec.step_missions(self._actions, slice(None))
        obs = vec.observations()
        dones = result.terminated | result.truncated
        infos = step_infos(result)
        if dones.any():
            ended = np.flatnonzero(dones)
            for k in ended:
                infos[k]["terminal_observation"] = obs[k]
            vec.reset_missions(ended)
            obs = obs.copy()
            obs[ended] = vec.observations(ended)
        return obs, result.reward.astype(np.float32), dones, infos

    def close(self) -> None:
        self.vec_env.close()

    def _views(self, indices: VecEnvIndices) -> list[MissionView]:
        return self.vec_env.missions(indices)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(view, attr_name) for view in self._views(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        if attr_name != "reward_phase":
            raise AttributeError(f"set_attr: only 'reward_phase' can be set on the mission vector env, got {attr_name!r}")
        self.vec_env.set_reward_phase(value, indices=indices)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        return [getattr(view, method_name)(*method_args, **method_kwargs) for view in self._views(indices)]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._views(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        raise NotImplementedError("the mission vector env does not render; render a single env (gymnasium.make)")


def step_infos(result: MissionStep) -> list[dict[str, Any]]:
    """
    The ``info`` of each stepped mission as a ``DummyVecEnv`` of single envs gives it: the single env's ``info``
    (:meth:`noma_radiomap.core.MissionStep.info`) and SB3's ``TimeLimit.truncated``.

    :param result: the outcome of a step of the missions
    :return: one dict per stepped mission, in row order
    """
    time_limit = (result.truncated & ~result.terminated).tolist()
    infos = result.infos()
    for info, truncated in zip(infos, time_limit, strict=True):
        info["TimeLimit.truncated"] = truncated
    return infos


def make_mission_vec_env(
    env_id: str = "NomaRadioMap-v0",
    n_envs: int = 1,
    seed: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
    monitor: bool = True,
) -> VecEnv:
    """
    SB3's ``make_vec_env`` for the mission ids, batched: a :class:`MissionVecEnv` of ``n_envs`` missions,
    seeded ``seed + i``, in a ``VecMonitor`` (episode returns, lengths and ``is_success`` for SB3's logger).

    :param env_id: a registered mission id
    :param n_envs: number of missions
    :param seed: seed of mission 0 (mission i gets ``seed + i``); None: random
    :param env_kwargs: overrides of the id's kwargs (``scenario``, ``reward_phase``, ...)
    :param monitor: wrap in ``VecMonitor``
    :return: the vector env
    """
    check_num_envs(n_envs, "n_envs")
    env: VecEnv = MissionVecEnv.from_id(env_id, n_envs, **(env_kwargs or {}))
    if seed is not None:
        env.seed(seed)
    if monitor:
        env = VecMonitor(env, info_keywords=("is_success",))
    return env
