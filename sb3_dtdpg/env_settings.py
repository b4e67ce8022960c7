"""The mission-env settings a model was trained with, saved with it and checked when it meets an env again.

A policy trained on one observation layout or downlink mode means nothing on another, and two layouts of
the same length (NOMA and OMA) would load silently. :func:`settings_of` reads the settings of a mission env
(:data:`SETTINGS`: scenario, observation, multiple_access, channel, task, power_mapping); a model stores them in its
``env_settings`` attribute, which SB3's ``save`` writes into the zip like any other attribute (``DTDPG.save``
fills it in; :func:`record` does it for any SB3 model). :func:`check_settings` refuses an env whose settings
differ, naming the ``gymnasium.make`` keyword arguments to use.

The scenario is recorded by its name, a digest of its content (:func:`scenario_digest`) and, for a scenario read
from a YAML file other than the built-in of its name, the file's absolute path: two rooms of one name are told
apart by their digests (a model saved before the digest was recorded is checked by the name alone).

The training channel is recorded but not checked: a model trained on the radio map is tested with Rayleigh
fading (the paper's protocol). Envs that are not mission envs have no settings and are never refused here.

The envs of a ``VecEnv`` that keeps them in other processes (SB3's ``SubprocVecEnv``) are read where they live:
:func:`settings_of` runs there on the first env, wrappers and all (:class:`_ReadSettings`), and gives what it gives
for the same env in a ``DummyVecEnv``. Where that cannot be done (a closed ``VecEnv``, an env without a Gymnasium
wrapper) it warns, once per ``VecEnv`` class and reason.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import warnings
from collections.abc import Iterator, Mapping
from typing import Any

__all__ = [
    "CHECKED",
    "RETIRED_BUILTINS",
    "SETTINGS",
    "EnvSettingsMismatch",
    "builtin_scenario_digest",
    "check_settings",
    "describe_scenario",
    "infer_observation",
    "record",
    "scenario_digest",
    "settings_of",
    "split_observation",
    "trained_settings",
]

#: What is recorded (``scenario_digest``: :func:`scenario_digest` of the scenario; ``scenario_file``: the absolute path
#: of the YAML file it was read from where it is not the built-in scenario of its name, else None).
SETTINGS: tuple[str, ...] = (
    "scenario",
    "observation",
    "multiple_access",
    "channel",
    "task",
    "power_mapping",
    "scenario_digest",
    "scenario_file",
)
#: What must match for a model to be used on an env (the channel may differ: train on the map, test with fading; a
#: model saved before ``power_mapping`` was recorded is not checked for it). The scenario is compared by its digest
#: where both sides have one, else by its name.
CHECKED: tuple[str, ...] = ("scenario", "observation", "multiple_access", "task", "power_mapping")


#: Joins a recorded observation layout and the wrapper that extends it (a layout no ``gymnasium.make`` keyword builds).
WRAPPED_MARK = "+"
#: Settings left out of a suggested ``gymnasium.make`` call at these values (the defaults).
_DEFAULTS: dict[str, Any] = {"power_mapping": "paper"}


class EnvSettingsMismatch(ValueError):
    """A model meets an env built with other settings than it was trained with."""


def _inner_vec_env(env: Any) -> Any:
    """The ``VecEnv`` behind SB3's ``VecEnvWrapper`` layers (VecNormalize, VecMonitor, ...), or ``env`` itself."""
    while hasattr(env, "venv"):
        env = env.venv
    return env


def _single_env(env: Any) -> Any:
    """The first single env behind an SB3 ``VecEnv`` (and its wrappers), or ``env`` itself."""
    env = _inner_vec_env(env)
    if hasattr(env, "envs") and env.envs:  # DummyVecEnv
        return env.envs[0]
    return env


#: The attribute of a remote env's outermost layer that :class:`_ReadSettings` leaves its reading in.
_READING = "_sb3_dtdpg_env_settings"
#: The (VecEnv class, reason) pairs :func:`_remote_settings` has warned of.
_WARNED: set[tuple[str, str]] = set()


def _remote_vec_env(env: Any) -> Any:
    """The SB3 ``VecEnv`` behind ``env`` (and its ``VecEnvWrapper``) whose envs live elsewhere, else None."""
    env = _inner_vec_env(env)
    if getattr(env, "envs", None) or hasattr(env, "vec_env"):  # DummyVecEnv, MissionVecEnv: read here
        return None
    remote = all(callable(getattr(env, name, None)) for name in ("env_is_wrapped", "get_attr", "set_attr"))
    return env if remote else None


class _ReadSettings(type):
    """
    The metaclass of :class:`_SettingsProbe`, which :func:`_remote_settings` hands to a ``VecEnv``'s
    ``env_is_wrapped``: where the env lives, the ``VecEnv`` asks whether each of its wrapper layers, outermost first,
    is an instance of it (SB3's ``is_wrapped``). SB3 calls no function of ours on the env itself (``env_method`` only
    calls the env's own methods, ``get_attr`` would pickle a whole env for a bound method such as an
    ``ObservationWrapper``'s ``observation``), so the first question runs :func:`settings_of` on the outermost
    layer, leaves the result in its :data:`_READING` attribute for ``get_attr`` and ends the search.
    """

    def __instancecheck__(cls, layer: Any) -> bool:
        try:
            reading: tuple[str, Any] = ("read", settings_of(layer))
        except Exception as error:  # an exception here would end SB3's worker process
            reading = ("failed", f"{type(error).__name__}: {error}")
        try:
            setattr(layer, _READING, reading)
        except Exception:
            return False
        return True


class _SettingsProbe(metaclass=_ReadSettings):
    """What a remote env is asked whether it is wrapped with, to read its settings (:class:`_ReadSettings`)."""


def _remote_settings(venv: Any) -> dict[str, Any] | None:
    """The settings of the first env of a ``VecEnv`` whose envs live in other processes (:class:`_ReadSettings`)."""
    if getattr(venv, "closed", False):
        reason = "it is closed"
    elif getattr(venv, "waiting", False):
        reason = "it is waiting for a step"
    else:
        try:
            venv.set_attr(_READING, None, indices=[0])  # get_attr below finds it even where nothing reads
            venv.env_is_wrapped(_SettingsProbe, indices=[0])
            reading = venv.get_attr(_READING, indices=[0])[0]
        except Exception as error:  # a VecEnv of other ways: warned of below
            reading = ("failed", f"{type(error).__name__}: {error}")
        if isinstance(reading, tuple) and reading[0] == "read":
            return reading[1]
        reason = reading[1] if isinstance(reading, tuple) else "its first env has no Gymnasium wrapper to ask"
        if reading is None and not _is_mission_env(venv):
            return None  # a bare env of another kind: no settings to miss
    key = (type(venv).__name__, reason)
    if key not in _WARNED:
        _WARNED.add(key)
        warnings.warn(
            f"the mission-env settings of the first env of this {key[0]} cannot be read ({reason}): they are neither "
            "recorded in a model saved with it nor checked against the settings a model was trained with",
            stacklevel=3,
        )
    return None


def _is_mission_env(venv: Any) -> bool:
    """Whether the remote first env has a mission env's attributes (True where that cannot be told)."""
    try:
        return bool(venv.has_attr("scenario") and venv.has_attr("multiple_access"))
    except Exception:
        return True


def _layers(env: Any) -> Iterator[Any]:
    """The env and every env behind it, outermost first (Gymnasium wrappers' ``env``, the SB3 face's ``vec_env``)."""
    layer = env
    while layer is not None:
        yield layer
        layer = getattr(layer, "env", None) or getattr(layer, "vec_env", None)


def _observation_of(env: Any) -> str | None:
    """
    The layout an agent sees: the env's own; behind a ``RelativeGoalObservation`` wrapper ``goal`` where the wrapper
    makes the ``goal`` layout of ``destinations`` (same values), else the inner layout and the wrapper, e.g.
    ``"paper+RelativeGoalObservation(distance_scale=10.0)"`` (:data:`WRAPPED_MARK`: no keyword builds it).
    """
    from noma_radiomap.observations import DISTANCE_SCALE
    from noma_radiomap.wrappers import RelativeGoalObservation

    for layer in _layers(env):
        if isinstance(layer, RelativeGoalObservation):
            inner = _observation_of(layer.env)
            if inner == "destinations" and layer.distance_scale == DISTANCE_SCALE:
                return "goal"
            return f"{inner}{WRAPPED_MARK}RelativeGoalObservation(distance_scale={layer.distance_scale!r})"
        if isinstance(getattr(layer, "observation", None), str):  # the envs and the batched envs say it themselves
            return layer.observation
    return None


def _power_mapping_of(env: Any) -> str:
    """``"shares"`` behind a :class:`~noma_radiomap.wrappers.PowerShares` wrapper, else the env's own ``"paper"``."""
    from noma_radiomap.wrappers import PowerShares

    return "shares" if any(isinstance(layer, PowerShares) for layer in _layers(env)) else "paper"


def scenario_digest(scenario: Any) -> str:
    """
    :param scenario: a :class:`noma_radiomap.Scenario`, or its ``to_dict()`` mapping (e.g. as a run record stores it)
    :return: the SHA-256 of its content (every field, the name included; not where it was loaded from), serialised
        canonically: equal for equal scenarios whether loaded from a file, a built-in or a JSON record
    """
    data = scenario if isinstance(scenario, Mapping) else scenario.to_dict()
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), default=lambda value: value.item())
    return hashlib.sha256(text.encode()).hexdigest()


#: Built-in rooms since recalibrated, by content digest: the file of the repository that keeps each (docs/SCENARIOS.md),
#: named in messages so that a model trained on one finds its room.
RETIRED_BUILTINS: dict[str, str] = {
    "19f0d709de115dbcc329fccb569f63970e27d1a9b99cf3ba244392f0912c1470": "benchmarks/rooms/mall_2026-12-03.yaml",
}


@functools.cache
def builtin_scenario_digest(name: str) -> str | None:
    """:return: the :func:`scenario_digest` of the built-in scenario ``name``, None where no built-in has that name"""
    from noma_radiomap import list_scenarios, load_scenario

    return scenario_digest(load_scenario(name)) if name in list_scenarios() else None


def _scenario_file(scenario: Any, digest: str) -> str | None:
    """The absolute path of the YAML file ``scenario`` was read from, None for a built-in one or one of no file."""
    source = getattr(scenario, "source", None)
    if not isinstance(source, str) or not os.path.isfile(source):
        return None
    # a built-in's source is "<name>.yaml": a file of that name in the working folder is not where it came from
    return None if digest == builtin_scenario_digest(scenario.name) else os.path.abspath(source)


def describe_scenario(settings: Mapping[str, Any]) -> str:
    """:return: where the recorded scenario comes from and its digest, for messages (empty where nothing tells)"""
    digest, file = settings.get("scenario_digest"), settings.get("scenario_file")
    if not digest:
        return f"from {file}" if file else ""
    if file:
        where = f"from {file}"
    elif digest == builtin_scenario_digest(str(settings.get("scenario"))):
        where = "the built-in scenario"
    elif digest in RETIRED_BUILTINS:
        where = f"the built-in scenario before its recalibration, kept as {RETIRED_BUILTINS[digest]} in the repository"
    else:
        where = "not from a file"
    return f"{where}, content sha256 {digest[:12]}"


def settings_of(env: Any) -> dict[str, Any] | None:
    """
    :param env: a Gymnasium env, an SB3 ``VecEnv`` (of its first env, read in its process for a ``SubprocVecEnv``)
        or :class:`sb3_dtdpg.vec_env.MissionVecEnv` (or None)
    :return: the env's :data:`SETTINGS` (``scenario`` is the scenario's name), or None for an env that is not a
        NomaRadioMap mission env, or one of a remote ``VecEnv`` that cannot be read (with a warning)
    """
    from noma_radiomap import Scenario

    if env is None:
        return None
    remote = _remote_vec_env(env)
    if remote is not None:
        return _remote_settings(remote)
    single = _single_env(env)
    base = getattr(single, "vec_env", None) or getattr(single, "unwrapped", single)
    # the batched NomaRadioMapVecEnv keeps its settings in its mission core
    base = next(
        (c for c in (base, getattr(base, "core", None)) if hasattr(c, "scenario") and hasattr(c, "multiple_access")), None
    )
    if base is None:
        return None
    scenario = base.scenario
    # the digest of the scenario as loaded (its radio map's): the paper's task runs it with another mission length
    loaded = getattr(getattr(base, "radio_map", None), "scenario", scenario)
    digest = scenario_digest(loaded) if isinstance(loaded, Scenario) else None
    return {
        "scenario": getattr(scenario, "name", str(scenario)),
        "observation": _observation_of(single),
        "multiple_access": base.multiple_access,
        "channel": getattr(base, "channel", None),
        "task": getattr(base, "task", None),
        "power_mapping": _power_mapping_of(single),
        "scenario_digest": digest,
        "scenario_file": None if digest is None else _scenario_file(scenario, digest),
    }


def record(model: Any, env: Any = None) -> dict[str, Any] | None:
    """
    Store the settings of ``env`` (default: the model's own env) in ``model.env_settings``, saved by ``save``.

    Without an env (a model loaded without one) the recorded settings are kept.

    :param model: an SB3 model
    :param env: the env it was trained on
    :return: the recorded settings
    """
    settings = settings_of(env if env is not None else model.get_env())
    if settings is not None:
        model.env_settings = settings
    return getattr(model, "env_settings", None)


def trained_settings(model: Any) -> dict[str, Any] | None:
    """
    :param model: an SB3 model (or any policy)
    :return: the settings of the env the model trains on, else those its file recorded (:func:`record`), else None
    """
    get_env = getattr(model, "get_env", None)
    settings = settings_of(get_env()) if callable(get_env) else None
    return settings if settings is not None else getattr(model, "env_settings", None)


def infer_observation(n_values: int, n_robots: int) -> str | None:
    """
    :param n_values: length of a flat observation
    :param n_robots: robots of the scenario
    :return: the layout with that length, or None
    """
    from noma_radiomap.observations import OBSERVATIONS

    return next((name for name, per_robot in OBSERVATIONS.items() if per_robot * n_robots == n_values), None)


def _make_call(settings: dict[str, Any]) -> str:
    """The ``gymnasium.make`` call of an env with these settings (the paper's power mapping, the default, left out)."""
    shown = {key: settings.get(key) for key in CHECKED if settings.get(key) not in (None, _DEFAULTS.get(key))}
    if file := _scenario_file_of(settings):  # a scenario of a file: the file builds it, its name would be the built-in
        shown["scenario"] = file
    layout, wrapper = split_observation(settings.get("observation"))
    if wrapper:
        shown["observation"] = layout
    arguments = ", ".join(f"{key}={value!r}" for key, value in shown.items())
    call = f'gym.make("NomaRadioMap-v0", {arguments})'
    return f"{wrapper[:-1]}, env={call})" if wrapper else call


def split_observation(observation: Any) -> tuple[Any, str | None]:
    """
    :param observation: a recorded observation layout
    :return: the layout an env is built with and the wrapper around it (e.g. ``"RelativeGoalObservation(distance_scale=
        4.0)"``), None where the layout is the env's own
    """
    if isinstance(observation, str) and WRAPPED_MARK in observation:
        layout, wrapper = observation.split(WRAPPED_MARK, 1)
        return layout, wrapper
    return observation, None


def _scenario_file_of(settings: dict[str, Any]) -> str | None:
    """The file that builds the recorded scenario: the one it was read from, or the kept file of a retired built-in."""
    return settings.get("scenario_file") or RETIRED_BUILTINS.get(str(settings.get("scenario_digest")))


def _differs(key: str, recorded: dict[str, Any], actual: dict[str, Any]) -> bool:
    """Whether a :data:`CHECKED` setting differs: the scenario by its digest where both have one, else by value."""
    if key == "scenario" and recorded.get("scenario_digest") and actual.get("scenario_digest"):
        return recorded["scenario_digest"] != actual["scenario_digest"]
    return recorded.get(key) is not None and recorded.get(key) != actual.get(key)


def _difference(key: str, recorded: dict[str, Any], actual: dict[str, Any]) -> str:
    """A differing setting and both values, for the message (two scenarios of one name: where each comes from)."""
    if key != "scenario" or recorded.get(key) != actual.get(key):
        return f"{key}={recorded[key]!r} (the env has {actual.get(key)!r})"
    return (
        f"{key}={recorded[key]!r} ({describe_scenario(recorded)}) (the env has {actual.get(key)!r}, "
        f"{describe_scenario(actual)}: another room of the same name)"
    )


def check_settings(recorded: dict[str, Any] | None, env: Any, what: str = "the model") -> None:
    """
    :param recorded: the settings a model was trained with (None: nothing recorded, nothing to check)
    :param env: the env it is about to be used on
    :param what: the model, for the message (e.g. its path)
    :raises EnvSettingsMismatch: when a :data:`CHECKED` setting differs; the message names every differing
        setting and the ``gymnasium.make`` call that builds a matching env
    """
    actual = settings_of(env)
    if not recorded or actual is None:
        return
    differences = [_difference(key, recorded, actual) for key in CHECKED if _differs(key, recorded, actual)]
    if differences:
        scenario = _scenario_file_of(recorded)  # a file's path, else the name of the built-in it is
        if scenario is None and recorded.get("scenario_digest") == builtin_scenario_digest(str(recorded.get("scenario"))):
            scenario = recorded.get("scenario")
        scenario_option = f"--scenario {scenario} " if scenario else ""
        if split_observation(recorded.get("observation"))[1]:
            cli = "no sb3-dtdpg option builds a wrapped env"
        else:
            cli = (
                f"sb3-dtdpg: {scenario_option}--observation {recorded.get('observation')} "
                f"--multiple-access {recorded.get('multiple_access')}"
            )
        older = ""
        if recorded.get("observation") == "goal" and split_observation(actual.get("observation"))[1]:
            older = (
                "; a model saved before 2026-12-06 behind RelativeGoalObservation records 'goal' whatever the layout "
                "under the wrapper: if this one was trained on this wrapped env, load it with "
                "custom_objects={'env_settings': None}"
            )
        raise EnvSettingsMismatch(
            f"{what} was trained with {', '.join(differences)}; build the env with those settings, e.g. "
            f"{_make_call(recorded)} ({cli}){older}"
        )
