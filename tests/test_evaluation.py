"""Evaluation metrics (sb3_dtdpg.evaluation) on scripted policies whose outcome is known."""

import gymnasium as gym
import numpy as np
import pytest
from scipy import stats

import noma_radiomap
from noma_radiomap.planners import ShortestPathPlanner
from sb3_dtdpg.evaluation import Planner, evaluate, mean_ci

# A mission on `small`: robot 0 from the bottom-left room to (10, 2) through the doorway, robot 1 to (9, 4).
MISSION = {"starts": [[1.25, 1.25], [1.25, 6.75]], "destinations": [[10.0, 2.0], [9.0, 4.0]]}


class StandStill:
    """An SB3-style predictor that never moves and gives no power: every step is an outage for every robot."""

    def predict(self, observation, state=None, episode_start=None, deterministic=False):
        n_robots = observation.shape[-1] // 9  # the default "goal" layout: 9 values per robot
        action = np.zeros((n_robots, 3), dtype=np.float32)
        action[:, 2] = -1.0
        return action.ravel(), state


@pytest.mark.parametrize("n", [2, 5, 30])
def test_mean_ci_matches_the_t_interval(n):
    values = np.random.default_rng(n).normal(3.0, 2.0, size=n)
    mean, half = mean_ci(values, confidence=0.95)
    low, high = stats.t.interval(0.95, df=n - 1, loc=values.mean(), scale=stats.sem(values))
    assert mean == pytest.approx(values.mean())
    assert mean - half == pytest.approx(low)
    assert mean + half == pytest.approx(high)


def test_mean_ci_edge_cases():
    assert np.isnan(mean_ci([4.0])[1])
    assert mean_ci([4.0, 4.0, 4.0]) == (4.0, 0.0)
    assert np.isnan(mean_ci([])[0])
    # A wider confidence level gives a wider interval.
    assert mean_ci([1.0, 2.0, 4.0], 0.99)[1] > mean_ci([1.0, 2.0, 4.0], 0.9)[1]
    with pytest.raises(ValueError, match="confidence"):
        mean_ci([1.0, 2.0], confidence=1.5)


def test_stand_still_policy_has_the_mqi_of_the_formula():
    # Nobody arrives (T_u = max_steps) and every step is an outage: MQI = t_total - U (max_steps + lambda max_steps).
    scenario = noma_radiomap.load_scenario("small")
    t_total, max_steps, lam = scenario.mission.t_total, scenario.mission.max_steps, scenario.mission.outage_penalty
    expected = t_total - scenario.n_robots * (max_steps + lam * max_steps)
    result = evaluate(StandStill(), "NomaRadioMap-v0", n_episodes=3, seed=1, env_kwargs={"scenario": "small"})
    assert result.n_episodes == 3
    assert result.success_rate == 0.0
    for record in result.episodes:
        assert record["mqi"] == expected
        assert record["steps"] == max_steps
        assert record["mission_time"] == max_steps
        assert record["outage_steps"] == scenario.n_robots * max_steps
        assert record["path_length"] == 0.0
    assert result.mqi_mean == expected and result.mqi_ci == 0.0


@pytest.mark.parametrize("channel", ["radio_map", "rayleigh"])
def test_planner_metrics_match_a_hand_computation_from_the_infos(channel):
    env = gym.make("NomaRadioMap-v0", scenario="small", channel=channel, observation="destinations")
    planner = ShortestPathPlanner()
    assert isinstance(planner, Planner)
    # Run the episode by hand and recompute MQI, outage, arrival times and path length from the step outputs.
    obs, _ = env.reset(seed=7, options=MISSION)
    planner.reset(env.unwrapped)
    scenario = env.unwrapped.scenario
    n_robots, max_steps = scenario.n_robots, scenario.mission.max_steps
    arrival = np.full(n_robots, max_steps)
    outage = np.zeros(n_robots)
    positions = [env.unwrapped.positions.copy()]
    steps, done = 0, False
    while not done:
        obs, _, terminated, truncated, info = env.step(planner.act(env.unwrapped, obs))
        steps += 1
        outage += info["outage"]
        arrived_now = obs.reshape(n_robots, 6)[:, 5] > 0.5
        arrival = np.where(arrived_now & (arrival == max_steps), steps, arrival)
        positions.append(env.unwrapped.positions.copy())
        done = terminated or truncated
    mqi = scenario.mission.t_total - float((arrival + scenario.mission.outage_penalty * outage).sum())
    path = np.linalg.norm(np.diff(np.stack(positions), axis=0), axis=-1).sum()

    result = evaluate(ShortestPathPlanner(), env, n_episodes=1, seed=7, options=MISSION, channel=channel)
    record = result.episodes[0]
    assert record["success"] is True and terminated
    assert record["mqi"] == pytest.approx(mqi)
    assert record["outage_steps"] == outage.sum()
    assert [record[f"outage_steps_{u}"] for u in range(n_robots)] == outage.tolist()
    assert [record[f"mission_time_{u}"] for u in range(n_robots)] == arrival.tolist()
    assert record["mission_time"] == arrival.max() == steps
    assert record["path_length"] == pytest.approx(path)
    # The robots cannot have walked less than the straight line to within arrival_radius of the destinations.
    straight = np.linalg.norm(np.array(MISSION["starts"]) - np.array(MISSION["destinations"]), axis=1)
    assert record["path_length"] >= (straight - scenario.robot.arrival_radius).sum()


def test_episodes_are_seeded_and_paired():
    first = evaluate(ShortestPathPlanner(), "NomaRadioMap-v0", n_episodes=4, seed=3, env_kwargs={"scenario": "small"})
    again = evaluate(ShortestPathPlanner(), "NomaRadioMap-v0", n_episodes=4, seed=3, env_kwargs={"scenario": "small"})
    assert first.episodes == again.episodes
    # The same seeds give the same missions to another policy: compare the starts of the trajectories.
    a = evaluate(
        ShortestPathPlanner(),
        "NomaRadioMap-v0",
        n_episodes=4,
        seed=3,
        env_kwargs={"scenario": "small"},
        return_trajectories=True,
    )
    b = evaluate(
        StandStill(), "NomaRadioMap-v0", n_episodes=4, seed=3, env_kwargs={"scenario": "small"}, return_trajectories=True
    )
    for ta, tb in zip(a.trajectories, b.trajectories, strict=True):
        np.testing.assert_array_equal(ta[0], tb[0])
    # Different episodes of one evaluation get different missions.
    assert len({tuple(t[0].ravel()) for t in a.trajectories}) > 1


def test_summary_and_records_are_consistent():
    result = evaluate(ShortestPathPlanner(), "NomaRadioMap-v0", n_episodes=4, seed=0, env_kwargs={"scenario": "small"})
    summary = result.summary()
    mqi = np.array([e["mqi"] for e in result.episodes])
    assert summary["mqi"] == pytest.approx(mqi.mean())
    assert summary["mqi_ci"] == pytest.approx(mean_ci(mqi)[1])
    assert summary["success_rate"] == np.mean([e["success"] for e in result.episodes])
    assert summary["n_episodes"] == 4
    # The printout is one line of means, not the per-episode records
    text = repr(result)
    assert "\n" not in text and text.startswith("EvaluationResult(4 episodes: success ")
    assert f"MQI {summary['mqi']:.1f} ± {summary['mqi_ci']:.1f}" in text and "destination_x_0" not in text
    one = evaluate(ShortestPathPlanner(), "NomaRadioMap-v0", n_episodes=1, seed=0, env_kwargs={"scenario": "small"})
    assert f"MQI {one.summary()['mqi']:.1f} ± n/a," in repr(one)  # one episode has no CI, as in the tables


def test_the_channel_given_in_env_kwargs_is_the_channel_evaluated():
    small = {"scenario": "small"}
    by_argument = evaluate(ShortestPathPlanner(), "NomaRadioMap-v0", n_episodes=3, channel="radio_map", env_kwargs=small)
    by_kwargs = evaluate(ShortestPathPlanner(), "NomaRadioMap-v0", n_episodes=3, env_kwargs={**small, "channel": "radio_map"})
    rayleigh = evaluate(ShortestPathPlanner(), "NomaRadioMap-v0", n_episodes=3, env_kwargs=small)  # the default
    assert by_kwargs.episodes == by_argument.episodes != rayleigh.episodes
    with pytest.raises(ValueError, match=r"channel='rayleigh' and env_kwargs\['channel'\]='radio_map': give it once"):
        evaluate(
            StandStill(), "NomaRadioMap-v0", n_episodes=1, channel="rayleigh", env_kwargs={**small, "channel": "radio_map"}
        )
    # numpy integers are seeds too; a confidence level out of range is refused before any episode
    assert evaluate(StandStill(), "NomaRadioMap-v0", n_episodes=1, seed=np.int64(4), env_kwargs=small).episodes[0]["seed"] == 4
    with pytest.raises(ValueError, match=r"confidence must be in \(0, 1\), got 2\.0"):
        evaluate(StandStill(), "NomaRadioMap-v0", n_episodes=1, confidence=2.0, env_kwargs=small)


def test_bad_arguments_raise_clear_errors():
    env = gym.make("NomaRadioMap-v0", scenario="small", channel="radio_map")
    with pytest.raises(ValueError, match=r"channel='rayleigh'.*channel='radio_map'"):
        evaluate(StandStill(), env, n_episodes=1, channel="rayleigh")
    for n_episodes in (0, 2.5, "2", True):  # True once ran one episode
        with pytest.raises(ValueError, match=f"n_episodes must be an integer >= 1, got {n_episodes!r}"):
            evaluate(StandStill(), env, n_episodes=n_episodes)
    for seed in (None, -1, 1.5):
        with pytest.raises(ValueError, match=f"seed must be an integer >= 0 .*, got {seed!r}"):
            evaluate(StandStill(), env, n_episodes=1, seed=seed)
    with pytest.raises(ValueError, match="policy"):
        evaluate(object(), env, n_episodes=1)
    with pytest.raises(ValueError, match="options"):
        evaluate(StandStill(), env, n_episodes=2, options=[MISSION])
    # Another kind of env: was "unexpected keyword argument 'channel'" (an id) or "no attribute 'positions'" (an env)
    for other in ("Pendulum-v1", gym.make("Pendulum-v1")):
        with pytest.raises(ValueError, match=r"evaluate measures the missions of noma_radiomap's envs.* is .*Pendulum"):
            evaluate(StandStill(), other, n_episodes=1)
    with pytest.raises(TypeError, match="chanel"):  # a misspelt keyword of a mission env keeps gymnasium's message
        evaluate(StandStill(), "NomaRadioMap-v0", n_episodes=1, env_kwargs={"scenario": "small", "chanel": "rayleigh"})


def test_a_model_is_only_tested_on_an_env_with_its_training_settings(tmp_path):
    # evaluate(model, "NomaRadioMap-v0") of a model trained on `small` once ran it on `mall` and returned numbers
    from sb3_dtdpg import DTDPG
    from sb3_dtdpg.env_settings import EnvSettingsMismatch

    model = DTDPG("MlpPolicy", gym.make("NomaRadioMap-v0", scenario="small"), learning_starts=10, seed=0)
    model.save(tmp_path / "model.zip")
    loaded = DTDPG.load(tmp_path / "model.zip")  # no env: the settings its file recorded
    for policy in (model, loaded):
        with pytest.raises(EnvSettingsMismatch, match=r"scenario='small' \(the env has 'mall'\)"):
            evaluate(policy, "NomaRadioMap-v0", n_episodes=1)
        with pytest.raises(EnvSettingsMismatch, match=r"multiple_access='noma' \(the env has 'oma'\)"):
            evaluate(policy, gym.make("NomaRadioMap-v0", scenario="small", multiple_access="oma"), n_episodes=1)
        result = evaluate(policy, "NomaRadioMap-v0", n_episodes=1, env_kwargs={"scenario": "small"}, channel="radio_map")
        assert result.n_episodes == 1
