"""Across-seed aggregates for few-run comparisons: the interquartile mean (IQM) and bootstrap CIs.

These follow Agarwal et al., "Deep Reinforcement Learning at the Edge of the Statistical Precipice"
(NeurIPS 2021), the method of the ``rliable`` library: the IQM is the mean of the middle 50 % of the
scores (``scipy.stats.trim_mean(scores, 0.25)``), robust to one outlier seed yet less noisy than the
median, and its CI is a percentile bootstrap that resamples the runs of each task independently
("stratified"). A comparison here has one task per configuration, so only a few lines of numpy/scipy
are needed and ``rliable`` (which pulls in ``arch`` and its own plotting stack) is not a dependency.

With fewer than two runs no interval can be estimated: the bounds are ``nan``, shown as ``n/a``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import stats

__all__ = ["iqm", "pointwise_bootstrap_ci", "stratified_bootstrap_ci"]


def iqm(scores: np.ndarray) -> float:
    """
    Interquartile mean: the mean of the scores left after cutting the lowest and highest 25 %.

    :param scores: scores of any shape (runs, or runs x tasks); NaNs are dropped
    :return: the IQM (``nan`` without scores)
    """
    x = np.asarray(scores, dtype=np.float64).ravel()
    x = x[~np.isnan(x)]
    return float(stats.trim_mean(x, 0.25)) if x.size else float("nan")


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
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence!r}")
    x = np.asarray(scores, dtype=np.float64)
    x = x.reshape(len(x), -1) if x.ndim else x.reshape(1, 1)
    n_runs, n_tasks = x.shape
    if n_runs < 2:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    rows = rng.integers(0, n_runs, size=(n_resamples, n_runs, n_tasks))
    resampled = np.take_along_axis(x[None], rows, axis=1)
    values = np.array([statistic(sample) for sample in resampled])
    tail = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(values, [tail, 100.0 - tail])
    return float(low), float(high)


def pointwise_bootstrap_ci(
    curves: np.ndarray, confidence: float = 0.95, n_resamples: int = 1000, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """
    Percentile bootstrap CI of the mean over runs, at every point of a set of curves.

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
    rng = np.random.default_rng(seed)
    rows = rng.integers(0, x.shape[0], size=(n_resamples, x.shape[0]))
    means = x[rows].mean(axis=1)
    tail = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(means, [tail, 100.0 - tail], axis=0)
    return low, high
