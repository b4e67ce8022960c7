"""Reward components, phase weights and the MQI (paper Eq. (14), (26)-(27)): by hand, and batch = missions."""

import numpy as np
import pytest

from noma_radiomap.rewards import (
    REWARD_COMPONENTS,
    RewardConstants,
    mission_quality_indicator,
    phase_weights,
    reward_components,
    weighted_reward,
)
from noma_radiomap.scenario import Room

PAPER = RewardConstants()


def test_components_by_hand():
    # Robot 0 on its way and in outage at 3 m of its goal, robot 1 arriving: the success is not paid yet.
    c = reward_components([True, True], [False, True], [True, False], [3.0, 0.5], 10.0, PAPER)
    assert {k: float(v) for k, v in c.items()} == pytest.approx(
        {"time": -2.0, "inducing": (1 - 0.3) + (1 - 0.05), "qos": -1.0, "arrival": 10.0, "success": 0.0}
    )
    # Robot 0 arrived before, robot 1 arrives now: only robot 1 counts, and the mission succeeds.
    c = reward_components([False, True], [False, True], [True, True], [0.0, 0.5], 10.0, PAPER)
    assert (float(c["time"]), float(c["qos"]), float(c["success"])) == (-1.0, -1.0, 200.0)


def test_phase_weights_are_the_paper_phases():
    assert [k for k, w in phase_weights("destination").items() if w] == ["time", "inducing", "arrival", "success"]
    assert [k for k, w in phase_weights("mqi").items() if w] == ["time", "qos", "arrival", "success"]
    assert list(phase_weights("combined")) == list(REWARD_COMPONENTS)
    with pytest.raises(ValueError, match="reward_phase must be one of"):
        phase_weights("bogus")


def test_batch_gives_the_same_bits_as_each_mission():
    rng = np.random.default_rng(0)
    active, arriving, outage = rng.random((3, 8, 3)) < 0.5
    arriving &= active
    distance = rng.uniform(0, 30, (8, 3))
    batch = reward_components(active, arriving, outage, distance, 31.0, PAPER)
    weights = phase_weights("combined")
    batch_reward = weighted_reward(batch, weights)
    for n in range(8):
        one = reward_components(active[n], arriving[n], outage[n], distance[n], 31.0, PAPER)
        for key in REWARD_COMPONENTS:
            assert batch[key][n] == one[key]
        assert batch_reward[n] == weighted_reward(one, weights)


def test_mqi_by_hand():
    assert mission_quality_indicator(100.0, np.array([10, 60]), np.array([3, 0]), 2.0) == 100 - (10 + 6 + 60)


def test_room_owns_cells_and_d_max():
    room = Room(12.0, 8.0, 0.5)
    assert room.d_max == pytest.approx(np.hypot(12, 8))
    points = np.array([[0.0, 0.0], [0.49, 0.51], [11.99, 7.99], [6.25, 3.75]])
    ix, iy = room.cell_index(points)
    assert ix.tolist() == [0, 0, 23, 12] and iy.tolist() == [0, 1, 15, 7]
    assert room.flat_cell_index(points).tolist() == (ix * room.ny + iy).tolist()
    np.testing.assert_array_equal(room.cell_index(room.cell_center(ix, iy)), (ix, iy))
    assert room.contains(np.array([[0.0, 0.0], [12.0, 1.0], [-0.1, 1.0]])).tolist() == [True, False, False]


def test_components_broadcast_like_numpy_and_refuse_mismatched_shapes():
    active = np.ones((3, 2), dtype=bool)
    broadcast = reward_components(active, [False, True], np.zeros((3, 2), bool), [1.0, 2.0], 10.0, PAPER)
    explicit = reward_components(
        active, np.tile([False, True], (3, 1)), np.zeros((3, 2), bool), np.tile([1.0, 2.0], (3, 1)), 10.0, PAPER
    )
    for key in REWARD_COMPONENTS:
        np.testing.assert_array_equal(broadcast[key], explicit[key])
    with pytest.raises(ValueError, match="broadcast"):
        reward_components(active, [False, True, False], active, np.ones((3, 2)), 10.0, PAPER)
