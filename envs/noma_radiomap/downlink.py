"""NOMA and OMA downlink of one AP cluster (paper Sec. II-C, Eq. (8)-(13); docs/MODEL.md).

Pure functions on linear quantities (watts, linear power gains), broadcasting over any leading batch
dimensions (numpy; the power and SIC loops over robots compiled with numba): the last axis is the robot axis
(length U), so one mission ``(U,)`` and a batch of N missions ``(N, U)`` go through the same code. They are
shared by the environment, the planners and the tests. Sums over robots run in a fixed order (left to right,
or down the decoding order), so a batch gives the same bits as its missions one by one.

Notation: ``g_u`` is robot u's channel power gain from the AP (path loss and small-scale fading,
linear), ``I_u`` the interference power it receives from the external interferers over the whole
cluster band ``W = U B`` (the interferers spread their power evenly over ``W``), ``N0`` the noise
power spectral density and ``p_u`` the transmit power the AP allocates to robot u.
"""

from typing import Any, Literal, NamedTuple

import numpy as np

from noma_radiomap.compiled import as_rows, compiled
from noma_radiomap.propagation import _TINY, linear_to_db

MultipleAccess = Literal["noma", "oma"]
MULTIPLE_ACCESS: tuple[str, ...] = ("noma", "oma")

#: SINRs are reported in dB with this floor, so that a robot given no power (action -1) has a finite
#: SINR instead of -inf (its rate is exactly 0 either way).
SINR_DB_FLOOR = -300.0
_SINR_FLOOR = 10.0 ** (SINR_DB_FLOOR / 10.0)
#: The floors of :func:`gain_and_sinr_db`: the channel gain's (linear_to_db's default, the smallest normal float)
#: and the SINR's
_GAIN_AND_SINR_FLOORS = np.array([_TINY, _SINR_FLOOR]).reshape(2, 1, 1)


class DownlinkResult(NamedTuple):
    """Per-robot outcome of one downlink transmission; arrays of shape (..., U)."""

    rate_bps: np.ndarray
    """Achievable rate ``B_eff log2(1 + SINR)`` in bit/s."""
    sinr_db: np.ndarray
    """SINR in dB, floored at :data:`SINR_DB_FLOOR`."""
    decoding_order: np.ndarray
    """Robot indices from the weakest to the strongest equivalent gain (the SIC order; in OMA mode the
    same ordering, informational only)."""


def allocate_power(power_actions: np.ndarray, max_power_w: float, active: np.ndarray | None = None) -> np.ndarray:
    """
    Map power actions to transmit powers (docs/MODEL.md, power mapping): ``p_u = P_max (a_u + 1) / 2``; if
    ``sum_u p_u > P_max``, all powers are scaled down by the same factor so that they sum to ``P_max``
    (the AP's power constraint, paper Eq. (15e)).

    :param power_actions: actions ``a_u``, shape (..., U); clipped to [-1, 1]
    :param max_power_w: ``P_max`` in watts
    :param active: robots that get power, bool (..., U) (the others' actions count as -1: no power); None: all
    :return: allocated powers in watts, shape (..., U), summing to at most ``P_max``
    """
    actions = np.asarray(power_actions, dtype=np.float64)
    rows = (-1, actions.shape[-1])
    mask = np.ones(actions.shape, dtype=np.bool_) if active is None else np.broadcast_to(active, actions.shape)
    return allocate_rows(actions.reshape(rows), mask.reshape(rows), float(max_power_w)).reshape(actions.shape)


@compiled
def allocate_rows(power_actions: np.ndarray, active: np.ndarray, max_power_w: float) -> np.ndarray:
    """:func:`allocate_power` on (M, U) actions and active flags, compiled; each row's powers summed left to right."""
    power = np.empty(power_actions.shape)
    for row in range(power_actions.shape[0]):
        total = 0.0
        for u in range(power_actions.shape[1]):
            action = min(max(power_actions[row, u], -1.0), 1.0) if active[row, u] else -1.0
            power[row, u] = (0.5 * max_power_w) * (action + 1.0)
            total += power[row, u]
        power[row] *= min(1.0, max_power_w / max(total, _TINY))
    return power


@compiled
def equivalent_gain(gain: np.ndarray, interference_w: np.ndarray, noise_w: float | np.ndarray) -> np.ndarray:
    """
    Equivalent channel gain ``G_u = g_u / (I_u + N0 W)`` (paper Eq. (8)), the SIC ordering criterion.

    :param gain: linear channel gains ``g_u``, shape (..., U)
    :param interference_w: interference powers ``I_u`` in watts, shape (..., U)
    :param noise_w: noise power over the cluster band, ``N0 W`` in watts
    :return: ``G_u``, shape (..., U)
    """
    return gain / (interference_w + noise_w)


def decoding_order(equivalent_gains: np.ndarray) -> np.ndarray:
    """
    SIC decoding order (paper Eq. (9) and the ordering below it): robot indices sorted from the weakest to the strongest
    equivalent gain. Ties are broken by robot index (a lower index counts as weaker). :func:`decoding_order_rows`,
    the one implementation (the env's SIC kernels call it too).

    :param equivalent_gains: ``G_u``, shape (..., U)
    :return: integer indices, shape (..., U)
    :raises ValueError: a 0-d ``equivalent_gains``
    """
    (gains,), shape = as_rows("decoding_order: equivalent_gains", equivalent_gains)
    return decoding_order_rows(gains).reshape((*shape, gains.shape[1]))


@compiled
def decoding_order_rows(equivalent_gains: np.ndarray) -> np.ndarray:
    """:func:`decoding_order` of (M, U) equivalent gains, compiled: per row a stable sort (numba's mergesort; the
    order of numpy's stable sort)."""
    order = np.empty(equivalent_gains.shape, dtype=np.int64)
    for row in range(equivalent_gains.shape[0]):
        order[row] = np.argsort(equivalent_gains[row], kind="mergesort")
    return order


@compiled
def signal_band(n_robots: int, bandwidth_per_robot_hz: float, noma: bool) -> float:
    """
    The band a robot's signal occupies, per multiple-access mode (docs/MODEL.md, NOMA and OMA; the band of paper
    Eq. (12)): NOMA, the whole cluster band ``W = U B``; OMA, the robot's own band ``B``. Compiled (the kernels, the
    downlink, the radio map and the planners call it, or :func:`band_and_noise`): the one implementation.

    :param n_robots: ``U``
    :param bandwidth_per_robot_hz: ``B`` in Hz
    :param noma: NOMA (True) or OMA
    :return: the band in Hz
    """
    return n_robots * bandwidth_per_robot_hz if noma else bandwidth_per_robot_hz


@compiled
def band_and_noise(n_robots: int, bandwidth_per_robot_hz: float, noise_w_per_hz: float, noma: bool) -> tuple[float, float]:
    """
    :func:`signal_band` and the noise power over it (the noise of paper Eq. (8) and (11)): ``N0 W`` in NOMA, ``N0 B``
    in OMA.

    :param n_robots: ``U``
    :param bandwidth_per_robot_hz: ``B`` in Hz
    :param noise_w_per_hz: ``N0`` in W/Hz
    :param noma: NOMA (True) or OMA
    :return: the band in Hz and the noise power over it in watts
    """
    band_hz = signal_band(n_robots, bandwidth_per_robot_hz, noma)
    return band_hz, noise_w_per_hz * band_hz


@compiled
def sic_sinr(power_w: Any, gain: Any, stronger_power_w: Any, interference_w: Any, noise_w: Any) -> Any:
    """
    NOMA SINR after SIC given the power of the robots stronger than u (paper Eq. (11)):
    ``p_u g_u / (g_u P_stronger + I_u + N0 W)``. Compiled, on floats (the SIC loops) or arrays.
    """
    return power_w * gain / (gain * stronger_power_w + interference_w + noise_w)


@compiled
def fdma_sinr(power_w: Any, gain: Any, interference_w: Any, n_robots: int, noise_w_per_robot: Any) -> Any:
    """
    OMA (FDMA) SINR, ``p_u g_u / (I_u / U + N0 B)`` (see :func:`oma_sinr`). Compiled, on floats or arrays.
    """
    return power_w * gain / (interference_w / n_robots + noise_w_per_robot)


def noma_sinr(
    power_w: np.ndarray,
    gain: np.ndarray,
    interference_w: np.ndarray,
    noise_w: float,
) -> tuple[np.ndarray, np.ndarray]:
    """
    Downlink NOMA SINR with SIC (paper Eq. (10)-(11) with the signal powers squared out).

    Robot u cancels the signals of every robot weaker than itself; the signals of stronger robots
    stay as intra-cluster interference:
    ``SINR_u = p_u g_u / (g_u sum_{v stronger than u} p_v + I_u + N0 W)``.

    :param power_w: allocated powers ``p_u`` in watts, shape (..., U)
    :param gain: linear channel gains ``g_u``, shape (..., U)
    :param interference_w: interference powers ``I_u`` over the cluster band in watts, shape (..., U)
    :param noise_w: noise power over the cluster band, ``N0 W`` in watts
    :return: linear SINRs (..., U) and the decoding order (..., U), weakest first
    """
    power_w, gain, interference_w = (np.asarray(value, dtype=np.float64) for value in (power_w, gain, interference_w))
    shape = power_w.shape
    if gain.shape != shape or interference_w.shape != shape:
        shape = np.broadcast_shapes(shape, gain.shape, interference_w.shape)
        power_w, gain, interference_w = (np.broadcast_to(value, shape) for value in (power_w, gain, interference_w))
    rows = (-1, shape[-1])
    sinr, order = sic_rows(power_w.reshape(rows), gain.reshape(rows), interference_w.reshape(rows), float(noise_w))
    return sinr.reshape(shape), order.reshape(shape)


@compiled
def sic_rows(
    power_w: np.ndarray, gain: np.ndarray, interference_w: np.ndarray, noise_w: float
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`noma_sinr` of (M, U) robots, compiled: per row the decoding order (:func:`decoding_order`: a
    stable sort), then the SINRs from the strongest robot down, the power of the stronger ones summed on the way."""
    sinr = np.empty(power_w.shape)
    order = decoding_order_rows(equivalent_gain(gain, interference_w, noise_w))
    for row in range(power_w.shape[0]):
        row_order = order[row]
        stronger = 0.0
        for k in range(power_w.shape[1] - 1, -1, -1):
            u = row_order[k]
            sinr[row, u] = sic_sinr(power_w[row, u], gain[row, u], stronger, interference_w[row, u], noise_w)
            stronger += power_w[row, u]
    return sinr, order


def oma_sinr(
    power_w: np.ndarray,
    gain: np.ndarray,
    interference_w: np.ndarray,
    noise_w_per_robot: float | np.ndarray,
) -> np.ndarray:
    """
    Downlink OMA (FDMA) SINR (docs/MODEL.md, OMA): each robot has its own band ``B = W / U``, which carries a
    ``1/U`` share of the interference spread over ``W``:
    ``SINR_u = p_u g_u / (I_u / U + N0 B)``.

    :param power_w: allocated powers ``p_u`` in watts, shape (..., U)
    :param gain: linear channel gains ``g_u``, shape (..., U)
    :param interference_w: interference powers ``I_u`` over the whole cluster band ``W``, shape (..., U)
    :param noise_w_per_robot: noise power over one robot's band, ``N0 B`` in watts
    :return: linear SINRs, shape (..., U)
    """
    return fdma_sinr(power_w, gain, interference_w, np.shape(power_w)[-1], noise_w_per_robot)


def shannon_rate(sinr: np.ndarray, bandwidth_hz: float) -> np.ndarray:
    """
    Achievable rate ``B log2(1 + SINR)`` in bit/s (paper Eq. (12)).

    :param sinr: linear SINRs
    :param bandwidth_hz: bandwidth ``B`` in Hz
    :return: rates in bit/s
    """
    rate = 1.0 + sinr
    scalar_band = isinstance(bandwidth_hz, (int, float)) or np.ndim(bandwidth_hz) == 0  # isinstance: the fast test
    if not isinstance(rate, np.ndarray) or not scalar_band:
        return bandwidth_hz * np.log2(rate)
    np.log2(rate, out=rate)  # in place: the same bits with one array instead of three
    rate *= bandwidth_hz
    return rate


def sinr_to_db(sinr: np.ndarray) -> np.ndarray:
    """Linear SINR to dB, floored at :data:`SINR_DB_FLOOR` (0 W gives the floor, not -inf)."""
    return linear_to_db(sinr, _SINR_FLOOR)


def gain_and_sinr_db(gain_and_sinr: np.ndarray) -> np.ndarray:
    """
    The channel gains and the SINRs of (M, U) robots in dB in one pass, the same numbers as
    :func:`~noma_radiomap.propagation.linear_to_db` of the gains and :func:`sinr_to_db` of the SINRs.

    :param gain_and_sinr: linear gains and SINRs stacked, (2, M, U)
    :return: ``[gain_db, sinr_db]``, (2, M, U) float64
    """
    return linear_to_db(gain_and_sinr, _GAIN_AND_SINR_FLOORS)


def downlink(
    power_w: np.ndarray,
    gain: np.ndarray,
    interference_w: np.ndarray,
    bandwidth_per_robot_hz: float,
    noise_w_per_hz: float,
    multiple_access: MultipleAccess = "noma",
) -> DownlinkResult:
    """
    Rates, SINRs and the decoding order of one downlink transmission to U robots (paper Eq. (11)-(12)).

    NOMA uses the whole cluster band ``W = U B`` for every robot, with SIC; OMA gives each robot its own
    band ``B``. In both modes the decoding order is the order of the equivalent gains ``G_u``
    (:func:`equivalent_gain`, with the cluster-band noise ``N0 W``).

    :param power_w: allocated powers ``p_u`` in watts (see :func:`allocate_power`), shape (..., U)
    :param gain: linear channel gains ``g_u`` from the AP, shape (..., U)
    :param interference_w: interference powers ``I_u`` over the cluster band in watts, shape (..., U)
    :param bandwidth_per_robot_hz: ``B`` in Hz
    :param noise_w_per_hz: noise power spectral density ``N0`` in W/Hz
    :param multiple_access: ``"noma"`` or ``"oma"``
    :return: a :class:`DownlinkResult` (rate in bit/s, SINR in dB, decoding order)
    """
    if multiple_access not in MULTIPLE_ACCESS:
        raise ValueError(f"multiple_access must be one of {MULTIPLE_ACCESS}, got {multiple_access!r}")
    arrays = [np.asarray(value, dtype=np.float64) for value in (power_w, gain, interference_w)]
    shape = np.broadcast_shapes(*(array.shape for array in arrays))
    power_w, gain, interference_w = (array if array.shape == shape else np.broadcast_to(array, shape) for array in arrays)
    rows = (-1, shape[-1])
    noma = multiple_access == "noma"
    bandwidth_per_robot_hz = float(bandwidth_per_robot_hz)
    sinr, order = sinr_rows(
        power_w.reshape(rows),
        gain.reshape(rows),
        interference_w.reshape(rows),
        bandwidth_per_robot_hz,
        float(noise_w_per_hz),
        noma,
    )
    result = transmission_result(sinr, order, bandwidth_per_robot_hz, noma)
    return DownlinkResult(*(value.reshape(shape) for value in result))


@compiled
def sinr_rows(
    power_w: np.ndarray,
    gain: np.ndarray,
    interference_w: np.ndarray,
    bandwidth_per_robot_hz: float,
    noise_w_per_hz: float,
    noma: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """
    The linear SINRs and the decoding order of (M, U) robots, compiled: NOMA with SIC (:func:`sic_rows`) or OMA
    (:func:`fdma_sinr`); the decoding order is that of the equivalent gains with the cluster-band noise in both
    modes (:func:`decoding_order`). Float64 arrays of exactly that shape.
    """
    n_robots = power_w.shape[1]
    cluster_noise_w = band_and_noise(n_robots, bandwidth_per_robot_hz, noise_w_per_hz, True)[1]
    if noma:
        return sic_rows(power_w, gain, interference_w, cluster_noise_w)
    robot_noise_w = band_and_noise(n_robots, bandwidth_per_robot_hz, noise_w_per_hz, False)[1]
    sinr = np.empty(power_w.shape)
    order = decoding_order_rows(equivalent_gain(gain, interference_w, cluster_noise_w))
    for row in range(power_w.shape[0]):
        for u in range(n_robots):
            sinr[row, u] = fdma_sinr(power_w[row, u], gain[row, u], interference_w[row, u], n_robots, robot_noise_w)
    return sinr, order


def transmission_result(sinr: np.ndarray, order: np.ndarray, bandwidth_per_robot_hz: float, noma: bool) -> DownlinkResult:
    """
    The outcome of a transmission from its linear SINRs (..., U): the rates (paper Eq. (12), over the cluster band
    ``W = U B`` in NOMA and over ``B`` in OMA), the SINRs in dB and the decoding order as given.
    """
    band_hz = signal_band(sinr.shape[-1], bandwidth_per_robot_hz, noma)
    return DownlinkResult(rate_bps=shannon_rate(sinr, band_hz), sinr_db=sinr_to_db(sinr), decoding_order=order)


def in_outage(rate_bps: np.ndarray, qos_rate_bps: float) -> np.ndarray:
    """
    Outage (paper Eq. (13)): a robot whose rate falls below the QoS rate, ``rate_u < qos_rate_bps``.

    :param rate_bps: rates in bit/s, any shape
    :param qos_rate_bps: the QoS rate in bit/s
    :return: bool array, the shape of ``rate_bps``
    """
    return rate_bps < qos_rate_bps
