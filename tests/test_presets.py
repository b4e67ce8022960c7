"""The settings registry (sb3_dtdpg.presets): every (algorithm, preset) built, its settings read back from the model."""

import argparse
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.noise import VectorizedActionNoise

import noma_radiomap  # noqa: F401
from sb3_dtdpg import DTDPG, LinearDecayOUNoise, presets
from sb3_dtdpg.baselines import ALGORITHMS, hyperparameter, make_env, make_model
from sb3_dtdpg.cli import build_parser
from sb3_dtdpg.common.phases import parse_phases

CONFIGS = Path(__file__).resolve().parents[1] / "zoo_configs"
PAIRS = [(algo, name) for algo in ALGORITHMS for name in presets.presets_of(algo)]
#: The paper's Table I and Sec. V, as printed (not read from the package)
TABLE_ONE = {"learning_rate": 1e-4, "batch_size": 64, "tau": 0.002, "buffer_size": 50_000, "gamma": 1.0, "n_steps": 1}
#: DTDPG's constructor defaults before they became SB3's: the mission settings every `compare` run trains with
TODAYS_MISSION_DEFAULTS = {
    "learning_rate": 1e-3,
    "buffer_size": 200_000,
    "learning_starts": 2000,
    "batch_size": 128,
    "tau": 0.005,
    "gamma": 0.95,
    "n_steps": 3,
    "train_freq": [1, "step"],
    "gradient_steps": 1,
    "policy.net_arch": [128, 128],
}


def _sigma(noise):
    noise = noise.base_noise if isinstance(noise, VectorizedActionNoise) else noise
    return noise.initial_sigma if isinstance(noise, LinearDecayOUNoise) else noise.sigma


def _json_types(value, key="") -> None:
    assert value is None or isinstance(value, (bool, int, float, str, list, dict)), (key, value)
    if isinstance(value, str):
        assert "<" not in value and "(" not in value, f"{key}: a repr string {value!r}"
    for k, item in value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else []:
        _json_types(item, f"{key}.{k}")


@pytest.mark.parametrize("algo, name", PAIRS)
def test_settings_are_read_back_from_the_model_and_match_the_preset(algo, name):
    model = make_model(algo, make_env(algo, env_kwargs={"scenario": "small"}), seed=0, hyperparams=name)
    settings = presets.model_settings(model)
    _json_types(settings)
    assert json.loads(json.dumps(settings)) == settings
    # the model's actual attributes
    assert settings["learning_rate"] == model.lr_schedule(1.0) == model.policy.actor.optimizer.param_groups[0]["lr"]
    for key in ("batch_size", "gamma", "tau", "buffer_size", "learning_starts", "n_steps", "gradient_steps"):
        assert settings[key] == getattr(model, key), key
    assert settings["buffer_size"] == model.replay_buffer.buffer_size
    if isinstance(model.replay_buffer, NStepReplayBuffer):
        assert (model.replay_buffer.n_steps, model.replay_buffer.gamma) == (settings["n_steps"], settings["gamma"])
    assert settings["train_freq"] == [model.train_freq.frequency, model.train_freq.unit.value]
    assert settings["policy.net_arch"] == model.policy.net_arch
    first = next(m for m in model.actor.modules() if isinstance(m, th.nn.Linear))
    assert first.out_features == settings["policy.net_arch"][0]
    if model.action_noise is None:
        assert settings["action_noise"] is None
    else:
        np.testing.assert_array_equal(settings["action_noise"]["sigma"], _sigma(model.action_noise))
    if algo == "dtdpg":
        assert parse_phases(settings["phases"]) == model.phases
    # the preset's definition
    preset = presets.settings(algo, name)
    for key, value in preset.items():
        if key == "policy_kwargs":
            assert settings["policy.net_arch"] == value["net_arch"]
        elif key == "noise_type":
            assert settings["action_noise"]["type"].endswith(
                {"normal": "Normal", "ornstein-uhlenbeck": "OrnsteinUhlenbeck"}[value] + "ActionNoise"
            )
        elif key == "noise_std":
            assert settings["action_noise"]["sigma"] == [value] * model.action_space.shape[0]
        elif key == "train_freq":
            assert settings[key] == [value, "step"]
        else:
            assert settings[key] == value, key
        if key not in ("noise_type", "noise_std", "phases"):
            assert hyperparameter(algo, key, name) == value, key  # the CLI's budget check reads the same set


def test_dtdpg_with_the_paper_set_trains_with_table_one():
    """The run identity once recorded lr 1e-3, batch 128, gamma 0.95 for such a run, which trained with Table I."""
    model = make_model("dtdpg", make_env("dtdpg", env_kwargs={"scenario": "small"}), hyperparams="paper")
    settings = presets.model_settings(model)
    assert {key: settings[key] for key in TABLE_ONE} == TABLE_ONE
    assert (model.learning_rate, model.batch_size, model.gamma) == (1e-4, 64, 1.0)


def _table_one_model_settings(settings: dict) -> None:
    assert {key: settings[key] for key in TABLE_ONE} == TABLE_ONE
    assert all(64 <= units <= 128 for units in settings["policy.net_arch"])  # "64-128 nodes for each hidden layer"
    assert settings["policy.activation_fn"] == "torch.nn.modules.activation.ReLU"
    assert settings["policy.optimizer_class"] == "torch.optim.adam.Adam"
    phases = parse_phases(settings["phases"])
    assert [(p.reward_phase, p.sigma) for p in phases] == [("destination", 0.5), ("mqi", 0.4)]
    assert all(p.final_sigma < p.sigma for p in phases), "OU noise decayed linearly per phase"


def test_table_one_is_one_definition_that_the_cli_python_and_zoo_read(tmp_path):
    from sb3_dtdpg.zoo import ExperimentManager, register_dtdpg

    args = build_parser().parse_args(["train", "--algo", "dtdpg", "--preset", "paper", "--out", str(tmp_path)])
    cli = make_model(args.algo, make_env(args.algo), hyperparams=args.preset)
    python = DTDPG("MlpPolicy", gym.make("NomaRadioMap-v0"), **presets.preset("paper"))
    register_dtdpg()
    manager = ExperimentManager(
        argparse.Namespace(),
        "dtdpg",
        "NomaRadioMapPaper-v0",  # the paper file's env ids are the paper task's
        str(tmp_path / "zoo"),
        eval_freq=-1,
        config=str(CONFIGS / "dtdpg_paper.yml"),
    )
    zoo, _ = manager.setup_experiment()
    found = [presets.model_settings(model) for model in (cli, python, zoo)]
    for settings in found:
        _table_one_model_settings(settings)
        settings.pop("seed")  # the zoo draws one
    assert found[0] == found[1] == found[2]
    zoo.env.close()


def test_tuned_preset_is_the_former_mission_defaults():
    """`compare` (the tuned set) trains with the settings DTDPG's former defaults gave on the mission."""
    env = make_env("dtdpg", env_kwargs={"scenario": "small"})
    settings = presets.model_settings(make_model("dtdpg", env, hyperparams="tuned", destination_episodes=300))
    assert {key: settings[key] for key in TODAYS_MISSION_DEFAULTS} == TODAYS_MISSION_DEFAULTS
    assert settings["phases"] == [
        dict(name="destination", reward_phase="destination", n_episodes=300, n_timesteps=None, sigma=0.5, final_sigma=0.1,
             decay_episodes=None, success_threshold=0.95, success_window=20, replay_handling="keep"),
        dict(name="mqi", reward_phase="mqi", n_episodes=None, n_timesteps=None, sigma=0.4, final_sigma=0.05,
             decay_episodes=300, success_threshold=None, success_window=20, replay_handling="relabel"),
    ]  # fmt: skip
    assert settings["replay_buffer_class"] == "sb3_dtdpg.common.buffers.RewardComponentsNStepReplayBuffer"


def test_the_readme_line_is_the_tuned_make_model():
    env = gym.make("NomaRadioMap-v0", scenario="small")
    readme = DTDPG("MlpPolicy", env, seed=0, **presets.preset("tuned"))
    built = make_model("dtdpg", make_env("dtdpg", env_kwargs={"scenario": "small"}), seed=0, hyperparams="tuned")
    assert presets.model_settings(readme) == presets.model_settings(built)


def test_unknown_sets_are_refused():
    with pytest.raises(ValueError, match=r"preset: name must be one of \('paper', 'tuned'\), got 'Tuned'"):
        presets.preset("Tuned")  # named the CLI's option, hyperparams, which preset() does not have
    with pytest.raises(ValueError, match="hyperparams must be one of"):
        presets.settings("dtdpg", "fast")
    with pytest.raises(ValueError, match="'tuned' is defined for 'dtdpg' and 'ddpg' only, got algo='sac'"):
        presets.settings("sac", "tuned")
    with pytest.raises(ValueError, match="destination_episodes applies to 'dtdpg' only"):
        presets.model_kwargs("ddpg", "paper", gym.spaces.Box(-1, 1, (2,)), destination_episodes=3)
