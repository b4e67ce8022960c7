"""
The RL Zoo files ``zoo_configs/*.yml``, written from the settings sets of :mod:`sb3_dtdpg.presets`.

The files are the presets in the zoo's format (keyed by env id, with the zoo's ``n_timesteps``, ``policy``,
``env_kwargs``, ``noise_type``, ``noise_std`` and ``callback``); they are not edited by hand. Each file's budget is
the paper's 500 training episodes of its env's longest episode (:func:`n_timesteps`), and every mission entry
names :class:`sb3_dtdpg.MissionLoggerCallback`, so a zoo run logs the ``mission/*`` scalars. After a change to the
presets::

    python -m sb3_dtdpg.zoo_files zoo_configs

``tests/test_zoo_files.py`` fails while a file differs from what this module writes.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import Any

import yaml

from noma_radiomap.registration import ENV_IDS
from sb3_dtdpg import presets
from sb3_dtdpg.common.files import write_text
from sb3_dtdpg.common.phases import Phase
from sb3_dtdpg.missions import PAPER_EPISODES

__all__ = [
    "FILES",
    "MISSION_CALLBACK",
    "MISSION_IDS",
    "PAPER_IDS",
    "PAPER_TASK_FILES",
    "env_ids",
    "n_timesteps",
    "write_zoo_files",
    "zoo_entries",
    "zoo_text",
]


def _ids_of_task(task: str) -> tuple[str, ...]:
    """The registered env ids (:data:`noma_radiomap.registration.ENV_IDS`) of a task."""
    return tuple(env_id for env_id, kwargs in ENV_IDS.items() if kwargs.get("task", "missions") == task)


#: The env ids of the missions task: every file but those of :data:`PAPER_TASK_FILES` has an entry for each (one
#: shared entry, YAML aliases).
MISSION_IDS: tuple[str, ...] = _ids_of_task("missions")
#: The env ids of the paper's task (``task="paper"``, docs/MODEL.md): the keys of the files of :data:`PAPER_TASK_FILES`.
PAPER_IDS: tuple[str, ...] = _ids_of_task("paper")
#: The files of the paper's task, keyed by :data:`PAPER_IDS`.
PAPER_TASK_FILES: tuple[str, ...] = ("dtdpg_paper", "ddpg_paper")
#: The RL Zoo's ``callback`` of every mission entry: the ``mission/*`` TensorBoard scalars, for every algorithm.
MISSION_CALLBACK = "sb3_dtdpg.MissionLoggerCallback"

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
        {"reward_phase": "mqi"},
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
        {"reward_phase": "combined"},
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

#: dtdpg.yml's sanity entry: the RL Zoo's DDPG settings for Pendulum-v1 with one phase of OU noise (no ``callback``:
#: Pendulum's infos hold no mission figures).
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


def env_ids(name: str) -> tuple[str, ...]:
    """
    :param name: a key of :data:`FILES`
    :return: the env ids the file has entries for: :data:`PAPER_IDS` for the files of the paper's task
        (:data:`PAPER_TASK_FILES`), :data:`MISSION_IDS` for the others
    """
    if name not in FILES:
        raise ValueError(f"name must be one of {sorted(FILES)}, got {name!r}")
    return PAPER_IDS if name in PAPER_TASK_FILES else MISSION_IDS


def n_timesteps(env_id: str, env_kwargs: dict[str, Any]) -> int:
    """
    The paper's training budget in env steps: its :data:`~sb3_dtdpg.missions.PAPER_EPISODES` training episodes
    (Table II) of the env's longest episode.

    :param env_id: a registered env id
    :param env_kwargs: the ``gymnasium.make`` arguments (a file's ``env_kwargs``)
    :return: ``PAPER_EPISODES`` times the env's ``spec.max_episode_steps`` (the ``mall`` missions: 300 steps, the
        paper's task: 1000)
    """
    import gymnasium as gym

    env = gym.make(env_id, **env_kwargs)
    try:
        max_steps = env.spec.max_episode_steps if env.spec is not None else None
    finally:
        env.close()
    if max_steps is None:
        raise ValueError(f"env {env_id!r} with env_kwargs {env_kwargs!r} has no max_episode_steps: its budget is unbounded")
    return PAPER_EPISODES * int(max_steps)


def zoo_entries(name: str) -> dict[str, Any]:
    """
    :param name: a key of :data:`FILES`
    :return: the file's content: one entry per env id of :func:`env_ids` (and dtdpg.yml's Pendulum-v1 entry)
    """
    algo, preset, env_kwargs, _ = FILES[name]
    ids = env_ids(name)
    budgets = {env_id: n_timesteps(env_id, env_kwargs) for env_id in ids}
    if len(set(budgets.values())) > 1:
        raise ValueError(
            f"the env ids of {name}.yml have episodes of different lengths, one shared entry cannot hold "
            f"their budgets: n_timesteps {budgets}"
        )
    entry: dict[str, Any] = {"n_timesteps": budgets[ids[0]], "policy": "MlpPolicy"}
    entry.update(presets.settings(algo, preset))
    if "phases" in entry:
        entry["phases"] = [_phase(phase) for phase in entry["phases"]]
    entry["env_kwargs"] = dict(env_kwargs)
    entry["callback"] = MISSION_CALLBACK
    entries = {env_id: entry for env_id in ids}
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
        f"#   python -m sb3_dtdpg.train --algo {FILES[name][0]} --env {env_ids(name)[0]} --conf-file zoo_configs/{name}.yml",
        f"# Written by `python -m sb3_dtdpg.zoo_files zoo_configs` from sb3_dtdpg/presets.py (preset {preset!r}):",
        '# change the presets, not this file (docs/ZOO.md, "Presets").',
    ]
    entries = zoo_entries(name)
    first, *others = env_ids(name)
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
