"""The statistics behind every verdict the report prints, against independent calculations:
numbers worked by hand, SciPy's own t interval and bootstrap, and the rules the verdicts state."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as sps

from uavris.experiments.report.deployment import (
    HOVER_OPTIMIZER,
    NEAREST,
    ORACLE,
    _excludes_zero,
    deployment_section,
    layout_scores,
    over_layouts,
)
from uavris.stats import bootstrap_band, bootstrap_ci, iqm, summarize, t_interval, versus


# ------------------------------------------------------------------------------ uavris.stats
def test_t_interval_worked_by_hand():
    # x = 1, 2, 3, 4: mean 2.5, s = sqrt(5/3), sem = s / 2, t(0.975, 3) = 3.182446305284263
    low, high = t_interval([1.0, 2.0, 3.0, 4.0])
    half = 3.182446305284263 * math.sqrt(5.0 / 3.0) / 2.0
    assert low == pytest.approx(2.5 - half, rel=1e-12) and high == pytest.approx(2.5 + half, rel=1e-12)
    assert all(math.isnan(v) for v in t_interval([7.0]))  # one sample: no interval


def test_t_interval_is_scipys():
    x = np.random.default_rng(3).normal(10, 2, 23)
    want = sps.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=sps.sem(x))
    np.testing.assert_allclose(t_interval(x), want, rtol=1e-12)
    np.testing.assert_allclose(t_interval(x, 0.8), sps.t.interval(0.8, len(x) - 1, x.mean(), sps.sem(x)), rtol=1e-12)


def test_iqm_worked_by_hand():
    # 8 values: the middle half is 3, 4, 5, 6
    assert iqm([1, 2, 3, 4, 5, 6, 7, 100]) == pytest.approx(4.5)


def test_bootstrap_ci_is_scipys_percentile_bootstrap():
    x = np.random.default_rng(5).exponential(2.0, 40)
    res = sps.bootstrap((x,), np.mean, confidence_level=0.95, n_resamples=2000, method="percentile",
                        rng=np.random.default_rng(11))
    assert bootstrap_ci(x, seed=11) == pytest.approx((res.confidence_interval.low, res.confidence_interval.high),
                                                     rel=1e-12)
    # the IQM's interval holds the IQM and is narrower than the range
    lo, hi = bootstrap_ci(x, "iqm", seed=1)
    assert x.min() < lo <= iqm(x) <= hi < x.max()
    assert bootstrap_ci([3.0, 3.0, 3.0]) == (3.0, 3.0)  # no spread: a point
    assert all(math.isnan(v) for v in bootstrap_ci([1.0]))


def test_bootstrap_band_covers_the_mean_and_shrinks_with_agreement():
    rng = np.random.default_rng(0)
    curves = rng.normal(0, 1, (10, 5)) + np.arange(5)
    mean, low, high = bootstrap_band(curves)
    np.testing.assert_allclose(mean, curves.mean(axis=0))
    assert np.all(low <= mean) and np.all(mean <= high)
    # the band of the mean of 10 seeds is about 2 x 1.96 x sd / sqrt(10) wide
    width = (high - low) / (2 * 1.96 * curves.std(axis=0, ddof=1) / np.sqrt(10))
    assert np.all((width > 0.6) & (width < 1.3))
    same = np.tile(np.arange(5.0), (4, 1))
    _, lo2, hi2 = bootstrap_band(same)
    np.testing.assert_array_equal(lo2, hi2)


def test_summarize_worked_by_hand():
    s = summarize([1.0, 2.0, 3.0, 4.0])
    assert s["n"] == 4 and s["mean"] == 2.5 and s["iqm"] == pytest.approx(2.5)
    assert s["std"] == pytest.approx(math.sqrt(5.0 / 3.0))
    assert 1.0 <= s["mean_ci_low"] < 2.5 < s["mean_ci_high"] <= 4.0


@pytest.mark.parametrize("low, high, ref, want", [(1.0, 2.0, 0.5, "above"), (1.0, 2.0, 2.5, "below"),
                                                  (1.0, 2.0, 1.5, "tie"), (1.0, 2.0, 1.0, "tie"),
                                                  (float("nan"), 2.0, 1.0, "n/a")])
def test_versus_states_its_rule(low, high, ref, want):
    assert versus(low, high, ref) == want


# ------------------------------------------------------------------------------ the deployment section
def test_over_layouts_is_the_t_interval_over_layouts():
    x = [0.8, 0.9, 0.95, 0.7]
    s = over_layouts(x)
    want = sps.t.interval(0.95, 3, loc=np.mean(x), scale=sps.sem(x))
    assert s["n"] == 4 and s["mean"] == pytest.approx(0.8375)
    assert (s["ci_low"], s["ci_high"]) == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("low, high, want", [(0.1, 0.5, "above zero"), (-0.5, -0.1, "below zero"),
                                             (-0.1, 0.1, "includes zero"), (0.0, 0.1, "includes zero"),
                                             (float("nan"), float("nan"), "not resolved (one layout)")])
def test_excludes_zero_states_its_rule(low, high, want):
    assert _excludes_zero({"mean": 0.0, "ci_low": low, "ci_high": high}) == want


def _result(**means):
    return {k: {"mean": v, "label": k} for k, v in means.items()}


def test_layout_scores_average_seeds_per_layout_and_summarise_transfers():
    res = {"h0": {**_result(**{"dt-zero-shot": 30.0, "dt-zero-shot@s1": 34.0, "dt-zero-shot@s2": 35.0, "oracle": 40.0}),
                  "transfer-a": {"mean": 20.0, "label": "oracle plan of a (nearest), 3.0 m"},
                  "transfer-b": {"mean": 28.0, "label": "transferred from b"}}}
    row = layout_scores(res)["h0"]
    assert row["dt-zero-shot"] == pytest.approx(33.0)  # (30 + 34 + 35) / 3
    assert row["dt-zero-shot@s0"] == 30.0 and row["dt-zero-shot@s2"] == 35.0
    assert row[NEAREST] == 20.0 and row["transfer-mean"] == 24.0 and row["transfer-best"] == 28.0
    one = {"h0": {**_result(oracle=40.0), "transfer-a": {"mean": 20.0, "label": "x (nearest)"}}}
    assert "transfer-mean" not in layout_scores(one)["h0"]  # one transferred policy is its own mean


def _scores(dt, hover, near, bc, oracle):
    return {f"h{i}": {"dt-zero-shot": d, HOVER_OPTIMIZER: h, NEAREST: n, "bc": b, ORACLE: o}
            for i, (d, h, n, b, o) in enumerate(zip(dt, hover, near, bc, oracle))}


def _zero_shot_claim(scores) -> str:
    return next(c for c in deployment_section(scores, {}, None, None)[1] if "**zero-shot DT >=" in c)


def test_the_zero_shot_claim_holds_only_by_its_stated_rule():
    oracle = [40.0, 42.0, 41.0, 43.0]
    # 96-97% of the oracle, above hovering and the nearest plan in every hall by 2-3 bps/Hz
    good = _scores([39.0, 40.5, 39.5, 41.5], [36.0, 38.0, 37.5, 38.5], [37.0, 38.0, 36.5, 39.0],
                   [39.0, 40.5, 39.5, 41.5], oracle)
    _, claims = deployment_section(good, {}, None, None)
    claim = next(c for c in claims if "**zero-shot DT >=" in c)
    assert ": holds (" in claim
    frac = np.mean([39.0 / 40, 40.5 / 42, 39.5 / 41, 41.5 / 43])
    assert f"{frac:.1%}" in claim
    d = np.array([39.0, 40.5, 39.5, 41.5]) - np.array([36.0, 38.0, 37.5, 38.5])
    lo, hi = sps.t.interval(0.95, 3, loc=d.mean(), scale=sps.sem(d))
    assert f"{d.mean():+.2f} [{lo:+.2f}, {hi:+.2f}] bps/Hz, above zero" in claim
    # the same DT, with hovering better in one hall: the paired CI includes zero -> does not hold
    close = _scores([39.0, 40.5, 39.5, 41.5], [36.0, 38.0, 37.5, 43.0], [37.0, 38.0, 36.5, 39.0],
                    [39.0, 40.5, 39.5, 41.5], oracle)
    assert ": does not hold (" in _zero_shot_claim(close)
    # far above both but below 95% of the oracle -> does not hold
    low = _scores([36.0, 37.0, 36.0, 38.0], [30.0, 31.0, 30.5, 32.0], [29.0, 30.0, 31.0, 30.0],
                  [36.0, 37.0, 36.0, 38.0], oracle)
    assert ": does not hold (" in _zero_shot_claim(low)


def test_the_return_conditioning_verdict_is_the_paired_ci():
    oracle = [40.0, 42.0, 41.0, 43.0]
    s = _scores([39.0, 40.5, 39.5, 41.5], [36.0] * 4, [37.0] * 4, [38.0, 39.0, 38.5, 40.0], oracle)
    _, claims = deployment_section(s, {}, None, None)
    claim = next(c for c in claims if "return conditioning on demonstrations" in c)
    d = np.array([1.0, 1.5, 1.0, 1.5])
    lo, hi = sps.t.interval(0.95, 3, loc=d.mean(), scale=sps.sem(d))
    assert f"{d.mean():+.2f} [{lo:+.2f}, {hi:+.2f}] bps/Hz per layout, above zero" in claim
