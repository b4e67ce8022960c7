"""Across-seed statistics for few-run comparisons, after Agarwal et al., "Deep Reinforcement Learning at the
Edge of the Statistical Precipice" (NeurIPS 2021): the interquartile mean (IQM) with stratified-bootstrap CIs,
performance profiles and the probability of improvement.

Why not ``rliable``, the authors' library: rliable 1.2 (the latest) pins ``arch < 8``, and every ``arch`` below
8 fails at import with pandas 3 (``deprecate_kwarg`` changed), which this package uses; so rliable cannot be
imported next to it. The same estimators are in ``scipy.stats``, which the package already needs, and they are
used here rather than re-implemented:

- IQM: ``scipy.stats.trim_mean(scores, 0.25)`` (rliable's ``metrics.aggregate_iqm``);
- CIs: ``scipy.stats.bootstrap`` with the percentile method (rliable's default). Given one sample per task
  with ``paired=False`` it resamples the runs of each task independently, which is rliable's *stratified*
  bootstrap;
- probability of improvement ``P(X > Y) + P(X = Y) / 2``: the Mann-Whitney U statistic divided by
  ``n_x n_y`` (``scipy.stats.mannwhitneyu``), as rliable's ``metrics.probability_of_improvement`` computes it;
- performance profile: the share of runs scoring above each threshold tau (rliable's
  ``create_performance_profile``), with a bootstrap CI per threshold.

With fewer than two runs no interval can be estimated: the bounds are ``nan``, shown as ``n/a``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy import stats

from sb3_dtdpg.common.checks import check_confidence

__all__ = [
    "iqm",
    "performance_profile",
    "pointwise_bootstrap_ci",
    "probability_of_improvement",
    "stratified_bootstrap_ci",
]


def iqm(scores: np.ndarray) -> float:
    """
    Interquartile mean: the mean of the scores left after cutting the lowest and highest 25 %.

    :param scores: scores of any shape (runs, or runs x tasks); NaNs are dropped
    :return: the IQM (``nan`` without scores)
    """
    x = np.asarray(scores, dtype=np.float64).ravel()
    x = x[~np.isnan(x)]
    return float(stats.trim_mean(x, 0.25)) if x.size else float("nan")


def _pooled_iqm(*columns: np.ndarray, axis: int = -1) -> np.ndarray:
    """:func:`iqm` of the runs x tasks of every resample at once (``scipy.stats.bootstrap``'s vectorized form; the
    scores in the order of :func:`iqm`'s ``ravel``, so each resample gives the same bits). No NaNs."""
    pooled = np.stack([np.moveaxis(column, axis, -1) for column in columns], axis=-1)
    return stats.trim_mean(pooled.reshape(*pooled.shape[:-2], -1), 0.25, axis=-1)


def _percentile_ci(
    samples: Sequence[np.ndarray],
    statistic: Callable[..., float],
    confidence: float,
    n_resamples: int,
    seed: int,
    vectorized: bool = False,
) -> tuple[float, float]:
    """``scipy.stats.bootstrap`` of independent samples (percentile method); a constant statistic gives a point.
    ``vectorized``: ``statistic`` takes an ``axis`` and maps batches of resamples at once."""
    point = statistic(*samples)
    result = stats.bootstrap(
        tuple(samples),
        statistic if vectorized else lambda *resampled: statistic(*resampled),
        vectorized=vectorized,
        paired=False,
        confidence_level=confidence,
        n_resamples=n_resamples,
        method="percentile",
        random_state=np.random.default_rng(seed),
    )
    low, high = float(result.confidence_interval.low), float(result.confidence_interval.high)
    if np.isnan(low) or np.isnan(high):  # every resample equal (scipy reports a degenerate distribution as nan)
        return float(point), float(point)
    return low, high


def stratified_bootstrap_ci(
    scores: np.ndarray,
    statistic: Callable[[np.ndarray], float] = iqm,
    confidence: float = 0.95,
    n_resamples: int = 2000,
    seed: int = 0,
) -> tuple[float, float]:
    """
    Percentile bootstrap CI of ``statistic``, resampling the runs of every task independently.

    :param scores: ``(runs,)`` or ``(runs, tasks)``
    :param statistic: maps a ``(runs, tasks)`` array to a number (default: :func:`iqm`)
    :param confidence: confidence level in (0, 1)
    :param n_resamples: bootstrap resamples
    :param seed: seed of the resampling (the CI is deterministic for a given seed)
    :return: ``(low, high)``; ``(nan, nan)`` with fewer than two runs
    """
    check_confidence(confidence)
    x = np.asarray(scores, dtype=np.float64)
    x = x.reshape(len(x), -1) if x.ndim else x.reshape(1, 1)
    if x.shape[0] < 2:
        return float("nan"), float("nan")
    tasks = [x[:, k] for k in range(x.shape[1])]
    if statistic is iqm and not np.isnan(x).any():  # the default, on all resamples at once (the same CI, ~50x faster)
        return _percentile_ci(tasks, _pooled_iqm, confidence, n_resamples, seed, vectorized=True)
    return _percentile_ci(tasks, lambda *columns: statistic(np.stack(columns, axis=1)), confidence, n_resamples, seed)


def pointwise_bootstrap_ci(
    curves: np.ndarray, confidence: float = 0.95, n_resamples: int = 1000, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """
    Percentile bootstrap CI of the mean over runs, at every point of a set of curves (``scipy.stats.bootstrap``
    along the runs axis).

    Unlike a t-interval, the band stays within the range of the runs (a success rate stays in [0, 1])
    and does not blow up with two or three seeds.

    :param curves: ``(runs, points)``
    :param confidence: confidence level in (0, 1)
    :param n_resamples: bootstrap resamples
    :param seed: seed of the resampling
    :return: ``(low, high)``, each ``(points,)``; ``nan`` with fewer than two runs
    """
    x = np.asarray(curves, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f"curves: expected shape (runs, points), got {x.shape}")
    if x.shape[0] < 2:
        nan = np.full(x.shape[1], np.nan)
        return nan, nan.copy()
    check_confidence(confidence)
    result = stats.bootstrap(
        (x,),
        np.mean,
        axis=0,
        vectorized=True,
        confidence_level=confidence,
        n_resamples=n_resamples,
        method="percentile",
        random_state=np.random.default_rng(seed),
    )
    low, high = np.asarray(result.confidence_interval.low), np.asarray(result.confidence_interval.high)
    constant = np.isnan(low) | np.isnan(high)  # a point where every run has the same value
    mean = x.mean(axis=0)
    return np.where(constant, mean, low), np.where(constant, mean, high)


def probability_of_improvement(
    x: np.ndarray, y: np.ndarray, confidence: float = 0.95, n_resamples: int = 2000, seed: int = 0
) -> tuple[float, float, float]:
    """
    The probability that a run of X scores above a run of Y, ties counting half (Mann-Whitney U / (n_x n_y)).

    :param x: scores of X's runs
    :param y: scores of Y's runs
    :param confidence: confidence level of the CI
    :param n_resamples: bootstrap resamples (X and Y resampled independently)
    :param seed: seed of the resampling
    :return: ``(probability, low, high)``; the bounds are ``nan`` unless both have at least two runs
    """
    check_confidence(confidence)
    a, b = np.asarray(x, dtype=np.float64).ravel(), np.asarray(y, dtype=np.float64).ravel()
    if a.size == 0 or b.size == 0:
        raise ValueError(f"probability_of_improvement needs scores for both, got {a.size} and {b.size}")

    def probability(p: np.ndarray, q: np.ndarray) -> float:
        return float(stats.mannwhitneyu(p, q).statistic) / (p.size * q.size)

    point = probability(a, b)
    if a.size < 2 or b.size < 2:
        return point, float("nan"), float("nan")
    return (point, *_percentile_ci([a, b], probability, confidence, n_resamples, seed))


def performance_profile(
    scores: np.ndarray, taus: np.ndarray, confidence: float = 0.95, n_resamples: int = 1000, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    The share of runs with a score above each threshold (a run-score distribution), with bootstrap CIs.

    :param scores: the runs' scores
    :param taus: thresholds
    :param confidence: confidence level of the CIs
    :param n_resamples: bootstrap resamples
    :param seed: seed of the resampling
    :return: ``(share, low, high)``, each shaped like ``taus``; the bounds are ``nan`` with fewer than two runs
    """
    x = np.asarray(scores, dtype=np.float64).ravel()
    thresholds = np.asarray(taus, dtype=np.float64).ravel()
    above = (x[:, None] > thresholds[None, :]).astype(np.float64)  # (runs, taus)
    share = above.mean(axis=0)
    low, high = pointwise_bootstrap_ci(above, confidence, n_resamples, seed)
    return share, low, high
