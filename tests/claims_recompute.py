"""Every cell of a claims page computed again from its evidence (``claims-evidence/units.json``),
independently of uavris's judging code: from the rules as the claims page states them, with
numpy and scipy only. Used by tests/test_claims_evidence.py (the committed page) and the smoke
studies' tests (a page written there).

The evidence holds what each cell read, unit by unit: the comparison's scores per algorithm;
per (seed, scenario) pair of the paper and strong tracks the rows' per-episode rates, the two
learning curves, the expert's final evaluation and the pre-training's interactions; per unseen
hall of the deployment track each row's per-episode rates per pre-training seed and the
nearest training hall's plan, and the from-scratch curves.
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import Any

import numpy as np
from scipy import stats

LEVEL, WITHIN, MIN_UNITS = 0.95, 0.05, 3
# the cells whose p-value is their own interval's (the others combine two: "within 5%" both ways, the two
# charging rules of "fewer-total", DDPG against each algorithm)
ONE_SAMPLE = ("zero-shot", "finetuned", "fluctuates", "dt-over-bc", "fewer", "fewer-finetuning")


def cell(values: Any) -> dict[str, float]:
    """Mean and Student-t 95% interval of per-unit values (NaN interval for one unit)."""
    x = np.asarray(values, dtype=np.float64)
    if x.size < 2:
        return {"n": int(x.size), "mean": float(x.mean()) if x.size else math.nan, "ci_low": math.nan,
                "ci_high": math.nan}
    half = stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size)
    return {"n": int(x.size), "mean": float(x.mean()), "ci_low": float(x.mean() - half),
            "ci_high": float(x.mean() + half)}


def verdict(c: dict[str, float]) -> str:
    if not (np.isfinite(c["ci_low"]) and np.isfinite(c["ci_high"])):
        return "not resolved"
    return "holds" if c["ci_low"] > 0 else "refuted" if c["ci_high"] < 0 else "not resolved"


def welch(a: Any, b: Any) -> dict[str, float]:
    res = stats.ttest_ind(np.asarray(a, float), np.asarray(b, float), equal_var=False)
    ci = res.confidence_interval(0.95)
    return {"n": min(len(a), len(b)), "mean": float(np.mean(a) - np.mean(b)), "ci_low": float(ci.low),
            "ci_high": float(ci.high)}


def to_level(curve: Any, level: float) -> tuple[float, bool]:
    """The first x whose y reaches ``level``; else the last x, censored."""
    x, y = (np.asarray(v, dtype=np.float64) for v in curve)
    hit = x[y >= level]
    return (float(hit[0]), False) if hit.size else (float(x[-1]) if x.size else 0.0, True)


def _comparison(entry: dict[str, Any]) -> dict[str, float]:
    scores = entry["scores"]
    others = {a: welch(scores["ddpg"], s) for a, s in scores.items() if a != "ddpg"}
    closest = min(others, key=lambda a: others[a]["mean"])
    if any(len(scores.get(a, ())) < MIN_UNITS for a in ("ddpg", "ppo", "sac", "td3")):
        return {"mean": others[closest]["mean"], "ci_low": math.nan, "ci_high": math.nan,
                "n": min(len(scores.get(a, ())) for a in ("ddpg", "ppo", "sac", "td3"))}
    return others[closest]


def _by_seed(pairs: list[dict[str, Any]], value: Any) -> tuple[list[float], list[int]]:
    seeds = sorted({p["seed"] for p in pairs})
    return [float(np.mean([value(p) for p in pairs if p["seed"] == s])) for s in seeds], seeds


def _scenario(pairs: list[dict[str, Any]]) -> dict[str, list[dict[str, float]]]:
    """The scenario track's cells, in the order the page lists each claim's entries."""
    sites = {p["site"] for p in pairs}
    pairs = [p for p in pairs if sum(q["seed"] == p["seed"] for q in pairs) == len(sites)]
    r = {id(p): {k: np.asarray(v, dtype=np.float64) for k, v in p["rows"].items()} for p in pairs}

    def over(fn: Any) -> dict[str, float]:
        return cell(_by_seed(pairs, lambda p: fn(r[id(p)]))[0])

    sd = lambda v: float(np.std(v, ddof=1))  # noqa: E731
    out = {"zero-shot": [over(lambda x: np.mean(x["dt-zero-shot"] - x["transfer"]))],
           "finetuned": [over(lambda x: np.mean(x["dt-finetuned"] - x["dt-zero-shot"]))],
           "fluctuates": [over(lambda x: sd(x["dt-zero-shot"]) - sd(x["dt-finetuned"])),
                          over(lambda x: sd(x["transfer"]) - sd(x["expert"]))]}
    below = over(lambda x: np.mean(x["dt-finetuned"] - (1 - WITHIN) * x["expert"]))
    above = over(lambda x: np.mean((1 + WITHIN) * x["expert"] - x["dt-finetuned"]))
    out["near-expert"] = [_within(below, above)]
    if all("bc" in p["rows"] for p in pairs):
        out["dt-over-bc"] = [over(lambda x: np.mean(x["dt-zero-shot"] - x["bc"]))]
    need = {}
    for p in pairs:
        level = LEVEL * p["expert_final"]
        (e, ce), (f, cf) = to_level(p["expert_curve"], level), to_level(p["finetune_curve"], level)
        need[id(p)] = (e - f, ce or cf, f == 0 and not cf)
    out["fewer"] = [_censored(pairs, lambda p: need[id(p)][0], need)]
    worked = [p for p in pairs if not need[id(p)][2]]
    out["fewer-finetuning"] = [_censored(worked, lambda p: need[id(p)][0], need)] if worked else []
    out["fewer-total"] = [_censored(pairs, lambda p: need[id(p)][0] - p["pretraining"], need)]
    return out


def _censored(pairs: list[dict[str, Any]], value: Any, need: dict[int, Any]) -> dict[str, float]:
    values, seeds = _by_seed(pairs, value)
    c = cell(values)
    c["censored"] = sum(any(need[id(p)][1] for p in pairs if p["seed"] == s) for s in seeds)
    return c


def _within(below: dict[str, float], above: dict[str, float]) -> dict[str, float]:
    """The side that decides "within 5%": a refuted side, else one not resolved, else the lower."""
    sides = [below, above]
    for want in ("refuted", "not resolved"):
        found = [s for s in sides if verdict(s) == want]
        if found:
            return found[0]
    return below


def _deployment(ev: dict[str, Any]) -> dict[str, list[dict[str, float]]]:
    halls = ev.get("halls", [])
    if not halls:
        return {}
    mean = lambda seeds: np.mean(np.asarray(seeds, dtype=np.float64), axis=0)  # noqa: E731
    spread = lambda seeds: float(np.mean([np.std(s, ddof=1) for s in seeds]))  # noqa: E731
    has = lambda v: all(v in h["rows"] for h in halls)  # noqa: E731
    out: dict[str, list[dict[str, float]]] = defaultdict(list)
    out["zero-shot"].append(cell([np.mean(mean(h["rows"]["dt-zero-shot-safe"]) - np.asarray(h["transfer"]))
                                  for h in halls]))
    if has("dt-goal-safe"):
        out["zero-shot"].append(cell([np.mean(mean(h["rows"]["dt-goal-safe"]) - np.asarray(h["transfer"]))
                                      for h in halls]))
    for fine, start in (("dt-finetuned", "dt-zero-shot"), ("dt-goal-finetuned", "dt-goal")):
        if all(has(v) for v in (fine, start, fine + "-safe", start + "-safe")):
            out["finetuned"].append(cell([np.mean(mean(h["rows"][fine]) - mean(h["rows"][start])) for h in halls]))
            oracle = [np.asarray(h["rows"]["oracle-safe"][0]) for h in halls]
            fs = [mean(h["rows"][fine + "-safe"]) for h in halls]
            out["near-expert"].append(_within(cell([np.mean(f - (1 - WITHIN) * o) for f, o in zip(fs, oracle)]),
                                              cell([np.mean((1 + WITHIN) * o - f) for f, o in zip(fs, oracle)])))
            out["fluctuates"].append(cell([spread(h["rows"][start + "-safe"]) - spread(h["rows"][fine + "-safe"])
                                           for h in halls]))
            break
    out["fluctuates"].append(cell([np.std(h["transfer"], ddof=1) - np.std(h["rows"]["oracle-safe"][0], ddof=1)
                                   for h in halls]))
    if has("bc-safe"):
        out["dt-over-bc"].append(cell([np.mean(mean(h["rows"]["dt-zero-shot-safe"]) - mean(h["rows"]["bc-safe"]))
                                       for h in halls]))
    scratch = ev.get("from_scratch")
    if scratch:
        rows = []
        for h in scratch["halls"]:
            final = float(h["expert_curve"][1][-1])
            (e, ce), (f, cf) = (to_level(h[k], LEVEL * final) for k in ("expert_curve", "finetune_curve"))
            rows.append((e - f, ce or cf, f == 0 and not cf))
        out["fewer"].append({**cell([d for d, _, _ in rows]), "censored": sum(c for _, c, _ in rows)})
        worked = [(d, c) for d, c, there in rows if not there]
        if worked:
            out["fewer-finetuning"].append({**cell([d for d, _ in worked]), "censored": sum(c for _, c in worked)})
        out["fewer-total"].append({**cell([d - scratch["pretraining"] for d, _, _ in rows]),
                                   "censored": sum(c for _, c, _ in rows)})
    return dict(out)


def expected_cells(units: dict[str, Any]) -> dict[tuple[str, str], list[dict[str, float]]]:
    """Every judged cell the evidence gives, by (track, claim), in the page's order of entries."""
    out: dict[tuple[str, str], list[dict[str, float]]] = {}
    comparison = [_comparison(e) for e in units.get("comparison", []) if "ddpg" in e["scores"]]
    if comparison:
        out[("paper", "ddpg-best")] = comparison
    for track, pairs in units.get("scenario", {}).items():
        if pairs:
            out.update({(track, k): v for k, v in _scenario(pairs).items() if v})
    out.update({("deployment", k): v for k, v in _deployment(units.get("deployment", {})).items() if v})
    return out


def p_value(c: dict[str, float]) -> float:
    """The two-sided p-value of a cell from its interval (1 where a unit is censored)."""
    if c.get("censored"):
        return 1.0
    half = (c["ci_high"] - c["ci_low"]) / 2
    dof = c["n"] - 1
    if not (np.isfinite(half) and dof > 0):
        return math.nan
    return float(2 * stats.t.sf(abs(c["mean"]) / (half / stats.t.ppf(0.975, dof)), dof))


def mismatches(claims: dict[str, Any], units: dict[str, Any], tol: float = 1e-9) -> list[str]:
    """Where ``claims.json``'s judged cells differ from the cells computed again from ``units``
    (mean, interval, units; the p-value of the one-sample cells), and cells either side lacks."""
    want = expected_cells(units)
    got: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for j in claims["judgements"]:
        if j["verdict"] != "not tested":
            got[(j["track"], j["claim"])].append(j)
    bad = [f"{k}: judged on the page, not computable from the evidence" for k in got if k not in want]
    for key, cells in want.items():
        page = got.get(key, [])
        if len(page) != len(cells):
            bad.append(f"{key}: {len(cells)} entries from the evidence, {len(page)} on the page")
            continue
        for c, j in zip(cells, page):
            for field in ("mean", "ci_low", "ci_high"):
                a, b = c[field], j[field]
                if not ((a is None or math.isnan(a)) and (b is None or math.isnan(b))) and \
                        not abs(a - b) <= tol * max(1.0, abs(a)):
                    bad.append(f"{key} {field}: {b} on the page, {a} from the evidence")
            if c["n"] != j["n"]:
                bad.append(f"{key}: {j['n']} units on the page, {c['n']} from the evidence")
            if key[1] in ONE_SAMPLE and c["n"] >= MIN_UNITS:
                p = p_value(c)
                if not (math.isnan(p) or abs(p - j["p"]) <= 1e-9):
                    bad.append(f"{key} p: {j['p']} on the page, {p} from the evidence")
    return bad
