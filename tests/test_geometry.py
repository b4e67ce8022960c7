"""Grid snapping, occupancy, occlusion (slab test, distinct obstacles) and grid paths (paper Sec. III-B, III-C)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from noma_radiomap import RadioMap, load_scenario
from noma_radiomap import geometry as G
from noma_radiomap.scenario import Scenario


def reference_count(origin, end, boxes, owner):
    """Per-ray, per-box slab test written plainly (Kay-Kajiya), counting distinct owners."""
    crossed = set()
    for box, k in zip(boxes, owner, strict=True):
        lo, hi = (box[0], box[1], box[4]), (box[2], box[3], box[5])
        t0, t1 = 0.0, 1.0
        hit = True
        for a in range(3):
            d = end[a] - origin[a]
            if d == 0.0:
                if not lo[a] < origin[a] < hi[a]:
                    hit = False
                    break
                continue
            ta, tb = (lo[a] - origin[a]) / d, (hi[a] - origin[a]) / d
            t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
        if hit and t0 < t1:
            crossed.add(int(k))
    return len(crossed)


def test_ray_through_two_boxes_of_one_object_counts_once():
    # An L-shaped counter: two boxes of one object, both on the ray's way.
    boxes = np.array([[2.0, -1.0, 3.0, 1.0, 0.0, 2.0], [5.0, -1.0, 6.0, 1.0, 0.0, 2.0]])
    origin, end = np.array([0.0, 0.0, 1.0]), np.array([[10.0, 0.0, 1.0]])
    assert G.segment_box_hits(origin, end, boxes).tolist() == [[True, True]]
    assert G.count_obstacles(origin, end, boxes, owner=[0, 0]).tolist() == [1]
    # The same boxes as two objects count twice.
    assert G.count_obstacles(origin, end, boxes, owner=[0, 1]).tolist() == [2]
    # A segment that stops before the second box only sees the first.
    assert G.count_obstacles(origin, np.array([[4.0, 0.0, 1.0]]), boxes, owner=[0, 1]).tolist() == [1]


def test_segment_misses_and_grazing():
    box = np.array([[2.0, 2.0, 3.0, 3.0, 0.0, 2.0]])
    origin = np.array([0.0, 0.0, 1.0])
    # passes beside, above, and exactly along a face plane (grazing: not a crossing)
    ends = np.array([[10.0, 0.0, 1.0], [2.5, 2.5, 5.0 + 1.5 * 4], [10.0, 2.0, 1.0], [2.5, 2.5, 1.0]])
    hits = G.segment_box_hits(origin, ends, box)[:, 0]
    assert hits.tolist() == [False, False, False, True]


def test_hanging_object_blocks_rays_not_motion():
    scenario = load_scenario("small")
    radio_map = RadioMap.for_scenario(scenario)
    lamp = next(o for o in scenario.obstacles if o.name == "lamp")
    x0, y0, x1, y1, z0, z1 = lamp.boxes[0]
    assert z0 >= scenario.robot.body_height
    ix, iy = radio_map.cell_index(np.array([(x0 + x1) / 2, (y0 + y1) / 2]))
    assert not radio_map.blocked[ix, iy]
    # A ray at the lamp's height through it is blocked; one below it is not.
    z = (z0 + z1) / 2
    assert radio_map.obstacles_crossed((x0 - 1.0, (y0 + y1) / 2, z), (x1 + 1.0, (y0 + y1) / 2, z)) == 1
    assert radio_map.obstacles_crossed((x0 - 1.0, (y0 + y1) / 2, 1.5), (x1 + 1.0, (y0 + y1) / 2, 1.5)) == 0
    # The low table blocks motion but not a ray at antenna height.
    table = next(o for o in scenario.obstacles if o.name == "table").boxes[0]
    tx, ty = radio_map.cell_index(np.array([(table[0] + table[2]) / 2, (table[1] + table[3]) / 2]))
    assert radio_map.blocked[tx, ty]
    assert radio_map.obstacles_crossed((table[0] - 1, ty * 0.5 + 0.25, 1.5), (table[2] + 1, ty * 0.5 + 0.25, 1.5)) == 0


def test_floor_slab_counts_for_upstairs_interferer():
    scenario = load_scenario("mall")
    radio_map = RadioMap.for_scenario(scenario)
    upstairs = next(i for i in scenario.interferers if i.name == "upstairs")
    slab = next(o for o in scenario.obstacles if o.name == "floor_slab").boxes[0]
    assert slab[4] > scenario.ap.position[2] and upstairs.position[2] > slab[5]
    # Every cell sees at least the slab from upstairs; the AP, below the slab, sees it nowhere.
    assert radio_map.n_obstacles["upstairs"].min() >= 1
    below = (upstairs.position[0], upstairs.position[1], scenario.robot.antenna_height)
    assert radio_map.obstacles_crossed(upstairs.position, below) == 1
    ix, iy = radio_map.cell_index(np.array(upstairs.position[:2]))
    assert radio_map.n_obstacles["upstairs"][ix, iy] == 1
    # Without the slab the link from upstairs to the cell below it is LoS, and the AP's counts are unchanged.
    data = scenario.to_dict()
    data["obstacles"] = [o for o in data["obstacles"] if o["name"] != "floor_slab"]
    without_slab = RadioMap(Scenario.from_dict(data))
    assert without_slab.n_obstacles["upstairs"][ix, iy] == 0
    np.testing.assert_array_equal(without_slab.n_obstacles["ap"], radio_map.n_obstacles["ap"])


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), chunk=st.sampled_from([1, 7, 1000, G.CHUNK_PAIRS]))
def test_vectorised_count_equals_reference(seed, chunk):
    rng = np.random.default_rng(seed)
    n_boxes = int(rng.integers(1, 12))
    lo = rng.uniform(0, 8, size=(n_boxes, 3))
    size = rng.uniform(0.2, 4, size=(n_boxes, 3))
    boxes = np.column_stack(
        [lo[:, 0], lo[:, 1], lo[:, 0] + size[:, 0], lo[:, 1] + size[:, 1], lo[:, 2], lo[:, 2] + size[:, 2]]
    )
    owner = np.sort(rng.integers(0, max(1, n_boxes // 2), size=n_boxes))
    ends = rng.uniform(-1, 11, size=(40, 3))
    origin = rng.uniform(-1, 11, size=3)
    got = G.count_obstacles(origin, ends, boxes, owner, chunk_pairs=chunk)
    expected = [reference_count(origin, end, boxes, owner) for end in ends]
    assert got.tolist() == expected
    # per-ray origins too
    origins = rng.uniform(-1, 11, size=(40, 3))
    got = G.count_obstacles(origins, ends, boxes, owner, chunk_pairs=chunk)
    assert got.tolist() == [reference_count(o, e, boxes, owner) for o, e in zip(origins, ends, strict=True)]


def test_radio_map_counts_equal_reference_on_small():
    scenario = load_scenario("small")
    radio_map = RadioMap(scenario)
    for name, (position, _) in radio_map.transmitters.items():
        for ix in range(0, radio_map.nx, 3):
            for iy in range(0, radio_map.ny, 3):
                rx = (*radio_map.cell_center(ix, iy), scenario.robot.antenna_height)
                assert radio_map.n_obstacles[name][ix, iy] == reference_count(
                    position, rx, radio_map.boxes, radio_map.box_owner
                )


def test_snapping_rule():
    shape = (20, 10)  # 10 m x 5 m at 0.5 m
    boxes = np.array(
        [
            [1.0, 1.0, 2.0, 2.0, 0.0, 1.0],  # on grid lines
            [1.2, 1.3, 2.8, 2.2, 0.0, 1.0],  # edges round to the nearest line: 1.0, 1.5, 3.0, 2.0
            [4.1, 0.0, 4.3, 5.0, 0.0, 3.0],  # thinner than a cell: the cell containing its centre (4.2 -> ix 8)
            [9.9, 4.9, 10.0, 5.0, 0.0, 1.0],  # a sliver in the corner keeps one cell
        ]
    )
    cells = G.snap_boxes(boxes, 0.5, shape)
    assert cells.tolist() == [[2, 2, 4, 4], [2, 3, 6, 4], [8, 0, 9, 10], [19, 9, 20, 10]]
    metres = G.snapped_boxes_m(boxes, 0.5, shape)
    np.testing.assert_allclose(metres[1], [1.0, 1.5, 3.0, 2.0, 0.0, 1.0])


def test_occupancy_and_height_matrices():
    boxes = np.array(
        [
            [0.0, 0.0, 1.0, 1.0, 0.0, 0.8],  # sofa: blocks motion
            [2.0, 0.0, 3.0, 1.0, 2.5, 3.0],  # hanging: does not
            [2.0, 0.0, 2.5, 0.5, 0.0, 1.2],  # a stand under it: blocks
            [4.0, 0.0, 5.0, 1.0, 0.99, 2.0],  # bottom just under body height: blocks
        ]
    )
    blocked = G.occupancy_grid(boxes, 5.0, 1.0, 0.5, body_height=1.0)
    assert blocked.shape == (10, 2)
    expected = np.zeros((10, 2), dtype=bool)
    expected[0:2, :] = True
    expected[4, 0] = True
    expected[8:10, :] = True
    np.testing.assert_array_equal(blocked, expected)
    bottom, top = G.height_matrices(boxes, 5.0, 1.0, 0.5)
    assert bottom[4, 0] == 0.0 and top[4, 0] == 3.0  # the stand and the hanging box stack
    assert bottom[5, 1] == 2.5 and top[5, 1] == 3.0
    assert bottom[6, 0] == 0.0 and top[6, 0] == 0.0  # empty


def test_region_cells():
    cells = G.region_cells((1.0, 1.0, 2.0, 1.5), 0.5, (10, 10))
    # centres 1.25, 1.75 in x; 1.25 in y
    assert cells.tolist() == [[2, 2], [3, 2]]
    # a region too small for any centre gives the cell of its midpoint
    assert G.region_cells((1.05, 1.05, 1.1, 1.1), 0.5, (10, 10)).tolist() == [[2, 2]]


def octile(dx, dy, res):
    return res * (abs(abs(dx) - abs(dy)) + math.sqrt(2) * min(abs(dx), abs(dy)))


def test_distance_field_open_grid_is_octile():
    blocked = np.zeros((12, 7), dtype=bool)
    field = G.grid_distance_field(blocked, (3, 2), 0.5)
    for ix in range(12):
        for iy in range(7):
            assert field[ix, iy] == pytest.approx(octile(ix - 3, iy - 2, 0.5))


def test_no_corner_cutting_and_walls():
    blocked = np.zeros((3, 3), dtype=bool)
    blocked[1, 0] = True
    # (0, 0) -> (1, 1) would cut the corner of (1, 0): the path goes through (0, 1) instead.
    assert G.grid_distance_field(blocked, (1, 1), 1.0)[0, 0] == pytest.approx(2.0)
    # A wall with one gap: the field goes around it, blocked cells are inf.
    blocked = np.zeros((7, 5), dtype=bool)
    blocked[3, 1:] = True
    field = G.grid_distance_field(blocked, (0, 4), 1.0)
    assert np.isinf(field[3, 2])
    # (0, 4) -> (2, 0), straight through the gap (3, 0) to (4, 0) (no diagonal into or out of it:
    # that would cut the corner of (3, 1)), then (4, 0) -> (6, 4).
    assert field[6, 4] == pytest.approx(octile(2, 4, 1.0) + 2.0 + octile(2, 4, 1.0))
    blocked[3, 0] = True  # close the gap
    assert np.isinf(G.grid_distance_field(blocked, (0, 4), 1.0)[6, 4])


def test_shortest_path():
    rng = np.random.default_rng(3)
    blocked = rng.random((30, 20)) < 0.25
    blocked[0, 0] = blocked[29, 19] = False
    field = G.grid_distance_field(blocked, (29, 19), 0.5)
    cells, length = G.shortest_path(blocked, (0, 0), (29, 19), resolution=0.5)
    if not np.isfinite(field[0, 0]):
        assert len(cells) == 0 and length == math.inf
        return
    assert length == pytest.approx(field[0, 0])
    assert cells[0].tolist() == [0, 0] and cells[-1].tolist() == [29, 19]
    assert not blocked[cells[:, 0], cells[:, 1]].any()
    steps = np.diff(cells, axis=0)
    assert np.abs(steps).max() == 1
    for (x, y), (dx, dy) in zip(cells[:-1], steps, strict=True):
        if dx and dy:
            assert not blocked[x + dx, y] and not blocked[x, y + dy]
    assert 0.5 * np.hypot(steps[:, 0], steps[:, 1]).sum() == pytest.approx(length)


def test_shortest_path_with_cost_detours():
    blocked = np.zeros((11, 5), dtype=bool)
    cost = np.zeros((11, 5))
    cost[5, 0:4] = 100.0  # expensive strip with a cheap gap at the top row
    cells, _ = G.shortest_path(blocked, (0, 0), (10, 0), cost=cost, resolution=1.0)
    assert [5, 4] in cells.tolist()
    cells, length = G.shortest_path(blocked, (0, 0), (10, 0), resolution=1.0)
    assert length == pytest.approx(10.0)
    with pytest.raises(ValueError, match=r"cost: expected a finite non-negative array of shape \(11, 5\)"):
        G.shortest_path(blocked, (0, 0), (10, 0), cost=-cost)
    with pytest.raises(ValueError, match=r"start_cell: \(11, 0\) is outside the grid"):
        G.shortest_path(blocked, (11, 0), (10, 0))


@settings(max_examples=40, deadline=None)
@given(
    data=st.lists(
        st.tuples(st.floats(0.0, 9.8), st.floats(0.0, 4.8), st.floats(0.05, 4.0), st.floats(0.05, 3.0), st.floats(0.0, 2.0)),
        min_size=1,
        max_size=6,
    )
)
def test_occupancy_follows_snapping(data):
    # 10 m x 5 m at 0.5 m. A cell whose centre is strictly inside a blocking box is blocked, and a
    # blocked cell is within half a cell of some blocking box (edges round to the nearest grid line).
    res, body = 0.5, 1.0
    boxes = np.array([[x, y, min(x + w, 10.0), min(y + d, 5.0), z, z + 1.0] for x, y, w, d, z in data])
    blocked = G.occupancy_grid(boxes, 10.0, 5.0, res, body)
    blocking = boxes[boxes[:, 4] < body]
    cx, cy = np.meshgrid((np.arange(20) + 0.5) * res, (np.arange(10) + 0.5) * res, indexing="ij")
    inside = np.zeros_like(blocked)
    near = np.zeros_like(blocked)
    for x0, y0, x1, y1, _, _ in blocking:
        inside |= (cx > x0 + 1e-9) & (cx < x1 - 1e-9) & (cy > y0 + 1e-9) & (cy < y1 - 1e-9)
        near |= (cx >= x0 - res) & (cx <= x1 + res) & (cy >= y0 - res) & (cy <= y1 + res)
    assert not (inside & ~blocked).any()
    assert not (blocked & ~near).any()
    # hanging boxes (z_bottom >= body) never block on their own
    if len(blocking) == 0:
        assert not blocked.any()


finite_floats = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=2000, deadline=None)
@given(dx=finite_floats, dy=finite_floats)
def test_compiled_hypot_gives_the_bits_of_math_hypot(dx, dy):
    assert G.hypot(dx, dy) == math.hypot(dx, dy)


@settings(max_examples=300, deadline=None)
@given(scale=st.sampled_from([1e-310, 1e-3, 1.0, 55.0, 1e300]), seed=st.integers(0, 2**32 - 1))
def test_distance_gives_the_bits_of_math_hypot(scale, seed):
    # Random magnitudes (subnormal ones included) and near-equal points, where libm's hypot differs most often
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((64, 2)) * scale
    b = a + rng.standard_normal((64, 2)) * scale * rng.choice([1e-9, 1.0], (64, 1))
    expected = [math.hypot(x0 - x1, y0 - y1) for (x0, y0), (x1, y1) in zip(a.tolist(), b.tolist(), strict=True)]
    assert G.distance(a, b).tolist() == expected
    assert G.distance(a.reshape(4, 16, 2), b.reshape(4, 16, 2)).shape == (4, 16)


def test_hypot_edge_values_follow_math_hypot():
    for dx, dy in [(0.0, -0.0), (3.0, 4.0), (math.inf, math.nan), (math.nan, -math.inf), (1e308, 1e308), (5e-324, 0.0)]:
        assert G.hypot(dx, dy) == math.hypot(dx, dy)
    assert math.isnan(G.hypot(math.nan, 1.0))


def test_point_cell_and_flat_cell_clip_to_the_grid():
    points = np.array([[-0.1, 0.2], [0.49, 0.51], [5.0, 2.99], [100.0, -3.0]])
    ix, iy = G.point_cell(points, 0.5, (10, 6))
    assert ix.tolist() == [0, 0, 9, 9] and iy.tolist() == [0, 1, 5, 0]
    assert G.flat_cell(points.reshape(2, 2, 2), 0.5, (10, 6)).tolist() == [[0, 1], [59, 54]]


def test_points_must_have_two_coordinates():
    for call in (lambda: G.point_cell(np.ones((4, 3)), 0.5, (10, 6)), lambda: G.distance(np.ones((2, 3)), np.zeros(3))):
        with pytest.raises(ValueError, match=r"points: expected shape \(..., 2\), got \((4|2), 3\)"):
            call()
