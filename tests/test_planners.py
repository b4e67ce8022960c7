"""Non-learning references (noma_radiomap.planners): they reach the destinations, and comm-awareness pays."""

import itertools
import re

import gymnasium as gym
import numpy as np
import pytest

import noma_radiomap
from noma_radiomap.downlink import allocate_power, downlink, in_outage
from noma_radiomap.planners import (
    CommAwarePlanner,
    RandomPlanner,
    ReferencePlanner,
    ShortestPathPlanner,
    channel_maps,
    mqi_upper_bound,
)
from noma_radiomap.propagation import dbm_to_watt
from sb3_dtdpg.evaluation import evaluate


def _start_corners(radio_map, robot):
    """The free start cells at the corners of a robot's start region (the hardest starts for a path)."""
    cells = radio_map.start_cells(robot)
    picks = [cells[np.argmin(cells @ w)] for w in ([1, 1], [-1, 1], [1, -1], [-1, -1])]
    return [radio_map.cell_center(*cell).tolist() for cell in picks]


@pytest.mark.parametrize("planner_cls", [ShortestPathPlanner, CommAwarePlanner])
@pytest.mark.parametrize("multiple_access", ["noma", "oma"])
def test_planners_reach_every_destination_on_small(planner_cls, multiple_access):
    env = gym.make("NomaRadioMap-v0", scenario="small", multiple_access=multiple_access)
    scenario, radio_map = env.unwrapped.scenario, env.unwrapped.radio_map
    destination_sets = list(itertools.product(*(robot.destinations for robot in scenario.robots)))
    start_sets = list(zip(*(_start_corners(radio_map, u) for u in range(scenario.n_robots)), strict=True))
    options = [{"starts": list(s), "destinations": [list(d) for d in ds]} for ds in destination_sets for s in start_sets]
    result = evaluate(planner_cls(), env, n_episodes=len(options), options=options, channel="radio_map")
    failed = [o for o, e in zip(options, result.episodes, strict=True) if not e["success"]]
    assert not failed, f"{planner_cls.__name__} did not arrive on {failed}"
    # Full speed on a clear path: the mission never takes far longer than the longest straight line.
    longest = max(np.hypot(*np.subtract(s, d)) for o in options for s, d in zip(o["starts"], o["destinations"], strict=True))
    assert max(e["mission_time"] for e in result.episodes) <= 1.6 * longest / scenario.robot.v_max


@pytest.mark.parametrize("planner_cls", [ShortestPathPlanner, CommAwarePlanner])
def test_planners_reach_sampled_missions_on_mall(planner_cls):
    result = evaluate(planner_cls(), "NomaRadioMap-v0", n_episodes=6, seed=11, channel="rayleigh")
    assert result.success_rate == 1.0


def test_shortest_path_follows_the_geodesic():
    env = gym.make("NomaRadioMap-v0")
    radio_map, scenario = env.unwrapped.radio_map, env.unwrapped.scenario
    result = evaluate(ShortestPathPlanner(), env, n_episodes=4, seed=5, channel="radio_map", return_trajectories=True)
    for record, trajectory in zip(result.episodes, result.trajectories, strict=True):
        for u in range(scenario.n_robots):
            start, end = trajectory[0, u], trajectory[-1, u]
            geodesic = radio_map.distance_field(end)[radio_map.cell_index(start)]
            # The grid geodesic joins cell centres (up to a cell diagonal off the true points); the planner cuts
            # the 8-connected staircase into straight lines, so it is never much longer.
            assert record[f"path_length_{u}"] <= geodesic + scenario.room.resolution * np.sqrt(2) + 1e-6


def test_comm_aware_mqi_beats_shortest_path_on_mall():
    for multiple_access in ("noma", "oma"):
        kwargs = {"n_episodes": 6, "seed": 100, "channel": "radio_map", "multiple_access": multiple_access}
        shortest = evaluate(ShortestPathPlanner(), "NomaRadioMap-v0", **kwargs)
        aware = evaluate(CommAwarePlanner(), "NomaRadioMap-v0", **kwargs)
        assert aware.success_rate == shortest.success_rate == 1.0
        assert aware.mqi_mean >= shortest.mqi_mean, multiple_access
        assert aware.summary()["outage_steps"] <= shortest.summary()["outage_steps"], multiple_access


@pytest.mark.parametrize("multiple_access", ["noma", "oma"])
def test_comm_aware_power_never_has_more_outages_than_an_equal_split(multiple_access):
    env = gym.make("NomaRadioMap-v0", multiple_access=multiple_access).unwrapped
    env.reset(seed=0)
    planner = CommAwarePlanner()
    planner.reset(env)
    gain, interference = channel_maps(env)
    free = np.argwhere(~env.radio_map.blocked)
    rng = np.random.default_rng(0)
    radio, max_power_w = env.scenario.radio, float(dbm_to_watt(env.scenario.ap.max_power_dbm))
    noise = float(dbm_to_watt(radio.noise_dbm_per_hz))
    fewer = 0
    for _ in range(200):
        cells = free[rng.choice(len(free), size=2, replace=False)]
        positions = env.radio_map.cell_center(cells[:, 0], cells[:, 1])
        active = np.ones(2, dtype=bool)

        def outages(actions, cells=cells):
            power = allocate_power(np.asarray(actions, dtype=float), max_power_w)
            g, i = gain[cells[:, 0], cells[:, 1]], interference[cells[:, 0], cells[:, 1]]
            rate = downlink(power, g, i, radio.bandwidth_per_robot_hz, noise, multiple_access).rate_bps
            return int(in_outage(rate, radio.qos_rate_bps).sum())

        chosen = planner.power_actions(env, positions, active)
        assert np.all(np.abs(chosen) <= 1.0)
        assert outages(chosen) <= outages([0.0, 0.0])
        fewer += outages(chosen) < outages([0.0, 0.0])
    assert fewer > 0  # it does better than the equal split somewhere


def test_random_planner_is_seeded_and_in_bounds():
    env = gym.make("NomaRadioMap-v0", scenario="small").unwrapped
    env.reset(seed=0)
    a, b = RandomPlanner(seed=3), RandomPlanner(seed=3)
    actions = np.stack([a.act(env, None) for _ in range(50)])
    np.testing.assert_array_equal(actions, np.stack([b.act(env, None) for _ in range(50)]))
    assert env.action_space.contains(actions[0]) and actions.std() > 0.3


def test_comm_aware_levels_are_validated():
    with pytest.raises(ValueError, match="levels"):
        CommAwarePlanner(levels=1)
    with pytest.raises(ValueError, match="lookahead"):
        ShortestPathPlanner(lookahead=0)


@pytest.mark.parametrize("multiple_access", ["noma", "oma"])
def test_min_outage_power_is_never_beaten_by_a_grid_of_splits(multiple_access):
    from noma_radiomap.planners import min_outage_power

    env = gym.make("NomaRadioMap-v0", multiple_access=multiple_access).unwrapped
    gain, interference = channel_maps(env)
    free = np.argwhere(~env.radio_map.blocked)
    rng = np.random.default_rng(1)
    cells = free[rng.choice(len(free), size=(300, 2))]
    g, i = gain[cells[..., 0], cells[..., 1]], interference[cells[..., 0], cells[..., 1]]
    active = rng.random((300, 2)) < 0.85
    _, n_outage = min_outage_power(g, i, active, env.scenario, multiple_access)
    radio, max_power_w = env.scenario.radio, float(dbm_to_watt(env.scenario.ap.max_power_dbm))
    grid = np.array(list(itertools.product(np.linspace(-1.0, 1.0, 61), repeat=2)))
    power = allocate_power(grid, max_power_w)[None]
    rate = downlink(
        power,
        g[:, None],
        i[:, None],
        radio.bandwidth_per_robot_hz,
        float(dbm_to_watt(radio.noise_dbm_per_hz)),
        multiple_access,
    ).rate_bps
    grid_best = (in_outage(rate, radio.qos_rate_bps) & active[:, None]).sum(axis=-1).min(axis=1)
    assert np.all(n_outage <= grid_best)
    assert 0 < n_outage.sum() < active.sum()  # the sample has served and unserved robots


@pytest.mark.parametrize("multiple_access", ["noma", "oma"])
def test_rayleigh_success_matches_monte_carlo(multiple_access):
    from noma_radiomap.planners import rayleigh_success

    env = gym.make("NomaRadioMap-v0", multiple_access=multiple_access).unwrapped
    scenario, radio_map = env.scenario, env.radio_map
    ix, iy = np.array([60, 40]), np.array([24, 40])
    gain = radio_map.path_gain["ap"][ix, iy]
    powers = dbm_to_watt(np.array([i.power_dbm for i in scenario.interferers]))
    interferer = np.stack([radio_map.path_gain[i.name][ix, iy] for i in scenario.interferers], axis=-1) * powers
    max_power_w = float(dbm_to_watt(scenario.ap.max_power_dbm))
    split = np.array([[0.2, 0.8], [0.5, 0.5], [0.9, 0.1]]) * max_power_w
    predicted = rayleigh_success(split[None], gain[None], interferer[None], scenario, multiple_access)[0]
    rng = np.random.default_rng(0)
    fading = rng.exponential(size=(100_000, 1, 2, 1 + len(powers)))
    rate = downlink(
        split[None],
        gain * fading[..., 0],
        (interferer * fading[..., 1:]).sum(axis=-1),
        scenario.radio.bandwidth_per_robot_hz,
        float(dbm_to_watt(scenario.radio.noise_dbm_per_hz)),
        multiple_access,
    ).rate_bps
    measured = (~in_outage(rate, scenario.radio.qos_rate_bps)).mean(axis=0)
    # OMA is exact; NOMA's planning model keeps the mean decoding order (the fading may swap it).
    np.testing.assert_allclose(predicted, measured, atol=0.01 if multiple_access == "oma" else 0.03)


def test_shortest_path_power_is_validated():
    with pytest.raises(ValueError, match="power"):
        ShortestPathPlanner(power="greedy")
    from noma_radiomap.planners import ReferencePlanner

    with pytest.raises(ValueError, match="weights"):
        ReferencePlanner(weights=(0.0,))


@pytest.mark.parametrize("planner_cls", [ShortestPathPlanner, CommAwarePlanner, ReferencePlanner])
def test_a_planner_keeps_the_radio_map_its_cache_is_keyed_on(planner_cls):
    # The planners cache their fields and paths for the env's radio map. The shared maps live in an LRU cache: were
    # one evicted and collected, a map of another scenario could take its id (an id-keyed cache would then be stale).
    # The planner holds the map it planned on and compares maps by identity.
    import gc
    import weakref

    from noma_radiomap import radiomap

    env = gym.make("NomaRadioMap-v0", scenario="small")
    env.reset(seed=0)
    planner = planner_cls()
    planner.reset(env.unwrapped)
    held = weakref.ref(env.unwrapped.radio_map)
    env.close()
    del env
    radiomap._cached_radio_map.cache_clear()
    gc.collect()
    assert held() is not None


def test_the_exhaustive_planners_refuse_more_robots_than_they_can_search(tmp_path):
    # 200 robots: a MemoryError of the comm-aware planner's 3^U grid; 7: minutes per mission for the best planner
    import yaml

    from noma_radiomap.planners import MAX_PLANNER_ROBOTS

    data = noma_radiomap.load_scenario("small").to_dict()
    data["robots"] = [data["robots"][u % 2] for u in range(MAX_PLANNER_ROBOTS + 1)]
    path = tmp_path / "crowd.yaml"
    path.write_text(yaml.safe_dump(data))
    env = gym.make("NomaRadioMap-v0", scenario=str(path))
    env.reset(seed=0)
    for planner in (ReferencePlanner(), CommAwarePlanner(), ShortestPathPlanner(power="best")):
        with pytest.raises(ValueError, match=f"has {MAX_PLANNER_ROBOTS + 1} robots, more than the {MAX_PLANNER_ROBOTS}"):
            planner.reset(env.unwrapped)
            planner.act(env.unwrapped, None)
    ShortestPathPlanner().reset(env.unwrapped)  # the equal split takes any number
    from sb3_dtdpg.experiments.compare import run_compare

    with pytest.raises(ValueError, match=r"compare's reference planners on .*crowd\.yaml: the scenario has 7 robots"):
        run_compare(tmp_path / "out", budget="tiny", scenario=str(path))  # before any run trains
    assert not (tmp_path / "out").exists()


def test_the_grid_planners_refuse_motion_steps_far_shorter_than_a_cell(tmp_path):
    # time_step 1e-6 with v_max 100 (a valid room): each chord check took millions of motion steps, a hang
    import yaml

    from noma_radiomap.planners import MAX_CELL_STEPS

    data = noma_radiomap.load_scenario("small").to_dict()
    data["robot"]["v_max"] = 1.0
    data["mission"]["time_step"] = 0.5 / MAX_CELL_STEPS / 2  # half a thousandth of the 0.5 m cell per step
    path = tmp_path / "slow.yaml"
    path.write_text(yaml.safe_dump(data))
    env = gym.make("NomaRadioMap-v0", scenario=str(path))
    env.reset(seed=0)
    for planner in (ShortestPathPlanner(), CommAwarePlanner(), ReferencePlanner()):
        with pytest.raises(ValueError, match=r"moves at most 0\.00025 m per step .*less than 1/1,000 of a cell"):
            planner.reset(env.unwrapped)


# --- rooms other than the built-in ones -------------------------------------------------------------------------
def _small(**changes) -> "noma_radiomap.Scenario":
    data = noma_radiomap.load_scenario("small").to_dict()
    for path, value in changes.items():  # "robot.arrival_radius" -> data["robot"]["arrival_radius"]
        *parents, key = path.split(".")
        target = data
        for parent in parents:
            target = target[parent]
        target[key] = value
    return noma_radiomap.Scenario.from_dict(data)


GRID_PLANNERS = {
    "shortest": ShortestPathPlanner,
    "shortest_best": lambda: ShortestPathPlanner(power="best"),
    "comm_aware": CommAwarePlanner,
    "best": ReferencePlanner,
}


@pytest.mark.parametrize("name", GRID_PLANNERS)
def test_planners_reach_an_off_centre_destination_within_a_small_arrival_radius(name):
    # The last leg from the cell centre before the destination used to be refused (the costs are cell-centred): the
    # robot stood there for the rest of the episode.
    env = gym.make("NomaRadioMap-v0", scenario=_small(**{"obstacles": [], "robot.arrival_radius": 0.5}), channel="radio_map")
    options = {"starts": [[3.75, 4.25], [1.25, 6.25]], "destinations": [[6.49, 4.49], [9.0, 4.0]]}
    episode = evaluate(GRID_PLANNERS[name](), env, n_episodes=1, options=options).episodes[0]
    assert episode["success"] and episode["mission_time_0"] < 10


@pytest.mark.parametrize("channel", ["radio_map", "rayleigh"])
@pytest.mark.parametrize("name", ["shortest_best", "best"])
def test_planners_of_the_best_power_split_work_in_a_room_without_interferers(name, channel):
    env = gym.make("NomaRadioMap-v0", scenario=_small(interferers=[]), channel=channel)
    result = evaluate(GRID_PLANNERS[name](), env, n_episodes=2, seed=3)
    assert all(episode["success"] for episode in result.episodes) and np.isfinite(result.mqi_mean)


def test_the_best_planner_reused_across_the_two_tasks_of_a_room_plans_each_anew():
    # The paper task of a room shares its radio map but not its episode length: candidates cut at one task's
    # max_steps must not be scored in the other.
    scenario = _small(**{"mission.max_steps": 8})
    options = {"starts": [[0.75, 0.75], [0.75, 5.75]], "destinations": [[10.0, 2.0], [9.0, 4.0]]}
    missions, paper = (gym.make(env_id, scenario=scenario) for env_id in ("NomaRadioMap-v0", "NomaRadioMapPaper-v0"))
    reused = ReferencePlanner()
    for env in (paper, missions, paper):
        mqi = evaluate(reused, env, n_episodes=1, options=options).mqi_mean
        assert mqi == evaluate(ReferencePlanner(), env, n_episodes=1, options=options).mqi_mean


def test_planner_arguments_and_bound_points_are_checked():
    for make, message in [
        (lambda: ShortestPathPlanner(lookahead=2.5), "lookahead must be an integer >= 1, got 2.5"),
        (lambda: ReferencePlanner(lookahead=0), "lookahead must be an integer >= 1, got 0"),
        (lambda: CommAwarePlanner(levels=2.5), "levels must be an integer >= 2, got 2.5"),
        (lambda: ReferencePlanner(weights="ab"), "weights must be a sequence of positive finite numbers, got 'ab'"),
    ]:
        with pytest.raises(ValueError, match=re.escape(message)):
            make()
    env = gym.make("NomaRadioMap-v0", scenario="small").unwrapped
    env.reset(seed=0)
    starts, destinations = env.positions.copy(), env.destinations.copy()
    assert np.isfinite(mqi_upper_bound(env, starts, destinations))
    for bad, message in [
        (starts[:1], r"starts: expected one point per robot, shape \(2, 2\), got \(1, 2\)"),
        (starts.ravel(), r"starts: expected one point per robot, shape \(2, 2\), got \(4,\)"),
        ([[np.nan, 1.0], [1.0, 1.0]], r"starts\[0\]: \[nan, 1\.0\] is outside the room or in a blocked cell"),
        ([[1.0, 1.0], [50.0, 1.0]], r"starts\[1\]: \[50\.0, 1\.0\] is outside the room or in a blocked cell"),
    ]:
        with pytest.raises(ValueError, match=message):
            mqi_upper_bound(env, bad, destinations)
