"""Indoor propagation: path loss (ITU-R P.1238, as in the paper), fading constants, power units.

Everything here is a pure, numpy-broadcasting function of arrays, so it can be tested against
hand-computed values and reused by the radio map, the downlink model, planners and plots.
"""

from __future__ import annotations

import numpy as np

#: Expected Rayleigh fading in dB, ``E[10 log10 |h|^2]`` with ``|h|^2 ~ Exp(1)`` (paper Eq. (4) and (17)).
#: For ``X ~ Exp(1)``, ``E[ln X] = -gamma`` (the Euler-Mascheroni constant), hence
#: ``E[10 log10 X] = -10 gamma / ln 10 = -2.5068 dB`` — the paper's ``E(h)`` of Eq. (17),
#: -2.51 dB (docs/MODEL.md).
EXPECTED_FADING_DB: float = float(-10.0 * np.euler_gamma / np.log(10.0))

#: Path-loss distances are clipped to this minimum (metres): the ITU-R P.1238 model is only valid
#: for d >= 1 m (docs/MODEL.md, decisions), and without the clip a receiver right under the transmitter would get
#: a path loss below the free-space value at 1 m.
MIN_DISTANCE_M: float = 1.0

_TINY = float(np.finfo(np.float64).tiny)


def path_loss_db(
    distance_m: np.ndarray | float,
    n_obstacles: np.ndarray | int,
    frequency_mhz: float = 2000.0,
    nlos_distance_coefficient: float = 25.5,
    wall_loss_db: float = 15.0,
    wall_loss_step_db: float = 4.0,
) -> np.ndarray:
    """
    Path loss in dB of the indoor model of the paper (ITU-R P.1238), paper Eq. (1)-(3):

    - LoS (``n == 0``): ``L = 16.9 log10(d) - 27.2 + 20 log10(f)``
    - NLoS (``n >= 1``): ``L = 20 log10(f) - 28 + N log10(d) + L_f(n)``,
      ``L_f(n) = wall_loss_db + wall_loss_step_db (n - 1)``

    with ``f`` in MHz and ``d`` in metres, clipped to ``d >= 1`` (:data:`MIN_DISTANCE_M`).
    The arguments broadcast against each other like numpy arrays.

    :param distance_m: 3D transmitter-receiver distance(s) in metres
    :param n_obstacles: number of distinct obstacles the direct path crosses (0 = LoS)
    :param frequency_mhz: carrier frequency ``f`` in MHz
    :param nlos_distance_coefficient: the distance power loss coefficient ``N`` of the NLoS formula
    :param wall_loss_db: the loss of the first obstacle
    :param wall_loss_step_db: the extra loss of each further obstacle
    :return: path loss in dB (a float64 array of the broadcast shape)
    """
    if not np.isfinite(frequency_mhz) or frequency_mhz <= 0:
        raise ValueError(f"frequency_mhz: must be a positive number, got {frequency_mhz!r}")
    d = np.maximum(np.asarray(distance_m, dtype=np.float64), MIN_DISTANCE_M)
    n = np.asarray(n_obstacles)
    if np.any(n < 0):
        raise ValueError(f"n_obstacles: must be >= 0, got min {n.min().item()!r}")
    log_d = np.log10(d)
    log_f = np.log10(frequency_mhz)
    los = 16.9 * log_d - 27.2 + 20.0 * log_f
    nlos = 20.0 * log_f - 28.0 + nlos_distance_coefficient * log_d + wall_loss_db + wall_loss_step_db * (n - 1)
    return np.where(n <= 0, los, nlos)


def dbm_to_watt(power_dbm: np.ndarray | float) -> np.ndarray:
    """
    Convert dBm to watts: ``P_W = 10^((P_dBm - 30) / 10)``.

    :param power_dbm: power(s) in dBm
    :return: power(s) in watts
    """
    return np.power(10.0, (np.asarray(power_dbm, dtype=np.float64) - 30.0) / 10.0)


def watt_to_dbm(power_w: np.ndarray | float) -> np.ndarray:
    """
    Convert watts to dBm: ``P_dBm = 10 log10(P_W) + 30`` (``-inf`` for zero power).

    :param power_w: power(s) in watts, >= 0
    :return: power(s) in dBm
    """
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(np.asarray(power_w, dtype=np.float64)) + 30.0


def db_to_linear(value_db: np.ndarray | float) -> np.ndarray:
    """
    Convert a ratio in dB to linear scale: ``10^(x / 10)``.

    :param value_db: ratio(s) in dB
    :return: linear ratio(s)
    """
    return np.power(10.0, np.asarray(value_db, dtype=np.float64) / 10.0)


def linear_to_db(value: np.ndarray | float, floor: np.ndarray | float = _TINY) -> np.ndarray:
    """
    Convert a linear power ratio to dB, ``10 log10(max(x, floor))``: the floor keeps a zero ratio (a robot
    given no power, a fade with ``|h|^2 = 0``) finite.

    :param value: linear ratio(s), >= 0
    :param floor: the smallest ratio converted (default: the smallest normal float64, -3077 dB), or an array of
        them broadcasting against ``value``
    :return: ratio(s) in dB
    """
    ratio = np.maximum(value, floor)
    if not isinstance(ratio, np.ndarray):  # a number
        return 10.0 * np.log10(ratio)
    np.log10(ratio, out=ratio)  # in place: the same bits as 10.0 * np.log10(ratio) with one array instead of three
    ratio *= 10.0
    return ratio


# --------------------------------------------------------------------------------------------------
# The channel of a link: path gain, Rayleigh fading, interference. Leading axes are free, so one
# mission (..., U) and a batch of missions (N, U) go through the same functions.
# --------------------------------------------------------------------------------------------------


def path_gain(path_loss_db: np.ndarray | float, fading_db: float = 0.0) -> np.ndarray:
    """
    Linear channel power gain of links from their path loss, ``g = 10^((-L + F) / 10)``: with ``F = 0`` the
    path gain alone, with ``F =`` :data:`EXPECTED_FADING_DB` the radio-map channel (the paper's Eq.
    (17), path loss plus the expected Rayleigh fading ``E(h)``).

    :param path_loss_db: path losses ``L`` in dB (see :func:`path_loss_db`), any shape
    :param fading_db: fading ``F`` in dB added to every link
    :return: linear gains, the shape of ``path_loss_db``
    """
    return db_to_linear(-np.asarray(path_loss_db, dtype=np.float64) + fading_db)


def expected_channel_gain(path_loss_db: np.ndarray | float) -> np.ndarray:
    """
    The radio-map channel: linear gain with the expected Rayleigh fading (paper Eq. (17)),
    ``g = 10^((-L + E(h)) / 10)``, ``E(h) =`` :data:`EXPECTED_FADING_DB`.

    :param path_loss_db: path losses ``L`` in dB, any shape
    :return: linear gains, the shape of ``path_loss_db``
    """
    return path_gain(path_loss_db, EXPECTED_FADING_DB)


def rayleigh_fading(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """
    Rayleigh fading power ``|h|^2 ~ Exp(1)`` (unit mean), drawn independently per link.

    :param rng: the random generator (the env's ``np_random``)
    :param shape: the shape of the draws, e.g. ``(U, transmitters)`` or ``(N, U, transmitters)``
    :return: fading powers, ``shape``
    """
    return rng.exponential(size=shape)


def faded_gain(gain: np.ndarray, fading_power: np.ndarray) -> np.ndarray:
    """
    Channel gain of a link with small-scale fading, ``g |h|^2`` (paper Eq. (4); the "reality" channel).

    :param gain: linear path gains ``g`` (:func:`path_gain` with ``fading_db=0``), any shape
    :param fading_power: ``|h|^2`` (:func:`rayleigh_fading`), broadcastable to ``gain``
    :return: linear gains
    """
    return gain * fading_power


def interference_power(gain: np.ndarray, power_w: np.ndarray) -> np.ndarray:
    """
    Interference a receiver gets from the external transmitters, ``I = sum_i P_i g_i`` in watts, over the
    whole cluster band ``W`` over which they spread their power (paper Eq. (6); docs/MODEL.md).

    The sum runs left to right over the transmitters (:func:`sequential_sum`), so a batch gives the same
    bits as one receiver.

    :param gain: linear gains ``g_i`` from each interferer, shape (..., I)
    :param power_w: transmit powers ``P_i`` in watts, shape (I,)
    :return: interference powers in watts, shape (...); 0 without interferers
    """
    return sequential_sum(np.asarray(gain) * power_w)


def sequential_sum(values: np.ndarray) -> np.ndarray:
    """
    Sum over the last axis from left to right, ``(((0 + x_0) + x_1) + ...)``.

    numpy's ``sum`` adds pairwise, whose rounding depends on the length of the axis; the physics sums
    over robots or transmitters in this fixed order so that one mission and a batch of missions give the
    same bits.

    :param values: shape (..., K)
    :return: shape (...); 0 for ``K = 0``
    """
    values = np.asarray(values, dtype=np.float64)
    if values.shape[-1] == 0:
        return np.zeros(values.shape[:-1])
    return values.cumsum(axis=-1)[..., -1]


def noise_power_dbm(noise_dbm_per_hz: float, bandwidth_hz: np.ndarray | float) -> np.ndarray:
    """
    Thermal noise power over a band: ``N = N0 + 10 log10(bandwidth)`` in dBm (i.e. ``N0 x bandwidth``
    in linear units, docs/MODEL.md).

    :param noise_dbm_per_hz: noise power spectral density ``N0`` in dBm/Hz
    :param bandwidth_hz: bandwidth in Hz, > 0
    :return: noise power in dBm
    """
    bandwidth = np.asarray(bandwidth_hz, dtype=np.float64)
    if np.any(bandwidth <= 0):
        raise ValueError(f"bandwidth_hz: must be > 0, got {bandwidth_hz!r}")
    return noise_dbm_per_hz + 10.0 * np.log10(bandwidth)
