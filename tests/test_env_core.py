"""The mission engine's contracts that both envs share: the episode summary under any time limit, the paper's task
and its observation, and the named error before the first reset."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from stable_baselines3.common.monitor import Monitor

import noma_radiomap  # noqa: F401  (registers the ids)
from noma_radiomap import NomaRadioMapEnv, load_scenario
from noma_radiomap.core import PAPER_MAX_STEPS, SUMMARY_KEYS
from noma_radiomap.vector import NomaRadioMapVecEnv
from sb3_dtdpg.evaluation import evaluate
from sb3_dtdpg.vec_env import MissionVecEnv


class StandStill:
    """A planner that never moves (missions end by the time limit only)."""

    def reset(self, env):
        pass

    def act(self, env, obs):
        return np.zeros(env.action_space.shape, dtype=np.float32)


# --- the episode summary under an outer TimeLimit ---------------------------------------------------


def test_a_shorter_time_limit_ends_with_the_episode_summary():
    env = gym.make("NomaRadioMap-v0", scenario="small", max_episode_steps=5)
    env.reset(seed=0)
    for _ in range(5):
        _, _, terminated, truncated, info = env.step(np.zeros(6, dtype=np.float32))
    assert truncated and not terminated
    assert set(SUMMARY_KEYS) <= set(info)
    base = env.unwrapped
    assert info["is_success"] is False and info["mqi"] == base.episode_summary()["mqi"]
    mission = base.scenario.mission
    assert info["mqi"] == mission.t_total - (2 * base.max_steps + mission.outage_penalty * info["outage_steps"].sum())


def test_monitor_info_keywords_and_evaluate_under_a_shorter_time_limit():
    env = Monitor(gym.make("NomaRadioMap-v0", scenario="small", max_episode_steps=5), info_keywords=SUMMARY_KEYS)
    env.reset(seed=0)
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(np.zeros(6, dtype=np.float32))
        done = terminated or truncated
    assert info["episode"]["l"] == 5 and set(SUMMARY_KEYS) <= set(info["episode"])
    result = evaluate(StandStill(), gym.make("NomaRadioMap-v0", scenario="small", max_episode_steps=5), n_episodes=2)
    assert result.n_episodes == 2 and result.success_rate == 0.0


# --- the paper's task -------------------------------------------------------------------------------


def test_paper_task_observes_positions_and_gains_only():
    env = gym.make("NomaRadioMapPaper-v0")
    base = env.unwrapped
    n_robots = base.n_robots
    assert env.observation_space.shape == (3 * n_robots,)
    assert base.observation == "paper" and base.task == "paper"
    assert env.spec.max_episode_steps == PAPER_MAX_STEPS and base.scenario.mission.t_total == PAPER_MAX_STEPS
    starts = [[1.75, 16.25], [1.75, 20.25]]  # in mall's start areas
    obs, _ = env.reset(seed=0, options={"starts": starts})
    # The destination is fixed: the scenario's first listed one per robot
    first = [robot.destinations[0] for robot in load_scenario("mall").robots]
    np.testing.assert_array_equal(base.destinations, first)
    # Other destinations, the same positions: the same observation (it holds no destination, no arrived flag)
    other, _ = env.reset(seed=0, options={"starts": starts, "destinations": [[8.0, 28.0], [3.0, 4.0]]})
    np.testing.assert_array_equal(obs, other)
    # ... and it is exactly (x, y, gain) per robot, scaled as the other layouts scale them
    room = np.array([base.scenario.room.width, base.scenario.room.depth])
    per_robot = obs.reshape(n_robots, 3)
    np.testing.assert_allclose(per_robot[:, :2], 2 * np.array(starts) / room - 1, atol=1e-6)
    destinations = NomaRadioMapEnv(observation="destinations")
    full, _ = destinations.reset(seed=0, options={"starts": starts})
    np.testing.assert_array_equal(per_robot[:, 2], full.reshape(n_robots, 6)[:, 4])


def test_paper_task_draws_only_the_fixed_destination():
    env = NomaRadioMapEnv(task="paper")
    first = np.array([robot.destinations[0] for robot in env.scenario.robots])
    for seed in range(20):
        env.reset(seed=seed)
        np.testing.assert_array_equal(env.destinations, first)
    vec = NomaRadioMapVecEnv(4, task="paper")
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (4, 3 * env.n_robots)
    np.testing.assert_array_equal(vec.destinations, np.broadcast_to(first, vec.destinations.shape))


def test_default_observation_is_the_goal_layout_everywhere():
    n_robots = 2
    assert gym.make("NomaRadioMap-v0").observation_space.shape == (9 * n_robots,)
    assert NomaRadioMapEnv(scenario="small").observation_space.shape == (9 * n_robots,)
    assert NomaRadioMapVecEnv(2, scenario="small").single_observation_space.shape == (9 * n_robots,)
    assert MissionVecEnv(2, scenario="small").observation_space.shape == (9 * n_robots,)
    with pytest.raises(ValueError, match="observation must be one of"):
        NomaRadioMapEnv(scenario="small", observation="positions")
    with pytest.raises(ValueError, match="task must be one of"):
        NomaRadioMapEnv(scenario="small", task="fixed")


# --- before the first reset -------------------------------------------------------------------------


@pytest.mark.parametrize("call", ["step", "render", "trajectory", "episode_summary"])
def test_single_env_before_reset_raises_reset_needed(call):
    env = NomaRadioMapEnv(scenario="small", render_mode="rgb_array")
    actions = {
        "step": lambda: env.step(np.zeros(6)),
        "render": env.render,
        "trajectory": lambda: env.trajectory,
        "episode_summary": env.episode_summary,
    }
    with pytest.raises(ResetNeeded, match=r"call reset\(\) first"):
        actions[call]()
    env.reset(seed=0)
    actions[call]()  # works once reset


def test_vector_envs_before_reset_raise_reset_needed():
    vec = NomaRadioMapVecEnv(2, scenario="small")
    with pytest.raises(ResetNeeded, match=r"call reset\(\) first"):
        vec.step(np.zeros((2, 6)))
    with pytest.raises(ResetNeeded, match=r"call reset\(\) first"):
        vec.mission(1).episode_summary()
    with pytest.raises(ResetNeeded, match=r"call reset\(\) first"):
        MissionVecEnv(2, scenario="small").step(np.zeros((2, 6)))
    # A partial reset leaves the other mission unusable
    vec.reset(seed=0, options={"reset_mask": [True, False]})
    with pytest.raises(ResetNeeded):
        vec.step(np.zeros((2, 6)))
    vec.reset(seed=0)
    _, rewards, _, _, infos = vec.step(np.zeros((2, 6)))
    assert rewards.shape == (2,) and infos["_mqi"].all()


def test_infos_of_a_batch_are_the_info_of_each_mission():
    from noma_radiomap.core import INFO_KEYS, MissionCore

    core = MissionCore(5, "small", channel="rayleigh")
    core.reset(np.arange(5), list(range(5)))
    rng = np.random.default_rng(0)
    for _ in range(30):
        result = core.step(rng.uniform(-1, 1, (5, 2, 3)), slice(None))
        for k, batched in enumerate(result.infos()):
            single = result.info(k)
            assert list(batched) == list(single) == ["reward_components", *INFO_KEYS, *SUMMARY_KEYS]
            for key, value in single.items():
                assert type(batched[key]) is type(value)
                np.testing.assert_equal(batched[key], value)


def test_a_robot_off_the_free_space_raises_before_anything_changes():
    env = gym.make("NomaRadioMap-v0", scenario="small").unwrapped
    env.reset(seed=0)
    core = env.core
    blocked = np.argwhere(core.radio_map.blocked)[0]
    core.positions[0, 1] = (blocked + 0.5) * core.scenario.room.resolution
    state = [array.copy() for array in (core.positions, core.step_counts, core.outage_steps, core.gain_db)]
    with pytest.raises(ValueError, match=r"positions\[0, 1\]: .* is outside the room or in a blocked cell"):
        env.step(np.zeros(3 * core.n_robots))
    for before, after in zip(state, (core.positions, core.step_counts, core.outage_steps, core.gain_db), strict=True):
        np.testing.assert_array_equal(before, after)


# --- refused resets ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ([{}], r"options: expected a dict of reset options \(or None\), got list"),
        ("starts", r"options: expected a dict of reset options \(or None\), got str"),
        ({"starts": [[1.0, 1.0], [100.0, 100.0]]}, r"options\['starts'\]\[1\]: \[100\.0, 100\.0\] is outside the room"),
        ({"starts": [[1.0, 1.0], [1.0, 6.0]], "destinations": [[1.2, 1.2], [9.0, 4.0]]}, r"already within arrival"),
    ],
)
def test_a_refused_single_env_reset_leaves_the_env_as_it_was(options, match):
    env, twin = NomaRadioMapEnv(scenario="small", channel="rayleigh"), NomaRadioMapEnv(scenario="small", channel="rayleigh")
    rng = np.random.default_rng(3)
    for e in (env, twin):
        e.reset(seed=0)
    for _ in range(3):
        action = rng.uniform(-1, 1, 6)
        for e in (env, twin):
            e.step(action)
    generator, state = env.np_random, env.np_random.bit_generator.state
    positions, trajectory, steps = env.positions, env.trajectory, env.step_count
    with pytest.raises(ValueError, match=match):
        env.reset(seed=9, options=options)
    assert env.np_random is generator and env.np_random.bit_generator.state == state and env.core.np_randoms[0] is generator
    np.testing.assert_array_equal(env.positions, positions)
    np.testing.assert_array_equal(env.trajectory, trajectory)
    assert env.step_count == steps == 3
    for _ in range(2):  # the Rayleigh channel draws from the generator every step: the same draws as the twin's
        action = rng.uniform(-1, 1, 6)
        for a, b in zip(env.step(action), twin.step(action), strict=True):
            np.testing.assert_equal(a, b)
    np.testing.assert_array_equal(env.reset()[0], twin.reset()[0])
