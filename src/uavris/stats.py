"""Statistics of results: mean, IQM, Student-t and bootstrap confidence intervals.

Lives here: every interval and aggregate a report or an evaluation prints. Not here: how
the samples are produced.

Over evaluation episodes (many, roughly normal means) the 95% interval of the mean is
Student's t (:func:`t_interval`). Over a few training seeds, following Agarwal et al.
(NeurIPS 2021), final performance is the mean and the interquartile mean (IQM,
``scipy.stats.trim_mean`` with 25% cut) with percentile-bootstrap 95% CIs
(:func:`summarize`); with one task, the stratified bootstrap resamples runs within that
task, i.e. an ordinary bootstrap over seeds.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats


def iqm(x: ArrayLike, axis: int = -1) -> NDArray[np.float64] | float:
    return stats.trim_mean(np.asarray(x, dtype=np.float64), 0.25, axis=axis)


def t_interval(x: ArrayLike, confidence: float = 0.95) -> tuple[float, float]:
    """Student-t interval of the mean of a 1-D sample (NaN for fewer than 2 values)."""
    x = np.asarray(x, dtype=np.float64)
    mean = float(np.mean(x))
    half = float(stats.t.ppf(0.5 + confidence / 2, len(x) - 1) * stats.sem(x)) if len(x) > 1 else float("nan")
    return mean - half, mean + half


def over_units(values: ArrayLike) -> dict[str, float]:
    """Mean and Student-t 95% interval of per-unit values, each unit (a hall, a cell) one
    sample: ``n``, ``mean``, ``ci_low``, ``ci_high`` (the interval NaN for one unit)."""
    x = np.asarray(values, dtype=np.float64)
    low, high = t_interval(x)
    return {"n": int(x.size), "mean": float(x.mean()), "ci_low": low, "ci_high": high}


def bootstrap_ci(x: ArrayLike, statistic: str = "mean", confidence: float = 0.95, n_resamples: int = 2000,
                 seed: int = 0) -> tuple[float, float]:
    """Percentile-bootstrap CI of the mean or IQM of a 1-D sample (NaN for fewer than 2 values)."""
    x = np.asarray(x, dtype=np.float64)
    if x.size < 2 or np.all(x == x[0]):
        v = float(x[0]) if x.size else float("nan")
        return (v, v) if x.size >= 2 else (float("nan"), float("nan"))
    fn = np.mean if statistic == "mean" else iqm
    res = stats.bootstrap((x,), fn, confidence_level=confidence, n_resamples=n_resamples, method="percentile",
                          vectorized=True, rng=np.random.default_rng(seed))
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def bootstrap_band(curves: ArrayLike, confidence: float = 0.95, n_resamples: int = 1000,
                   seed: int = 0) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Mean over seeds and its bootstrap band at every point of ``curves`` (seeds, points)."""
    c = np.asarray(curves, dtype=np.float64)
    mean = c.mean(axis=0)
    if c.shape[0] < 2:
        return mean, mean.copy(), mean.copy()
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, c.shape[0], (n_resamples, c.shape[0]))
    boot = c[idx].mean(axis=1)  # (resamples, points)
    alpha = (1 - confidence) / 2
    return mean, np.quantile(boot, alpha, axis=0), np.quantile(boot, 1 - alpha, axis=0)


def summarize(scores: ArrayLike, seed: int = 0) -> dict[str, float]:
    """Mean, IQM, their 95% bootstrap CIs, std and count of per-run scores."""
    x = np.asarray(scores, dtype=np.float64)
    m_lo, m_hi = bootstrap_ci(x, "mean", seed=seed)
    i_lo, i_hi = bootstrap_ci(x, "iqm", seed=seed)
    return {"n": int(x.size), "mean": float(x.mean()), "mean_ci_low": m_lo, "mean_ci_high": m_hi,
            "iqm": float(iqm(x)), "iqm_ci_low": i_lo, "iqm_ci_high": i_hi,
            "std": float(x.std(ddof=1)) if x.size > 1 else 0.0}


def versus(low: float, high: float, reference: float) -> str:
    """Where a score with 95% CI [low, high] stands against a reference value: "above" or
    "below" when the CI excludes it, "tie" (not resolved) otherwise."""
    if np.isnan(low) or np.isnan(high):
        return "n/a"
    return "above" if low > reference else "below" if high < reference else "tie"
