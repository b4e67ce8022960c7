"""
The RL Zoo files ``zoo_configs/*.yml``, written from the settings sets of :mod:`sb3_dtdpg.presets`.

The files are the presets in the zoo's format (keyed by env id, with the zoo's ``n_timesteps``, ``policy``,
``env_kwargs``, ``noise_type`` and ``noise_std``); they are not edited by hand. After a change to the presets::

    python -m sb3_dtdpg.zoo_files zoo_configs

``tests/test_zoo_files.py`` fails while a file differs from what this module writes.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import Any

import yaml

from sb3_dtdpg import presets
from sb3_dtdpg.common.files import write_text
from sb3_dtdpg.common.phases import Phase

__all__ = ["FILES", "MISSION_IDS", "N_TIMESTEPS", "write_zoo_files", "zoo_entries", "zoo_text"]

#: The env ids every file has an entry for (one shared entry, YAML aliases).
MISSION_IDS: tuple[str, ...] = ("NomaRadioMap-v0", "NomaRadioMapOMA-v0", "NomaRadioMapReality-v0", "NomaRadioMapOMAReality-v0")
#: Every algorithm's budget: the paper's 500 training episodes (Table II) of at most 300 steps.
N_TIMESTEPS = 150_000

_GOAL = {"observation": "goal"}  # the goal-conditioned observation (docs/MODEL.md, "Observations")
#: file name -> (algorithm, settings set, the env's keyword arguments, what the file is)
FILES: dict[str, tuple[str, str, dict[str, Any], str]] = {
    "dtdpg": (
        "dtdpg",
        "tuned",
        {"reward_phase": "mqi", **_GOAL},
        "DT-DPG, the best measured settings (preset 'tuned'), the goal-conditioned observation; the default file of\n"
        "--algo dtdpg. The curriculum switches the reward phase; the --optimize objective keeps env_kwargs' 'mqi'.",
    ),
    "dtdpg_paper": (
        "dtdpg",
        "paper",
        {"reward_phase": "mqi", "task": "paper"},
        "DT-DPG with the paper's Table I and Section V (preset 'paper') on the paper's task: fixed destinations, Eq. (24).",
    ),
    "ddpg": (
        "ddpg",
        "tuned",
        {"reward_phase": "combined", **_GOAL},
        "Plain SB3 DDPG, the paper's baseline (plain MLP, constant OU noise, the 'combined' reward) with DT-DPG's\n"
        "tuned settings (zoo_configs/dtdpg.yml); the default file of --algo ddpg for these env ids.",
    ),
    "ddpg_paper": (
        "ddpg",
        "paper",
        {"reward_phase": "combined", "task": "paper"},
        "Plain SB3 DDPG, the paper's baseline, with Table I (zoo_configs/dtdpg_paper.yml), on the paper's task.",
    ),
    **{
        algo: (
            algo,
            "paper",
            {"reward_phase": "combined", **_GOAL},
            f"SB3{'-contrib' if algo == 'tqc' else ''} {algo.upper()}, a stronger baseline: its own defaults"
            f"{' and Gaussian exploration noise' if algo == 'td3' else ''}, the 'combined' reward.",
        )
        for algo in ("td3", "sac", "tqc")
    },
}

#: dtdpg.yml's sanity entry: the RL Zoo's DDPG settings for Pendulum-v1 with one phase of OU noise.
_PENDULUM: dict[str, Any] = {
    "n_timesteps": 20_000,
    "policy": "MlpPolicy",
    "policy_kwargs": {"net_arch": [400, 300]},
    "learning_rate": 1e-3,
    "buffer_size": 200_000,
    "learning_starts": 10_000,
    "batch_size": 256,
    "tau": 0.005,
    "gamma": 0.98,
    "train_freq": 1,
    "gradient_steps": 1,
    "phases": [{"name": "train", "reward_phase": None, "sigma": 0.1}],
}


def _phase(fields: dict[str, Any]) -> dict[str, Any]:
    """A phase's fields less those at their default (the name, and the reward phase, always shown)."""
    defaults = {field.name: field.default for field in dataclasses.fields(Phase)}
    return {key: value for key, value in fields.items() if key in ("name", "reward_phase") or value != defaults[key]}


def zoo_entries(name: str) -> dict[str, Any]:
    """
    :param name: a key of :data:`FILES`
    :return: the file's content: one entry per env id of :data:`MISSION_IDS` (and dtdpg.yml's Pendulum-v1 entry)
    """
    algo, preset, env_kwargs, _ = FILES[name]
    entry: dict[str, Any] = {"n_timesteps": N_TIMESTEPS, "policy": "MlpPolicy"}
    entry.update(presets.settings(algo, preset))
    if "phases" in entry:
        entry["phases"] = [_phase(phase) for phase in entry["phases"]]
    entry["env_kwargs"] = dict(env_kwargs)
    entries = {env_id: entry for env_id in MISSION_IDS}
    if name == "dtdpg":
        entries["Pendulum-v1"] = _PENDULUM
    return entries


def zoo_text(name: str) -> str:
    """
    :param name: a key of :data:`FILES`
    :return: the text of ``zoo_configs/<name>.yml``
    """
    _, preset, _, about = FILES[name]
    lines = [f"# {line}" for line in about.splitlines()]
    lines += [
        f"#   python -m sb3_dtdpg.train --algo {FILES[name][0]} --env NomaRadioMap-v0 --conf-file zoo_configs/{name}.yml",
        f"# Written by `python -m sb3_dtdpg.zoo_files zoo_configs` from sb3_dtdpg/presets.py (preset {preset!r}):",
        '# change the presets, not this file (docs/ZOO.md, "Presets").',
    ]
    entries = zoo_entries(name)
    first, *others = MISSION_IDS
    body = yaml.safe_dump({first: entries.pop(first)}, sort_keys=False, default_flow_style=None, width=120)
    body = body.replace(f"{first}:\n", f"{first}: &mission\n", 1)
    aliases = [f"{env_id}: *mission" for env_id in others]
    for env_id in others:
        entries.pop(env_id)
    extra = yaml.safe_dump(entries, sort_keys=False, default_flow_style=None, width=120) if entries else ""
    return "\n".join(lines) + "\n" + body + "\n".join(aliases) + "\n" + extra


def write_zoo_files(folder: str | Path) -> list[Path]:
    """
    Write every file of :data:`FILES` into a folder.

    :param folder: the folder (``zoo_configs/`` of a source checkout)
    :return: the files written
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name in FILES:
        path = folder / f"{name}.yml"
        write_text(path, zoo_text(name))
        written.append(path)
    return written


if __name__ == "__main__":  # pragma: no cover
    for path in write_zoo_files(sys.argv[1] if len(sys.argv) > 1 else "zoo_configs"):
        print(path)
