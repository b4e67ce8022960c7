"""Range checks of the numeric settings of SB3's off-policy algorithms, each error naming the field and its value; the
shortened lists of error messages."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

__all__ = [
    "check_action_noise",
    "check_callback",
    "check_folder",
    "check_log_interval",
    "check_off_policy_settings",
    "check_switches",
    "check_total_timesteps",
    "shortened",
]


def _is_int(value: Any) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _is_real(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) and math.isfinite(value)


def _int_at_least(owner: str, name: str, value: Any, low: int) -> None:
    if not _is_int(value) or value < low:
        raise ValueError(f"{owner}: {name} must be an integer >= {low}, got {value!r}")


def _learning_rate(owner: str, value: Any) -> None:
    initial = value(1.0) if callable(value) else value  # SB3 schedules start at progress_remaining = 1
    if not _is_real(initial) or initial <= 0:
        what = "the initial value of the learning-rate schedule" if callable(value) else "learning_rate"
        raise ValueError(f"{owner}: {what} must be a finite number > 0, got {initial!r}")


def _train_freq(owner: str, value: Any) -> None:
    if isinstance(value, tuple):
        if len(value) != 2:
            raise ValueError(f"{owner}: train_freq must be an integer or a tuple (frequency, unit), got {value!r}")
        frequency, unit = value
    else:
        frequency, unit = value, "step"
    if type(frequency) is not int or frequency < 1:  # SB3 takes a Python int only (not a list, nor a numpy integer)
        if isinstance(frequency, np.integer):  # named with its type: numpy 1 shows np.int64(2) as a bare 2
            shown = f"{frequency} (numpy.{type(frequency).__name__})"
            shown = f"({shown}, {unit!r})" if isinstance(value, tuple) else shown
        else:
            shown = repr(value)
        raise ValueError(
            f"{owner}: train_freq must be a Python integer >= 1 or a tuple (frequency, unit) with one, got {shown}"
        )
    if getattr(unit, "value", unit) not in ("step", "episode"):  # a string or SB3's TrainFrequencyUnit
        raise ValueError(f"{owner}: the unit of train_freq must be 'step' or 'episode', got {unit!r}")


def _net_arch(owner: str, policy_kwargs: Mapping[str, Any] | None) -> None:
    if not isinstance(policy_kwargs, Mapping):
        raise ValueError(f"{owner}: policy_kwargs must be a dict, e.g. dict(net_arch=[64, 64]), got {policy_kwargs!r}")
    net_arch = policy_kwargs.get("net_arch")
    if net_arch is None:
        return
    layers = [*net_arch.get("pi", []), *net_arch.get("qf", [])] if isinstance(net_arch, Mapping) else net_arch
    if not isinstance(layers, (list, tuple)) or any(not _is_int(units) or units < 1 for units in layers):
        raise ValueError(f"{owner}: policy_kwargs['net_arch'] must hold layer sizes >= 1, got {net_arch!r}")


#: setting -> check(owner, value); settings that are absent or None are not checked
_CHECKS: dict[str, Callable[[str, Any], None]] = {
    "learning_rate": _learning_rate,
    "buffer_size": lambda owner, value: _int_at_least(owner, "buffer_size", value, 1),
    "learning_starts": lambda owner, value: _int_at_least(owner, "learning_starts", value, 0),
    "batch_size": lambda owner, value: _int_at_least(owner, "batch_size", value, 1),
    "n_steps": lambda owner, value: _int_at_least(owner, "n_steps", value, 1),
    "train_freq": _train_freq,
    "policy_kwargs": _net_arch,
}


def check_off_policy_settings(owner: str, settings: Mapping[str, Any]) -> None:
    """
    Range-check the numeric constructor arguments of an SB3 off-policy algorithm (DDPG, TD3, SAC, TQC, DTDPG):
    ``learning_rate`` (a schedule's initial value) finite and > 0, ``buffer_size``, ``batch_size`` and ``n_steps``
    >= 1, ``learning_starts`` >= 0, ``gamma`` in [0, 1], ``tau`` in (0, 1], ``train_freq`` >= 1 (with unit
    ``"step"`` or ``"episode"``), ``gradient_steps`` >= 0 (0: collect only) or -1 (SB3: as many as env steps),
    ``n_steps`` <= ``buffer_size`` (when both are given), and the layer sizes of ``policy_kwargs["net_arch"]`` >= 1.

    :param owner: what the settings are for, at the start of the message (e.g. ``"DTDPG"``)
    :param settings: the constructor arguments; absent or None ones are not checked
    :raises ValueError: naming the first setting out of range and its value
    """
    for name, check in _CHECKS.items():
        if settings.get(name) is not None:
            check(owner, settings[name])
    gamma, tau, gradient_steps = settings.get("gamma"), settings.get("tau"), settings.get("gradient_steps")
    if gamma is not None and (not _is_real(gamma) or not 0 <= gamma <= 1):
        raise ValueError(f"{owner}: gamma must be a number in [0, 1], got {gamma!r}")
    if tau is not None and (not _is_real(tau) or not 0 < tau <= 1):
        raise ValueError(f"{owner}: tau must be a number in (0, 1], got {tau!r}")
    if gradient_steps is not None and (not _is_int(gradient_steps) or gradient_steps < -1):
        raise ValueError(f"{owner}: gradient_steps must be an integer >= 0, or -1, got {gradient_steps!r}")
    n_steps, buffer_size = settings.get("n_steps"), settings.get("buffer_size")
    if n_steps is not None and buffer_size is not None and n_steps > buffer_size:  # each return reads n_steps rows
        raise ValueError(f"{owner}: n_steps must be at most buffer_size ({buffer_size}), got {n_steps!r}")


def check_total_timesteps(total_timesteps: Any) -> int:
    """
    :param total_timesteps: the budget of ``learn()``: a positive integer, or a float of one (``1e5``, as SB3 takes)
    :return: it as an ``int``
    :raises ValueError: unless it is a positive integer
    """
    if isinstance(total_timesteps, float | np.floating) and np.isfinite(total_timesteps) and total_timesteps.is_integer():
        total_timesteps = int(total_timesteps)
    if not _is_int(total_timesteps) or total_timesteps < 1:
        raise ValueError(f"learn(): total_timesteps must be a positive integer, got {total_timesteps!r}")
    return int(total_timesteps)


def check_switches(owner: str, switches: Mapping[str, Any]) -> None:
    """
    :param owner: what the settings are for, at the start of the message
    :param switches: on/off settings by name
    :raises ValueError: naming the first that is not True or False (a string such as ``"no"`` would count as on)
    """
    for name, value in switches.items():
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{owner}: {name} must be True or False, got {value!r}")


def _noise_shape(owner: str, noise: Any) -> tuple[int, ...] | None:
    """:return: the shape of the draws of SB3's noises (and of noises built like them: a mean ``_mu`` or ``mean``
    and a scale ``_sigma`` or ``sigma``), of one env's copy for a vectorized noise; None where the noise does not
    show it
    :raises ValueError: the mean and the scale do not broadcast together"""
    noises = getattr(noise, "noises", None)
    if isinstance(noises, list) and noises:  # VectorizedActionNoise: one copy per env
        noise = noises[0]
    shapes = {}
    for part, names in (("mean", ("_mu", "mean")), ("sigma", ("_sigma", "sigma"))):
        values = [getattr(noise, name, None) for name in names]
        arrays = [value for value in values if isinstance(value, np.ndarray)]
        if arrays:
            shapes[part] = arrays[0].shape
    if "mean" not in shapes:
        return None
    try:
        return np.broadcast_shapes(*shapes.values())
    except ValueError:
        raise ValueError(
            f"{owner}: action_noise has a mean of shape {shapes['mean']} and a sigma of shape {shapes['sigma']}, "
            "which do not broadcast together"
        ) from None


def check_action_noise(owner: str, noise: Any, action_shape: tuple[int, ...]) -> None:
    """
    :param owner: what the noise is for, at the start of the message
    :param noise: the action noise (None: no noise)
    :param action_shape: the shape of one action
    :raises ValueError: the noise's draws do not broadcast to one action (SB3 would fail at the first noisy step, or
        widen the action), naming both shapes
    """
    from stable_baselines3.common.noise import ActionNoise

    if noise is not None and not isinstance(noise, ActionNoise):  # SB3 calls it at the first noisy step
        raise ValueError(
            f"{owner}: action_noise must be an ActionNoise (e.g. NormalActionNoise(mean, sigma)) or None, got {noise!r}"
        )
    shape = _noise_shape(owner, noise) if noise is not None else None
    if shape is None:
        return
    try:
        fits = np.broadcast_shapes((1, *action_shape), shape) == (1, *action_shape)
    except ValueError:
        fits = False
    if not fits:
        raise ValueError(
            f"{owner}: action_noise draws noise of shape {shape}, which does not fit the action space's shape "
            f"{tuple(action_shape)}: build it with mean and sigma of that shape, e.g. np.zeros({tuple(action_shape)})"
        )


def check_confidence(confidence: Any) -> None:
    """:raises ValueError: ``confidence`` is not a confidence level in (0, 1), naming the value"""
    if not _is_real(confidence) or not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")


def check_log_interval(log_interval: Any) -> None:
    """
    :param log_interval: ``learn()``'s episodes between log dumps (None: never)
    :raises ValueError: unless it is None or a positive integer
    """
    if log_interval is not None and (not _is_int(log_interval) or log_interval < 1):
        raise ValueError(f"learn(): log_interval must be a positive integer or None, got {log_interval!r}")


def check_callback(callback: Any) -> None:
    """
    :param callback: ``learn()``'s callback: None, an SB3 ``BaseCallback``, a function of ``(locals, globals)``, or a
        list of these
    :raises ValueError: naming the entry that is none of these
    """
    for entry in callback if isinstance(callback, list) else [callback]:
        if entry is not None and not callable(entry) and not hasattr(entry, "on_step"):
            raise ValueError(
                f"learn(): callback must be a BaseCallback, a function or a list of these, got {type(entry).__name__} "
                f"{entry!r}"
            )


def check_folder(owner: str, name: str, path: str | os.PathLike[str] | None) -> None:
    """
    :param owner: what the setting is for, at the start of the message
    :param name: the setting
    :param path: a folder to write into later (None: none); it may not exist yet
    :raises ValueError: when the path is an existing file (or anything else that is not a folder)
    """
    if path is not None and os.path.lexists(path) and not os.path.isdir(path):
        raise ValueError(f"{owner}: {name} must be a folder, got the file {os.fspath(path)!r}")


def shortened(items: list[str], limit: int, separator: str = ", ") -> str:
    """
    The first ``limit`` items joined, and how many more there are: ``"a, b and 3 more"``, ``"a; b; and 3 more"``.

    :param items: the items, as text
    :param limit: how many to show, at least 1
    :param separator: between two items
    :return: the text
    """
    if not _is_int(limit) or limit < 1:
        raise ValueError(f"limit must be an integer >= 1, got {limit!r}")
    shown = separator.join(items[:limit])
    if len(items) <= limit:
        return shown
    joiner = f"{separator.rstrip()} and" if separator.strip() == ";" else " and"
    return f"{shown}{joiner} {len(items) - limit} more"
