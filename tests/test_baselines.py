"""The algorithm set (sb3_dtdpg.baselines): every algorithm in NOMA and OMA, with its documented settings."""

from pathlib import Path

import numpy as np
import pytest
import torch as th
from sb3_contrib import TQC
from stable_baselines3 import DDPG, SAC, TD3
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

from sb3_dtdpg import DTDPG, presets
from sb3_dtdpg.baselines import (
    ALGORITHMS,
    DDPG_OU_SIGMA,
    algorithm_class,
    base_learning_rate,
    make_env,
    make_model,
    reward_phase,
)
from sb3_dtdpg.dtdpg.lean import LeanDDPG

ZOO_CONFIGS = Path(__file__).resolve().parents[1] / "zoo_configs"


@pytest.mark.parametrize("algo", ALGORITHMS)
@pytest.mark.parametrize("multiple_access", ["noma", "oma"])
def test_every_algorithm_trains_in_both_modes(algo, multiple_access):
    env = make_env(algo, multiple_access=multiple_access, env_kwargs={"scenario": "small"})
    assert env.unwrapped.multiple_access == multiple_access
    assert env.unwrapped.reward_phase == reward_phase(algo)
    model = make_model(algo, env, seed=0, learning_starts=10, batch_size=8)
    assert isinstance(model, algorithm_class(algo))
    model.learn(30)
    assert model.num_timesteps == 30
    action, _ = model.predict(env.observation_space.sample(), deterministic=True)
    assert env.action_space.contains(action)


def test_ddpg_is_the_papers_plain_baseline():
    env = make_env("ddpg", env_kwargs={"scenario": "small"})
    model = make_model("ddpg", env, seed=0)
    assert type(model) is LeanDDPG and isinstance(model, DDPG) and not isinstance(model, DTDPG)
    assert env.unwrapped.reward_phase == "combined"
    # Plain MLP (no batch norm), DT-DPG's sizes and Table I hyperparameters, constant OU noise.
    assert not any(isinstance(m, th.nn.BatchNorm1d) for m in model.policy.modules())
    assert (model.learning_rate, model.batch_size, model.tau, model.buffer_size) == (1e-4, 64, 0.002, 50_000)
    assert isinstance(model.action_noise, OrnsteinUhlenbeckActionNoise)
    np.testing.assert_allclose(model.action_noise.sigma, DDPG_OU_SIGMA)


@pytest.mark.parametrize("hyperparams", ["paper", "tuned"])
def test_the_ddpg_baseline_trains_as_sb3s_own_ddpg_bit_for_bit(hyperparams):
    """make_model("ddpg") runs SB3's DDPG with the lean step: the weights, batch for batch, are SB3's DDPG's."""
    short = dict(learning_starts=50, batch_size=16, buffer_size=2_000)
    models = []
    for build in ("make_model", "sb3"):
        env = make_env("ddpg", env_kwargs={"scenario": "small"})
        if build == "make_model":
            model = make_model("ddpg", env, seed=5, hyperparams=hyperparams, **short)
        else:
            options = presets.model_kwargs("ddpg", hyperparams, env.action_space, curriculum=False)
            model = DDPG("MlpPolicy", env, seed=5, **{**options, **short})
        models.append(model.learn(400))
    lean, sb3 = models
    assert type(sb3) is DDPG and sb3.actor.optimizer.state  # SB3's generic step has trained
    assert lean._n_updates == sb3._n_updates > 300
    lean_state, sb3_state = lean.policy.state_dict(), sb3.policy.state_dict()
    assert lean_state.keys() == sb3_state.keys()
    for name, value in sb3_state.items():
        assert th.equal(lean_state[name], value), name


def test_dtdpg_starts_in_the_destination_phase_and_others_use_the_combined_reward():
    assert reward_phase("dtdpg") == "destination"
    assert {reward_phase(a) for a in ALGORITHMS if a != "dtdpg"} == {"combined"}
    td3 = make_model("td3", make_env("td3", env_kwargs={"scenario": "small"}))
    assert isinstance(td3.action_noise, NormalActionNoise)
    assert type(make_model("sac", make_env("sac", env_kwargs={"scenario": "small"}))) is SAC
    assert type(make_model("tqc", make_env("tqc", env_kwargs={"scenario": "small"}))) is TQC
    assert type(td3) is TD3


def test_options_are_validated():
    with pytest.raises(ValueError, match="algo must be one of"):
        make_env("ppo")
    with pytest.raises(ValueError, match="destination_episodes"):
        make_model("ddpg", make_env("ddpg", env_kwargs={"scenario": "small"}), destination_episodes=10)
    model = make_model("dtdpg", make_env("dtdpg", env_kwargs={"scenario": "small"}), destination_episodes=7)
    assert model.phases[0].n_episodes == 7 and model.phases[0].reward_phase == "destination"
    assert make_model("dtdpg", make_env("dtdpg", env_kwargs={"scenario": "small"}), learning_rate=1e-3).learning_rate == 1e-3


@pytest.mark.parametrize("algo", ["dtdpg", "ddpg"])
def test_tuned_hyperparameters_are_shared_by_dtdpg_and_ddpg(algo):
    model = make_model(algo, make_env(algo, env_kwargs={"scenario": "small"}), seed=0, hyperparams="tuned")
    got = (model.learning_rate, model.batch_size, model.tau, model.gamma, model.buffer_size, model.learning_starts)
    assert got == (1e-3, 128, 0.005, 0.95, 200_000, 2000)
    assert isinstance(model.replay_buffer, NStepReplayBuffer) and model.replay_buffer.n_steps == 3
    assert model.replay_buffer.gamma == 0.95
    first_layer = next(m for m in model.actor.modules() if isinstance(m, th.nn.Linear))
    assert first_layer.out_features == 128
    assert base_learning_rate(algo, "tuned") == model.learning_rate
    if algo == "ddpg":  # still the paper's plain baseline: no batch norm, constant OU noise
        assert not any(isinstance(m, th.nn.BatchNorm1d) for m in model.policy.modules())
        assert isinstance(model.action_noise, OrnsteinUhlenbeckActionNoise)


def test_paper_learning_rates():
    assert base_learning_rate("dtdpg") == 1e-4 == base_learning_rate("ddpg")
    assert base_learning_rate("sac") == SAC("MlpPolicy", "Pendulum-v1").learning_rate
    with pytest.raises(ValueError, match="hyperparams must be one of"):
        base_learning_rate("dtdpg", "fast")
    with pytest.raises(ValueError, match="'tuned' is defined for 'dtdpg' and 'ddpg' only, got algo='td3'"):
        make_model("td3", make_env("td3", env_kwargs={"scenario": "small"}), hyperparams="tuned")


def test_building_a_model_leaves_the_callers_dicts_as_given():
    # DDPG wrote n_critics=1 into the policy_kwargs it was given: a TD3 built next from the same dict had one critic
    from sb3_dtdpg.presets import model_settings

    env_kwargs = {"scenario": "small"}
    policy_kwargs, buffer_kwargs = {"net_arch": [16, 16]}, {"handle_timeout_termination": True}
    given = {"policy_kwargs": policy_kwargs, "n_steps": 3, "replay_buffer_kwargs": buffer_kwargs, "learning_starts": 10}
    for algo in ("ddpg", "dtdpg", "sac", "td3"):
        make_model(algo, make_env(algo, env_kwargs=env_kwargs), seed=0, **given)
        assert policy_kwargs == {"net_arch": [16, 16]} and buffer_kwargs == {"handle_timeout_termination": True}, algo
    td3 = make_model("td3", make_env("td3", env_kwargs=env_kwargs), seed=0, **given)
    assert len(td3.critic.q_networks) == 2  # TD3's twin critics (was 1, DDPG's)
    # two runs of one settings dict build the same nets, whatever was built between them
    settings = [model_settings(make_model("ddpg", make_env("ddpg", env_kwargs=env_kwargs), seed=0, **given)) for _ in "ab"]
    assert settings[0] == settings[1] and settings[0]["policy_kwargs"] == {"net_arch": [16, 16], "n_critics": 1}
    assert model_settings(td3) == model_settings(make_model("td3", make_env("td3", env_kwargs=env_kwargs), seed=0, **given))
    # DTDPG itself, built directly, copies them too
    DTDPG("MlpPolicy", make_env("dtdpg", env_kwargs=env_kwargs), policy_kwargs=policy_kwargs, _init_setup_model=False)
    assert policy_kwargs == {"net_arch": [16, 16]}
