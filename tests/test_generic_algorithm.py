"""DTDPG knows no env: any reward-phase names work, the default curriculum is the env's own or a single phase,
and mission logging is opt-in."""

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from phased_env import PhasedPointEnv
from stable_baselines3.common.logger import Logger

from sb3_dtdpg import DTDPG, MissionLoggerCallback


class PendulumPhases(gym.Wrapper):
    """Pendulum with two reward phases of its own: "explore" adds a bonus for speed, "exploit" is Pendulum's reward."""

    REWARD_PHASES = ("explore", "exploit")

    def __init__(self, curriculum: Any = None) -> None:
        super().__init__(gym.make("Pendulum-v1", max_episode_steps=50))
        self.reward_phase = "explore"
        self.phases_seen = ["explore"]
        if curriculum is not None:
            self.default_curriculum = curriculum

    def set_reward_phase(self, name: str) -> None:
        if name not in self.REWARD_PHASES:
            raise ValueError(f"reward_phase must be one of {self.REWARD_PHASES}, got {name!r}")
        self.reward_phase = name
        self.phases_seen.append(name)

    def step(self, action: np.ndarray) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        bonus = 0.1 * abs(float(obs[2])) if self.reward_phase == "explore" else 0.0
        return obs, float(reward) + bonus, terminated, truncated, info


def test_an_env_with_its_own_phase_names_trains_with_the_defaults():
    env = PendulumPhases()
    model = DTDPG("MlpPolicy", env, seed=0)
    assert [(phase.name, phase.reward_phase) for phase in model.phases] == [("train", None)]
    model.learn(300)
    assert model.num_timesteps == 300
    assert env.phases_seen == ["explore"]  # one phase that leaves the env's reward alone


def test_the_envs_curriculum_with_any_phase_names():
    curriculum = [
        {"name": "explore", "n_episodes": 2, "sigma": 0.3, "final_sigma": 0.1},
        {"name": "exploit", "sigma": 0.2},
    ]
    env = PendulumPhases(curriculum)
    model = DTDPG("MlpPolicy", env, seed=0, learning_starts=50, batch_size=32)
    assert [phase.reward_phase for phase in model.phases] == ["explore", "exploit"]
    model.learn(150)  # 2 episodes of 50 steps, then the transfer
    assert model.curriculum_state["phase_index"] == 1
    assert env.phases_seen[-1] == "exploit" and env.reward_phase == "exploit"
    np.testing.assert_allclose(model.action_noise.current_sigma, [0.2])


class _KeyLogger(Logger):
    def __init__(self) -> None:
        super().__init__(folder=None, output_formats=[])
        self.keys: set[str] = set()

    def record(self, key: str, *args: Any, **kwargs: Any) -> None:
        self.keys.add(key)
        super().record(key, *args, **kwargs)

    def record_mean(self, key: str, *args: Any, **kwargs: Any) -> None:
        self.keys.add(key)
        super().record_mean(key, *args, **kwargs)


@pytest.mark.parametrize("opt_in", [False, True])
def test_mission_logging_is_opt_in(opt_in):
    model = DTDPG("MlpPolicy", PhasedPointEnv(), learning_starts=10, batch_size=8, policy_kwargs=dict(net_arch=[8]))
    logger = _KeyLogger()
    model.set_logger(logger)
    model.learn(60, callback=[MissionLoggerCallback()] if opt_in else None, log_interval=1)
    assert ("mission/success_rate" in logger.keys) is opt_in
    assert "curriculum/phase" in logger.keys
