"""Checking the agent's actions before the env uses them.

The env's action is one flat vector of ``3 U`` numbers, ``[dx, dy, power]`` per robot. A wrong shape, a
non-numeric array or a non-finite component (NaN, +-inf) raises a ``ValueError`` naming what is wrong (the
robot and the component) *before* anything in the env changes, so a bad action never corrupts its state:
a NaN motion would make the robot's position NaN, a NaN power would give NaN rates that compare as "not in
outage". Finite values outside [-1, 1] are valid and clipped by the env, as for any ``Box`` action space.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["COMPONENTS", "check_action"]

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
    expected = (3 * n_robots,)
    try:
        array = np.asarray(action)
    except (TypeError, ValueError) as error:  # ragged nested sequences
        raise ValueError(f"action: expected an array of shape {expected}, got {type(action).__name__} ({error})") from None
    if array.shape != expected:
        raise ValueError(f"action: expected shape {expected} ([dx, dy, power] per robot), got shape {array.shape}")
    if array.dtype.kind not in "fiu":  # floats and integers; not bool, complex, strings or objects
        raise ValueError(f"action: expected real numbers, got dtype {array.dtype}")
    values = array.astype(np.float64).reshape(n_robots, 3)
    if not np.isfinite(values).all():
        bad = ~np.isfinite(values)
        u, k = (int(i) for i in np.argwhere(bad)[0])
        raise ValueError(
            f"action[{3 * u + k}] (robot {u}, {COMPONENTS[k]}): expected a finite number, got {values[u, k]!r}; "
            f"{int(bad.sum())} non-finite component(s) in all; the env state is unchanged"
        )
    return values
