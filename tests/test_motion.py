"""Robot motion (paper Sec. IV-D): clipping, sub-steps, wall sliding, arrival; property tests on random grids."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from noma_radiomap.motion import GridMotion, clip_displacements
from noma_radiomap.scenario import Room

RES = 0.5


def _motion(blocked, max_step=1.0, arrival_radius=0.0):
    nx, ny = blocked.shape
    return GridMotion(blocked, Room(nx * RES, ny * RES, RES), max_step, arrival_radius)


def _cells(positions):
    return np.floor(np.asarray(positions) / RES).astype(int)


def test_clip_displacements():
    out = clip_displacements(np.array([[1.0, 1.0], [0.5, 0.0], [-3.0, 0.0], [0.0, 0.0]]), 2.0)
    np.testing.assert_allclose(out, [[np.sqrt(2), np.sqrt(2)], [1.0, 0.0], [-2.0, 0.0], [0.0, 0.0]])
    assert (np.linalg.norm(out, axis=-1) <= 2.0 + 1e-12).all()


def test_straight_move_in_open_room():
    motion = _motion(np.zeros((20, 20), dtype=bool), max_step=1.5)
    new, arrived = motion.move(np.array([[2.0, 2.0], [5.0, 5.0]]), np.array([[1.0, 0.0], [-0.6, 0.8]]))
    np.testing.assert_allclose(new, [[3.5, 2.0], [5.0 - 0.9, 5.0 + 1.2]])
    assert not arrived.any()


def test_room_boundary_stops_and_slides():
    motion = _motion(np.zeros((20, 20), dtype=bool), max_step=1.0)
    pos = np.array([[0.3, 2.0]])
    for _ in range(5):
        pos, _ = motion.move(pos, np.array([[-0.6, 0.8]]))
    assert 0.0 <= pos[0, 0] < 0.3
    # The y component (parallel to the wall x = 0) is kept in full: 5 steps of 0.8 m.
    assert pos[0, 1] == pytest.approx(2.0 + 5 * 0.8)


def test_slides_along_wall_keeping_parallel_component():
    blocked = np.zeros((20, 20), dtype=bool)
    blocked[:, 10] = True  # a wall y in [5.0, 5.5)
    motion = _motion(blocked, max_step=1.0)
    pos = np.array([[2.0, 4.9]])
    for k in range(1, 4):
        pos, _ = motion.move(pos, np.array([[0.6, 0.8]]))
        assert pos[0, 0] == pytest.approx(2.0 + 0.6 * k)
        assert pos[0, 1] < 5.0


def test_arrival_stops_robot_inside_radius():
    motion = _motion(np.zeros((20, 20), dtype=bool), max_step=1.0, arrival_radius=0.3)
    pos, arrived = motion.move(np.array([[2.0, 2.0]]), np.array([[1.0, 0.0]]), destinations=np.array([[2.5, 2.0]]))
    assert arrived[0]
    # Stopped at the first sub-step point inside the radius, not carried on to x = 3.0.
    assert abs(pos[0, 0] - 2.5) <= 0.3


def test_inactive_robots_do_not_move():
    motion = _motion(np.zeros((20, 20), dtype=bool))
    start = np.array([[2.0, 2.0], [4.0, 4.0]])
    pos, _ = motion.move(start, np.ones((2, 2)), active=np.array([False, True]))
    np.testing.assert_array_equal(pos[0], start[0])
    assert not np.array_equal(pos[1], start[1])


def test_is_free():
    blocked = np.zeros((4, 4), dtype=bool)
    blocked[1, 2] = True
    motion = _motion(blocked)
    pts = np.array([[0.1, 0.1], [0.6, 1.1], [-0.1, 0.5], [2.0, 0.5], [1.99, 1.99]])
    np.testing.assert_array_equal(motion.is_free(pts), [True, False, False, False, True])


action_sequences = st.lists(
    arrays(np.float64, (2, 2), elements=st.floats(-1, 1)),
    min_size=1,
    max_size=25,
)


@settings(max_examples=150, deadline=None)
@given(
    blocked=arrays(np.bool_, (8, 6)),
    actions=action_sequences,
    max_step=st.sampled_from([0.2, 0.7, 1.0, 2.3]),
    starts=st.tuples(st.integers(0, 47), st.integers(0, 47)),
)
def test_any_actions_stay_inside_room_and_free(blocked, actions, max_step, starts):
    free = np.argwhere(~blocked)
    assume(len(free) > 0)
    motion = _motion(blocked, max_step=max_step)
    pos = (free[[starts[0] % len(free), starts[1] % len(free)]] + 0.5) * RES
    for action in actions:
        pos, _ = motion.move(pos, action)
        assert motion.is_free(pos).all()
        assert (pos >= 0).all() and (pos[:, 0] < 8 * RES).all() and (pos[:, 1] < 6 * RES).all()


@settings(max_examples=100, deadline=None)
@given(actions=action_sequences, max_step=st.sampled_from([0.5, 1.0, 3.0]), y0=st.floats(0.0, 9.99))
def test_never_tunnels_through_one_cell_wall(actions, max_step, y0):
    blocked = np.zeros((20, 20), dtype=bool)
    blocked[10, :] = True  # x in [5.0, 5.5): no gap
    motion = _motion(blocked, max_step=max_step)
    pos = np.array([[4.9, y0], [5.6, y0]])
    for action in actions:
        pos, _ = motion.move(pos, action)
        assert pos[0, 0] < 5.0 and pos[1, 0] >= 5.5


@settings(max_examples=100, deadline=None)
@given(actions=action_sequences, max_step=st.sampled_from([0.5, 1.0, 3.0]))
def test_never_slips_through_diagonal_wall(actions, max_step):
    blocked = np.eye(12, dtype=bool)  # cells (i, i): touching only at corners
    motion = _motion(blocked, max_step=max_step)
    pos = np.array([[3.3, 1.2], [1.2, 3.3]])  # below and above the diagonal
    for action in actions:
        pos, _ = motion.move(pos, action)
        cells = _cells(pos)
        assert cells[0, 0] > cells[0, 1] and cells[1, 0] < cells[1, 1]


@settings(max_examples=100, deadline=None)
@given(actions=arrays(np.float64, (3, 2), elements=st.floats(-1, 1)), max_step=st.sampled_from([0.3, 1.0, 2.0]))
def test_open_room_move_equals_clipped_displacement(actions, max_step):
    motion = _motion(np.zeros((40, 40), dtype=bool), max_step=max_step)
    start = np.array([[10.0, 10.0], [5.0, 12.0], [14.0, 6.0]])
    new, _ = motion.move(start, actions)
    np.testing.assert_allclose(new - start, clip_displacements(actions, max_step), atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(
    blocked=arrays(np.bool_, (8, 6), elements=st.integers(0, 5).map(lambda k: k == 0)),  # 1 cell in 6 blocked
    actions=action_sequences,
    max_step=st.sampled_from([0.7, 2.3]),
)
def test_collision_free_fast_path_changes_nothing(blocked, actions, max_step):
    free = np.argwhere(~blocked)
    assume(len(free) > 0)
    fast = _motion(blocked, max_step=max_step, arrival_radius=0.4)
    slow = _motion(blocked, max_step=max_step, arrival_radius=0.4)
    slow._fast_path = False  # always take the sub-step collision tests
    pos = fast_pos = (free[[0, -1]] + 0.5) * RES
    goals = (free[[-1, 0]] + 0.5) * RES
    for action in actions:
        fast_pos, fast_arrived = fast.move(fast_pos, action, goals)
        pos, arrived = slow.move(pos, action, goals)
        np.testing.assert_array_equal(fast_pos, pos)
        np.testing.assert_array_equal(fast_arrived, arrived)


def test_move_refuses_mismatched_shapes_and_positions_that_are_not_free():
    blocked = np.zeros((8, 6), dtype=bool)
    blocked[3, 2] = True
    motion = _motion(blocked)
    with pytest.raises(
        ValueError,
        match=r"must be points \(..., 2\); actions \(1, 2\) and destinations \(2, 2\) must have their shape",
    ):
        motion.move_batch(np.ones((2, 2)), np.zeros((1, 2)), np.ones((2, 2)), np.ones(2, dtype=bool))
    with pytest.raises(ValueError, match=r"active \(3,\)"):
        motion.move(np.ones((2, 2)), np.zeros((2, 2)), active=np.ones(3, dtype=bool))
    blocked_point = [3.5 * RES, 2.5 * RES]
    with pytest.raises(ValueError, match=r"positions\[1, 0\]: \[1.75, 1.25\] is outside the room or in a blocked cell"):
        motion.move_batch(
            np.array([[[1.0, 1.0]], [blocked_point]]), np.zeros((2, 1, 2)), np.ones((2, 1, 2)), np.ones((2, 1), bool)
        )
    with pytest.raises(ValueError, match=r"positions\[0\]: \[-0.1, 1.0\]"):
        motion.move(np.array([[-0.1, 1.0]]), np.zeros((1, 2)))
