"""The learning extensions: the goal-conditioned observation wrapper and replay seeded with demonstrations."""

import re

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3 import DDPG
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

from noma_radiomap.planners import ShortestPathPlanner
from noma_radiomap.propagation import dbm_to_watt
from noma_radiomap.wrappers import RelativeGoalObservation, power_shares
from sb3_dtdpg import DTDPG
from sb3_dtdpg.common.buffers import RewardComponentsReplayBuffer
from sb3_dtdpg.common.demonstrations import DemonstrationCallback
from sb3_dtdpg.vec_env import make_mission_vec_env


def _small(**kwargs) -> gym.Env:
    return gym.make("NomaRadioMap-v0", scenario="small", **{"observation": "destinations", **kwargs})


def test_relative_goal_features_point_at_the_destination():
    env = RelativeGoalObservation(_small(), distance_scale=4.0)
    obs, _ = env.reset(seed=3)
    base = env.unwrapped
    assert obs.shape == (9 * base.n_robots,) and env.observation_space.contains(obs)
    plain_obs, _ = _small().reset(seed=3)
    np.testing.assert_array_equal(obs[: 6 * base.n_robots], plain_obs)
    for u, (ux, uy, dist) in enumerate(obs[6 * base.n_robots :].reshape(-1, 3)):
        offset = base.destinations[u] - base.positions[u]
        d = np.hypot(*offset)
        np.testing.assert_allclose([ux, uy], offset / d, rtol=1e-6)
        assert dist == pytest.approx(min(d / 4.0, 1.0), rel=1e-6)


def test_relative_goal_features_are_zero_once_arrived():
    env = RelativeGoalObservation(_small())
    env.reset(seed=0)
    planner = ShortestPathPlanner()
    planner.reset(env.unwrapped)
    obs, done = None, False
    while not done:
        obs, _, terminated, truncated, _ = env.step(planner.act(env.unwrapped, obs))
        done = terminated or truncated
        arrived = env.unwrapped.arrived
        features = obs[-3 * len(arrived) :].reshape(-1, 3)
        assert np.all(features[arrived] == 0) and np.all(features[~arrived, 2] > 0)
    assert terminated and arrived.all()


def test_power_shares_give_the_robots_under_way_the_whole_ap_power():
    actions = np.array([0.5, 0.0, 0.2, 0.5, 0.0, -0.8], dtype=np.float32)  # asking for 0.6 and 0.1 of P_max
    powers, positions = {}, {}
    for mapping in ("paper", "shares"):
        env = gym.make("NomaRadioMap-v0", power_mapping=mapping)
        env.reset(seed=0)
        powers[mapping] = env.step(actions)[4]["power_w"]
        positions[mapping] = env.unwrapped.positions.copy()
        max_power = float(dbm_to_watt(env.unwrapped.scenario.ap.max_power_dbm))
    assert powers["paper"] == pytest.approx(np.array([0.6, 0.1]) * max_power)  # the paper's: 0.3 of P_max unused
    assert powers["shares"] == pytest.approx(np.array([6.0, 1.0]) / 7.0 * max_power)  # the whole P_max, same ratio
    assert env.step(np.array([0.5, 0.0, -1.0, 0.5, 0.0, -1.0]))[4]["power_w"].tolist() == [0.0, 0.0]  # nothing asked
    assert np.array_equal(positions["paper"], positions["shares"])  # the motion components pass unchanged
    # A NaN power is refused by the env, not turned into "no power"
    with pytest.raises(ValueError, match="power"):
        env.step(np.array([0.5, 0.0, np.nan, 0.5, 0.0, 0.0]))
    # An arrived robot's wish does not count
    assert power_shares(np.array([0.2, 1.0]), np.array([True, False])) == pytest.approx([1.0, -1.0])
    with pytest.raises(ValueError, match=r"power_mapping must be one of \['paper', 'shares'\], got 'equal'"):
        gym.make("NomaRadioMap-v0", power_mapping="equal")
    with pytest.raises(ValueError, match="the batched env has the paper's mapping only"):
        gym.make_vec("NomaRadioMap-v0", num_envs=2, power_mapping="shares")
    with pytest.raises(ValueError, match="the batched env has the paper's mapping only"):
        make_mission_vec_env("NomaRadioMap-v0", n_envs=2, seed=0, env_kwargs={"power_mapping": "shares"})


# The wrapper itself is what is checked here, so gymnasium's advice to check env.unwrapped does not apply
@pytest.mark.filterwarnings("ignore:.*is different from the unwrapped version")
def test_relative_goal_wrapper_passes_the_env_checker_and_keeps_reward_phases():
    env = RelativeGoalObservation(_small())
    check_env(env, skip_render_check=True)
    env.get_wrapper_attr("set_reward_phase")("mqi")
    assert env.unwrapped.reward_phase == "mqi"
    for bad in (0.0, float("inf"), "10", None, True):  # a string or None was numpy's TypeError, True taken as 1 m
        with pytest.raises(ValueError, match=rf"distance_scale must be a finite number > 0, got {re.escape(repr(bad))}"):
            RelativeGoalObservation(_small(), distance_scale=bad)
    assert RelativeGoalObservation(_small(), distance_scale=np.float32(4.0)).distance_scale == 4.0


def test_demonstrations_fill_the_replay_buffer_before_training():
    env = make_vec_env(lambda: _small(reward_phase="destination"), n_envs=1, seed=0)
    model = DDPG(
        "MlpPolicy",
        env,
        learning_starts=10_000,
        replay_buffer_class=RewardComponentsReplayBuffer,
        policy_kwargs=dict(net_arch=[8]),
        seed=0,
    )
    demos = DemonstrationCallback(ShortestPathPlanner(), n_episodes=3)
    model.learn(5, callback=demos)
    buffer = model.replay_buffer
    assert demos.transitions == buffer.pos - 5 and model.num_timesteps == 5
    stored = slice(0, demos.transitions)
    # three complete, successful episodes: three terminal transitions, each with the success reward
    assert buffer.dones[stored].sum() == 3 and buffer.timeouts[stored].sum() == 0
    components = buffer.reward_components[stored, 0]
    assert (components[:, list(buffer.component_keys).index("success")] > 0).sum() == 3
    # the stored rewards are the env's destination-phase rewards, recomputable from the components
    weights = env.env_method("reward_weights", "destination")[0]
    recomputed = components @ np.array([weights[name] for name in buffer.component_keys])
    np.testing.assert_allclose(buffer.rewards[stored, 0], recomputed, rtol=1e-5)
    # a second learn() does not seed again
    model.learn(5, callback=demos, reset_num_timesteps=False)
    assert buffer.pos == demos.transitions + 10


def test_demonstrations_need_one_env():
    env = make_vec_env(lambda: _small(), n_envs=2, seed=0)
    model = DDPG("MlpPolicy", env, learning_starts=100, policy_kwargs=dict(net_arch=[8]))
    with pytest.raises(ValueError, match="one env"):
        model.learn(4, callback=DemonstrationCallback(ShortestPathPlanner(), n_episodes=1))
    with pytest.raises(ValueError, match="n_episodes"):
        DemonstrationCallback(ShortestPathPlanner(), n_episodes=0)


def test_demonstrations_seed_a_model_once_also_across_learn_calls_and_save_load(tmp_path):
    env = make_vec_env(lambda: _small(), n_envs=1, seed=0)
    model = DTDPG("MlpPolicy", env, learning_starts=10_000, policy_kwargs=dict(net_arch=[8]), seed=0)
    demos = DemonstrationCallback(ShortestPathPlanner(), n_episodes=2)
    model.learn(5, callback=demos)
    seeded = demos.transitions
    assert seeded > 0 and model.replay_buffer.pos == seeded + 5
    model.learn(5, callback=demos)  # reset_num_timesteps=True, the default: was seeded a second time
    assert model.replay_buffer.pos == seeded + 10 and demos.transitions == seeded
    model.save(tmp_path / "model.zip")
    loaded = DTDPG.load(tmp_path / "model.zip", env=env)
    other = DemonstrationCallback(ShortestPathPlanner(), n_episodes=2)
    loaded.learn(5, callback=other)
    assert other.transitions == 0 and loaded.replay_buffer.pos == 5


class _Overshooting(ShortestPathPlanner):
    """The shortest path planner asking for 1.5 times its motion, beyond the action space: the env clips it."""

    def __init__(self) -> None:
        super().__init__()
        self.actions: list[np.ndarray] = []

    def act(self, env: gym.Env, observation: np.ndarray) -> np.ndarray:
        action = np.array(super().act(env, observation), dtype=np.float32)
        action[0::3] *= 1.5
        self.actions.append(action)
        return action


def test_demonstrated_actions_are_stored_as_the_env_executed_them():
    env = make_vec_env(lambda: _small(), n_envs=1, seed=0)
    model = DDPG("MlpPolicy", env, learning_starts=10_000, policy_kwargs=dict(net_arch=[8]), seed=0)
    planner = _Overshooting()
    demos = DemonstrationCallback(planner, n_episodes=1)
    model.learn(1, callback=demos)
    asked = np.array(planner.actions)
    space = model.action_space
    assert (asked > space.high).any()  # the planner did overshoot
    stored = model.replay_buffer.actions[: demos.transitions, 0]
    # what SB3 stores for an executed action: the clipped action scaled to [-1, 1] (was: 1.5 times the motion)
    np.testing.assert_array_equal(stored, model.policy.scale_action(np.clip(asked, space.low, space.high)))
    assert stored.min() >= -1 and stored.max() <= 1

    class Scalar(ShortestPathPlanner):
        def act(self, env: gym.Env, observation: np.ndarray) -> np.ndarray:
            return np.float32(0.5)  # clipping must not broadcast it to a whole action

    with pytest.raises(ValueError, match=r"the demonstrator's action has shape \(\), the action space \(6,\)"):
        DDPG("MlpPolicy", env, learning_starts=10_000, policy_kwargs=dict(net_arch=[8])).learn(
            1, callback=DemonstrationCallback(Scalar(), n_episodes=1)
        )


class _RecordingDemonstrations(DemonstrationCallback):
    def _on_training_start(self) -> None:
        super()._on_training_start()
        self.start_obs = self.model.get_env().get_original_obs().copy()


def test_under_vec_normalize_training_starts_from_the_observation_of_the_reset_after_the_demonstrations():
    env = VecNormalize(make_vec_env(lambda: _small(), n_envs=1, seed=0))
    model = DDPG("MlpPolicy", env, learning_starts=10_000, policy_kwargs=dict(net_arch=[8]), seed=0)
    demos = _RecordingDemonstrations(ShortestPathPlanner(), n_episodes=1)
    model.learn(1, callback=demos)
    # the first training transition starts from the training env's start (was: the discarded reset's observation)
    first = model.replay_buffer.observations[demos.transitions]
    np.testing.assert_array_equal(first, demos.start_obs)


def test_demonstration_arguments_are_checked_when_the_callback_is_made():
    assert DemonstrationCallback(ShortestPathPlanner(), n_episodes=np.int64(2)).n_episodes == 2  # was refused
    for bad in (True, np.bool_(True), 2.0, "2", None):
        with pytest.raises(ValueError, match=rf"n_episodes must be a positive integer, got {re.escape(repr(bad))}"):
            DemonstrationCallback(ShortestPathPlanner(), n_episodes=bad)
    # were an AttributeError when training started
    with pytest.raises(ValueError, match=r"demonstrator must have the methods .*got None, which lacks reset and act"):
        DemonstrationCallback(None, n_episodes=1)

    class ResetOnly:
        def reset(self, env: gym.Env) -> None: ...

    with pytest.raises(ValueError, match=r"demonstrator must have the methods .*, which lacks act$"):
        DemonstrationCallback(ResetOnly(), n_episodes=1)


def test_goal_observation_through_gymnasium_make():
    env = gym.make("NomaRadioMap-v0", scenario="small", observation="goal")
    obs, _ = env.reset(seed=1)
    assert obs.shape == (18,) and env.observation_space.shape == (18,)
    assert env.spec.max_episode_steps == 60
    plain_obs, _ = _small().reset(seed=1)
    np.testing.assert_array_equal(obs[:12], plain_obs)
    with pytest.raises(ValueError, match=r"observation must be one of .*'relative'"):
        gym.make("NomaRadioMap-v0", observation="relative")
