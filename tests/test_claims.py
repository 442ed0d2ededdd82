"""The paper's claims, judged: the verdict rule on worked cases against SciPy, the
interactions-to-level count on a hand-made learning curve, and the claims table of a study
against an independent recomputation from its evaluation files."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as sps

from uavris.experiments.study.claims import judge_comparison
from uavris.stats import HOLDS, NOT_RESOLVED, REFUTED, paired_difference, steps_to_level, verdict, welch_difference


def _scipy_paired(a, b):
    ci = sps.ttest_rel(a, b).confidence_interval(0.95)
    return ci.low, ci.high


@pytest.mark.parametrize("a, b, want", [
    ([3.1, 3.4, 2.9, 3.3], [2.0, 2.1, 1.9, 2.2], HOLDS),  # above in every unit, little spread
    ([1.0, 1.2, 0.9, 1.1], [2.0, 2.1, 1.9, 2.2], REFUTED),  # below in every unit
    ([2.5, 1.0, 3.0, 1.5], [2.0, 2.1, 1.9, 2.2], NOT_RESOLVED),  # above in two, below in two
])
def test_paired_verdict_on_worked_cases_matches_scipy(a, b, want):
    d = paired_difference(a, b)
    low, high = _scipy_paired(a, b)
    assert (d["ci_low"], d["ci_high"]) == pytest.approx((low, high), rel=1e-12)
    assert d["mean"] == pytest.approx(np.mean(np.subtract(a, b)))
    assert d["verdict"] == want == (HOLDS if low > 0 else REFUTED if high < 0 else NOT_RESOLVED)


def test_overlapping_intervals_can_still_hold_when_paired():
    # The unpaired CIs of a and b overlap, yet every unit is 0.1 above: the paired rule says holds.
    b = np.array([10.0, 12.0, 14.0, 16.0, 18.0])
    a = b + np.array([0.10, 0.12, 0.09, 0.11, 0.10])
    assert sps.ttest_ind(a, b).confidence_interval().low < 0
    assert paired_difference(a, b)["verdict"] == HOLDS


def test_one_unit_is_not_resolved():
    d = paired_difference([5.0], [1.0])
    assert d["mean"] == 4.0 and math.isnan(d["ci_low"]) and d["verdict"] == NOT_RESOLVED
    assert verdict(float("nan"), 1.0) == NOT_RESOLVED


def test_welch_difference_matches_scipy():
    a, b = np.array([29.0, 31.5, 30.2]), np.array([20.1, 25.3, 22.0, 18.4])
    d = welch_difference(a, b)
    ci = sps.ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
    assert (d["ci_low"], d["ci_high"]) == pytest.approx((ci.low, ci.high), rel=1e-10)
    assert d["verdict"] == HOLDS


def test_ddpg_best_holds_is_refuted_or_not_resolved():
    rng = np.random.default_rng(0)
    low, high = rng.normal(10, 0.3, 5), rng.normal(20, 0.3, 5)
    assert judge_comparison({"ddpg": high, "ppo": low, "sac": low - 1, "td3": low}).verdict == HOLDS
    refuted = judge_comparison({"ddpg": low, "ppo": high, "sac": low - 1, "td3": low})
    assert refuted.verdict == REFUTED and refuted.mean == pytest.approx(low.mean() - high.mean())
    # above two, tied with one: not resolved
    assert judge_comparison({"ddpg": high, "ppo": high[::-1] + 0.01, "sac": low}).verdict == NOT_RESOLVED


def test_steps_to_level_on_a_hand_made_curve():
    steps = [10_000, 20_000, 30_000, 40_000]
    rates = [5.0, 9.0, 8.5, 12.0]
    assert steps_to_level(steps, rates, 9.0) == 20_000  # reached exactly
    assert steps_to_level(steps, rates, 8.8) == 20_000  # the first point above, not a later one
    assert steps_to_level(steps, rates, 10.0) == 40_000
    assert steps_to_level(steps, rates, 4.0) == 10_000
    assert math.isnan(steps_to_level(steps, rates, 12.5))  # never: its budget is only a lower bound
