"""The statistics behind every verdict the report prints, against independent calculations:
numbers worked by hand, SciPy's own t interval and bootstrap, and the rules the verdicts state."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from report_check import ci_verdict, every_verdict
from scipy import stats as sps

from uavris.experiments.study.report.deployment import (
    HOVER_OPTIMIZER,
    NEAREST,
    ORACLE,
    _excludes_zero,
    deployment_section,
    layout_scores,
    row_labels,
    row_order,
    seed_scores,
)
from uavris.stats import bootstrap_ci, iqm, over_units, summarize, t_band, t_interval, versus


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


def test_t_band_is_scipys_t_interval_at_every_point():
    rng = np.random.default_rng(0)
    curves = rng.normal(0, 1, (3, 5)) + np.arange(5)
    mean, low, high = t_band(curves)
    for j in range(5):
        ci = sps.ttest_1samp(curves[:, j], 0.0).confidence_interval(0.95)
        assert (low[j], high[j]) == pytest.approx((ci.low, ci.high), rel=1e-12)
        assert mean[j] == pytest.approx(curves[:, j].mean())
    same = np.tile(np.arange(5.0), (4, 1))
    _, lo2, hi2 = t_band(same)
    np.testing.assert_array_equal(lo2, hi2)
    one = t_band(curves[:1])  # one seed: no band
    for part in one:
        np.testing.assert_array_equal(part, curves[0])


def test_t_band_of_three_seeds_is_wider_than_their_range():
    # the under-coverage of a bootstrap band over few seeds: a bootstrap band of 3 seeds lies inside their range
    curves = np.array([[1.0, 2.0], [2.0, 4.0], [3.0, 3.0]])
    _, low, high = t_band(curves)
    assert np.all(low < curves.min(axis=0)) and np.all(high > curves.max(axis=0))


def test_summarize_worked_by_hand():
    s = summarize([1.0, 2.0, 3.0, 4.0])
    assert s["n"] == 4 and s["mean"] == 2.5 and s["iqm"] == pytest.approx(2.5)
    assert s["std"] == pytest.approx(math.sqrt(5.0 / 3.0))
    assert 1.0 <= s["mean_ci_low"] < 2.5 < s["mean_ci_high"] <= 4.0


@pytest.mark.parametrize("low, high, ref, want", [(1.0, 2.0, 0.5, "above"), (1.0, 2.0, 2.5, "below"),
                                                  (1.0, 2.0, 1.5, "tie"), (1.0, 2.0, 1.0, "tie"),
                                                  (float("nan"), 2.0, 1.0, "n/a"),
                                                  (None, None, 1.0, "n/a")])  # NaN as a stage record stores it
def test_versus_states_its_rule(low, high, ref, want):
    assert versus(low, high, ref) == want


# ------------------------------------------------------------------------------ the deployment section
def test_over_layouts_is_the_t_interval_over_units():
    x = [0.8, 0.9, 0.95, 0.7]
    s = over_units(x)
    want = sps.t.interval(0.95, 3, loc=np.mean(x), scale=sps.sem(x))
    assert s["n"] == 4 and s["mean"] == pytest.approx(0.8375)
    assert (s["ci_low"], s["ci_high"]) == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("n, low, high, want", [(5, 0.1, 0.5, "above zero"), (5, -0.5, -0.1, "below zero"),
                                                (5, -0.1, 0.1, "includes zero"), (3, 0.0, 0.1, "includes zero"),
                                                (3, float("nan"), float("nan"), "not resolved"),
                                                (2, 0.1, 0.5, "not measured (2 layouts)"),
                                                (1, float("nan"), float("nan"), "not measured (1 layout)")])
def test_excludes_zero_states_its_rule(n, low, high, want):
    """What a paired difference's interval says about zero, by the CI rule: nothing under 3 halls."""
    assert _excludes_zero({"n": n, "mean": 0.0, "ci_low": low, "ci_high": high}) == want


REFERENCE_KEYS = ("zero-action", "hover-optimizer", "oracle")


def _facts(key, label=None, kind=None, seed=None, variant=None, **more):
    """A row's summary as an evaluation stage records it (Row.facts beside its numbers)."""
    kind = kind or ("reference" if key in REFERENCE_KEYS else "learned")
    return {"label": label or key, "name": variant or key, "kind": kind, "variant": variant or key, "seed": seed,
            "rank": None, "training_halls": None, "plan_of": None, "front_margin_deg": None, "level": False, **more}


def _result(**means):
    return {k: {"mean": v, **_facts(k)} for k, v in means.items()}


def _seeded(variant, *means):
    return {f"{variant}@s{s}" if s else variant: {"mean": m, **_facts(f"{variant}@s{s}" if s else variant,
                                                                      variant + (f", seed {s}" if s else ""),
                                                                      seed=s, variant=variant)}
            for s, m in enumerate(means)}


def _transfer(mean, src, rank, plan=True):
    return {"mean": mean, **_facts(f"transfer-{src}", f"{'oracle plan' if plan else 'expert'} of {src}", "transfer",
                                   rank=rank, plan_of=src if plan else None)}


def test_layout_scores_average_seeds_per_layout_and_summarise_transfers():
    res = {"h0": {**_seeded("dt-zero-shot", 30.0, 34.0, 35.0), **_result(oracle=40.0),
                  "transfer-b": _transfer(28.0, "b", 1), "transfer-a": _transfer(20.0, "a", 0)}}
    row = layout_scores(res)["h0"]
    assert row["dt-zero-shot"] == pytest.approx(33.0)  # (30 + 34 + 35) / 3
    assert seed_scores(res)["h0"]["dt-zero-shot"] == {0: 30.0, 1: 34.0, 2: 35.0}
    assert row[NEAREST] == 20.0 and row["transfer-mean"] == 24.0 and row["transfer-best"] == 28.0  # rank 0 nearest
    one = {"h0": {**_result(oracle=40.0), "transfer-a": _transfer(20.0, "a", 0)}}
    assert "transfer-mean" not in layout_scores(one)["h0"]  # one transferred policy is its own mean
    assert row_order(res) == ["dt-zero-shot", "oracle", NEAREST, "transfer-mean", "transfer-best"]
    assert row_labels(res)[NEAREST] == "oracle plan of the nearest training layout, flown here"


def _scores(dt, hover, near, bc, oracle):
    return {f"h{i}": {"dt-zero-shot": d, HOVER_OPTIMIZER: h, NEAREST: n, "bc": b, ORACLE: o}
            for i, (d, h, n, b, o) in enumerate(zip(dt, hover, near, bc, oracle))}


def _section(scores, **kw):
    """The deployment section of made-up scores, each row under its own key."""
    keys = list(next(iter(scores.values())))
    return deployment_section(scores, {k: k for k in keys}, keys, None, None, **kw)


def _zero_shot_claim(scores) -> str:
    return next(c for c in _section(scores)[1] if "**zero-shot DT >=" in c)


def _word(x, target: float = 0.0, at_least: bool = False) -> str:
    """The CI rule (tests/report_check.py) on scipy's t interval of the per-hall values ``x``."""
    x = np.asarray(x, dtype=float)
    return ci_verdict(x.size, *_t95(x)[1:], target, strict=not at_least)


def test_the_zero_shot_claim_holds_only_by_its_stated_rule():
    """Holds only where the fraction's CI over halls is at or above 96% and both paired CIs are above
    zero; refuted where the fraction's CI is below 96%; not resolved where one interval straddles."""
    oracle = np.array([40.0, 42.0, 41.0, 43.0])
    dt = np.array([39.0, 40.95, 40.0, 41.9])  # 97.4-97.6% in every hall
    hover, near = dt - [2.0, 3.0, 2.5, 2.2], dt - [3.0, 2.0, 2.4, 2.6]
    claim = _zero_shot_claim(_scores(dt, hover, near, dt, oracle))
    assert _word(dt / oracle, 0.96, at_least=True) == _word(dt - hover) == _word(dt - near) == "holds"
    assert ": holds (" in claim
    assert f"{np.mean(dt / oracle):.1%}" in claim
    _, lo, hi = _t95(dt - hover)
    assert f"{np.mean(dt - hover):+.2f} [{lo:+.2f}, {hi:+.2f}] bps/Hz, above zero" in claim
    # the same DT, with hovering better in one hall: the paired CI includes zero -> not resolved
    close = hover.copy()
    close[3] = 45.0
    assert _word(dt - close) == "not resolved"
    assert ": not resolved (" in _zero_shot_claim(_scores(dt, close, near, dt, oracle))
    # far above both but its CI below 96% of the oracle -> refuted
    low = 0.90 * oracle + [0.1, -0.1, 0.05, 0.0]
    assert _word(low / oracle, 0.96, at_least=True) == "refuted"
    assert ": refuted (" in _zero_shot_claim(_scores(low, low - 6, low - 7, low, oracle))


def test_the_return_conditioning_verdict_is_the_paired_ci():
    oracle = [40.0, 42.0, 41.0, 43.0]
    s = _scores([39.0, 40.5, 39.5, 41.5], [36.0] * 4, [37.0] * 4, [38.0, 39.0, 38.5, 40.0], oracle)
    _, claims = _section(s)
    claim = next(c for c in claims if "return conditioning on demonstrations" in c)
    d = np.array([1.0, 1.5, 1.0, 1.5])
    lo, hi = sps.t.interval(0.95, 3, loc=d.mean(), scale=sps.sem(d))
    assert f"{d.mean():+.2f} [{lo:+.2f}, {hi:+.2f}] bps/Hz per layout, above zero" in claim


# ------------------------------------------------------------------------------ more of uavris.stats
def test_summarize_is_scipys_bootstrap_of_the_mean_and_the_iqm():
    x = np.random.default_rng(8).gamma(2.0, 3.0, 12)

    def percentile(statistic):
        res = sps.bootstrap((x,), statistic, confidence_level=0.95, n_resamples=2000, method="percentile",
                            rng=np.random.default_rng(4))
        return res.confidence_interval.low, res.confidence_interval.high

    s = summarize(x, seed=4)
    assert s["n"] == 12 and s["mean"] == pytest.approx(x.sum() / 12, rel=1e-12)
    assert s["std"] == pytest.approx(math.sqrt(((x - x.mean()) ** 2).sum() / 11), rel=1e-12)
    middle = np.sort(x)[3:9]  # 12 values: the IQM is the mean of the middle 6
    assert s["iqm"] == pytest.approx(middle.mean(), rel=1e-12)
    assert (s["mean_ci_low"], s["mean_ci_high"]) == pytest.approx(percentile(np.mean), rel=1e-12)
    assert (s["iqm_ci_low"], s["iqm_ci_high"]) == pytest.approx(
        percentile(lambda v, axis: sps.trim_mean(v, 0.25, axis=axis)), rel=1e-12)


# ------------------------------------------------------------------------------ the whole deployment section
def _t95(x):
    x = np.asarray(x, dtype=float)
    if np.all(x == x[0]):
        return x[0], x[0], x[0]
    lo, hi = sps.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=sps.sem(x))
    return x.mean(), lo, hi


def _rows(lines, header):
    i = next(i for i, line in enumerate(lines) if line.startswith(header))
    out = []
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        out.append([c.strip() for c in line.strip("|").split("|")])
    return out


# three unseen halls; each learned row with 2 pre-training seeds; two transferred plans
ORACLES = [40.0, 50.0, 20.0]
HALLS = {
    "dt-zero-shot": ([38.0, 47.0, 19.5], [39.0, 48.0, 19.0]),
    "dt-ensemble": ([39.2, 49.0, 19.8],), "dt-finetuned": ([39.6, 49.5, 19.9],),
    "bc": ([37.0, 46.0, 19.0], [37.5, 46.5, 18.0]), "dt-flat": ([30.0, 40.0, 15.0], [31.0, 41.0, 16.0]),
    "dt-mixed": ([35.0, 44.0, 17.0], [36.0, 45.0, 18.0]), "bc-mixed": ([34.0, 44.5, 16.0], [35.0, 44.0, 17.0]),
    "zero-action": ([12.0, 13.0, 6.0],), "hover-optimizer": ([34.0, 43.0, 17.0],), "oracle": (ORACLES,)}
TRANSFERS = {"transfer-a": [33.0, 20.0, 18.0], "transfer-b": [36.0, 45.0, 10.0]}  # a is the nearest


def _results():
    out = {}
    for j in range(3):
        res = {}
        for key, seeds in HALLS.items():
            if len(seeds) == 1:
                res[key] = {"mean": seeds[0][j], **_facts(key)}
            else:
                res.update(_seeded(key, *(values[j] for values in seeds)))
        res["transfer-a"] = _transfer(TRANSFERS["transfer-a"][j], "a", 0)
        res["transfer-b"] = _transfer(TRANSFERS["transfer-b"][j], "b", 1)
        out[f"hall-{j}"] = res
    return out


def _by_hand():
    """Every row's per-hall score, worked here: learned rows the mean of their seeds."""
    rows = {k: np.mean(np.array(seeds), axis=0) for k, seeds in HALLS.items()}
    t = np.array(list(TRANSFERS.values()))
    rows[NEAREST], rows["transfer-mean"], rows["transfer-best"] = t[0], t.mean(axis=0), t.max(axis=0)
    return rows


def test_the_deployment_section_against_numbers_worked_here():
    results = _results()
    labels = row_labels(results)
    lines, claims = deployment_section(layout_scores(results), labels, row_order(results), None, None,
                                       seeds=seed_scores(results))
    rows = _by_hand()
    oracle = np.array(ORACLES)
    assert rows["dt-zero-shot"].tolist() == [38.5, 47.5, 19.25]
    # over halls: fraction of the oracle, mean [t CI], mean score, worst hall
    table = {r[0]: r[1:] for r in _rows(lines, "| policy | fraction of oracle")}
    assert set(table) == {labels[k] for k in rows}
    for key, values in rows.items():
        f = values / oracle
        m, lo, hi = _t95(f)
        assert table[labels[key]] == [f"{m:.1%} [{lo:.1%}, {hi:.1%}]", f"{values.mean():.2f}", f"{f.min():.1%}"], key
    # per hall
    per_hall = {r[0]: r[1:] for r in _rows(lines, "| layout |")}
    for j in range(3):
        want = sorted(f"{v[j]:.2f} ({v[j] / oracle[j]:.0%})" for v in rows.values())
        assert sorted(per_hall[f"hall-{j}"]) == want
    # each seed's own model: its fraction of the oracle over halls
    seeds = {r[0]: r[1:] for r in _rows(lines, "| policy | seed 0 | seed 1 |")}
    for key in ("dt-zero-shot", "bc", "dt-flat", "dt-mixed", "bc-mixed"):
        want = []
        for values in HALLS[key]:
            m, lo, hi = _t95(np.array(values) / oracle)
            want.append(f"{m:.1%} [{lo:.1%}, {hi:.1%}]")
        assert seeds[labels[key]] == want, key
    # paired differences: per hall, then their mean and t CI, and what the CI says about zero
    pairs = {r[0]: r[1:] for r in _rows(lines, "| difference |")}
    assert len(pairs) == 9
    for a, b in [("dt-zero-shot", "hover-optimizer"), ("dt-zero-shot", NEAREST), ("dt-ensemble", "hover-optimizer"),
                 ("dt-ensemble", NEAREST), ("dt-zero-shot", "transfer-mean"), ("dt-zero-shot", "bc"),
                 ("dt-zero-shot", "dt-flat"), ("dt-mixed", "bc-mixed"), ("dt-finetuned", "dt-zero-shot")]:
        d = rows[a] - rows[b]
        m, lo, hi = _t95(d)
        word = "above zero" if lo > 0 else "below zero" if hi < 0 else "includes zero"
        assert pairs[f"{labels[a]} - {labels[b]}"] == [*(f"{x:+.2f}" for x in d), f"{m:+.2f} [{lo:+.2f}, {hi:+.2f}]",
                                                       word], (a, b)
    # the claims, by their stated rules
    frac = {k: (v / oracle).mean() for k, v in rows.items()}
    for key, head in (("dt-zero-shot", "**zero-shot DT >= 96%"), ("dt-ensemble", "**zero-shot DT ensemble")):
        [claim] = [c for c in claims if head in c]
        word = every_verdict(_word(rows[key] / oracle, 0.96, at_least=True), _word(rows[key] - rows["hover-optimizer"]),
                    _word(rows[key] - rows[NEAREST]))
        assert f"**: {word} (" in claim, claim
    # by hand: the zero-shot DT at 95.0% [..] of the oracle (0.9625, 0.95, 0.9625), above hovering in every
    # hall (+4.5, +4.5, +2.25) but not clearly above the nearest plan (+5.5, +27.5, +1.25: the CI includes zero)
    assert frac["dt-zero-shot"] == pytest.approx(0.9583333333333334)
    claim = next(c for c in claims if "**zero-shot DT >= 96%" in c)
    assert "**: not resolved (95.8% [" in claim and "bps/Hz, above zero; minus nearest +11.42 [" in claim
    assert claim.endswith("bps/Hz, includes zero).")
    # the fine-tuned DT: 99.0%, 99.0%, 99.5% of the oracle (its CI at or above 98%), but above zero-shot by
    # +1.10, +2.00, +0.65 bps/Hz, whose CI includes zero: not resolved
    [claim] = [c for c in claims if "**fine-tuned DT >= 98%" in c]
    assert _word(rows["dt-finetuned"] / oracle, 0.98, at_least=True) == "holds"
    assert _word(rows["dt-finetuned"] - rows["dt-zero-shot"]) == "not resolved"
    assert "**: not resolved (" in claim
    assert len(claims) == 6


@pytest.mark.parametrize("finetuned, zero_shot, word", [
    (0.98, 0.90, "holds"),  # exactly the target in every hall: ">= 98%", and above zero-shot in every hall
    (0.97, 0.90, "refuted"),  # below the target in every hall
    (0.99, 0.995, "refuted"),  # above the target but below zero-shot in every hall
    (0.99, 0.99, "not resolved")])  # equal to zero-shot: not above it
def test_the_finetuned_claim_states_its_rule(finetuned, zero_shot, word):
    oracle = [50.0, 100.0, 50.0, 100.0]  # 49 / 50 and 98 / 100 are both the double nearest 0.98
    scores = {f"h{i}": {"dt-zero-shot": zero_shot * o, "dt-finetuned": finetuned * o, HOVER_OPTIMIZER: 0.5 * o,
                        NEAREST: 0.5 * o, ORACLE: o} for i, o in enumerate(oracle)}
    _, claims = _section(scores)
    [claim] = [c for c in claims if "**fine-tuned DT >= 98% of the oracle and above zero-shot**" in c]
    assert f"**: {word} (fine-tuned {finetuned:.1%} [" in claim


def test_one_layout_resolves_nothing():
    scores = {"h0": {"dt-zero-shot": 48.0, HOVER_OPTIMIZER: 40.0, NEAREST: 30.0, "bc": 20.0, ORACLE: 50.0}}
    _, claims = _section(scores)
    zero_shot = next(c for c in claims if "**zero-shot DT >= 96%" in c)
    # 96% of the oracle, 8 and 18 bps/Hz above the others, but one hall gives no interval: no verdict
    assert ": not measured (96.0% (no CI: 1 unit) of the oracle" in zero_shot
    assert zero_shot.count("not measured (1 layout)") == 2
    bc = next(c for c in claims if "return conditioning on demonstrations" in c)
    assert bc.endswith("+28.00 (no CI: 1 unit) bps/Hz per layout, not measured (1 layout).")  # as the percentages
    assert "minus hovering +8.00 (no CI: 1 unit) bps/Hz, not measured (1 layout)" in zero_shot


def test_two_layouts_print_no_interval_and_no_verdict():
    """Under 3 halls a report prints the mean alone and "not measured" for every verdict, the
    worst hall's target and the paired differences' column included (a smoke report printed
    "59.2% [-412.8%, 531.2%]" and "below zero" over 2 halls)."""
    scores = {h: {"dt-zero-shot": 40.0 + i, "dt-goal-safe": 49.0 + i, HOVER_OPTIMIZER: 30.0, NEAREST: 20.0,
                  "bc": 20.0, ORACLE: 50.0 + i} for i, h in enumerate(("h0", "h1"))}
    lines, claims = _section(scores)
    text = "\n".join(lines + claims)
    assert not re.search(r"\d%? \[", text), "an interval over two halls"
    assert "below zero" not in text and "above zero" not in text and "includes zero" not in text
    assert "not measured (2 layouts)" in text
    place = next(c for c in claims if ">= 99.0% of the oracle, no hall below 97%" in c)
    assert ": not measured (" in place  # its worst hall (98%, above 97%) alone would have decided it


def test_a_row_added_to_the_study_shows_under_its_own_label():
    """A row the report has no name for (one added to tracks.track_rows) gets its line in the
    table of every row, in the per-layout table and in the decomposition, under its label."""
    from uavris.experiments.study.report.decomposition import decomposition_section

    results = _results()
    for j, res in enumerate(results.values()):
        res["dt-new"] = {"mean": 30.0 + j, **_facts("dt-new", "my new controller")}
    lines, _ = deployment_section(layout_scores(results), row_labels(results), row_order(results), None, None,
                                  seeds=seed_scores(results))
    table = {r[0]: r[1:] for r in _rows(lines, "| policy | fraction of oracle")}
    fractions = np.array([30.0, 31.0, 32.0]) / np.array(ORACLES)
    assert table["my new controller"][2] == f"{fractions.min():.1%}"
    for res in results.values():  # the decomposition's fields, the same for every row here
        for v in res.values():
            v.update(end_rate_level=v["mean"], end_rate_own=v["mean"], behind_share=0.0)
        res["oracle"]["plan_rate_level"] = res["oracle"]["mean"]
    lines, _ = decomposition_section(results, row_labels(results))
    assert any(line.startswith("| my new controller |") for line in lines)
