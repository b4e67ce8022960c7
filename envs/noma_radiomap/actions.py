"""Checking the agent's actions before the env uses them.

The env's action is one flat vector of ``3 U`` numbers, ``[dx, dy, power]`` per robot. A wrong shape, a
non-numeric array or a non-finite component (NaN, +-inf) raises a ``ValueError`` naming what is wrong (the
robot and the component) *before* anything in the env changes, so a bad action never corrupts its state:
a NaN motion would make the robot's position NaN, a NaN power would give NaN rates that compare as "not in
outage". Finite values outside [-1, 1] are valid and clipped by the env, as for any ``Box`` action space.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from noma_radiomap.compiled import compiled

__all__ = ["COMPONENTS", "check_action", "check_actions"]

#: The per-robot components of an action, in order.
COMPONENTS: tuple[str, ...] = ("dx", "dy", "power")


def check_action(action: Any, n_robots: int) -> np.ndarray:
    """
    Validate an action and return it as a float64 array of shape ``(n_robots, 3)``.

    :param action: the action, an array-like of shape ``(3 * n_robots,)`` (a single flat vector, as the
        action space says; a batch or a ``(n_robots, 3)`` array is refused: the layout would be a guess)
    :param n_robots: the number of robots ``U``
    :return: the action as ``(n_robots, 3)`` float64, rows ``[dx, dy, power]``
    :raises ValueError: wrong shape, non-numeric entries, or a NaN/inf component (naming robot and component)
    """
    values = _real_array(action, "action", (3 * n_robots,), "[dx, dy, power] per robot").reshape(n_robots, 3)
    _check_finite(values, "action")
    return values


def check_actions(actions: Any, missions: np.ndarray, n_robots: int) -> np.ndarray:
    """
    :func:`check_action` for a batch of missions (the vector env): validate and return the actions as float64
    ``(len(missions), n_robots, 3)``.

    :param actions: one flat action per mission, an array-like of shape ``(len(missions), 3 * n_robots)``
    :param missions: the missions' indices (for the messages)
    :param n_robots: the number of robots ``U``
    :return: the actions as ``(len(missions), n_robots, 3)`` float64
    :raises ValueError: wrong shape, non-numeric entries, or a NaN/inf component (naming mission, robot and
        component)
    """
    expected = (len(missions), 3 * n_robots)
    values = _real_array(actions, "actions", expected, "one flat action per mission").reshape(-1, n_robots, 3)
    _check_finite(values, "actions", missions)
    return values


def _check_finite(values: np.ndarray, name: str, missions: np.ndarray | None = None) -> None:
    """
    A ValueError naming the first non-finite component of ``values`` ((n_robots, 3), or (missions, n_robots, 3)
    with ``missions`` their indices): its index in the flat action(s), its robot and component.
    """
    if _all_finite(values):
        return
    finite = np.isfinite(values)
    *mission, u, k = (int(j) for j in np.argwhere(~finite)[0])
    where = f"mission {int(missions[mission[0]])}, " if missions is not None else ""
    index = ", ".join(str(j) for j in [*mission, 3 * u + k])
    raise ValueError(
        f"{name}[{index}] ({where}robot {u}, {COMPONENTS[k]}): expected a finite number, got "
        f"{values[(*mission, u, k)]!r}; {int((~finite).sum())} non-finite component(s) in all; the env state is "
        "unchanged"
    )


@compiled
def _all_finite(values: np.ndarray) -> bool:
    """Whether every entry is finite (compiled: one pass, no temporary array)."""
    for value in values.flat:
        if not math.isfinite(value):
            return False
    return True


def _real_array(value: Any, name: str, expected: tuple[int, ...], layout: str) -> np.ndarray:
    """``value`` as a float64 array of shape ``expected``, or a ValueError naming what is wrong."""
    try:
        array = np.asarray(value)
    except (TypeError, ValueError) as error:  # ragged nested sequences
        raise ValueError(f"{name}: expected an array of shape {expected}, got {type(value).__name__} ({error})") from None
    if array.shape != expected:
        raise ValueError(f"{name}: expected shape {expected} ({layout}), got shape {array.shape}")
    if array.dtype.kind not in "fiu":  # floats and integers; not bool, complex, strings or objects
        raise ValueError(f"{name}: expected real numbers, got dtype {array.dtype}")
    return array.astype(np.float64)
