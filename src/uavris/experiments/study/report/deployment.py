"""The deployment track's part of the report: unseen layouts as the unit of generalisation.

Lives here: :func:`layout_scores` (every policy's score in every unseen layout, from the
evaluation stages; :func:`seed_scores`: each pre-training seed's), the means with 95% CIs
over layouts (:func:`uavris.stats.over_units`) and paired differences,
:func:`deployment_section` (the tables and verdicts) and the two figures (:func:`layouts_figure`,
:func:`scaling_figure`). Not here: the evaluations (written by
:func:`uavris.experiments.study.workers.evaluate_rows`) and the other tracks' report.

Statistics (docs/study.md, section 2): a policy's score in a layout is its mean average sum
rate over the evaluation episodes, and its fraction of the oracle there. Across layouts:
the mean and Student's t 95% interval over the unseen layouts (each layout one sample);
paired differences (DT minus another policy) are taken per layout first, on the same
episodes, then summarised the same way, so that what varies from hall to hall cancels.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uavris.agents.references import HOVER_OPTIMIZER, ORACLE
from uavris.experiments.display.plots import REFERENCE_STYLE, plt, save_figure
from uavris.experiments.display.tables import MISSING, counted, markdown_table, pct, signed, with_ci
from uavris.experiments.tools.rows import variant_key
from uavris.stats import HOLDS, MIN_UNITS, NOT_MEASURED, NOT_RESOLVED, REFUTED, over_units, verdict

# Targets of the deployment track (docs/study.md, section 2).
ZERO_SHOT_TARGET, FINETUNED_TARGET = 0.96, 0.98
# Targets of the rows that choose a place (docs/places.md): (row, mean, worst hall, what it is)
PLACE_TARGETS: tuple[tuple[str, float, float | None, str], ...] = (
    ("dt-goal-safe", 0.99, 0.97, "zero-shot: the deployed place, flown by the goal-conditioned DT"),
    ("plan-deployed", 0.99, None, "the deployed place (V proposes, R disposes), flown by the oracle's controller"),
    ("dt-goal-finetuned-safe", 0.985, 0.95, "the goal-conditioned DT fine-tuned by trying places"))
COUNT_TARGET = 0.99  # at every device count, the zero-shot place row (docs/places.md)
# the rows whose place the learned value V chooses (a fit of V per pre-training seed)
VALUE_ROWS = ("plan-learned", "plan-deployed", "dt-goal", "dt-goal-safe", "dt-goal-finetuned", "dt-goal-finetuned-safe")
# The transferred policies of a hall, summarised by the report: the nearest deployment's, their mean, their best.
NEAREST, MEAN_TRANSFER, BEST_TRANSFER = "transfer-nearest", "transfer-mean", "transfer-best"
TRANSFER_LABELS = {NEAREST: "expert of the nearest training layout", MEAN_TRANSFER: "transferred experts, mean",
                   BEST_TRANSFER: "transferred experts, best (chosen afterwards)"}
ORACLE_SAFE = variant_key(ORACLE, safe=True)
PAIRS: tuple[tuple[str, str], ...] = (("dt-zero-shot", HOVER_OPTIMIZER), ("dt-zero-shot", NEAREST),
                                      ("dt-ensemble", HOVER_OPTIMIZER), ("dt-ensemble", NEAREST),
                                      ("dt-zero-shot-safe", HOVER_OPTIMIZER), ("dt-zero-shot-safe", NEAREST),
                                      ("dt-zero-shot-safe", "dt-zero-shot"), ("dt-ensemble-safe", HOVER_OPTIMIZER),
                                      ("dt-ensemble-safe", NEAREST), ("dt-finetuned-safe", "dt-zero-shot-safe"),
                                      ("dt-zero-shot-safe", "dt-zero-shot-level"),
                                      ("dt-zero-shot", MEAN_TRANSFER), ("dt-zero-shot", "bc"),
                                      ("dt-zero-shot-safe", "bc-safe"),
                                      ("dt-zero-shot", "dt-flat"), ("dt-mixed", "bc-mixed"),
                                      ("dt-finetuned", "dt-zero-shot"),
                                      ("dt-goal-safe", HOVER_OPTIMIZER), ("dt-goal-safe", NEAREST),
                                      ("dt-goal-safe", "dt-zero-shot-safe"), ("plan-learned", HOVER_OPTIMIZER),
                                      ("dt-goal-finetuned-safe", "dt-goal-safe"), ("dt-goal-safe", "dt-goal-mlp-safe"),
                                      ("dt-goal-safe", "bc-best-safe"), ("dt-zero-shot-safe", "bc-best-safe"))


def row_facts(results: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """What each row of a group of halls is, by its variant (the key its seeds are averaged
    under), as the evaluation stages recorded it (:meth:`uavris.experiments.tools.rows.Row.facts`):
    its first hall's summary of the row, of its first pre-training seed where it has several."""
    out: dict[str, dict[str, Any]] = {}
    for v in next(iter(results.values())).values():
        if not v["seed"]:
            out.setdefault(v["variant"], v)
    return out


def row_labels(results: dict[str, dict[str, Any]]) -> dict[str, str]:
    """Each row's label, as the study names it (its first seed's has no seed in it), and the
    transferred policies' summaries'."""
    facts = row_facts(results)
    labels = {k: v["label"] for k, v in facts.items() if v["kind"] != "transfer"}
    plans = any(v["plan_of"] is not None for v in facts.values() if v["kind"] == "transfer")
    return {**labels, **TRANSFER_LABELS,
            **({NEAREST: "oracle plan of the nearest training layout, flown here"} if plans else {})}


def row_order(results: dict[str, dict[str, Any]]) -> list[str]:
    """The report's rows in the order the study evaluated them, the transferred policies as
    their summaries (where the first of them stood) and the data curve's models last, by their
    number of training halls."""
    facts = row_facts(results)
    order: list[str] = []
    for k, v in facts.items():
        if v["kind"] == "transfer":
            if NEAREST not in order:
                order += [NEAREST, MEAN_TRANSFER, BEST_TRANSFER]
        elif v["training_halls"] is None:
            order.append(k)
    return order + sorted((k for k, v in facts.items() if v["training_halls"] is not None),
                          key=lambda k: facts[k]["training_halls"])


def layout_scores(results: dict[str, dict[str, Any]], field: str = "mean") -> dict[str, dict[str, float]]:
    """``{layout: {row: mean}}`` from the evaluation stages' results (or another ``field`` of
    the summaries, e.g. the decomposition's), with the transferred experts summarised as the
    nearest (its label says so), their mean and their best, and a row trained over several
    pre-training seeds (its summaries' ``seed``) as the mean over its seeds in the layout,
    under its ``variant`` (:class:`uavris.experiments.tools.rows.Row`)."""
    out = {}
    for layout, res in results.items():
        res = {k: {**v, "mean": v[field]} for k, v in res.items() if field in v}
        row = {k: float(v["mean"]) for k, v in res.items() if v["kind"] != "transfer" and v["seed"] is None}
        for variant, by_seed in _seeded(res).items():  # seed 0 last: the order the means were first taken in
            row[variant] = float(np.mean([x for s, x in by_seed.items() if s] + [by_seed[0]]))
        transfers = {k: v for k, v in res.items() if v["kind"] == "transfer"}
        if transfers:
            nearest = next((v for v in transfers.values() if v["rank"] == 0), None)
            if nearest is not None:
                row[NEAREST] = float(nearest["mean"])
            if len(transfers) > 1:  # one transferred policy (the nearest hall's) is its own mean and best
                row[MEAN_TRANSFER] = float(np.mean([v["mean"] for v in transfers.values()]))
                row[BEST_TRANSFER] = float(max(v["mean"] for v in transfers.values()))
        out[layout] = row
    return out


def seed_scores(results: dict[str, dict[str, Any]]) -> dict[str, dict[str, dict[int, float]]]:
    """``{layout: {row: {seed: mean}}}`` of the rows trained over several pre-training seeds."""
    return {layout: _seeded(res) for layout, res in results.items()}


def _seeded(res: dict[str, dict[str, Any]]) -> dict[str, dict[int, float]]:
    out: dict[str, dict[int, float]] = {}
    for v in res.values():
        if v["seed"] is not None:
            out.setdefault(v["variant"], {})[int(v["seed"])] = float(v["mean"])
    return out


def at_least(s: dict[str, float], target: float) -> str:
    """A target on a mean over halls, by the CI rule: it holds where the 95% CI is at or above
    the target, is refuted where it is below, is not resolved otherwise, and is not measured
    with fewer than :data:`~uavris.stats.MIN_UNITS` halls (a mean alone is no verdict)."""
    if s.get("n", 0) < MIN_UNITS:
        return NOT_MEASURED
    low, high = s["ci_low"], s["ci_high"]
    if not (np.isfinite(low) and np.isfinite(high)):
        return NOT_RESOLVED
    return HOLDS if low >= target else REFUTED if high < target else NOT_RESOLVED


def above(d: dict[str, float] | None) -> str:
    """"Above" by a paired difference over halls: the CI rule, not measured under 3 halls."""
    if d is None or d.get("n", 0) < MIN_UNITS:
        return NOT_MEASURED
    return verdict(d["ci_low"], d["ci_high"])


def every(*verdicts: str) -> str:
    """The verdict on several conditions at once: refuted where one is, holds where all do, not
    measured where one is and none is refuted, not resolved otherwise."""
    if REFUTED in verdicts:
        return REFUTED
    if all(v == HOLDS for v in verdicts):
        return HOLDS
    return NOT_MEASURED if NOT_MEASURED in verdicts else NOT_RESOLVED


def _excludes_zero(s: dict[str, float]) -> str:
    if s["n"] < MIN_UNITS:
        return f"{NOT_MEASURED} ({counted(s['n'], 'layout')})"
    if math.isnan(s["ci_low"]):
        return NOT_RESOLVED
    return "above zero" if s["ci_low"] > 0 else "below zero" if s["ci_high"] < 0 else "includes zero"


def deployment_section(scores: dict[str, dict[str, float]], labels: dict[str, str], order: Sequence[str],
                       figure: str | None, scaling: str | None, where: str = "deployment track", first_seed: int = 0,
                       seeds: dict[str, dict[str, dict[int, float]]] | None = None, zero_shot_only: bool = False
                       ) -> tuple[list[str], list[str]]:
    """The report's lines for a group of the deployment track's halls and its claims (each a
    bullet, headed ``where``): the rows of ``order`` (:func:`row_order`) under ``labels``
    (:func:`row_labels`); the seed table (``seeds``: :func:`seed_scores`) names the
    pre-training seeds from the study's ``first_seed``; halls evaluated ``zero_shot_only`` are
    judged by the count target (:func:`_place_claims`)."""
    layouts = list(scores)
    rows = [(k, labels[k]) for k in order if all(k in scores[lay] for lay in layouts)]
    frac = {k: [scores[lay][k] / scores[lay][ORACLE] for lay in layouts] for k, _ in rows}
    lines = [f"Unseen layouts: {len(layouts)}; the unit of generalisation is the layout: means and 95% CIs are "
             "over layouts (Student's t), each layout's score being its mean over the evaluation episodes.", ""]
    if figure:
        lines += [f"![deployment track, per layout]({figure})", ""]
    summary = {k: over_units(frac[k]) for k, _ in rows}
    lines += markdown_table(
        ("policy", "fraction of oracle, mean [95% CI over layouts]", "mean (bps/Hz)", "worst layout"),
        [(label, with_ci(summary[k], pct), f"{np.mean([scores[lay][k] for lay in layouts]):.2f}", pct(min(frac[k])))
         for k, label in rows], "llrr")
    first = (seeds or {}).get(layouts[0], {})
    seeded = [(k, label) for k, label in rows if k in first]
    if seeded:
        n_seeds = max(max(by) for by in first.values()) + 1
        lines += ["", f"A learned row is the mean over {n_seeds} pre-training seeds in each layout; each seed's own "
                  "model (fraction of the oracle, mean [95% CI over layouts]):", ""]
        lines += markdown_table(("policy", *(f"seed {first_seed + i}" for i in range(n_seeds))), [
            (label, *(with_ci(over_units([seeds[lay][k][i] / scores[lay][ORACLE] for lay in layouts]), pct)
                      if i in first[k] else MISSING for i in range(n_seeds)))
            for k, label in seeded])
    if any(k in VALUE_ROWS for k, _ in rows):
        lines += ["", "Each pre-training seed has its own fit of the learned value V, which chooses the places of "
                  "that seed's rows told a place (the learned planner's, the deployed one): a row's mean over its "
                  "seeds averages over the fits of V as over the models."]
    lines += ["", "Per layout (bps/Hz; in brackets the fraction of the oracle):", ""]
    lines += markdown_table(("layout", *(label for _, label in rows)), [
        (lay, *(f"{scores[lay][k]:.2f} ({scores[lay][k] / scores[lay][ORACLE]:.0%})" for k, _ in rows))
        for lay in layouts], "l" + "r" * len(rows))
    lines += ["", "Paired differences per layout (bps/Hz, same episodes), mean [95% CI over layouts]:", ""]
    diffs, table = {}, []
    for a, b in PAIRS:
        if a in summary and b in summary:
            d = [scores[lay][a] - scores[lay][b] for lay in layouts]
            diffs[(a, b)] = over_units(d)
            table.append((f"{labels.get(a, a)} - {labels.get(b, b)}", *(signed(x) for x in d),
                          with_ci(diffs[(a, b)], signed), _excludes_zero(diffs[(a, b)])))
    lines += markdown_table(("difference", *layouts, "mean [95% CI]", "the CI"), table,
                            "l" + "r" * len(layouts) + "ll")
    if scaling:
        lines += ["", f"![zero-shot score against the number of training layouts]({scaling})"]
    claims = _claims(summary, diffs) + _place_claims(summary, diffs, frac, zero_shot_only)
    return lines, [f"- {where}: {c}" for c in claims]


def _place_claims(summary: dict[str, dict[str, float]], diffs: dict[tuple[str, str], dict[str, float]],
                  frac: dict[str, list[float]], zero_shot_only: bool) -> list[str]:
    """The place rows' targets (docs/places.md), each judged on this group of halls: a row's mean and worst hall as
    fractions of the oracle, and (zero-shot) above hovering with optimised phases and the
    nearest training hall's plan, paired CIs over halls excluding zero. In a group evaluated
    zero-shot only (another generator's or another device count's halls): the count target."""
    out = []
    if zero_shot_only:
        own, hover = summary.get("dt-goal-safe"), diffs.get(("dt-goal-safe", HOVER_OPTIMIZER))
        if own is not None and hover is not None:
            judged = every(at_least(own, COUNT_TARGET), above(hover))
            out.append(f"**the deployed place flown by the goal-conditioned DT >= "
                       f"{COUNT_TARGET:.0%} of the oracle and above hovering with optimised phases**: "
                       f"{judged} ({with_ci(own, pct)}; minus hovering "
                       f"{with_ci(hover, signed)} bps/Hz, {_excludes_zero(hover)}).")
        return out
    for key, mean, worst, what in PLACE_TARGETS:
        own = summary.get(key)
        if own is None:
            continue
        low = float(min(frac[key]))
        # the worst hall is a fact of these halls, not an estimate: a hall below it refutes
        parts = [at_least(own, mean), *([] if worst is None else [HOLDS if low >= worst else REFUTED])]
        extra = ""
        if key == "dt-goal-safe":
            hover, near = diffs.get((key, HOVER_OPTIMIZER)), diffs.get((key, NEAREST))
            parts += [above(hover), above(near)]
            extra = "".join(f"; minus {name} {with_ci(d, signed)} bps/Hz, {_excludes_zero(d)}"
                            for name, d in (("hovering", hover), ("nearest", near)) if d is not None)
        target = f">= {mean:.1%} of the oracle" + (f", no hall below {worst:.0%}" if worst is not None else "")
        if key == "dt-goal-safe":
            target += ", above hovering with optimised phases and the nearest training hall's plan"
        judged = every(*parts) if len(frac[key]) >= MIN_UNITS else NOT_MEASURED  # a worst of two halls is no verdict
        out.append(f"**{what} {target}**: {judged} "
                   f"({with_ci(own, pct)} of the oracle, worst hall {pct(low)}{extra}).")
    return out


def _claims(summary: dict[str, dict[str, float]], diffs: dict[tuple[str, str], dict[str, float]]) -> list[str]:
    out = []
    for key, what in (("dt-zero-shot", "zero-shot DT"), ("dt-ensemble", "zero-shot DT ensemble (one controller)"),
                      ("dt-zero-shot-safe", "zero-shot DT under the attitude safety layer"),
                      ("dt-ensemble-safe", "zero-shot DT ensemble under the attitude safety layer")):
        own, hover, near = summary.get(key), diffs.get((key, HOVER_OPTIMIZER)), diffs.get((key, NEAREST))
        if own is None or near is None or hover is None:
            continue
        judged = every(at_least(own, ZERO_SHOT_TARGET), above(hover), above(near))
        out.append(f"**{what} >= {ZERO_SHOT_TARGET:.0%} of the oracle, above hovering with "
                   f"optimised phases and above the nearest training hall's expert (paired CIs over layouts "
                   f"excluding zero)**: {judged} ({with_ci(own, pct)} of the oracle; "
                   f"minus hovering {with_ci(hover, signed)} bps/Hz, {_excludes_zero(hover)}; minus nearest "
                   f"{with_ci(near, signed)} bps/Hz, {_excludes_zero(near)}).")
    for ft_key, zs_key, what in (("dt-finetuned", "dt-zero-shot", "fine-tuned DT"),
                                 ("dt-finetuned-safe", "dt-zero-shot-safe",
                                  "fine-tuned DT under the attitude safety layer")):
        ft, zs, gain = summary.get(ft_key), summary.get(zs_key), diffs.get((ft_key, zs_key))
        if ft is None or zs is None:
            continue
        judged = every(at_least(ft, FINETUNED_TARGET), above(gain))
        out.append(f"**{what} >= {FINETUNED_TARGET:.0%} of the oracle and above "
                   f"zero-shot**: {judged} (fine-tuned {with_ci(ft, pct)}; "
                   "fine-tuned minus "
                   f"zero-shot {with_ci(gain, signed) if gain else 'n/a'} bps/Hz).")
    for (a, b), what in ((("dt-zero-shot", "bc"), "return conditioning on demonstrations of one quality (DT minus "
                                                    "behaviour cloning on the same data, model and budget)"),
                         (("dt-zero-shot-safe", "bc-safe"), "return conditioning under the attitude safety layer "
                                                            "(DT minus behaviour cloning, both under the layer)"),
                         (("dt-mixed", "bc-mixed"), "return conditioning on mixed-quality data (DT minus behaviour "
                                                    "cloning, both on the mixed dataset)"),
                         (("dt-zero-shot", "dt-flat"), "the device-set encoder (DT minus the flat encoder, same "
                                                       "data)"),
                         (("dt-goal-safe", "dt-goal-mlp-safe"), "a history of slots is needed (the goal-conditioned "
                                                                "DT minus the goal-conditioned MLP, the same network "
                                                                "on one slot trained for as many steps, told the same "
                                                                "place, both under the layer)"),
                         (("dt-goal-safe", "bc-best-safe"), "the goal-conditioned DT above filtered behaviour cloning "
                                                            "(the best 10% of the demonstrations by return), both "
                                                            "under the layer")):
        d = diffs.get((a, b))
        if d is not None:
            out.append(f"**{what}**: {with_ci(d, signed)} bps/Hz per layout, {_excludes_zero(d)}.")
    return out


def layouts_figure(scores: dict[str, dict[str, float]], labels: dict[str, str], order: Sequence[str],
                   stem: Path, learned: Sequence[str] = ()) -> list[Path]:
    """Every policy of ``order`` but the oracle as a fraction of the oracle in every unseen layout
    (dots, the ``learned`` rows in blue), with the mean over layouts and its 95% CI (bar)."""
    layouts = list(scores)
    keys = [k for k in order if k != ORACLE and all(k in scores[lay] for lay in layouts)]
    fig, ax = plt.subplots(figsize=(5.6, 0.45 * len(keys) + 1.2))
    rng = np.random.default_rng(0)
    for i, k in enumerate(keys):
        f = np.array([scores[lay][k] / scores[lay][ORACLE] for lay in layouts])
        s = over_units(f)
        y = len(keys) - 1 - i
        color = REFERENCE_STYLE.get(k, ("#1f77b4" if k in learned else "#7f7f7f", "-"))[0]
        ax.scatter(f, y + rng.uniform(-0.15, 0.15, f.size), s=12, color=color, alpha=0.7, zorder=3)
        bar = s["n"] >= MIN_UNITS and not math.isnan(s["ci_low"])  # no bar over two halls: too wide to read
        ax.errorbar(s["mean"], y, xerr=[[s["mean"] - s["ci_low"]], [s["ci_high"] - s["mean"]]] if bar else None,
                    fmt="|", color="k", ms=14, capsize=3, zorder=4)
    ax.axvline(1.0, color="k", ls=":", lw=1.0)
    ax.set_yticks(range(len(keys)))
    ax.set_yticklabels([labels[k] for k in reversed(keys)], fontsize=7)
    ax.set_xlabel("fraction of the oracle in the unseen layout")
    ax.set_title(f"deployment track: {len(layouts)} unseen layouts (dots), mean and 95% CI over layouts (bars)",
                 fontsize=8)
    return save_figure(fig, stem)


def scaling_figure(points: dict[int, Sequence[float]], references: dict[str, Sequence[float]],
                   stem: Path) -> list[Path]:
    """Zero-shot fraction of the oracle against the number of training layouts: mean and 95% CI
    over unseen layouts, with reference policies' means as lines."""
    fig, ax = plt.subplots(figsize=(4.4, 3.2))
    ns = sorted(points)
    stats = [over_units(points[n]) for n in ns]
    mean = np.array([s["mean"] for s in stats])
    ax.plot(ns, mean, "o-", color="#ff7f0e", label="zero-shot DT")
    if all(s["n"] >= MIN_UNITS and not math.isnan(s["ci_low"]) for s in stats):
        ax.fill_between(ns, [s["ci_low"] for s in stats], [s["ci_high"] for s in stats], color="#ff7f0e", alpha=0.2,
                        lw=0)
    for label, values in references.items():
        ax.axhline(float(np.mean(values)), color="0.4", ls="--" if "hover" in label else ":", lw=1.0, label=label)
    ax.set_xscale("log", base=2)
    ax.set_xticks(ns)
    ax.set_xticklabels([str(n) for n in ns])
    ax.set_xlabel("training layouts")
    ax.set_ylabel("fraction of the oracle (unseen layouts)")
    ax.legend(fontsize=7, frameon=False)
    return save_figure(fig, stem)
