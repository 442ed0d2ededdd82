"""Independent recomputation of a study's report from its stage files: every table cell, interval
and verdict the report prints about the paper, strong and deployment tracks, worked out here
with numpy and SciPy from the per-episode files and stage results (used by test_reproduce.py
and test_deployment_track.py), never by calling the report's code."""

import csv
import re
from pathlib import Path

import numpy as np
from scipy import stats as sps

from uavris.io import read_json


def mean_ci(x) -> tuple[float, float, float, int]:
    """Mean, Student-t 95% interval of a sample (a sample without spread: a point) and its size."""
    x = np.asarray(x, dtype=float)
    if sps.sem(x) == 0:
        return x.mean(), x.mean(), x.mean(), len(x)
    lo, hi = sps.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=sps.sem(x))
    return x.mean(), lo, hi, len(x)


def _zero(lo: float, hi: float, n: int) -> str:
    """What a difference's interval says about zero; under 3 halls nothing."""
    if n < 3:
        return f"not measured ({n} layout{'' if n == 1 else 's'})"
    return "above zero" if lo > 0 else "below zero" if hi < 0 else "includes zero"


def ci_verdict(n: int, low: float, high: float, target: float = 0.0, strict: bool = True) -> str:
    """The CI rule, written out here: not measured under 3 halls; holds where the interval is above the
    target (at or above it for a fraction's target), refuted where below, else not resolved."""
    if n < 3:
        return "not measured"
    if np.isnan(low) or np.isnan(high):
        return "not resolved"
    if (low > target) if strict else (low >= target):
        return "holds"
    return "refuted" if high < target else "not resolved"


def every_verdict(*verdicts: str) -> str:
    if "refuted" in verdicts:
        return "refuted"
    if all(v == "holds" for v in verdicts):
        return "holds"
    return "not measured" if "not measured" in verdicts else "not resolved"


def _no_ci(n: int) -> str:
    return f"(no CI: {n} unit{'' if n == 1 else 's'})"


def _pct3(m: tuple[float, float, float, int]) -> str:
    """A fraction with its interval; under 3 units the mean alone, saying so."""
    return f"{m[0]:.1%} {_no_ci(m[3])}" if m[3] < 3 else f"{m[0]:.1%} [{m[1]:.1%}, {m[2]:.1%}]"


def _num3(m: tuple[float, float, float, int]) -> str:
    return f"{m[0]:+.2f} {_no_ci(m[3])}" if m[3] < 3 else f"{m[0]:+.2f} [{m[1]:+.2f}, {m[2]:+.2f}]"


def _table(text: str, header: str) -> list[list[str]]:
    """The body rows of the table whose header line starts with ``header``, as cells."""
    lines = text.splitlines()
    i = next(i for i, line in enumerate(lines) if line.startswith(header))
    rows = []
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip().strip("|").split("|")])
    return rows


# DT minus another policy, per layout (the report's paired differences)
DEPLOYMENT_PAIRS = (("dt-zero-shot", "hover-optimizer"), ("dt-zero-shot", "nearest"),
                    ("dt-ensemble", "hover-optimizer"), ("dt-ensemble", "nearest"), ("dt-zero-shot", "transfers"),
                    ("dt-zero-shot", "bc"), ("dt-zero-shot", "dt-flat"), ("dt-mixed", "bc-mixed"),
                    ("dt-finetuned", "dt-zero-shot"), ("dt-zero-shot-safe", "hover-optimizer"),
                    ("dt-zero-shot-safe", "nearest"), ("dt-zero-shot-safe", "dt-zero-shot"),
                    ("dt-ensemble-safe", "hover-optimizer"), ("dt-ensemble-safe", "nearest"),
                    ("dt-finetuned-safe", "dt-zero-shot-safe"), ("dt-zero-shot-safe", "dt-zero-shot-level"),
                    ("dt-zero-shot-safe", "bc-safe"), ("dt-goal-safe", "hover-optimizer"), ("dt-goal-safe", "nearest"),
                    ("dt-goal-safe", "dt-zero-shot-safe"), ("plan-learned", "hover-optimizer"),
                    ("dt-goal-finetuned-safe", "dt-goal-safe"), ("dt-goal-safe", "dt-goal-mlp-safe"),
                    ("dt-goal-safe", "bc-best-safe"), ("dt-zero-shot-safe", "bc-best-safe"))
# the targets of the rows that choose a place: (row, mean, worst hall); in zero-shot-only halls, the count's
PLACE_TARGETS = (("dt-goal-safe", 0.99, 0.97, "zero-shot: the deployed place, flown by the goal-conditioned DT"),
                 ("plan-deployed", 0.99, None, "the deployed place (V proposes, R disposes), flown by the oracle's"),
                 ("dt-goal-finetuned-safe", 0.985, 0.95, "the goal-conditioned DT fine-tuned by trying places"))


def _m(diff: tuple) -> tuple[float, float, float, int]:
    """A paired difference's mean, interval and size (``diffs``'s entries below)."""
    return (*diff[:3], diff[5])


def check_deployment_report(results: dict[str, dict], text: str, where: str = "deployment track") -> None:
    """The deployment track's tables and claims in ``text`` against ``{layout: stage result}``;
    ``where`` heads the claims of this group of halls."""
    scores = {}
    for layout, result in results.items():
        seeds: dict[str, list[float]] = {}
        for s in result.values():
            if s["kind"] != "transfer":
                seeds.setdefault(s["variant"], []).append(s["mean"])
        row = {k: sum(v) / len(v) for k, v in seeds.items()}  # a learned row: the mean over its seeds
        [row["nearest"]] = [s["mean"] for s in result.values() if s["kind"] == "transfer" and s["rank"] == 0]
        transfers = [s["mean"] for s in result.values() if s["kind"] == "transfer"]
        if len(transfers) > 1:
            row["transfers"], row["best-transfer"] = sum(transfers) / len(transfers), max(transfers)
        scores[layout] = row
    layouts = list(scores)
    keys = [k for k in scores[layouts[0]] if all(k in scores[lay] for lay in layouts)]
    frac = {k: [scores[lay][k] / scores[lay]["oracle"] for lay in layouts] for k in keys}
    stat = {k: mean_ci(frac[k]) for k in keys}

    # per layout: every policy's score and fraction of the oracle (cells compared as a multiset)
    per_layout = {r[0]: r[1:] for r in _table(text, "| layout |")}
    assert set(per_layout) == set(layouts)
    for lay in layouts:
        want = [f"{scores[lay][k]:.2f} ({scores[lay][k] / scores[lay]['oracle']:.0%})" for k in keys]
        assert sorted(per_layout[lay]) == sorted(want), lay
    # over layouts: fraction of the oracle, mean [t CI], mean score, worst layout
    summary = _table(text, "| policy | fraction of oracle")
    want = [[_pct3(stat[k]), f"{np.mean([scores[lay][k] for lay in layouts]):.2f}", f"{min(frac[k]):.1%}"]
            for k in keys]
    assert sorted(r[1:] for r in summary) == sorted(want)
    # paired differences per layout, their mean [t CI] and what the CI says about zero
    diffs = {}
    for a, b in DEPLOYMENT_PAIRS:
        if a in keys and b in keys:
            d = [scores[lay][a] - scores[lay][b] for lay in layouts]
            m = mean_ci(d)
            diffs[(a, b)] = (*m[:3], _zero(*m[1:]), [f"{x:+.2f}" for x in d], m[3])
    table = _table(text, "| difference |")
    assert sorted(r[1:] for r in table) == sorted([*v[4], _num3(_m(v)), v[3]] for v in diffs.values())

    claims = [line for line in text.splitlines() if line.startswith(f"- {where}: **")]
    expected = _check_score_claims(claims, where, keys, stat, diffs)
    expected += _check_place_claims(claims, where, keys, stat, diffs, frac)
    # blocking: every learned row's share of slots with a device behind the RIS, its seeds averaged per layout
    blocked, learned = {}, set()
    for layout, result in results.items():
        for s in result.values():
            blocked.setdefault(s["variant"], {}).setdefault(layout, []).append(s["behind_share"])
            if s["kind"] == "learned" and s["training_halls"] is None:  # the data curve's models aside
                learned.add(s["variant"])
    # each row's share per hall (its seeds averaged), the CI rule on the limit minus it, over halls
    per_hall = {k: [np.mean(v) for v in by.values()] for k, by in blocked.items() if k in learned}
    words = [ci_verdict(len(v), *mean_ci(0.01 - np.asarray(v))[1:3]) for v in per_hall.values()]
    expected += 1
    [claim] = [c for c in claims if c.startswith(f"- {where}: **no learned row blocks a device")]
    assert f"**: {every_verdict(*words)} (" in claim, claim
    assert len(claims) == expected >= 5


def _check_place_claims(claims: list[str], where: str, keys: list[str], stat: dict, diffs: dict, frac: dict) -> int:
    """The place rows' targets against the recomputed statistics; how many claims there are."""
    if where != "deployment track":  # zero-shot halls: the count target, >= 99% and above hovering
        if "dt-goal-safe" not in keys:
            return 0
        [claim] = [c for c in claims if c.startswith(f"- {where}: **the deployed place flown by")]
        hover, n = diffs[("dt-goal-safe", "hover-optimizer")], len(frac["dt-goal-safe"])
        word = every_verdict(ci_verdict(n, *stat["dt-goal-safe"][1:3], 0.99, strict=False), ci_verdict(n, *hover[1:3]))
        assert f"**: {word} ({_pct3(stat['dt-goal-safe'])}; minus hovering " \
               f"{_num3(_m(hover))} bps/Hz, {hover[3]})." in claim, claim
        return 1
    count = 0
    for key, mean, worst, what in PLACE_TARGETS:
        if key not in keys:
            continue
        count += 1
        [claim] = [c for c in claims if f">= {mean:.1%} of the oracle" in c and c.startswith(f"- {where}: **{what}")]
        n = len(frac[key])
        parts = [ci_verdict(n, *stat[key][1:3], mean, strict=False)]
        parts += [] if worst is None else ["holds" if min(frac[key]) >= worst else "refuted"]
        if key == "dt-goal-safe":
            parts += [ci_verdict(n, *diffs[(key, other)][1:3]) for other in ("hover-optimizer", "nearest")]
        word = every_verdict(*parts) if n >= 3 else "not measured"  # the worst of two halls decides nothing
        assert f"**: {word} ({_pct3(stat[key])} of the oracle, worst hall " \
               f"{min(frac[key]):.1%}" in claim, claim
    return count


def _check_score_claims(claims: list[str], where: str, keys: list[str], stat: dict, diffs: dict) -> int:
    """The deployment claims about scores (targets, fine-tuning, paired differences) against the
    recomputed statistics; how many there are."""
    expected = 0
    for key, what in (("dt-zero-shot", "zero-shot DT"), ("dt-ensemble", "zero-shot DT ensemble (one controller)"),
                      ("dt-zero-shot-safe", "zero-shot DT under the attitude safety layer"),
                      ("dt-ensemble-safe", "zero-shot DT ensemble under the attitude safety layer")):
        if key not in keys:
            continue
        expected += 1
        [claim] = [c for c in claims if c.startswith(f"- {where}: **{what} >= ")]
        target = int(re.search(r">= (\d+)% of the oracle", claim).group(1)) / 100
        hover, near = diffs[(key, "hover-optimizer")], diffs[(key, "nearest")]
        n = len(hover[4])
        word = every_verdict(ci_verdict(n, *stat[key][1:3], target, strict=False), ci_verdict(n, *hover[1:3]),
                             ci_verdict(n, *near[1:3]))
        assert f"**: {word} (" in claim, claim
        assert (f"({_pct3(stat[key])} of the oracle; minus hovering {_num3(_m(hover))} bps/Hz, {hover[3]}; minus "
                f"nearest {_num3(_m(near))} bps/Hz, {near[3]})." in claim), claim
    for ft, zs, what in (("dt-finetuned", "dt-zero-shot", "fine-tuned DT"),
                         ("dt-finetuned-safe", "dt-zero-shot-safe", "fine-tuned DT under the attitude safety layer")):
        if ft not in keys:
            continue
        expected += 1
        [claim] = [c for c in claims if c.startswith(f"- {where}: **{what} >= ")]
        target = int(re.search(r">= (\d+)% of the oracle", claim).group(1)) / 100
        gain = diffs[(ft, zs)]
        n = len(gain[4])
        word = every_verdict(ci_verdict(n, *stat[ft][1:3], target, strict=False), ci_verdict(n, *gain[1:3]))
        assert f"**: {word} (" in claim, claim
        assert f"(fine-tuned {_pct3(stat[ft])}; fine-tuned minus zero-shot {_num3(_m(gain))} bps/Hz)." in claim, claim
    for pair, what in ((("dt-zero-shot", "bc"), "**return conditioning on demonstrations of one quality"),
                       (("dt-zero-shot-safe", "bc-safe"), "**return conditioning under the attitude safety layer"),
                       (("dt-mixed", "bc-mixed"), "**return conditioning on mixed-quality data"),
                       (("dt-zero-shot", "dt-flat"), "**the device-set encoder"),
                       (("dt-goal-safe", "dt-goal-mlp-safe"), "**a history of slots is needed"),
                       (("dt-goal-safe", "bc-best-safe"), "**the goal-conditioned DT above filtered behaviour")):
        if pair in diffs:
            expected += 1
            [claim] = [c for c in claims if c.startswith(f"- {where}: {what}")]
            assert claim.endswith(f"**: {_num3(_m(diffs[pair]))} bps/Hz per layout, {diffs[pair][3]}."), claim
    return expected


def _cell(diffs, noun: str) -> str:
    """The claims table's cell for per-unit differences, by the stated rule, with SciPy's t
    interval: below 3 units the estimate alone, "not measured"."""
    diffs = np.asarray(diffs, dtype=float)
    count = f"({diffs.size} {noun}{'' if diffs.size == 1 else 's'})"
    if diffs.size < 3:
        return f"**not measured**: {diffs.mean():+,.2f} {count}"
    ci = sps.ttest_1samp(diffs, 0.0).confidence_interval(0.95)
    word = "holds" if ci.low > 0 else "refuted" if ci.high < 0 else "not resolved"
    return f"**{word}**: {diffs.mean():+,.2f} [{ci.low:+,.2f}, {ci.high:+,.2f}] {count}"


def _episodes(stage: Path, row: str) -> np.ndarray:
    with open(stage / f"{row}.csv", newline="") as f:
        return np.array([float(r["avg_sum_rate"]) for r in csv.DictReader(f)])


def check_deployment_claims(stages: list[Path], text: str) -> None:
    """The claims table's deployment cell of the zero-shot claim: the return- and the
    goal-conditioned DT (safety layer, mean of the seeds per episode) minus the nearest training
    hall's plan, per unseen hall of the study's own generator and count."""
    table = _table(text, "| claim | paper | strong | deployment |")
    [row] = [r for r in table if r[0].startswith("the zero-shot DT scores above")]
    cells = []
    for variant in ("dt-zero-shot-safe", "dt-goal-safe"):
        diffs = []
        for stage in stages:
            res = read_json(stage / "stage.json")["result"]
            keys = [k for k, s in res.items() if s.get("variant") == variant]
            [near] = [k for k, s in res.items() if s["kind"] == "transfer"]
            diffs.append(np.mean(np.mean([_episodes(stage, k) for k in keys], axis=0) - _episodes(stage, near)))
        cells.append(_cell(diffs, "hall"))
    assert row[3] == " / ".join(cells), (row[3], cells)


def check_track_claims(stages: dict[tuple[str, str], Path], compare_dir: Path, text: str) -> None:
    """The claims table's paper and strong cells in ``text`` against their evaluation stages'
    per-episode files (``{(track, scenario): stage dir}``) and the comparison's runs."""
    assert len(stages) == 4
    table = _table(text, "| claim | paper | strong |")
    rows = {r[0]: r[1:] for r in table}
    with open(compare_dir / "final_per_run.csv", newline="") as f:
        runs = list(csv.DictReader(f))
    by_algo = {}
    for r in runs:
        by_algo.setdefault(r["algo"], []).append(float(r["final_eval_mean"]))
    gaps = {a: np.mean(by_algo["ddpg"]) - np.mean(v) for a, v in by_algo.items() if a != "ddpg"}
    [ddpg] = [v for k, v in rows.items() if k.startswith("DDPG trains the best")]
    seeds = min(len(v) for v in by_algo.values())
    assert ddpg[0] == f"**not measured**: {min(gaps.values()):+,.2f} ({seeds} seed{'' if seeds == 1 else 's'})"
    for col, track in enumerate(("paper", "strong")):
        zs, near, above, bc = [], [], [], []
        for (t, _scenario), stage in sorted(stages.items()):
            if t != track:
                continue
            res = read_json(stage / "stage.json")["result"]
            top = max((k for k, v in res.items() if v["kind"] == "transfer"), key=lambda k: res[k]["mean"])
            z = _episodes(stage, "dt-zero-shot")
            zs.append(np.mean(z - _episodes(stage, top)))
            near.append(np.mean(_episodes(stage, "dt-finetuned") - 0.95 * _episodes(stage, "expert")))
            above.append(np.mean(_episodes(stage, "dt-finetuned") - z))
            bc.append(np.mean(z - _episodes(stage, "bc")))
        # one study is one training seed: its scenarios are averaged into one unit
        for start, diffs in (("the zero-shot DT scores above", zs), ("the fine-tuned DT is within 5%", near),
                             ("fine-tuning raises the DT", above), ("the DT scores above behaviour cloning", bc)):
            [cells] = [v for k, v in rows.items() if k.startswith(start)]
            assert cells[col] == _cell([np.mean(diffs)], "seed"), (track, start, cells)
