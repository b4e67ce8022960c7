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

Non-finite scores (the ``nan`` of a run without a score, an ``inf``) are dropped before any statistic, per task.
With fewer than two (finite) runs no interval can be estimated: the bounds are ``nan``, shown as ``n/a``.
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

    :param scores: scores of any shape (runs, or runs x tasks); non-finite scores are dropped
    :return: the IQM (``nan`` without finite scores)
    """
    x = _finite(scores)
    return float(stats.trim_mean(x, 0.25)) if x.size else float("nan")


def _finite(scores: np.ndarray) -> np.ndarray:
    """The finite scores, flattened."""
    x = np.asarray(scores, dtype=np.float64).ravel()
    return x[np.isfinite(x)]


def _pooled_iqm(*columns: np.ndarray, axis: int = -1) -> np.ndarray:
    """:func:`iqm` of the runs x tasks of every resample at once (``scipy.stats.bootstrap``'s vectorized form; with
    as many runs in every task, the scores in the order of :func:`iqm`'s ``ravel``, so each resample gives the same
    bits). No NaNs."""
    columns = tuple(np.moveaxis(column, axis, -1) for column in columns)
    if len({column.shape[-1] for column in columns}) > 1:  # tasks that lost different numbers of runs
        return stats.trim_mean(np.concatenate(columns, axis=-1), 0.25, axis=-1)
    pooled = np.stack(columns, axis=-1)
    return stats.trim_mean(pooled.reshape(*pooled.shape[:-2], -1), 0.25, axis=-1)


def _percentile_ci(
    samples: Sequence[np.ndarray],
    statistic: Callable[..., float],
    confidence: float,
    n_resamples: int,
    seed: int,
    vectorized: bool = False,
) -> tuple[float, float]:
    """``scipy.stats.bootstrap`` of independent samples (percentile method); a statistic equal on every resample
    gives a point, one that is ``nan`` on some resample gives ``(nan, nan)``. ``vectorized``: ``statistic`` takes an
    ``axis`` and maps batches of resamples at once."""
    if not np.isfinite(statistic(*samples)):  # nothing to resample (and no warning from scipy about it)
        return float("nan"), float("nan")
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
    distribution = np.asarray(result.bootstrap_distribution, dtype=np.float64).ravel()
    if np.all(np.isfinite(distribution)) and np.all(distribution == distribution[0]):
        return float(distribution[0]), float(distribution[0])  # some scipy versions give nan bounds here
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def stratified_bootstrap_ci(
    scores: np.ndarray,
    statistic: Callable[[np.ndarray], float] = iqm,
    confidence: float = 0.95,
    n_resamples: int = 2000,
    seed: int = 0,
) -> tuple[float, float]:
    """
    Percentile bootstrap CI of ``statistic``, resampling the runs of every task independently.

    Non-finite scores are dropped first, in each task; a task with fewer finite runs than another reaches
    ``statistic`` padded with ``nan`` (which :func:`iqm` drops).

    :param scores: ``(runs,)`` or ``(runs, tasks)``
    :param statistic: maps a ``(runs, tasks)`` array to a number (default: :func:`iqm`)
    :param confidence: confidence level in (0, 1)
    :param n_resamples: bootstrap resamples
    :param seed: seed of the resampling (the CI is deterministic for a given seed)
    :return: ``(low, high)``; ``(nan, nan)`` where a task has fewer than two finite runs
    """
    check_confidence(confidence)
    x = np.asarray(scores, dtype=np.float64)
    if x.size == 0:
        return float("nan"), float("nan")
    x = x.reshape(len(x), -1) if x.ndim else x.reshape(1, 1)
    tasks = [x[np.isfinite(x[:, k]), k] for k in range(x.shape[1])]
    if min(task.size for task in tasks) < 2:
        return float("nan"), float("nan")
    if statistic is iqm:  # the default, on all resamples at once (the same CI, ~50x faster)
        return _percentile_ci(tasks, _pooled_iqm, confidence, n_resamples, seed, vectorized=True)

    def on_columns(*columns: np.ndarray) -> float:
        runs = max(column.size for column in columns)
        return statistic(np.stack([np.pad(c, (0, runs - c.size), constant_values=np.nan) for c in columns], axis=1))

    return _percentile_ci(tasks, on_columns, confidence, n_resamples, seed)


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

    :param x: scores of X's runs (non-finite scores are dropped)
    :param y: scores of Y's runs (likewise)
    :param confidence: confidence level of the CI
    :param n_resamples: bootstrap resamples (X and Y resampled independently)
    :param seed: seed of the resampling
    :return: ``(probability, low, high)``; the bounds are ``nan`` unless both have at least two finite runs
    :raises ValueError: X or Y has no finite score
    """
    check_confidence(confidence)
    a, b = _finite(x), _finite(y)
    if a.size == 0 or b.size == 0:
        raise ValueError(f"probability_of_improvement needs finite scores for both, got {a.size} and {b.size}")

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

    :param scores: the runs' scores (non-finite scores are dropped)
    :param taus: thresholds
    :param confidence: confidence level of the CIs
    :param n_resamples: bootstrap resamples
    :param seed: seed of the resampling
    :return: ``(share, low, high)``, each shaped like ``taus``; the bounds are ``nan`` with fewer than two finite
        runs, the shares too without any
    """
    x = _finite(scores)
    thresholds = np.asarray(taus, dtype=np.float64).ravel()
    if x.size == 0:
        nan = np.full(thresholds.size, np.nan)
        return nan, nan.copy(), nan.copy()
    above = (x[:, None] > thresholds[None, :]).astype(np.float64)  # (runs, taus)
    share = above.mean(axis=0)
    low, high = pointwise_bootstrap_ci(above, confidence, n_resamples, seed)
    return share, low, high
