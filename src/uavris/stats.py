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


def t_band(curves: ArrayLike, confidence: float = 0.95
           ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Mean over seeds and its Student-t band at every point of ``curves`` (seeds, points):
    with 3 seeds a percentile bootstrap under-covers (it cannot be wider than the seeds'
    range), so Fig. 2's band is this one. One seed: the band is the curve."""
    c = np.asarray(curves, dtype=np.float64)
    mean = c.mean(axis=0)
    if c.shape[0] < 2:
        return mean, mean.copy(), mean.copy()
    half = stats.t.ppf(0.5 + confidence / 2, c.shape[0] - 1) * stats.sem(c, axis=0)
    return mean, mean - half, mean + half


def summarize(scores: ArrayLike, seed: int = 0) -> dict[str, float]:
    """Mean, IQM, their 95% bootstrap CIs, std and count of per-run scores."""
    x = np.asarray(scores, dtype=np.float64)
    m_lo, m_hi = bootstrap_ci(x, "mean", seed=seed)
    i_lo, i_hi = bootstrap_ci(x, "iqm", seed=seed)
    return {"n": int(x.size), "mean": float(x.mean()), "mean_ci_low": m_lo, "mean_ci_high": m_hi,
            "iqm": float(iqm(x)), "iqm_ci_low": i_lo, "iqm_ci_high": i_hi,
            "std": float(x.std(ddof=1)) if x.size > 1 else 0.0}


def versus(low: float | None, high: float | None, reference: float) -> str:
    """Where a score with 95% CI [low, high] stands against a reference value: "above" or
    "below" when the CI excludes it, "tie" (not resolved) otherwise; "n/a" for an undefined
    CI (NaN in memory, None as a stage's record stores it: JSON has no NaN)."""
    if low is None or high is None or np.isnan(low) or np.isnan(high):
        return "n/a"
    return "above" if low > reference else "below" if high < reference else "tie"


# The verdict on a claim (docs/results.md, "The paper's claims, judged"): a claimed difference
# "holds" where the 95% CI of its paired difference over the unit of generalisation excludes
# zero the claimed way, is "refuted" where it excludes zero the other way, and is "not
# resolved" otherwise (a CI that cannot be formed, one unit, is not resolved).
HOLDS, REFUTED, NOT_RESOLVED = "holds", "refuted", "not resolved"
# A cell with fewer than MIN_UNITS units on a side is "not measured": no verdict is printed.
NOT_MEASURED, MIN_UNITS = "not measured", 3


def verdict(low: float, high: float) -> str:
    """The verdict on "the difference is > 0" from its 95% CI [low, high]."""
    if not (np.isfinite(low) and np.isfinite(high)):
        return NOT_RESOLVED
    return HOLDS if low > 0 else REFUTED if high < 0 else NOT_RESOLVED


def judged(differences: ArrayLike) -> dict[str, float]:
    """Per-unit differences (already paired): ``n``, ``mean``, the Student-t 95% interval of
    the mean and its ``verdict`` on "the difference is > 0"."""
    out = over_units(differences)
    return {**out, "verdict": verdict(out["ci_low"], out["ci_high"])}


def paired_difference(a: ArrayLike, b: ArrayLike) -> dict[str, float]:
    """``a - b`` unit by unit (the same halls, seeds or episodes in both), :func:`judged`."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"paired samples must be 1-D of one length, got {a.shape} and {b.shape}")
    return judged(a - b)


def welch_difference(a: ArrayLike, b: ArrayLike, confidence: float = 0.95) -> dict[str, float]:
    """``mean(a) - mean(b)`` of two independent samples (the seeds of two algorithms) with
    Welch's 95% interval (unequal variances), and its ``verdict``."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    diff = float(a.mean() - b.mean())
    va, vb = (a.var(ddof=1) / a.size if a.size > 1 else np.nan), (b.var(ddof=1) / b.size if b.size > 1 else np.nan)
    se = float(np.sqrt(va + vb))
    if not np.isfinite(se) or se == 0:
        low = high = diff if se == 0 else float("nan")
    else:
        dof = (va + vb) ** 2 / (va ** 2 / (a.size - 1) + vb ** 2 / (b.size - 1))
        half = float(stats.t.ppf(0.5 + confidence / 2, dof) * se)
        low, high = diff - half, diff + half
    return {"n": int(min(a.size, b.size)), "mean": diff, "ci_low": low, "ci_high": high,
            "verdict": verdict(low, high), "dof": float(dof) if np.isfinite(se) and se > 0 else float("nan")}


def t_p_value(mean: float, ci_low: float, ci_high: float, dof: float) -> float:
    """The two-sided p-value of "the difference is 0" read from its Student-t 95% interval
    ``[ci_low, ci_high]`` with ``dof`` degrees of freedom (the interval excludes zero exactly
    where it is below 0.05). NaN where the interval is."""
    if not (np.isfinite(ci_low) and np.isfinite(ci_high) and np.isfinite(dof) and dof > 0):
        return float("nan")
    half = (ci_high - ci_low) / 2
    if half <= 0:
        return 1.0 if mean == 0 else 0.0
    return float(2 * stats.t.sf(abs(mean) / (half / stats.t.ppf(0.975, dof)), dof))


def holm(p_values: ArrayLike) -> NDArray[np.float64]:
    """Holm's step-down adjusted p-values of one family of tests, in the order given: sorted
    ascending, the i-th (from 0) is multiplied by ``m - i`` and the running maximum is taken,
    capped at 1. A verdict of the family stands where its adjusted p is at most 0.05 (the
    family-wise error is then at most 5%, whatever the tests' dependence)."""
    p = np.asarray(p_values, dtype=np.float64)
    adjusted = np.empty_like(p)
    running = 0.0
    for rank, i in enumerate(np.argsort(p, kind="stable")):
        running = max(running, min(1.0, (p.size - rank) * float(p[i])))
        adjusted[i] = running
    return adjusted


def steps_to_level(steps: ArrayLike, values: ArrayLike, level: float) -> float:
    """The first of ``steps`` (a learning curve's x, increasing) whose value reaches
    ``level``; NaN when the curve never does (then its last step is only a lower bound)."""
    x, y = np.asarray(steps, dtype=np.float64), np.asarray(values, dtype=np.float64)
    reached = x[y >= level]
    return float(reached[0]) if reached.size else float("nan")


def interactions_to_level(steps: ArrayLike, values: ArrayLike, level: float) -> tuple[float, bool]:
    """How many interactions a learning curve took to reach ``level``: the first of ``steps``
    whose value reaches it (0 when the curve starts there: its first point at step 0), and
    whether the count is censored (the curve never reached the level: its last step, only a
    lower bound). An empty curve is censored at 0."""
    reached = steps_to_level(steps, values, level)
    if not np.isnan(reached):
        return reached, False
    x = np.asarray(steps, dtype=np.float64)
    return (float(x[-1]) if x.size else 0.0), True


def judged_censored(differences: ArrayLike, low_bounds: ArrayLike, high_bounds: ArrayLike) -> dict[str, float]:
    """:func:`judged` of per-unit differences some of which are censored: a difference that is
    only a lower bound (the true one is at least it: ``low_bounds``) or only an upper bound
    (``high_bounds``). A verdict stands only if it stands for every value a censored unit may
    take, and for a t interval none does: as one unit's value moves without limit the interval's
    half-width grows faster than its mean moves (per unit of that value's shift, the half-width
    grows towards ``t / n``, since the sample's standard deviation tends to ``shift / sqrt(n)``,
    while the mean moves by ``1 / n``; and ``t > 1`` for every ``n`` at 95%), so the interval
    comes to hold zero whichever way the unit is censored. A verdict resting on any
    censored unit is therefore "not resolved" (its interval is still reported, computed at the
    bounds). Adds ``censored``, the number of censored units."""
    low, high = np.asarray(low_bounds, dtype=bool), np.asarray(high_bounds, dtype=bool)
    out: dict[str, float] = judged(differences)
    v = NOT_RESOLVED if (low | high).any() and out["verdict"] in (HOLDS, REFUTED) else out["verdict"]
    return {**out, "verdict": v, "censored": int((low | high).sum())}
