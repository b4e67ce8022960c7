"""Path loss (paper Eq. (1)-(3)), the channel gain with fading (Eq. (4), (17)), power units and noise."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from noma_radiomap.propagation import (
    EXPECTED_FADING_DB,
    dbm_to_watt,
    expected_channel_gain,
    faded_gain,
    interference_power,
    linear_to_db,
    noise_power_dbm,
    path_gain,
    path_loss_db,
    sequential_sum,
    watt_to_dbm,
)

# 20 log10(2000 MHz) = 20 (3 + log10 2) = 66.0206 dB, the frequency term of both formulas.
FREQ_TERM = 20 * (3 + 0.30103)


def test_los_hand_computed():
    # L = 16.9 log10(d) - 27.2 + 20 log10(f); d = 10 m -> 16.9 - 27.2 + 66.0206 = 55.7206
    assert path_loss_db(10.0, 0) == pytest.approx(16.9 * 1 - 27.2 + FREQ_TERM, abs=1e-3)
    assert path_loss_db(10.0, 0) == pytest.approx(55.7206, abs=1e-3)
    # d = 100 m -> 33.8 - 27.2 + 66.0206 = 72.6206
    assert path_loss_db(100.0, 0) == pytest.approx(72.6206, abs=1e-3)


@pytest.mark.parametrize(
    ("n", "expected"),
    [
        # L = 20 log10(f) - 28 + N log10(d) + 15 + 4 (n - 1), N = 25.5, d = 10 m
        (1, FREQ_TERM - 28 + 25.5 * 1 + 15 + 4 * 0),  # 78.5206
        (2, FREQ_TERM - 28 + 25.5 * 1 + 15 + 4 * 1),  # 82.5206
        (3, FREQ_TERM - 28 + 25.5 * 1 + 15 + 4 * 2),  # 86.5206
    ],
)
def test_nlos_hand_computed(n, expected):
    assert path_loss_db(10.0, n) == pytest.approx(expected, abs=1e-3)


def test_nlos_at_20m_with_custom_constants():
    # f = 1000 MHz (60 dB), N = 30, d = 20 m (log10 20 = 1.30103), wall 10 dB, step 2 dB, n = 3
    expected = 60.0 - 28.0 + 30.0 * 1.30103 + 10.0 + 2.0 * 2
    got = path_loss_db(20.0, 3, frequency_mhz=1000.0, nlos_distance_coefficient=30.0, wall_loss_db=10.0, wall_loss_step_db=2.0)
    assert got == pytest.approx(expected, abs=1e-3)


def test_distance_clipped_to_one_metre():
    # Below 1 m the model is not valid (docs/MODEL.md: d >= 1); the loss is that of d = 1 m.
    assert path_loss_db(0.2, 0) == pytest.approx(-27.2 + FREQ_TERM, abs=1e-3)
    assert path_loss_db(0.0, 2) == pytest.approx(FREQ_TERM - 28 + 15 + 4, abs=1e-3)


def test_broadcasting():
    distances = np.array([[2.0], [5.0], [40.0]])
    counts = np.array([0, 1, 2, 3])
    loss = path_loss_db(distances, counts)
    assert loss.shape == (3, 4)
    for i, d in enumerate(distances[:, 0]):
        for j, n in enumerate(counts):
            assert loss[i, j] == path_loss_db(d, n)


@given(
    d=st.floats(1.0, 500.0),
    extra=st.floats(0.01, 100.0),
    n=st.integers(0, 6),
)
def test_loss_grows_with_distance_and_obstacles(d, extra, n):
    assert path_loss_db(d + extra, n) > path_loss_db(d, n)
    assert path_loss_db(d, n + 1) > path_loss_db(d, n)


def test_bad_arguments():
    with pytest.raises(ValueError, match=r"n_obstacles: must be >= 0, got min -1"):
        path_loss_db(10.0, -1)
    with pytest.raises(ValueError, match=r"frequency_mhz: must be a positive number, got 0.0"):
        path_loss_db(10.0, 0, frequency_mhz=0.0)


def test_expected_fading_constant():
    # E[10 log10 X], X ~ Exp(1): E[ln X] = -gamma (Euler-Mascheroni), so -10 * 0.5772157 / ln 10 = -2.5068 dB.
    assert pytest.approx(-10 * 0.5772156649 / math.log(10), abs=1e-9) == EXPECTED_FADING_DB
    assert pytest.approx(-2.51, abs=0.005) == EXPECTED_FADING_DB
    # Monte Carlo: std of 10 log10 X is 5.57 dB, so the mean of 10^6 draws is within ~0.006 dB.
    draws = np.random.default_rng(0).exponential(1.0, size=1_000_000)
    assert np.mean(10 * np.log10(draws)) == pytest.approx(EXPECTED_FADING_DB, abs=0.03)


def test_power_units():
    assert dbm_to_watt(30.0) == pytest.approx(1.0)
    assert dbm_to_watt(20.0) == pytest.approx(0.1)
    assert watt_to_dbm(1e-3) == pytest.approx(0.0)
    assert watt_to_dbm(0.0) == -np.inf


@given(st.floats(-200.0, 60.0))
def test_dbm_watt_round_trip(power_dbm):
    assert watt_to_dbm(dbm_to_watt(power_dbm)) == pytest.approx(power_dbm, abs=1e-9)


def test_noise_power():
    # N0 = -100 dBm/Hz = 1e-13 W/Hz; over W = 2 x 15 kHz: 3e-9 W = -100 + 10 log10(30000) = -55.2288 dBm.
    assert noise_power_dbm(-100.0, 30_000.0) == pytest.approx(-100.0 + 44.7712, abs=1e-4)
    # OMA: one robot's band B = 15 kHz -> -58.2391 dBm
    assert noise_power_dbm(-100.0, 15_000.0) == pytest.approx(-58.2391, abs=1e-4)
    with pytest.raises(ValueError, match=r"bandwidth_hz: must be > 0, got 0"):
        noise_power_dbm(-100.0, 0.0)


def test_channel_gain_by_hand():
    # 80 dB of path loss: 1e-8 without fading; the expected fading takes 2.5068 dB off.
    assert path_gain(80.0) == pytest.approx(1e-8, rel=1e-12)
    assert expected_channel_gain(80.0) == pytest.approx(1e-8 * 10 ** (EXPECTED_FADING_DB / 10), rel=1e-12)
    assert faded_gain(np.array([1e-8, 2e-8]), np.array([0.5, 2.0])).tolist() == [5e-9, 4e-8]


def test_interference_is_the_power_weighted_gain_sum():
    gains = np.array([[1e-9, 2e-9], [3e-9, 0.0]])  # two receivers, two interferers
    np.testing.assert_allclose(interference_power(gains, np.array([0.5, 1.0])), [2.5e-9, 1.5e-9], rtol=1e-12)
    assert interference_power(np.zeros((3, 0)), np.zeros(0)).tolist() == [0.0, 0.0, 0.0]


def test_sequential_sum_adds_left_to_right():
    values = np.array([1.0, 1e16, -1e16])
    assert sequential_sum(values) == (1.0 + 1e16) - 1e16  # 0.0; a pairwise or reordered sum may give 1.0
    np.testing.assert_array_equal(sequential_sum(np.stack([values, values[::-1]])), [0.0, (-1e16 + 1e16) + 1.0])


def test_linear_to_db_floors_zero():
    assert linear_to_db(100.0) == pytest.approx(20.0)
    assert np.isfinite(linear_to_db(0.0)) and linear_to_db(0.0) < -3000
