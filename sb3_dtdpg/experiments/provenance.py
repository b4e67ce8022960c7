"""
What made a run's numbers besides its identity: the versions of the libraries it ran on and the CPU kernels
torch chose, recorded with its checkpoints and its result (``made_with``), and a warning when stored runs made
with other library versions are reused.

A run's identity (:func:`sb3_dtdpg.experiments.specs.run_identity`) leaves the versions out on purpose: an
upgrade should not refuse a folder of finished runs. But torch, numpy and SB3 change results in their last bits
(and sometimes more), so a folder reused after an upgrade mixes versions; :func:`warn_other_versions` says so.
The CPU kind changes the bits too (AVX2 and AVX-512 kernels round differently), so it is recorded, but a job
spread over machines of different kinds is normal and is not warned about.
"""

from __future__ import annotations

import platform
import warnings
from collections.abc import Mapping
from importlib import metadata
from pathlib import Path
from typing import Any

__all__ = ["RESULT_LIBRARIES", "OtherVersionsWarning", "made_with", "version_differences", "warn_other_versions"]

#: The distributions whose versions can change a run's numbers, by the name ``made_with`` records them under
RESULT_LIBRARIES: dict[str, str] = {
    "sb3_dtdpg": "sb3-dtdpg",
    "stable_baselines3": "stable-baselines3",
    "torch": "torch",
    "numpy": "numpy",
    "gymnasium": "gymnasium",
}


class OtherVersionsWarning(UserWarning):
    """Stored runs made with other library versions than the running ones are reused (or resumed)."""


def made_with() -> dict[str, str]:
    """
    :return: the running Python's version, each of :data:`RESULT_LIBRARIES`' versions (``"unknown"`` when it is
        not installed as a distribution) and ``cpu_capability``, the kernels torch runs on this CPU (e.g.
        ``"AVX512"``, ``"AVX2"``)
    """
    import torch as th

    versions = {"python": platform.python_version()}
    for name, distribution in RESULT_LIBRARIES.items():
        try:
            versions[name] = metadata.version(distribution)
        except metadata.PackageNotFoundError:
            versions[name] = "unknown"
    versions["cpu_capability"] = str(th.backends.cpu.get_cpu_capability())
    return versions


def version_differences(stored: Any, current: Mapping[str, str] | None = None) -> dict[str, tuple[str, str]]:
    """
    The libraries of :data:`RESULT_LIBRARIES` whose recorded version differs from the running one.

    :param stored: a record's ``made_with`` (a record written before versions were recorded has none: no
        difference is known)
    :param current: the running versions (default: :func:`made_with`)
    :return: ``{library: (stored version, running version)}``
    """
    if not isinstance(stored, Mapping):
        return {}
    current = made_with() if current is None else current
    return {
        name: (str(stored[name]), current[name])
        for name in RESULT_LIBRARIES
        if name in stored and str(stored[name]) != current[name]
    }


def warn_other_versions(records: Mapping[str, Mapping[str, Any] | None], where: str | Path, reused: str = "reused") -> None:
    """
    Warn (:class:`OtherVersionsWarning`) when records made with other library versions are used, naming the
    versions and how many runs have each.

    :param records: stored records (a result, a checkpoint record) by run id; None for a run without one
    :param where: the folder they are in, for the message
    :param reused: what happens to them, for the message (e.g. ``"resumed"``)
    """
    current = made_with()
    found = {run_id: version_differences(record.get("made_with"), current) for run_id, record in records.items() if record}
    other = {run_id: differences for run_id, differences in found.items() if differences}
    if not other:
        return
    counts: dict[tuple[str, str, str], int] = {}
    for differences in other.values():
        for name, (stored, running) in differences.items():
            counts[(name, stored, running)] = counts.get((name, stored, running), 0) + 1
    versions = "; ".join(
        f"{name} {stored}, now {running}: {count} run{'s' if count > 1 else ''}"
        for (name, stored, running), count in sorted(counts.items())
    )
    warnings.warn(
        f"{len(other)} of {len(found)} stored runs in {where} were made with other library versions ({versions}); "
        f"they are {reused} as they are. Use a new output folder to make every run with the running versions.",
        OtherVersionsWarning,
        stacklevel=2,  # the caller's line: a job that loads the same records twice warns once
    )
