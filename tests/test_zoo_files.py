"""The RL Zoo files are the presets: each zoo_configs/*.yml is what sb3_dtdpg.zoo_files writes from sb3_dtdpg.presets."""

from pathlib import Path

import gymnasium as gym
import pytest
import yaml

import noma_radiomap  # noqa: F401  (registers the env ids)
from sb3_dtdpg import presets
from sb3_dtdpg.common.phases import parse_phases
from sb3_dtdpg.zoo_files import FILES, MISSION_IDS, PAPER_IDS, env_ids, n_timesteps, write_zoo_files, zoo_entries, zoo_text

CONFIGS = Path(__file__).resolve().parents[1] / "zoo_configs"


@pytest.mark.parametrize("name", sorted(FILES))
def test_each_file_is_written_from_the_presets(name):
    assert (CONFIGS / f"{name}.yml").read_text() == zoo_text(name), "run: python -m sb3_dtdpg.zoo_files zoo_configs"
    entries = yaml.safe_load((CONFIGS / f"{name}.yml").read_text())
    assert entries == zoo_entries(name)
    algo, preset, _, _ = FILES[name]
    expected = presets.settings(algo, preset)
    assert set(entries) - {"Pendulum-v1"} == set(env_ids(name))
    for env_id in env_ids(name):
        entry = entries[env_id]
        assert {key: entry[key] for key in expected if key != "phases"} == {k: v for k, v in expected.items() if k != "phases"}
        if "phases" in expected:
            assert parse_phases(entry["phases"]) == parse_phases(expected["phases"])


def test_every_file_is_shipped_and_no_other(tmp_path):
    assert sorted(path.name for path in CONFIGS.glob("*.yml")) == sorted(f"{name}.yml" for name in FILES)
    written = write_zoo_files(tmp_path)
    assert [path.read_text() for path in written] == [(CONFIGS / path.name).read_text() for path in written]


def _load(name: str) -> dict:
    return yaml.safe_load((CONFIGS / f"{name}.yml").read_text())


def _max_episode_steps(env_id: str, env_kwargs: dict) -> int:
    env = gym.make(env_id, **env_kwargs)
    try:
        return env.spec.max_episode_steps
    finally:
        env.close()


@pytest.mark.parametrize("name", sorted(FILES))
def test_every_budget_is_the_papers_500_episodes_of_its_env(name):
    entries = _load(name)
    for env_id in env_ids(name):
        entry = entries[env_id]
        assert entry["n_timesteps"] == 500 * _max_episode_steps(env_id, entry["env_kwargs"]), env_id
        assert entry["n_timesteps"] == n_timesteps(env_id, entry["env_kwargs"])
        assert entry["callback"] == "sb3_dtdpg.MissionLoggerCallback", "mission/* scalars in every zoo run"
    assert "callback" not in entries.get("Pendulum-v1", {}), "Pendulum's infos have no mission figures"


@pytest.mark.parametrize("name", ["dtdpg_paper", "ddpg_paper"])
def test_the_paper_files_are_keyed_by_the_paper_task_ids(name):
    entries = _load(name)
    assert set(entries) == set(PAPER_IDS) == {"NomaRadioMapPaper-v0", "NomaRadioMapPaperOMA-v0"}
    assert not set(entries) & set(MISSION_IDS), "a paper-task run would be logged under a mission id"
    for env_id in PAPER_IDS:
        assert "task" not in entries[env_id]["env_kwargs"], "the env id sets it"
        env = gym.make(env_id, **entries[env_id]["env_kwargs"])
        assert env.unwrapped.task == "paper"
        assert env.spec.max_episode_steps == 1000
        env.close()
        # the paper's 500 training episodes (Table II) of 1000 steps, not 500 of the missions' 300
        assert entries[env_id]["n_timesteps"] == 500_000


def test_the_paper_dtdpg_reaches_its_mqi_phase_within_its_budget():
    for env_id, entry in _load("dtdpg_paper").items():
        max_steps = _max_episode_steps(env_id, entry["env_kwargs"])
        *before, mqi = parse_phases(entry["phases"])
        assert mqi.reward_phase == "mqi" and mqi.n_episodes is None and mqi.n_timesteps is None, "the last phase"
        # at most this many env steps before the transfer: every earlier phase run to its budget, episodes at full length
        steps_before = sum(p.n_timesteps if p.n_timesteps is not None else p.n_episodes * max_steps for p in before)
        assert steps_before < entry["n_timesteps"], f"{env_id}: the MQI phase would never start"
        # and the MQI phase gets the rest of the paper's 500 episodes, its noise's whole decay horizon
        assert entry["n_timesteps"] // max_steps - sum(p.n_episodes for p in before) >= mqi.decay_episodes == 200


def test_the_budget_follows_the_envs_episode_length():
    assert n_timesteps("NomaRadioMap-v0", {"scenario": "small"}) == 500 * 60  # small's missions: 60 steps
    assert n_timesteps("NomaRadioMapOMA-v0", {"task": "paper"}) == n_timesteps("NomaRadioMapPaperOMA-v0", {}) == 500_000
    with pytest.raises(ValueError, match=r"name must be one of \[.*\], got 'dtdpg_pape'"):
        env_ids("dtdpg_pape")
