"""Registration of the environment ids with Gymnasium (SPEC 2.10).

:func:`register_envs` runs when :mod:`noma_radiomap` is imported and is idempotent, so importing the package
again, or Gymnasium importing it for an id written ``"noma_radiomap:NomaRadioMap-v0"`` (e.g. in a
``SubprocVecEnv`` worker started with ``spawn``), is harmless.
"""

import gymnasium as gym

ENTRY_POINT = "noma_radiomap.env:NomaRadioMapEnv"

#: ``mission.max_steps`` of the default ``mall`` scenario: the ``TimeLimit`` of the registered ids (a test
#: checks that they agree; the env also truncates at its own scenario's ``mission.max_steps``).
MAX_EPISODE_STEPS = 300

#: The registered ids and their default kwargs (any kwarg can still be overridden through ``gymnasium.make``).
ENV_IDS: dict[str, dict[str, str]] = {
    "NomaRadioMap-v0": {"multiple_access": "noma", "channel": "radio_map"},
    "NomaRadioMapOMA-v0": {"multiple_access": "oma", "channel": "radio_map"},
    "NomaRadioMapReality-v0": {"multiple_access": "noma", "channel": "rayleigh"},
    "NomaRadioMapOMAReality-v0": {"multiple_access": "oma", "channel": "rayleigh"},
}


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS` (``mall`` scenario, ``"destination"`` reward phase) once."""
    for env_id, kwargs in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        gym.register(
            id=env_id,
            entry_point=ENTRY_POINT,
            max_episode_steps=MAX_EPISODE_STEPS,
            kwargs={"scenario": "mall", "reward_phase": "destination", **kwargs},
        )
