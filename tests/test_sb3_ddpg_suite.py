"""SB3's own DDPG tests (tests/test_identity.py, test_run.py, test_deterministic.py of stable-baselines3), run with
DTDPG in DDPG's place and its constructor defaults: DTDPG is a drop-in for DDPG."""

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3 import DDPG
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.envs import IdentityEnvBox
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

from sb3_dtdpg import DTDPG


def _identity_reward(model_class: type[DDPG]) -> float:
    # SB3 test_identity.py::test_continuous for DDPG: 400 steps, learning rate 1e-3, its reward threshold 90
    env = IdentityEnvBox(eps=0.5)
    model = model_class("MlpPolicy", env, learning_rate=1e-3, policy_kwargs=dict(net_arch=[64, 64]), seed=0, gamma=0.95)
    model.learn(400)
    mean, _ = evaluate_policy(model, env, n_eval_episodes=20, warn=False)
    return float(mean)


def test_identity_env_box_in_400_steps():
    dtdpg = _identity_reward(DTDPG)
    assert dtdpg >= 90, f"DTDPG: {dtdpg} (SB3's threshold 90)"
    assert dtdpg >= _identity_reward(DDPG) - 1.0  # as good as DDPG, within one step's reward


@pytest.mark.parametrize(
    "action_noise",
    [NormalActionNoise(np.zeros(1), 0.1 * np.ones(1)), OrnsteinUhlenbeckActionNoise(np.zeros(1), 0.1 * np.ones(1))],
)
def test_deterministic_pg(action_noise):
    model = DTDPG(
        "MlpPolicy",
        "Pendulum-v1",
        policy_kwargs=dict(net_arch=[64, 64]),
        learning_starts=100,
        buffer_size=250,
        action_noise=action_noise,
    )
    model.learn(total_timesteps=200)
    assert model.num_timesteps == 200 and model.action_noise is action_noise


@pytest.mark.parametrize("train_freq", [4, (4, "step"), (1, "episode")])
def test_train_freq(tmp_path, train_freq):
    kwargs = dict(policy_kwargs=dict(net_arch=[64, 64]), learning_starts=100, buffer_size=10000, train_freq=train_freq)
    model = DTDPG("MlpPolicy", "Pendulum-v1", **kwargs)
    model.learn(total_timesteps=150)
    model.save(tmp_path / "test_save.zip")
    env = model.get_env()
    model = DTDPG.load(tmp_path / "test_save.zip", env=env)
    model.learn(total_timesteps=150)
    model = DTDPG.load(tmp_path / "test_save.zip", train_freq=train_freq, env=env)
    model.learn(total_timesteps=150)
    assert model.train_freq.frequency == (train_freq[0] if isinstance(train_freq, tuple) else train_freq)


@pytest.mark.parametrize("train_freq", ["4", ("1", "episode"), "non_sense", (1, "close")])
def test_train_freq_fail(train_freq):
    with pytest.raises(ValueError, match="train_freq"):
        DTDPG("MlpPolicy", "Pendulum-v1", learning_starts=100, buffer_size=10000, train_freq=train_freq).learn(250)


def test_offpolicy_multi_env():
    env = make_vec_env(lambda: gym.wrappers.TimeLimit(gym.make("Pendulum-v1"), 50), n_envs=2)
    kwargs = dict(policy_kwargs=dict(net_arch=[64], n_critics=1), buffer_size=10000, verbose=0)
    noise = NormalActionNoise(np.zeros(1), 0.1 * np.ones(1))  # converted to a VectorizedActionNoise by SB3
    DTDPG("MlpPolicy", env, learning_starts=100, train_freq=5, action_noise=noise, **kwargs).learn(total_timesteps=150)
    # gradient_steps=-1: as many gradient steps as transitions collected
    model = DTDPG("MlpPolicy", env, learning_starts=0, train_freq=3, gradient_steps=-1, action_noise=noise, **kwargs)
    model.learn(total_timesteps=3)
    assert model.logger.name_to_value["train/n_updates"] == 3 * env.num_envs


def test_deterministic_training():
    # SB3 test_deterministic.py for TD3 (DDPG's family): two seeded runs act and score the same
    results, rewards = [[], []], [[], []]
    for i in range(2):
        kwargs = dict(action_noise=NormalActionNoise(np.zeros(1), 0.1 * np.ones(1)), learning_starts=100, train_freq=4)
        model = DTDPG("MlpPolicy", "Pendulum-v1", seed=0, policy_kwargs=dict(net_arch=[64]), **kwargs)
        model.learn(500)
        env = model.get_env()
        obs = env.reset()
        for _ in range(100):
            action, _ = model.predict(obs, deterministic=False)
            obs, reward, _, _ = env.step(action)
            results[i].append(action)
            rewards[i].append(reward)
    assert sum(results[0]) == sum(results[1])
    assert sum(rewards[0]) == sum(rewards[1])
