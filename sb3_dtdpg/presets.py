"""The named settings sets of the algorithms on the mission env, each defined once (docs/ZOO.md, "Presets").

- ``"paper"``: the paper's Table I and Section V (:data:`TABLE_I`, with :func:`sb3_dtdpg.missions.paper_phases`).
- ``"tuned"``: the settings that learn the mission best (:data:`TUNED`, with
  :func:`sb3_dtdpg.missions.default_phases`; docs/BENCHMARKS.md).

DT-DPG and its DDPG baseline share a set, so that a comparison differs only in the method; the baselines add
their exploration noise (:data:`BASELINE_NOISE`: DDPG's constant OU noise, TD3's Gaussian noise). TD3, SAC and
TQC have one set, ``"paper"``: their SB3 defaults and that noise. :func:`sb3_dtdpg.baselines.make_model`,
the command line's ``--preset`` and the RL Zoo files ``zoo_configs/*.yml`` (written from here by
:mod:`sb3_dtdpg.zoo_files`) all read these definitions; :class:`sb3_dtdpg.DTDPG`'s own defaults are SB3's
generic ones. In Python::

    model = DTDPG("MlpPolicy", env, **preset("tuned"))

:func:`model_settings` reads the settings back from a built model, for a run's identity.
"""

from __future__ import annotations

import copy
import enum
import inspect
from collections.abc import Callable
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.utils import ConstantSchedule

from sb3_dtdpg.common.noise import NormalNoise, OrnsteinUhlenbeckNoise, noise_settings
from sb3_dtdpg.common.phases import Phase
from sb3_dtdpg.missions import default_phases, paper_phases

__all__ = [
    "BASELINE_NOISE",
    "PRESETS",
    "TABLE_I",
    "TUNED",
    "check_preset",
    "model_kwargs",
    "model_settings",
    "preset",
    "presets_of",
    "settings",
]

#: The names of the settings sets.
PRESETS: tuple[str, ...] = ("paper", "tuned")

#: The paper's Table I and Section V: learning rate alpha, buffer omega, batch e, tau, gamma = 1, one-step targets
#: (Algorithm 1), one update per step, hidden layers of 64-128 units (ReLU, tanh output and Adam are the policy's
#: own). The warm-up (``learning_starts``) is not in the paper.
TABLE_I: dict[str, Any] = {
    "learning_rate": 1e-4,
    "buffer_size": 50_000,
    "learning_starts": 100,
    "batch_size": 64,
    "tau": 0.002,
    "gamma": 1.0,
    "train_freq": 1,
    "gradient_steps": 1,
    "n_steps": 1,
    "policy_kwargs": {"net_arch": [128, 64]},
}

#: The best measured settings on NomaRadioMap-v0 (docs/BENCHMARKS.md, "The tuned settings").
TUNED: dict[str, Any] = {
    "learning_rate": 1e-3,
    "buffer_size": 200_000,
    "learning_starts": 2000,
    "batch_size": 128,
    "tau": 0.005,
    "gamma": 0.95,
    "train_freq": 1,
    "gradient_steps": 1,
    "n_steps": 3,
    "policy_kwargs": {"net_arch": [128, 128]},
}

_SHARED: dict[str, dict[str, Any]] = {"paper": TABLE_I, "tuned": TUNED}
_CURRICULA: dict[str, Callable[[int], list[Phase]]] = {
    "paper": paper_phases,
    "tuned": lambda destination_episodes: default_phases(destination_episodes=destination_episodes),
}
_DEFAULT_DESTINATION_EPISODES = {"paper": 300, "tuned": 500}

#: The baselines' exploration noise in the RL Zoo's terms, ``(noise_type, noise_std)``: DDPG's constant OU noise of
#: DT-DPG's initial scale xi(0, 0) = 0.5 (the paper gives no scale for its DDPG); TD3's Gaussian noise of the RL
#: Zoo's usual scale (SB3's TD3 has none by default).
BASELINE_NOISE: dict[str, tuple[str, float]] = {"ddpg": ("ornstein-uhlenbeck", 0.5), "td3": ("normal", 0.1)}

_ALGORITHMS = ("dtdpg", "ddpg", "td3", "sac", "tqc")


def presets_of(algo: str) -> tuple[str, ...]:
    """
    :param algo: an algorithm of :data:`sb3_dtdpg.baselines.ALGORITHMS`
    :return: the names of its settings sets
    """
    if algo not in _ALGORITHMS:
        raise ValueError(f"algo must be one of {_ALGORITHMS}, got {algo!r}")
    return PRESETS if algo in ("dtdpg", "ddpg") else ("paper",)


def check_preset(algo: str, name: str) -> None:
    """
    :param algo: an algorithm of :data:`sb3_dtdpg.baselines.ALGORITHMS`
    :param name: a name of :data:`PRESETS`
    :raises ValueError: when the set is unknown, or not defined for the algorithm
    """
    if name not in PRESETS:
        raise ValueError(f"hyperparams must be one of {PRESETS}, got {name!r}")
    if name not in presets_of(algo):
        raise ValueError(f"hyperparams={name!r} is defined for 'dtdpg' and 'ddpg' only, got algo={algo!r}")


def settings(algo: str, name: str) -> dict[str, Any]:
    """
    A settings set as plain data (what the RL Zoo files hold, less the zoo's own keys).

    :param algo: an algorithm of :data:`sb3_dtdpg.baselines.ALGORITHMS`
    :param name: a name of :data:`PRESETS` defined for it
    :return: the constructor arguments; the noise as ``noise_type`` and ``noise_std``, DT-DPG's ``phases`` as dicts
    """
    check_preset(algo, name)
    values = copy.deepcopy(_SHARED[name]) if algo in ("dtdpg", "ddpg") else {}
    if algo in BASELINE_NOISE:
        values["noise_type"], values["noise_std"] = BASELINE_NOISE[algo]
    if algo == "dtdpg":
        values["phases"] = [phase.to_dict() for phase in _CURRICULA[name](_DEFAULT_DESTINATION_EPISODES[name])]
    return values


def _noise(noise_type: str, noise_std: float, action_space: spaces.Space | None) -> ActionNoise:
    if not isinstance(action_space, spaces.Box):
        raise ValueError(f"noise_type={noise_type!r} needs a Box action space, got {action_space!r}")
    n_actions = int(np.prod(action_space.shape))
    noise_class = OrnsteinUhlenbeckNoise if noise_type == "ornstein-uhlenbeck" else NormalNoise
    return noise_class(np.zeros(n_actions), noise_std * np.ones(n_actions))


def model_kwargs(
    algo: str,
    name: str,
    action_space: spaces.Space | None = None,
    destination_episodes: int | None = None,
    curriculum: bool = True,
) -> dict[str, Any]:
    """
    A settings set as constructor arguments of the algorithm.

    :param algo: an algorithm of :data:`sb3_dtdpg.baselines.ALGORITHMS`
    :param name: a name of :data:`PRESETS` defined for it
    :param action_space: the env's action space (needed by the baselines' noise)
    :param destination_episodes: DT-DPG: the episode budget of the destination phase (None: the set's own)
    :param curriculum: DT-DPG: include the set's mission curriculum (``phases``); False leaves the curriculum to
        the env (an env that is not the mission)
    :return: the keyword arguments (fresh objects on every call)
    """
    values = settings(algo, name)
    if algo != "dtdpg" and destination_episodes is not None:
        raise ValueError(f"destination_episodes applies to 'dtdpg' only, got algo={algo!r}")
    if "noise_type" in values:
        values["action_noise"] = _noise(values.pop("noise_type"), values.pop("noise_std"), action_space)
    if algo == "dtdpg":
        del values["phases"]
        if curriculum:
            episodes = _DEFAULT_DESTINATION_EPISODES[name] if destination_episodes is None else destination_episodes
            values["phases"] = _CURRICULA[name](episodes)
    return values


def preset(name: str, destination_episodes: int | None = None) -> dict[str, Any]:
    """
    DT-DPG's settings on the mission env, to pass as ``DTDPG("MlpPolicy", env, **preset("tuned"))``.

    :param name: a name of :data:`PRESETS`
    :param destination_episodes: the episode budget of the destination phase (None: the set's own)
    :return: the ``DTDPG`` keyword arguments, the mission's curriculum (``phases``) included
    """
    if name not in PRESETS:  # check_preset's message names the CLI's and RunSpec's field, hyperparams
        raise ValueError(f"preset: name must be one of {PRESETS}, got {name!r}")
    return model_kwargs("dtdpg", name, destination_episodes=destination_episodes)


# ---------------------------------------------------------------------------------------------- identity
#: Constructor arguments that say where or how verbosely a model runs, not what it learns.
_NOT_SETTINGS = frozenset(
    {"self", "policy", "env", "tensorboard_log", "verbose", "device", "_init_setup_model", "curriculum_save_path"}
)


def _name(value: Any) -> str:
    return f"{value.__module__}.{value.__qualname__}"


def _json(key: str, value: Any) -> Any:
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, enum.Enum):
        return _json(key, value.value)
    if isinstance(value, np.ndarray):
        return [_json(key, item) for item in value.tolist()]
    if isinstance(value, (list, tuple)):
        return [_json(key, item) for item in value]
    if isinstance(value, dict):
        return {str(k): _json(f"{key}.{k}", item) for k, item in value.items()}
    if isinstance(value, Phase):
        return _json(key, value.to_dict())
    if inspect.isclass(value) or inspect.isfunction(value):
        return _name(value)
    raise TypeError(f"model_settings: cannot store {key}={value!r} ({type(value).__name__}) as JSON")


def model_settings(model: BaseAlgorithm) -> dict[str, Any]:
    """
    The settings of a built model, read back from the model itself (its attributes, not the arguments it was
    given): every constructor argument the model keeps as a public attribute, the policy's actual network
    (``net_arch``, activation, optimizer), the action noise (:func:`sb3_dtdpg.common.noise.noise_settings`)
    and, for DT-DPG, its phases. Read it before training: the curriculum re-arms the noise.

    :param model: an SB3 model (DTDPG, DDPG, TD3, SAC, TQC, ...)
    :return: a JSON-ready mapping, one JSON type per value: numbers, strings (classes as ``module.Name``),
        lists, mappings and null; ``learning_rate`` is a schedule's initial value, ``train_freq``
        ``[frequency, unit]``
    """
    values: dict[str, Any] = {"algorithm": _name(type(model)), "policy_class": _name(type(model.policy))}
    for name in inspect.signature(type(model).__init__).parameters:
        if name in _NOT_SETTINGS or not hasattr(model, name):
            continue
        value = getattr(model, name)
        if name == "learning_rate":
            schedule = value if inspect.isfunction(value) else type(value)
            constant = not callable(value) or isinstance(value, ConstantSchedule)  # the RL Zoo passes a ConstantSchedule
            values["learning_rate_schedule"] = "constant" if constant else _name(schedule)
            value = model.lr_schedule(1.0)
        elif name == "action_noise":
            value = noise_settings(value)
        elif name == "train_freq":
            value = [value.frequency, value.unit] if hasattr(value, "frequency") else value
        values[name] = _json(name, value)
    policy = model.policy
    for name in ("net_arch", "activation_fn", "optimizer_class", "optimizer_kwargs"):
        if hasattr(policy, name):
            values[f"policy.{name}"] = _json(name, getattr(policy, name))
    return values
