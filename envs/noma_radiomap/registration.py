"""Registration of the environment ids with Gymnasium (docs/ARCHITECTURE.md).

:func:`register_envs` runs when :mod:`noma_radiomap` is imported and is idempotent, so importing the package
again, or Gymnasium importing it for an id written ``"noma_radiomap:NomaRadioMap-v0"`` (e.g. in a
``SubprocVecEnv`` worker started with ``spawn``), is harmless.

Episodes are truncated only by Gymnasium's ``TimeLimit``, at the scenario's ``mission.max_steps``: the entry
point :func:`make_env` builds the env and wraps it in a ``TimeLimit`` of its own scenario's length, so
``gymnasium.make("NomaRadioMap-v0", scenario="small").spec.max_episode_steps`` is ``small``'s 60 and the
default ``mall`` gives 300. ``gymnasium.make(..., max_episode_steps=n)`` adds a shorter limit on top.

``gymnasium.make_vec(env_id, num_envs=N)`` builds the batched :class:`~noma_radiomap.vector.NomaRadioMapVecEnv`
(the ids' ``vector_entry_point``); ``vectorization_mode="sync"`` gives Gymnasium's ``SyncVectorEnv`` of single envs.
"""

from typing import Any

import gymnasium as gym
from gymnasium.wrappers import TimeLimit

from noma_radiomap.env import NomaRadioMapEnv

ENTRY_POINT = "noma_radiomap.registration:make_env"
VECTOR_ENTRY_POINT = "noma_radiomap.vector:make_vec_env"

#: The registered ids and their default kwargs (any kwarg can still be overridden through ``gymnasium.make``).
ENV_IDS: dict[str, dict[str, str]] = {
    "NomaRadioMap-v0": {"multiple_access": "noma", "channel": "radio_map"},
    "NomaRadioMapOMA-v0": {"multiple_access": "oma", "channel": "radio_map"},
    "NomaRadioMapReality-v0": {"multiple_access": "noma", "channel": "rayleigh"},
    "NomaRadioMapOMAReality-v0": {"multiple_access": "oma", "channel": "rayleigh"},
}


#: Observation layouts of :func:`make_env`: the paper's (the env's own) and the goal-conditioned extension.
OBSERVATIONS: tuple[str, ...] = ("paper", "goal")


def check_observation(observation: str) -> None:
    """:raises ValueError: ``observation`` is not one of :data:`OBSERVATIONS`"""
    if observation not in OBSERVATIONS:
        raise ValueError(f"observation must be one of {OBSERVATIONS}, got {observation!r}")


def make_env(observation: str = "paper", **kwargs: Any) -> gym.Env:
    """
    The entry point of the registered ids: :class:`NomaRadioMapEnv` in a ``TimeLimit`` of its scenario's
    ``mission.max_steps``.

    :param observation: ``"paper"`` (the paper's state, ``6U`` values) or ``"goal"`` (the goal-conditioned
        extension: :class:`noma_radiomap.wrappers.RelativeGoalObservation` adds each robot's direction and
        distance to its destination, ``9U`` values; docs/BENCHMARKS.md measures what it changes)
    :param kwargs: the arguments of :class:`NomaRadioMapEnv`
    :return: the wrapped env
    """
    check_observation(observation)
    env = NomaRadioMapEnv(**kwargs)
    wrapped: gym.Env = TimeLimit(env, max_episode_steps=env.max_steps)
    if observation == "goal":
        from noma_radiomap.wrappers import RelativeGoalObservation

        wrapped = RelativeGoalObservation(wrapped)
    return wrapped


# gymnasium.make reads the creator's render modes from here, as it does from an env class
make_env.metadata = NomaRadioMapEnv.metadata  # type: ignore[attr-defined]


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS` (``mall`` scenario, ``"destination"`` reward phase) once."""
    for env_id, kwargs in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point=ENTRY_POINT,
            vector_entry_point=VECTOR_ENTRY_POINT,
            kwargs={"scenario": "mall", "reward_phase": "destination", **kwargs},
        )
