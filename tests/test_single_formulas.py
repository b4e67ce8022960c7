"""One implementation of each formula: the public numpy functions and the env's compiled kernels share theirs.

Each test pins a merge to the bits of the code it replaced (where they are the same) or to its kernel's.
"""

import gymnasium as gym
import numpy as np
import pytest

import noma_radiomap  # noqa: F401  (registers the ids)
from noma_radiomap.core import _summary_rows
from noma_radiomap.downlink import band_and_noise, decoding_order, equivalent_gain, sinr_rows
from noma_radiomap.motion import clip_displacements, clipped_displacement
from noma_radiomap.planners import _qos_sinr, single_outage_maps
from noma_radiomap.propagation import dbm_to_watt
from noma_radiomap.radiomap import antenna_distance
from noma_radiomap.rewards import REWARD_COMPONENTS, mission_quality_indicator, phase_weights, weighted_reward


def _left_to_right(terms: np.ndarray) -> np.ndarray:
    total = terms[..., 0].copy()
    for u in range(1, terms.shape[-1]):
        total = total + terms[..., u]
    return total


@pytest.mark.parametrize("n_robots", [1, 2, 3, 7, 8, 13])
def test_mqi_is_one_left_to_right_sum(n_robots):
    rng = np.random.default_rng(n_robots)
    mission_time = rng.integers(1, 300, (50, n_robots))
    outage = rng.integers(0, 300, (50, n_robots))
    penalty = 0.37  # not an integer: the order of the sum shows in the bits
    mqi = mission_quality_indicator(1000.0, mission_time, outage, penalty)
    assert mqi.shape == (50,) and mqi.dtype == np.float64
    np.testing.assert_array_equal(mqi, 1000.0 - _left_to_right(mission_time + penalty * outage))
    if n_robots <= 7:  # numpy adds up to 7 terms left to right too (the bits of the numpy formula it replaces)
        np.testing.assert_array_equal(mqi, 1000.0 - (mission_time + penalty * outage).sum(axis=-1))
    # The env's summaries: the same function
    arrived = rng.random((50, n_robots)) < 0.7
    success, summary_mqi, summary_time, _ = _summary_rows(arrived, mission_time, outage, 300, 1000.0, penalty)
    np.testing.assert_array_equal(summary_time, np.where(arrived, mission_time, 300))
    np.testing.assert_array_equal(summary_mqi, mission_quality_indicator(1000.0, summary_time, outage, penalty))
    np.testing.assert_array_equal(success, arrived.all(axis=-1))
    # One mission: a 0-d array
    assert mission_quality_indicator(1000.0, mission_time[0], outage[0], penalty) == mqi[0]


def test_weighted_reward_keeps_the_bits_of_the_numpy_sum():
    rng = np.random.default_rng(1)
    components = {name: rng.normal(0, 50, 40) for name in REWARD_COMPONENTS}
    per_mission = {name: rng.choice([0.0, 1.0, 0.3], 40) for name in REWARD_COMPONENTS}
    for weights in (phase_weights("combined"), phase_weights("mqi"), per_mission, {"qos": 2.5}):
        expected = 0.0
        for name, value in components.items():
            expected = expected + weights.get(name, 0.0) * value
        np.testing.assert_array_equal(weighted_reward(components, weights), expected)
    one = {name: value[3] for name, value in components.items()}
    assert weighted_reward(one, phase_weights("destination")).shape == ()
    assert weighted_reward({}, {}) == 0.0


def test_clip_displacements_is_the_motion_kernel_s_clip():
    rng = np.random.default_rng(2)
    actions = rng.uniform(-1.5, 1.5, (200, 2))
    actions[:5] = [[0.0, 0.0], [1.0, 1.0], [-3.0, 0.0], [0.6, 0.8], [np.nextafter(0.6, 1), 0.8]]
    for max_step in (0.3, 1.0, 2.5):
        out = clip_displacements(actions, max_step)
        kernel = np.array([clipped_displacement(x, y, max_step, 1) for x, y in actions])
        np.testing.assert_array_equal(out, kernel)
        # The numpy formula it replaced, to the last bit or so (its norm was np.sqrt, the kernel's CPython's hypot)
        step = np.clip(actions, -1.0, 1.0) * max_step
        norm = np.sqrt((step * step).sum(axis=-1, keepdims=True))
        np.testing.assert_allclose(out, step * np.minimum(1.0, max_step / np.maximum(norm, 1e-300)), rtol=1e-15, atol=0)
        assert (np.linalg.norm(out, axis=-1) <= max_step * (1 + 1e-15)).all()
        # The sub-steps of the kernel: the displacement in n equal parts
        parts = np.array([clipped_displacement(x, y, max_step, 3) for x, y in actions])
        np.testing.assert_allclose(3 * parts, out, rtol=1e-15, atol=1e-300)
    assert clip_displacements(np.array([0.5, 0.0]), 2.0).shape == (2,)


def test_decoding_order_is_numpy_s_stable_argsort():
    rng = np.random.default_rng(3)
    gains = rng.integers(0, 4, (6, 5, 4)).astype(np.float64)  # many ties: a lower index counts as weaker
    np.testing.assert_array_equal(decoding_order(gains), np.argsort(gains, axis=-1, kind="stable"))
    gains = rng.lognormal(0, 3, (7, 3))
    np.testing.assert_array_equal(decoding_order(gains), np.argsort(gains, axis=-1, kind="stable"))
    assert decoding_order(gains[0]).shape == (3,)
    # The env's kernels order by the same function, with the cluster-band noise in both modes
    power, gain, interference = rng.uniform(0.0, 0.1, (7, 3)), gains * 1e-9, rng.uniform(0, 1e-10, (7, 3))
    n0, b = 1e-13, 15000.0
    for noma in (True, False):
        _, order = sinr_rows(power, gain, interference, b, n0, noma)
        np.testing.assert_array_equal(order, decoding_order(equivalent_gain(gain, interference, n0 * (3 * b))))


def test_band_and_noise_per_mode():
    assert band_and_noise(3, 15000.0, 1e-13, True) == (3 * 15000.0, 1e-13 * (3 * 15000.0))
    assert band_and_noise(3, 15000.0, 1e-13, False) == (15000.0, 1e-13 * 15000.0)


@pytest.mark.parametrize("scenario", ["small", "mall"])
def test_single_robot_outage_maps(scenario):
    # RadioMap.outage_map is the single-robot outage with the whole AP power over the NOMA band W (the radio map has
    # no mode); the planners' map of the NOMA mode is the same region (another computation: the least power, on the
    # linear scale), the OMA mode's a larger one (band B alone: a higher SINR threshold), by design (docs/MODEL.md).
    env = gym.make("NomaRadioMap-v0", scenario=scenario).unwrapped
    radio_map = env.radio_map
    noma, _ = single_outage_maps(env, "noma")
    oma, _ = single_outage_maps(env, "oma")
    np.testing.assert_array_equal(noma, radio_map.outage_map())
    assert (oma >= noma).all() and (oma & ~noma).any()
    assert radio_map.bandwidth_hz == env.scenario.n_robots * env.scenario.radio.bandwidth_per_robot_hz
    assert _qos_sinr(env.scenario, "oma") > _qos_sinr(env.scenario, "noma")
    noise_w = float(dbm_to_watt(env.scenario.radio.noise_dbm_per_hz)) * radio_map.bandwidth_hz
    assert 10 * np.log10(noise_w / 1e-3) == pytest.approx(radio_map.noise_dbm, abs=1e-9)


def test_antenna_distance():
    receivers = np.array([[3.0, 4.0, 1.5], [0.0, 0.0, 1.5]])
    np.testing.assert_allclose(antenna_distance(np.array([0.0, 0.0, 3.5]), receivers), [np.sqrt(29.0), 2.0])


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (
            lambda: mission_quality_indicator(100, 5, 2, 2.0),
            r"mission_time, outage_steps: expected arrays of shape \(\.\.\., U\), got shape \(\)",
        ),
        (
            lambda: mission_quality_indicator(np.array([100, 90]), [5], [2], 1.0),
            r"t_total: expected a number, got an array of shape \(2,\)",
        ),
        (lambda: decoding_order(np.float64(2.0)), r"equivalent_gains: expected arrays of shape \(\.\.\., U\), got shape \(\)"),
        (
            lambda: clip_displacements([1.0, 0.0, 0.0, 0.0], 0.5),
            r"actions: expected arrays of shape \(\.\.\., 2\), got shape \(4,\)",
        ),
        (lambda: clip_displacements([1.0, 0.0], np.array([0.5, 0.5])), r"max_step: expected a number, got an array"),
    ],
)
def test_the_row_functions_name_inputs_of_another_shape(call, message):
    with pytest.raises(ValueError, match=message):  # were IndexErrors, or a (4,) vector read as two robots
        call()


def test_the_row_functions_take_empty_batches_and_one_robot():
    assert mission_quality_indicator(100.0, np.zeros((0, 2)), np.zeros((0, 2)), 1.0).shape == (0,)
    assert mission_quality_indicator(100.0, [7], [3], 2.0) == 87.0
    assert decoding_order([[2.0]]).tolist() == [[0]] and clip_displacements(np.zeros((0, 2)), 0.5).shape == (0, 2)
