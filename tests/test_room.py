"""The default room poses the paper's problem (docs/SCENARIOS.md, "mall calibration"): on the test missions of
``sb3-dtdpg compare`` path design pays (the best planner beats the shortest paths with their best power split)
and NOMA pays (the best planner's NOMA beats its OMA), by the bars of the spec on the radio-map channel, path design
by its bar with Rayleigh fading too; on the radio-map channel the best planner never loses a mission to the
shortest path, and never scores above the upper bound."""

import gymnasium as gym
import numpy as np
import pytest

import noma_radiomap  # noqa: F401
from noma_radiomap.planners import (
    ReferencePlanner,
    ShortestPathPlanner,
    _geodesic_steps,
    mqi_upper_bound,
    rayleigh_power,
)
from noma_radiomap.propagation import dbm_to_watt
from sb3_dtdpg.evaluation import evaluate
from sb3_dtdpg.experiments.compare import (
    BEST_PLANNER,
    PLANNERS,
    SHORTEST_PATH_PLANNER,
    format_room_margins,
    room_margins,
)
from sb3_dtdpg.experiments.runs import RunSpec, get_budget
from sb3_dtdpg.experiments.tables import planner_row

MIN_PATH_MARGIN = 15.0  # docs/SCENARIOS.md, "mall calibration": best planner - shortest-path planner (best power), NOMA
MIN_NOMA_MARGIN = 25.0  # docs/SCENARIOS.md, "mall calibration": best planner NOMA - best planner OMA


@pytest.fixture(scope="module")
def test_missions():
    """The compare table's test missions: its default budget's episodes, the learners' evaluation seed."""
    budget = get_budget("default")
    assert budget.scenario is None and gym.spec("NomaRadioMap-v0").kwargs.get("scenario", "mall") == "mall"
    return {"n_episodes": budget.eval_episodes, "seed": RunSpec("dtdpg", "noma", 0, 1).eval_seed}


@pytest.fixture(scope="module")
def best_planner():
    return ReferencePlanner()  # one instance for every evaluation: the candidate rollouts are cached


@pytest.fixture(scope="module")
def shortest_path_planner():
    return ShortestPathPlanner(**PLANNERS[SHORTEST_PATH_PLANNER][1])


@pytest.fixture(scope="module")
def scores(test_missions, best_planner, shortest_path_planner):
    out = {}
    for channel in ("radio_map", "rayleigh"):
        for mode in ("noma", "oma"):
            env = gym.make("NomaRadioMap-v0", channel=channel, multiple_access=mode)
            out[channel, mode, BEST_PLANNER] = evaluate(best_planner, env, **test_missions)
            out[channel, mode, SHORTEST_PATH_PLANNER] = evaluate(shortest_path_planner, env, **test_missions)
    return out


def test_the_compare_table_lists_the_planners_of_the_margins():
    assert PLANNERS[BEST_PLANNER][0] == "ReferencePlanner"
    assert PLANNERS[SHORTEST_PATH_PLANNER] == ("ShortestPathPlanner", {"power": "best"})


def test_path_design_and_noma_pay_on_the_default_room(scores):
    # The radio-map channel: the deterministic channel the planners (and the paper's training) use.
    best_noma = scores["radio_map", "noma", BEST_PLANNER].mqi_mean
    shortest_noma = scores["radio_map", "noma", SHORTEST_PATH_PLANNER].mqi_mean
    best_oma = scores["radio_map", "oma", BEST_PLANNER].mqi_mean
    assert best_noma - shortest_noma >= MIN_PATH_MARGIN, (best_noma, shortest_noma)
    assert best_noma - best_oma >= MIN_NOMA_MARGIN, (best_noma, best_oma)
    assert scores["radio_map", "noma", BEST_PLANNER].success_rate == 1.0


def test_path_design_and_noma_pay_with_rayleigh_fading(scores):
    # The compare table's channel. Path design pays by the bar here too (the banner's shadow on the shortest paths is
    # too deep for fading to blur); NOMA pays by less: see the next test for why it cannot pay 25 here.
    best_noma = scores["rayleigh", "noma", BEST_PLANNER].mqi_mean
    assert best_noma - scores["rayleigh", "noma", SHORTEST_PATH_PLANNER].mqi_mean >= MIN_PATH_MARGIN
    assert best_noma > scores["rayleigh", "oma", BEST_PLANNER].mqi_mean
    assert scores["rayleigh", "oma", BEST_PLANNER].mqi_mean > scores["rayleigh", "oma", SHORTEST_PATH_PLANNER].mqi_mean


def test_no_room_gives_noma_25_over_oma_with_rayleigh_fading_on_missions_this_short(scores):
    # docs/SCENARIOS.md ("mall calibration"): with Rayleigh fading on every link, the best NOMA split saves at most
    # ~0.33 expected outages per step over the best OMA split at the same positions (one robot at ~6.9 dB, noise-
    # limited; interference only lowers it), so NOMA* - OMA* <= 0.33 x mission time: the 25 MQI bar needs missions
    # of >= 25 / 0.33 ~ 77 steps, 1.7 times this room's 45 (and longer than any shortest path from its start areas).
    scenario = gym.make("NomaRadioMap-v0").unwrapped.scenario
    radio = scenario.radio
    max_power_w = float(dbm_to_watt(scenario.ap.max_power_dbm))
    noise_w = float(dbm_to_watt(radio.noise_dbm_per_hz)) * radio.bandwidth_per_robot_hz * scenario.n_robots
    snr = np.logspace(-1.0, 3.0, 81)  # full-power SNR over the cluster band, -10 to 30 dB
    gain = np.stack(np.meshgrid(snr, snr, indexing="ij"), axis=-1).reshape(-1, 2) * noise_w / max_power_w
    no_interference = np.zeros((*gain.shape, 0))
    advantage = 0.0
    for active in ([True, True], [True, False]):
        rows = np.broadcast_to(np.array(active), gain.shape)
        _, noma = rayleigh_power(gain, no_interference, rows, scenario, "noma", levels=101)
        _, oma = rayleigh_power(gain, no_interference, rows, scenario, "oma", levels=101)
        assert np.all(oma >= noma - 1e-12)  # NOMA never does worse
        advantage = max(advantage, float((oma - noma).max()))
    assert 0.30 < advantage < 0.34
    mission_time = scores["rayleigh", "noma", BEST_PLANNER].summary()["mission_time"]
    assert advantage * mission_time < MIN_NOMA_MARGIN


@pytest.mark.parametrize("mode", ["noma", "oma"])
def test_best_planner_never_loses_a_mission_to_the_shortest_path_on_the_radio_map(scores, mode):
    best, shortest = scores["radio_map", mode, BEST_PLANNER], scores["radio_map", mode, SHORTEST_PATH_PLANNER]
    for b, s in zip(best.episodes, shortest.episodes, strict=True):
        assert b["seed"] == s["seed"]
        assert b["mqi"] >= s["mqi"], f"mission {b['seed']}: best planner {b['mqi']} < shortest path {s['mqi']}"


def test_upper_bound_holds_on_every_test_mission(scores, test_missions):
    for mode in ("noma", "oma"):
        env = gym.make("NomaRadioMap-v0", channel="radio_map", multiple_access=mode)
        base = env.unwrapped
        for planner in (BEST_PLANNER, SHORTEST_PATH_PLANNER):
            for record in scores["radio_map", mode, planner].episodes:
                env.reset(seed=record["seed"])
                bound = mqi_upper_bound(base, base.positions, base.destinations)
                assert record["mqi"] <= bound + 1e-9, (mode, planner, record["seed"], record["mqi"], bound)


def test_no_robot_arrives_sooner_than_its_shortest_path_allows(scores):
    """The steps of the bound's path-length relaxation, against the planners' robots: never more, and within one step
    of the shortest-path planner's robots (which follow a grid path, a little longer than the shortest line)."""
    env = gym.make("NomaRadioMap-v0", channel="radio_map")
    base = env.unwrapped
    tight = 0
    for planner in (BEST_PLANNER, SHORTEST_PATH_PLANNER):
        for record in scores["radio_map", "noma", planner].episodes:
            env.reset(seed=record["seed"])
            for robot, (start, goal) in enumerate(zip(base.positions, base.destinations, strict=True)):
                least = _geodesic_steps(base, start, goal)
                assert least <= record[f"mission_time_{robot}"], (planner, record["seed"], robot, least)
                tight += planner == SHORTEST_PATH_PLANNER and least >= record[f"mission_time_{robot}"] - 1
    assert tight == 40  # within one step of every robot of the shortest-path planner


def test_the_compare_table_prints_the_margins_of_the_default_room(scores, best_planner, shortest_path_planner):
    # The line under `sb3-dtdpg compare`'s table: the radio-map margins from its own planner runs, the Rayleigh ones
    # from the table's rows (here: this module's evaluations of the same planners on the same missions).
    rows = [
        planner_row(name, mode, scores["rayleigh", mode, name])
        for mode in ("noma", "oma")
        for name in (BEST_PLANNER, SHORTEST_PATH_PLANNER)
    ]
    for row in rows:  # the best planner's row of the table carries its radio-map MQI (for its gap to the bound)
        if row["algorithm"] == BEST_PLANNER:
            row["mqi_radio_map"] = scores["radio_map", row["multiple_access"].lower(), BEST_PLANNER].mqi_mean
    instances = {BEST_PLANNER: best_planner, SHORTEST_PATH_PLANNER: shortest_path_planner}  # their rollouts cached
    margins = room_margins(rows, get_budget("default"), instances=instances)
    mqi = {key: result.mqi_mean for key, result in scores.items()}
    for channel in ("radio_map", "rayleigh"):
        best = mqi[channel, "noma", BEST_PLANNER]
        assert margins[f"path {channel}"] == pytest.approx(best - mqi[channel, "noma", SHORTEST_PATH_PLANNER])
        assert margins[f"noma {channel}"] == pytest.approx(best - mqi[channel, "oma", BEST_PLANNER])
    assert margins["path radio_map"] >= MIN_PATH_MARGIN and margins["noma radio_map"] >= MIN_NOMA_MARGIN
    assert margins["path rayleigh"] >= MIN_PATH_MARGIN
    line = format_room_margins(margins)
    assert f"{margins['path radio_map']:+.1f} / {margins['path rayleigh']:+.1f}" in line
    assert f"{margins['noma radio_map']:+.1f} / {margins['noma rayleigh']:+.1f}" in line


def test_path_lengths_go_around_a_wall_through_its_gap():
    """A wall with a gap at the top: the shortest path from one side to the other bends at the gap's two corners."""
    from types import SimpleNamespace

    from noma_radiomap.planners import _path_lengths

    blocked = np.zeros((10, 10), dtype=bool)
    blocked[5, :8] = True  # x in [5, 6), y in [0, 8)
    env = SimpleNamespace(
        scenario=SimpleNamespace(room=SimpleNamespace(resolution=1.0), robot=SimpleNamespace(arrival_radius=0.5)),
        radio_map=SimpleNamespace(blocked=blocked),
    )
    around = 2 * np.hypot(3.0, 6.0) + 1.0  # (2, 2) -> (5, 8) -> (6, 8) -> (9, 2)
    lengths = _path_lengths(env, np.array([[2.0, 2.0], [2.0, 9.0], [8.0, 2.0]]), np.array([9.0, 2.0]))
    over = np.hypot(4.0, 1.0) + np.hypot(3.0, 6.0)  # (2, 9) -> (6, 8) -> (9, 2): over the wall's top corner
    assert lengths == pytest.approx([around - 0.5, over - 0.5, 0.5])
    assert _path_lengths(env, np.array([[9.0, 2.0]]), np.array([9.0, 2.0])) == pytest.approx([0.0])


def test_a_room_with_too_many_corners_falls_back_to_the_grid_bound(monkeypatch):
    from noma_radiomap import planners

    env = gym.make("NomaRadioMap-v0", channel="radio_map")
    env.reset(seed=10_000)
    base = env.unwrapped
    tight = mqi_upper_bound(base, base.positions, base.destinations)
    monkeypatch.setattr(planners, "_MAX_SEGMENTS", 10)  # fewer segments than mall's corners need
    planners._corner_graph.cache_clear()
    try:
        assert planners._corner_graph(base.radio_map.blocked.tobytes(), base.radio_map.blocked.shape, 0.5) is None
        loose = mqi_upper_bound(base, base.positions, base.destinations)
    finally:
        planners._corner_graph.cache_clear()
    assert loose > tight + 10  # the grid relaxation alone: still a bound, a looser one


def test_the_tables_gap_is_the_best_planners_distance_from_the_bound_on_the_radio_map(scores, best_planner):
    # The bound holds on the radio-map channel; the table's planner rows are with fading: the gap is taken where the
    # bound holds (bound - the planner's radio-map MQI), not against the fading row's MQI.
    import pandas as pd

    from sb3_dtdpg.experiments.compare import evaluate_planners
    from sb3_dtdpg.experiments.tables import add_planner_fractions

    rows, _ = evaluate_planners(
        ("noma", "oma"), get_budget("default"), names=(BEST_PLANNER,), instances={BEST_PLANNER: best_planner}
    )
    table = add_planner_fractions(pd.DataFrame(rows), BEST_PLANNER, BEST_PLANNER).set_index("multiple_access")
    for mode in ("noma", "oma"):
        on_radio_map = scores["radio_map", mode, BEST_PLANNER].mqi_mean
        assert table.loc[mode.upper(), "mqi"] == scores["rayleigh", mode, BEST_PLANNER].mqi_mean
        assert table.loc[mode.upper(), "mqi_radio_map"] == on_radio_map != table.loc[mode.upper(), "mqi"]
        assert table.loc[mode.upper(), "mqi_gap"] == pytest.approx(table.loc[mode.upper(), "mqi_bound"] - on_radio_map)
        assert table.loc[mode.upper(), "mqi_gap"] >= 0
