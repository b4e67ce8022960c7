"""Warnings of the command line as one line each, ``<prog>: warning: <message>``, like its own notices, instead of
Python's ``<file>:<line>: <Category>: <message>`` followed by the source line that raised it."""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator

__all__ = ["WarningLines", "warnings_as_lines"]


class WarningLines:
    """
    A ``warnings.formatwarning``: ``<prog>: warning: <message>``, the category's name before the message unless it is
    a plain ``UserWarning``. Picklable, so that a job's spawned workers show their warnings the same way
    (:func:`sb3_dtdpg.experiments.pool.worker_pool` hands the parent's on).

    :param prog: the command, e.g. ``sb3-dtdpg compare``
    """

    def __init__(self, prog: str) -> None:
        self.prog = prog

    def __call__(
        self, message: Warning | str, category: type[Warning], filename: str, lineno: int, line: str | None = None
    ) -> str:
        name = "" if category is UserWarning else f"{category.__name__}: "
        return f"{self.prog}: warning: {name}{message}\n"


@contextlib.contextmanager
def warnings_as_lines(prog: str) -> Iterator[None]:
    """
    Show warnings as :class:`WarningLines` of ``prog`` inside the block (what is shown, and when, is left to the
    warning filters; code that records warnings, such as ``pytest.warns``, still gets them).

    :param prog: the command, e.g. ``sb3-dtdpg compare``
    """
    formatter = warnings.formatwarning
    warnings.formatwarning = WarningLines(prog)  # type: ignore[assignment]
    try:
        yield
    finally:
        warnings.formatwarning = formatter
