"""Learning sanity checks: DTDPG's tuned preset learns the ``small`` mission (default suite, under a minute), and
DTDPG with RL Zoo's DDPG hyperparameters solves Pendulum-v1 (``pytest -m slow``: 20k steps, about 2 minutes on a
2-core machine). The long learning measurements live in benchmarks/ (benchmarks/targets.py,
benchmarks/diagnosis.py; docs/BENCHMARKS.md).
"""

import inspect
from importlib import resources

import gymnasium as gym
import numpy as np
import pytest
import yaml
from stable_baselines3 import DDPG
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.noise import NormalActionNoise

from sb3_dtdpg import DTDPG


def _zoo_ddpg_hyperparameters(env_id: str) -> tuple[int, dict]:
    """RL Zoo's tuned DDPG entry, completed with DDPG's own defaults for what it leaves out (batch size, tau)."""
    with resources.files("rl_zoo3").joinpath("hyperparams/ddpg.yml").open() as file:
        config = dict(yaml.safe_load(file)[env_id])
    n_timesteps = int(config.pop("n_timesteps"))
    assert config.pop("policy") == "MlpPolicy"
    assert config.pop("noise_type") == "normal"
    noise_std = config.pop("noise_std")
    config["policy_kwargs"] = eval(config["policy_kwargs"])  # the zoo's own format: a Python literal
    defaults = {
        name: parameter.default
        for name, parameter in inspect.signature(DDPG.__init__).parameters.items()
        if name in ("batch_size", "tau", "gamma", "learning_starts", "train_freq", "gradient_steps", "buffer_size")
    }
    config = defaults | config
    config["action_noise"] = NormalActionNoise(np.zeros(1), noise_std * np.ones(1))
    return n_timesteps, config


@pytest.mark.slow
def test_pendulum_with_zoo_ddpg_hyperparameters():
    n_timesteps, hyperparams = _zoo_ddpg_hyperparameters("Pendulum-v1")
    assert n_timesteps == 20_000
    model = DTDPG("MlpPolicy", "Pendulum-v1", seed=0, **hyperparams)
    model.learn(n_timesteps)
    mean_reward, _ = evaluate_policy(model, Monitor(gym.make("Pendulum-v1")), n_eval_episodes=10, deterministic=True)
    assert mean_reward >= -300


def test_default_hyperparameters_learn_the_small_mission():
    """The tuned preset learns ``small`` in 10k steps; Table I's values do not.

    Measured (2026-12-01, 20 Rayleigh test missions, seed 10 000): the tuned settings bring both robots home in 35 %
    (seed 0) and 45 % (seed 1) of the missions after 10k steps, Table I's values (lr 1e-4, batch 64, tau 0.002,
    buffer 5e4, gamma 0.99) in 0 % on both seeds. The threshold sits between the two.
    """
    from sb3_dtdpg.evaluation import evaluate
    from sb3_dtdpg.presets import preset

    env = gym.make("NomaRadioMap-v0", scenario="small")
    model = DTDPG("MlpPolicy", env, seed=0, **preset("tuned", destination_episodes=150)).learn(10_000)
    result = evaluate(model, "NomaRadioMap-v0", n_episodes=20, seed=10_000, env_kwargs={"scenario": "small"})
    assert result.success_rate >= 0.2
