"""The radio map (paper Eq. (16)-(19)): shapes and indexing, cache, the SINR formula, and the "communication
matters" properties of the built-in ``mall`` and ``warehouse`` scenarios (docs/SCENARIOS.md)."""

import math

import numpy as np
import pytest

from noma_radiomap import RadioMap, load_scenario
from noma_radiomap import geometry as G


@pytest.fixture(scope="module")
def mall():
    return RadioMap.for_scenario(load_scenario("mall"))


@pytest.fixture(scope="module")
def small():
    return RadioMap.for_scenario(load_scenario("small"))


@pytest.mark.parametrize("name", ["small", "mall", "warehouse"])
def test_shapes_and_keys(name):
    scenario = load_scenario(name)
    radio_map = RadioMap.for_scenario(scenario)
    shape = (scenario.room.nx, scenario.room.ny)
    keys = {"ap", *(i.name for i in scenario.interferers)}
    assert set(radio_map.path_loss_db) == set(radio_map.n_obstacles) == keys
    for array in [radio_map.blocked, radio_map.power_map_dbm, radio_map.sinr_map_db, *radio_map.path_loss_db.values()]:
        assert array.shape == shape
    assert radio_map.blocked.dtype == bool
    assert np.issubdtype(radio_map.n_obstacles["ap"].dtype, np.integer)
    assert np.isfinite(radio_map.sinr_map_db).all()


def test_indexing_convention(small):
    res = small.resolution
    # cell ix spans [ix * res, (ix + 1) * res)
    ix, iy = small.cell_index(np.array([[0.0, 0.0], [0.49, 0.51], [3 * res, 2 * res - 1e-9], [11.99, 7.99]]))
    assert ix.tolist() == [0, 0, 3, 23]
    assert iy.tolist() == [0, 1, 1, 15]
    # clipped to the grid
    ix, iy = small.cell_index(np.array([[-1.0, 100.0], [12.0, 8.0]]))
    assert ix.tolist() == [0, 23] and iy.tolist() == [15, 15]
    np.testing.assert_allclose(small.cell_center(3, 1), [1.75, 0.75])
    gx, gy = np.meshgrid(np.arange(small.nx), np.arange(small.ny), indexing="ij")
    back = small.cell_index(small.cell_center(gx, gy))
    np.testing.assert_array_equal(back[0], gx)
    np.testing.assert_array_equal(back[1], gy)


@pytest.mark.parametrize("name", ["small", "mall", "warehouse"])
def test_maps_are_indexed_x_then_y(name):
    # The AP's path loss is smallest in the AP's own cell (ties where the AP sits on a grid corner):
    # catches a transposed map (test_sinr_formula_recomputed_independently checks arbitrary cells).
    radio_map = RadioMap.for_scenario(load_scenario(name))
    ap_cell = tuple(int(i) for i in radio_map.cell_index(np.array(radio_map.scenario.ap.position[:2])))
    assert radio_map.path_loss_db["ap"][ap_cell] == radio_map.path_loss_db["ap"].min()
    # the wall of small at x in [6, 6.5] is a column of blocked cells ix = 12
    if name == "small":
        assert radio_map.blocked[12, 0] and not radio_map.blocked[0, 12]


def test_cache_returns_same_object():
    first = RadioMap.for_scenario(load_scenario("small"))
    assert RadioMap.for_scenario(load_scenario("small")) is first  # equal content, new Scenario object
    assert RadioMap(load_scenario("small")) is not first
    assert RadioMap.for_scenario(load_scenario("small").with_resolution(0.25)) is not first
    with pytest.raises(ValueError, match="read-only"):
        first.sinr_map_db[0, 0] = 0.0


def _independent_sinr_db(scenario, radio_map, ix, iy):
    """SINR at a cell recomputed from the paper's Eq. (1)-(4) and docs/MODEL.md with plain math (powers in mW)."""
    radio = scenario.radio
    x, y = (ix + 0.5) * scenario.room.resolution, (iy + 0.5) * scenario.room.resolution
    rx = (x, y, scenario.robot.antenna_height)
    fading_db = -10 * 0.5772156649015329 / math.log(10)

    def received_mw(position, power_dbm):
        d = max(1.0, math.dist(position, rx))
        n = radio_map.obstacles_crossed(position, rx)
        if n == 0:
            loss = 16.9 * math.log10(d) - 27.2 + 20 * math.log10(radio.frequency_mhz)
        else:
            loss = (
                20 * math.log10(radio.frequency_mhz)
                - 28
                + radio.nlos_distance_coefficient * math.log10(d)
                + radio.wall_loss_db
                + radio.wall_loss_step_db * (n - 1)
            )
        return 10 ** ((power_dbm - loss + fading_db) / 10)

    signal = received_mw(scenario.ap.position, scenario.ap.max_power_dbm)
    interference = sum(received_mw(i.position, i.power_dbm) for i in scenario.interferers)
    noise = 10 ** (radio.noise_dbm_per_hz / 10) * scenario.n_robots * radio.bandwidth_per_robot_hz
    return 10 * math.log10(signal / (interference + noise)), 10 * math.log10(signal)


def test_sinr_formula_recomputed_independently(mall):
    scenario = mall.scenario
    rng = np.random.default_rng(0)
    cells = [(int(rng.integers(mall.nx)), int(rng.integers(mall.ny))) for _ in range(12)]
    cells += [tuple(int(i) for i in mall.cell_index(np.array([20.0, 20.0])))]  # under the upstairs AP
    for ix, iy in cells:
        sinr_db, power_dbm = _independent_sinr_db(scenario, mall, ix, iy)
        assert mall.sinr_map_db[ix, iy] == pytest.approx(sinr_db, abs=1e-9)
        assert mall.power_map_dbm[ix, iy] == pytest.approx(power_dbm, abs=1e-9)


def test_outage_map_is_the_qos_test(mall):
    scenario = mall.scenario
    bandwidth = scenario.n_robots * scenario.radio.bandwidth_per_robot_hz
    rate = bandwidth * np.log2(1 + 10 ** (mall.sinr_map_db / 10))
    np.testing.assert_array_equal(mall.outage_map(), rate < scenario.radio.qos_rate_bps)
    # 60 kb/s over 30 kHz needs log2(1 + SINR) >= 2, i.e. SINR >= 3 (4.77 dB)
    np.testing.assert_array_equal(mall.outage_map(), mall.sinr_map_db < 10 * math.log10(3))


COMMUNICATION_MATTERS = ["mall", "warehouse"]


@pytest.mark.parametrize("name", COMMUNICATION_MATTERS)
def test_outage_share_in_range(name):
    # docs/SCENARIOS.md: with the whole AP power to one robot, 15 % to 60 % of free cells fail the QoS.
    radio_map = RadioMap.for_scenario(load_scenario(name))
    share = radio_map.outage_share()
    assert 0.15 <= share <= 0.60
    assert share == pytest.approx(radio_map.outage_map()[~radio_map.blocked].sum() / (~radio_map.blocked).sum())


def _length_and_outage_metres(cells: np.ndarray, outage: np.ndarray, resolution: float) -> tuple[float, float]:
    """A grid path's length and the metres of it in outage cells (a step's outage shared by its two cells)."""
    step = resolution * np.hypot(*np.diff(cells, axis=0).T)
    in_outage = 0.5 * (outage[cells[:-1, 0], cells[:-1, 1]] + outage[cells[1:, 0], cells[1:, 1]])
    return float(step.sum()), float(step @ in_outage)


@pytest.mark.parametrize("name", COMMUNICATION_MATTERS)
def test_shortest_path_crosses_outage_and_a_short_detour_cuts_most_of_it(name):
    # docs/SCENARIOS.md: for at least one robot (and destination), from every cell of its start region each shortest
    # path runs through outage cells, while a path at most 1.5 x as long spends at most a quarter as many metres there.
    radio_map = RadioMap.for_scenario(load_scenario(name))
    scenario, res = radio_map.scenario, radio_map.resolution
    outage = radio_map.outage_map().astype(np.float64)
    found = []
    for u, robot in enumerate(scenario.robots):
        for destination in robot.destinations:
            goal = tuple(int(i) for i in radio_map.cell_index(np.array(destination)))
            holds = True
            for start in radio_map.start_cells(u):
                # the shortest path with the fewest outage metres, and the path of least length + outage metres
                shortest, _ = G.shortest_path(radio_map.blocked, tuple(start), goal, cost=1e-6 * outage, resolution=res)
                detour, _ = G.shortest_path(radio_map.blocked, tuple(start), goal, cost=outage, resolution=res)
                short_length, short_outage = _length_and_outage_metres(shortest, outage, res)
                detour_length, detour_outage = _length_and_outage_metres(detour, outage, res)
                holds &= short_outage > 0 and detour_length <= 1.5 * short_length and detour_outage <= short_outage / 4
            if holds:
                found.append((u, destination))
    assert found, "no robot/destination whose shortest paths cross outage cells while a short detour cuts most of it"


@pytest.mark.parametrize("name", ["warehouse"])  # mall's banner shadow has no outage-free detour: the test above
def test_shortest_path_crosses_outage_but_a_detour_avoids_it(name):
    # docs/SCENARIOS.md: for at least one robot (and destination), every shortest path from the start region to
    # the destination crosses outage cells, while a path avoiding them exists and is at most 1.5 x as long.
    radio_map = RadioMap.for_scenario(load_scenario(name))
    scenario, res = radio_map.scenario, radio_map.resolution
    outage = radio_map.outage_map()
    found = []
    for u, robot in enumerate(scenario.robots):
        starts = radio_map.start_cells(u)
        for destination in robot.destinations:
            goal = tuple(int(i) for i in radio_map.cell_index(np.array(destination)))
            shortest = G.grid_distance_field(radio_map.blocked, goal, res)[starts[:, 0], starts[:, 1]]
            avoiding = G.grid_distance_field(radio_map.blocked | outage, goal, res)[starts[:, 0], starts[:, 1]]
            if np.all((avoiding > shortest + 1e-9) & (avoiding <= 1.5 * shortest)):
                found.append((u, destination))
    assert found, "no robot/destination where the shortest path must cross outage cells but a short detour avoids them"
    # and the shortest path found explicitly does cross outage cells
    u, destination = found[0]
    start = radio_map.start_cells(u)[0]
    goal = tuple(int(i) for i in radio_map.cell_index(np.array(destination)))
    cells, _ = G.shortest_path(radio_map.blocked, tuple(start), goal, resolution=res)
    assert outage[cells[:, 0], cells[:, 1]].any()


def test_small_blocked_cells(small):
    scenario = small.scenario
    assert [o.name for o in scenario.obstacles] == ["wall", "table", "lamp"]
    assert small.blocked[small.cell_index(np.array([6.2, 1.0]))]
    assert not small.blocked[small.cell_index(np.array([6.2, 5.5]))]  # the doorway
    assert small.blocked[small.cell_index(np.array([4.0, 1.5]))]  # the table
    assert not small.blocked[small.cell_index(np.array([8.5, 3.5]))]  # under the lamp
    # rays from the AP through the wall vs through the doorway
    assert small.obstacles_crossed(scenario.ap.position, (10.0, 2.0, 1.5)) == 1
    assert small.obstacles_crossed(scenario.ap.position, (7.5, 6.5, 1.5)) == 0


def test_distance_field_and_start_cells(small):
    starts = small.start_cells(0)
    assert len(starts) > 0 and not small.blocked[starts[:, 0], starts[:, 1]].any()
    field = small.distance_field(np.array([10.0, 2.0]))
    assert field is small.distance_field(np.array([10.1, 2.1]))  # same cell: cached
    assert np.isfinite(field[starts[:, 0], starts[:, 1]]).all()
    # the wall forces the path through the doorway: longer than the straight line
    s = small.cell_center(*starts[0])
    assert field[tuple(starts[0])] > math.dist(s, small.cell_center(*small.cell_index(np.array([10.0, 2.0]))))


def test_plot_writes_png(small, tmp_path):
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = tmp_path / "maps.png"
    figure = small.plot_maps(str(path))
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(figure.axes) >= 2
    plt.close(figure)
    with pytest.raises(ValueError, match=r"kind: expected 'sinr' or 'power', got 'rate'"):
        small.plot(kind="rate")


def test_pickle_round_trip(small):
    import pickle

    again = pickle.loads(pickle.dumps(small))
    assert again.scenario == small.scenario
    np.testing.assert_array_equal(again.sinr_map_db, small.sinr_map_db)
    np.testing.assert_array_equal(again.n_obstacles["outdoor"], small.n_obstacles["outdoor"])
