"""NOMA / OMA downlink (paper Eq. (8)-(13)): hand-computed values and properties against a loop re-computation."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from noma_radiomap.downlink import (
    SINR_DB_FLOOR,
    allocate_power,
    decoding_order,
    downlink,
    equivalent_gain,
    gain_and_sinr_db,
    in_outage,
    sinr_to_db,
)
from noma_radiomap.propagation import linear_to_db

B = 15_000.0  # Hz per robot (Table I)
N0 = 10 ** ((-100.0 - 30.0) / 10.0)  # -100 dBm/Hz in W/Hz
P_MAX = 0.1  # 20 dBm in W


def test_noise_power_by_hand():
    # -100 dBm/Hz over W = 2 x 15 kHz: -100 + 10 log10(30000) = -55.23 dBm = 3.0e-9 W.
    assert N0 * 2 * B == pytest.approx(3.0e-9)
    assert 10 * math.log10(N0 * 2 * B) + 30 == pytest.approx(-55.2288, abs=1e-4)


def test_allocate_power_mapping_and_scaling():
    # a = (0, -1): p = (P/2, 0), sum below P_max, kept.
    np.testing.assert_allclose(allocate_power(np.array([0.0, -1.0]), P_MAX), [0.05, 0.0])
    # a = (1, 0): p = (P, P/2), sum 1.5 P > P -> scaled by 2/3.
    np.testing.assert_allclose(allocate_power(np.array([1.0, 0.0]), P_MAX), [P_MAX * 2 / 3, P_MAX / 3])
    # Out-of-range actions are clipped first.
    np.testing.assert_allclose(allocate_power(np.array([5.0, -7.0]), P_MAX), [P_MAX, 0.0])


def test_two_robot_noma_by_hand():
    # Robot 0 near the AP (gain 1e-6), robot 1 far (gain 1e-9); no interference.
    gain = np.array([1e-6, 1e-9])
    power = np.array([0.02, 0.08])
    interference = np.zeros(2)
    result = downlink(power, gain, interference, B, N0, "noma")
    noise = N0 * 2 * B
    # Robot 0 is stronger: it cancels robot 1's signal -> interference-free.
    sinr0 = 0.02 * 1e-6 / noise
    # Robot 1 is weaker: robot 0's signal stays as interference.
    sinr1 = 0.08 * 1e-9 / (1e-9 * 0.02 + noise)
    np.testing.assert_allclose(result.sinr_db, 10 * np.log10([sinr0, sinr1]))
    np.testing.assert_allclose(result.rate_bps, 2 * B * np.log2(1 + np.array([sinr0, sinr1])))
    np.testing.assert_array_equal(result.decoding_order, [1, 0])
    # sinr0 = 2e-8 / 3e-9 = 6.667 -> rate = 30 kHz x log2(7.667) = 88.15 kb/s.
    assert result.rate_bps[0] == pytest.approx(30_000 * math.log2(1 + 20 / 3))


def test_two_robot_oma_by_hand():
    gain = np.array([1e-6, 1e-9])
    power = np.array([0.02, 0.08])
    interference = np.array([4e-9, 2e-9])
    result = downlink(power, gain, interference, B, N0, "oma")
    sinr = power * gain / (interference / 2 + N0 * B)
    np.testing.assert_allclose(result.rate_bps, B * np.log2(1 + sinr))
    # Robot 0: 2e-8 / (2e-9 + 1.5e-9) = 5.714.
    assert sinr[0] == pytest.approx(2e-8 / 3.5e-9)


def test_equivalent_gain_orders_by_interference_not_only_gain():
    # Same channel gain; robot 0 suffers more interference, so it is the weaker one.
    gain = np.array([1e-8, 1e-8])
    interference = np.array([1e-8, 0.0])
    order = decoding_order(equivalent_gain(gain, interference, N0 * 2 * B))
    np.testing.assert_array_equal(order, [0, 1])


def test_zero_power_gives_zero_rate_and_floored_sinr():
    result = downlink(np.array([0.0, 0.1]), np.array([1e-8, 1e-8]), np.zeros(2), B, N0, "noma")
    assert result.rate_bps[0] == 0.0
    assert result.sinr_db[0] == SINR_DB_FLOOR
    assert np.isfinite(result.sinr_db).all()


def test_outage():
    np.testing.assert_array_equal(in_outage(np.array([59_999.0, 60_000.0, 1e6]), 60_000.0), [True, False, False])


def test_invalid_multiple_access():
    with pytest.raises(ValueError, match=r"multiple_access.*'fdma'"):
        downlink(np.ones(2), np.ones(2), np.zeros(2), B, N0, "fdma")


def test_batched_equals_unbatched():
    rng = np.random.default_rng(0)
    gain = 10 ** rng.uniform(-12, -5, size=(7, 3))
    power = allocate_power(rng.uniform(-1, 1, size=(7, 3)), P_MAX)
    interference = 10 ** rng.uniform(-13, -7, size=(7, 3))
    for mode in ("noma", "oma"):
        batched = downlink(power, gain, interference, B, N0, mode)
        for i in range(7):
            single = downlink(power[i], gain[i], interference[i], B, N0, mode)
            np.testing.assert_allclose(batched.rate_bps[i], single.rate_bps)
            np.testing.assert_array_equal(batched.decoding_order[i], single.decoding_order)


def _reference(power, gain, interference, mode):
    """Straightforward loop re-computation of the paper's Eq. (10)-(12) (docs/MODEL.md)."""
    n = len(power)
    rates, sinrs = [], []
    for u in range(n):
        if mode == "noma":
            eq_u = gain[u] / (interference[u] + N0 * n * B)
            stronger = 0.0
            for v in range(n):
                eq_v = gain[v] / (interference[v] + N0 * n * B)
                # v is stronger than u: larger equivalent gain, ties broken by the larger index.
                if eq_v > eq_u or (eq_v == eq_u and v > u):
                    stronger += power[v]
            sinr = power[u] * gain[u] / (gain[u] * stronger + interference[u] + N0 * n * B)
            rates.append(n * B * math.log2(1 + sinr))
        else:
            sinr = power[u] * gain[u] / (interference[u] / n + N0 * B)
            rates.append(B * math.log2(1 + sinr))
        sinrs.append(sinr)
    return np.array(rates), np.array(sinrs)


placements = st.integers(1, 6).flatmap(
    lambda n: st.tuples(
        arrays(np.float64, n, elements=st.floats(-1, 1)),  # power actions
        arrays(np.float64, n, elements=st.floats(-14, -3)),  # log10 channel gains
        arrays(np.float64, n, elements=st.floats(-16, -6)),  # log10 interference (W)
    )
)


@settings(max_examples=200, deadline=None)
@given(placements, st.sampled_from(["noma", "oma"]))
def test_properties_and_reference(placement, mode):
    actions, log_gain, log_interference = placement
    power = allocate_power(actions, P_MAX)
    gain, interference = 10**log_gain, 10**log_interference
    result = downlink(power, gain, interference, B, N0, mode)

    assert power.sum() <= P_MAX * (1 + 1e-12)
    assert (power >= 0).all()
    assert np.isfinite(result.rate_bps).all() and (result.rate_bps >= 0).all()
    assert np.isfinite(result.sinr_db).all()
    eq = gain / (interference + N0 * len(power) * B)
    assert sorted(result.decoding_order.tolist()) == list(range(len(power)))
    assert (np.diff(eq[result.decoding_order]) >= 0).all()

    rates, sinrs = _reference(power, gain, interference, mode)
    np.testing.assert_allclose(result.rate_bps, rates, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(result.sinr_db, 10 * np.log10(np.maximum(sinrs, 1e-30)), rtol=1e-9, atol=1e-9)


@settings(max_examples=50, deadline=None)
@given(arrays(np.float64, st.integers(1, 6), elements=st.floats(-1, 1)))
def test_strongest_robot_decodes_without_intra_cluster_interference(actions):
    # SIC removes every other robot's signal at the strongest robot: its SINR is the single-user SINR over W.
    power = allocate_power(actions, P_MAX)
    gain = np.geomspace(1e-9, 1e-6, len(power))
    result = downlink(power, gain, np.zeros(len(power)), B, N0, "noma")
    strongest = result.decoding_order[-1]
    expected = power[strongest] * gain[strongest] / (N0 * len(power) * B)
    assert result.rate_bps[strongest] == pytest.approx(len(power) * B * math.log2(1 + expected))


@settings(max_examples=100, deadline=None)
@given(placements, st.sampled_from(["noma", "oma"]))
def test_batch_gives_the_same_bits_as_one_mission(placement, mode):
    # A vector env steps N missions through the same functions: each row must equal that mission alone.
    actions, log_gain, log_interference = placement
    gain, interference = 10**log_gain, 10**log_interference
    batch_actions = np.stack([actions, actions[::-1], -actions])
    batch_gain = np.stack([gain, gain[::-1], gain * 3.0])
    batch_interference = np.stack([interference, interference[::-1], interference])
    batch_power = allocate_power(batch_actions, P_MAX)
    batch = downlink(batch_power, batch_gain, batch_interference, B, N0, mode)
    for k in range(3):
        power = allocate_power(batch_actions[k], P_MAX)
        one = downlink(power, batch_gain[k], batch_interference[k], B, N0, mode)
        np.testing.assert_array_equal(batch_power[k], power)
        np.testing.assert_array_equal(batch.rate_bps[k], one.rate_bps)
        np.testing.assert_array_equal(batch.sinr_db[k], one.sinr_db)
        np.testing.assert_array_equal(batch.decoding_order[k], one.decoding_order)


@settings(max_examples=200, deadline=None)
@given(placements, st.data())
def test_inactive_robots_get_the_power_of_action_minus_one(placement, data):
    # allocate_power(..., active): an inactive robot's action counts as -1 (no power), bit for bit, and the
    # active robots share P_max as if the inactive ones had asked for nothing.
    actions = placement[0]
    active = data.draw(arrays(np.bool_, len(actions)))
    power = allocate_power(actions, P_MAX, active=active)
    np.testing.assert_array_equal(power, allocate_power(np.where(active, actions, -1.0), P_MAX))
    assert np.all(power[~active] == 0.0) and power.sum() <= P_MAX * (1 + 1e-12)


def test_noma_intra_cluster_power_sums_down_the_decoding_order():
    # Three robots, decoding order 1 (weakest), 0, 2 (strongest): robot 1 sees p0 + p2, robot 0 sees p2.
    power = np.array([0.02, 0.03, 0.05])
    gain = np.array([2e-8, 1e-8, 4e-8])
    result = downlink(power, gain, np.zeros(3), B, N0, "noma")
    np.testing.assert_array_equal(result.decoding_order, [1, 0, 2])
    noise = N0 * 3 * B
    expected = [
        0.02 * 2e-8 / (2e-8 * 0.05 + noise),
        0.03 * 1e-8 / (1e-8 * (0.05 + 0.02) + noise),
        0.05 * 4e-8 / noise,
    ]
    np.testing.assert_allclose(result.rate_bps, 3 * B * np.log2(1 + np.array(expected)), rtol=1e-12)


@settings(max_examples=50, deadline=None)
@given(
    arrays(np.float64, st.tuples(st.just(2), st.integers(1, 5), st.integers(1, 4)), elements=st.floats(0.0, 1e12)),
)
def test_gain_and_sinr_db_are_the_one_by_one_conversions_bit_for_bit(gain_and_sinr):
    # The env's step converts gains and SINRs in one pass: the bits of each conversion alone, floors included
    gain_db, sinr_db = gain_and_sinr_db(gain_and_sinr)
    assert np.array_equal(gain_db, linear_to_db(gain_and_sinr[0].copy()))
    assert np.array_equal(sinr_db, sinr_to_db(gain_and_sinr[1].copy()))
    assert gain_db.min() > -3100.0 and sinr_db.min() >= SINR_DB_FLOOR
