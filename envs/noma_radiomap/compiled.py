"""The env's compiled loops: numba's ``njit``, with the machine code cached on disk where it can be written."""

import warnings
from collections.abc import Callable
from typing import TypeVar

import numba

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
