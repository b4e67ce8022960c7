"""
argparse types of the command line (``sb3-dtdpg``) and of the repository's scripts (``benchmarks/``, ``examples/``).

A value an option cannot use is refused by argparse, before any work, as one error line that names the option, what
it expects and the value: ``error: argument --workers: expected a positive integer, got '0'``. Nothing heavy is
imported here, so that ``--help`` stays fast.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

__all__ = ["MAX_SEED", "MAX_SEEDS", "checked", "non_negative_int", "positive_int", "seed_count", "seed_int"]

#: Seeds go to numpy and torch, which take 0 <= seed < 2**32.
MAX_SEED = 2**32 - 1
#: The most seeds per configuration a job takes (seeds 0..N-1): 1,000 paper-scale runs of one configuration take weeks
#: of CPU, and a mistyped count (10**11) would fill the memory with run specs before anything ran.
MAX_SEEDS = 1_000


def checked(convert: Callable[[str], Any], valid: Callable[[Any], bool], expected: str) -> Callable[[str], Any]:
    """
    An argparse type: ``convert(text)``, refused with ``expected <expected>, got <text>`` unless ``valid`` holds.

    :param convert: turns the typed text into the value (``int``, ``float``, ...); a ``ValueError`` refuses it
    :param valid: whether a converted value can be used
    :param expected: what the option takes, for the message (``"a positive integer"``)
    :return: the type, for ``parser.add_argument(..., type=...)``
    """

    def parse(text: str) -> Any:
        try:
            value = convert(text)
        except ValueError:
            value = None
        if value is None or not valid(value):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return value

    return parse


positive_int = checked(int, lambda n: n >= 1, "a positive integer")
non_negative_int = checked(int, lambda n: n >= 0, "an integer >= 0")
seed_int = checked(int, lambda n: 0 <= n <= MAX_SEED, f"a seed in 0..{MAX_SEED} (numpy's and torch's range)")
seed_count = checked(int, lambda n: 1 <= n <= MAX_SEEDS, f"a number of seeds from 1 to {MAX_SEEDS:,}")
