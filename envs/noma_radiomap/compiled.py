"""The env's compiled loops: numba's ``njit``, with the machine code cached on disk where it can be written, and the
arrangement of arrays into the rows the loops take."""

import warnings
from collections.abc import Callable
from typing import Any, TypeVar

import numba
import numpy as np

Function = TypeVar("Function", bound=Callable)

_warned = False


def compiled(function: Function) -> Function:
    """
    ``numba.njit(cache=True)``: ``function`` is compiled on its first call and the machine code is cached on disk
    (next to the module, or in numba's user cache folder), so later processes load it instead of compiling it.
    Where no cache folder can be written (a read-only install and home folder), the function is compiled in every
    process instead, with one warning.

    :param function: a function numba's nopython mode compiles
    :return: its dispatcher
    """
    global _warned
    try:
        return numba.njit(cache=True)(function)
    except RuntimeError as error:
        if "no locator available" not in str(error):
            raise
        if not _warned:
            _warned = True
            warnings.warn(
                f"noma_radiomap: numba finds no writable cache folder ({error}); the env's loops are compiled in "
                "every process (a few seconds each). Set NUMBA_CACHE_DIR to a writable folder to cache them.",
                RuntimeWarning,
                stacklevel=2,
            )
        return numba.njit(function)


def as_rows(what: str, *arrays: Any, last: int | None = None) -> tuple[list[np.ndarray], tuple[int, ...]]:
    """
    Arrays with robots (or coordinates) on their last axis, as the (M, K) float64 rows a compiled kernel takes.

    :param what: the arrays, for the error (e.g. ``"mission_quality_indicator: mission_time, outage_steps"``)
    :param arrays: arrays broadcastable to one shape (..., K)
    :param last: the length K must have (None: any)
    :return: each array broadcast and reshaped to (M, K), and the leading shape (...) to reshape a result to
    :raises ValueError: a 0-d shape, or a last axis other than ``last``, naming the shape
    """
    values = [np.asarray(array, dtype=np.float64) for array in arrays]
    shape = np.broadcast_shapes(*(value.shape for value in values))
    if not shape or (last is not None and shape[-1] != last):
        raise ValueError(f"{what}: expected arrays of shape (..., {last or 'U'}), got shape {shape}")
    rows = (int(np.prod(shape[:-1], dtype=np.int64)), shape[-1])
    return [np.broadcast_to(value, shape).reshape(rows) for value in values], shape[:-1]


def as_scalar(name: str, value: Any) -> float:
    """:return: ``value`` as a float; :raises ValueError: for an array of more than one value, naming it"""
    if np.ndim(value) != 0:
        raise ValueError(f"{name}: expected a number, got an array of shape {np.shape(value)}")
    return float(value)
