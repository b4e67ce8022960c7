"""Registration of the environment ids with Gymnasium (docs/ARCHITECTURE.md).

:func:`register_envs` runs when :mod:`noma_radiomap` is imported and is idempotent, so importing the package
again, or Gymnasium importing it for an id written ``"noma_radiomap:NomaRadioMap-v0"`` (e.g. in a
``SubprocVecEnv`` worker started with ``spawn``), is harmless.

Episodes are truncated at the scenario's ``mission.max_steps``, by the env itself and by Gymnasium's ``TimeLimit``
at the same step: the entry point :func:`make_env` builds the env and wraps it in a ``TimeLimit`` of its own
scenario's length, so
``gymnasium.make("NomaRadioMap-v0", scenario="small").spec.max_episode_steps`` is ``small``'s 60 and the
default ``mall`` gives 300 (the paper's task: 1000). ``gymnasium.make(..., max_episode_steps=n)`` adds a shorter
limit on top: the env cannot see it, so every ``info`` of the single env carries the episode summary as of that
step (``mqi``, ``is_success``, ...), and the last one of an episode has it whatever limit ends the episode. A
longer one does not lengthen the missions: they still end at ``mission.max_steps`` (the env's own limit), while
``spec.max_episode_steps`` reports the longer one (Gymnasium's wrapper; the entry point never sees it).

``gymnasium.make_vec(env_id, num_envs=N)`` builds the batched :class:`~noma_radiomap.vector.NomaRadioMapVecEnv`
(the ids' ``vector_entry_point``; its truncation: its ``max_episode_steps`` kwarg); ``vectorization_mode="sync"``
gives Gymnasium's ``SyncVectorEnv`` of single envs.
"""

from typing import Any

import gymnasium as gym
from gymnasium.wrappers import TimeLimit

from noma_radiomap.env import NomaRadioMapEnv
from noma_radiomap.observations import OBSERVATIONS as _LAYOUTS
from noma_radiomap.observations import check_observation
from noma_radiomap.wrappers import PowerShares

__all__ = [
    "ENV_IDS",
    "OBSERVATIONS",
    "POWER_MAPPINGS",
    "check_observation",
    "check_power_mapping",
    "default_scenario",
    "make_env",
    "register_envs",
]

ENTRY_POINT = "noma_radiomap.registration:make_env"
VECTOR_ENTRY_POINT = "noma_radiomap.vector:make_vec_env"

#: The registered ids and their default kwargs (any kwarg can still be overridden through ``gymnasium.make``).
ENV_IDS: dict[str, dict[str, str]] = {
    "NomaRadioMap-v0": {"multiple_access": "noma", "channel": "radio_map"},
    "NomaRadioMapOMA-v0": {"multiple_access": "oma", "channel": "radio_map"},
    "NomaRadioMapReality-v0": {"multiple_access": "noma", "channel": "rayleigh"},
    "NomaRadioMapOMAReality-v0": {"multiple_access": "oma", "channel": "rayleigh"},
    # The paper's task (docs/MODEL.md): fixed destinations, the paper's state Eq. (24), 1000-step episodes
    "NomaRadioMapPaper-v0": {"multiple_access": "noma", "channel": "radio_map", "task": "paper"},
    "NomaRadioMapPaperOMA-v0": {"multiple_access": "oma", "channel": "radio_map", "task": "paper"},
}

#: How the power actions become transmit powers: the env's own mapping (paper Eq. (15e)) or as shares of ``P_max``.
POWER_MAPPINGS: tuple[str, ...] = ("paper", "shares")

#: The observation layouts (:mod:`noma_radiomap.observations`), the default (``"goal"``) first.
OBSERVATIONS: tuple[str, ...] = tuple(_LAYOUTS)


def make_env(power_mapping: str = "paper", **kwargs: Any) -> gym.Env:
    """
    The entry point of the registered ids: :class:`NomaRadioMapEnv` in a ``TimeLimit`` of its scenario's
    ``mission.max_steps``.

    :param power_mapping: ``"paper"`` (the env's own mapping, paper Eq. (15e)) or ``"shares"`` (the power actions
        as shares of the whole ``P_max``: :class:`~noma_radiomap.wrappers.PowerShares` around the env)
    :param kwargs: the arguments of :class:`NomaRadioMapEnv` (``observation``: ``"goal"``, the default,
        ``"destinations"`` or ``"paper"``, :mod:`noma_radiomap.observations`; ``task``: ``"missions"`` or ``"paper"``)
    :return: the wrapped env
    """
    check_power_mapping(power_mapping)
    env: gym.Env = NomaRadioMapEnv(**kwargs)
    env = TimeLimit(env, max_episode_steps=env.max_steps)
    return PowerShares(env) if power_mapping == "shares" else env


def default_scenario(env_id: str) -> Any:
    """
    :param env_id: a registered env id
    :return: the scenario the id makes when ``gymnasium.make`` gets none: the one registered with it, else ``mall``
    """
    return gym.spec(env_id).kwargs.get("scenario", "mall")


def check_power_mapping(power_mapping: Any) -> str:
    """:return: ``power_mapping`` if it is one of :data:`POWER_MAPPINGS`; :raises ValueError: else, naming the value"""
    if power_mapping not in POWER_MAPPINGS:
        raise ValueError(f"power_mapping must be one of {list(POWER_MAPPINGS)}, got {power_mapping!r}")
    return str(power_mapping)


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
