"""Why a learned row falls short of the oracle in a new hall: its place, its attitude, blocked devices.

Lives here: :func:`decomposition_section`, the deployment report's table of every row's gap to
the oracle split into place and attitude, with the share of its slots in which a device is
behind the RIS plane, over halls and per hall, and the claim that no learned row blocks a
device; :func:`value_section`, how well the learned value knows the place (its accuracy);
:func:`counts_section`, the rows per device count.
Not here: the numbers, which the evaluation stages record
(:func:`uavris.experiments.study.workers.evaluate_rows`), and the rest of the deployment
section (:mod:`.deployment`).

Definitions (docs/study.md section 2), with R the planner's expected sum rate with
optimised phases at a pose, on the fresh draws a plan states its numbers with
(:func:`uavris.agents.oracle.objective.assessed_rate`: every pose on the same draws, none of
them the draws the plan was chosen on, so the target's R is not biased upwards):

- **place gap** = R(the oracle's target, level) - R(the row's median end position, level):
  what the place it flew to costs, whatever its attitude;
- **attitude gap** = R(that position, level) - R(that position, the row's median end
  attitude): what its tilt costs there; large when a device is behind the plane, negative
  where a tilt helps (the oracle's own, by 1-2%);
- **blocked** = the share of the row's slots (all episodes) in which at least one device is
  behind the RIS plane (docs/model.md section 3: every pair with it is lost).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from uavris.agents.references import HOVER_OPTIMIZER, ORACLE, ZERO_ACTION
from uavris.experiments.display.tables import counted, markdown_table, pct, signed, with_ci
from uavris.experiments.study.report.deployment import (
    ORACLE_SAFE,
    every,
    layout_scores,
    row_facts,
    row_labels,
    row_order,
)
from uavris.stats import MIN_UNITS, NOT_MEASURED, over_units, verdict

BLOCKING_LIMIT = 0.01  # no learned row blocks a device in more than this share of its slots (docs/study.md, section 2)


def decomposition_section(results: dict[str, dict[str, Any]], labels: dict[str, str],
                          where: str = "deployment track") -> tuple[list[str], list[str]]:
    """The decomposition's lines and its claim (headed ``where``), from the evaluation stages'
    ``results`` (``{layout: {policy: summary}}``): every learned row (the data curve's aside) and
    the oracle; nothing when the summaries hold no decomposition."""
    layouts = list(results)
    if not layouts or "end_rate_level" not in next(iter(results.values()))[ORACLE]:
        return [], []
    level, own = layout_scores(results, "end_rate_level"), layout_scores(results, "end_rate_own")
    blocked = layout_scores(results, "behind_share")
    target = {lay: float(results[lay][ORACLE]["plan_rate_level"]) for lay in layouts}
    facts = row_facts(results)
    learned = [k for k in row_order(results)
               if k in facts and facts[k]["kind"] == "learned" and facts[k]["training_halls"] is None]
    keys = [k for k in (*learned, ORACLE, ORACLE_SAFE) if all(k in level[lay] for lay in layouts)]
    place = {k: [target[lay] - level[lay][k] for lay in layouts] for k in keys}
    tilt = {k: [level[lay][k] - own[lay][k] for lay in layouts] for k in keys}
    block = {k: [blocked[lay][k] for lay in layouts] for k in keys}
    lines = ["", "### Where the gap to the oracle is: place, attitude, blocked devices", "",
             "R: the expected sum rate with optimised phases at a pose (the planner's). Place gap: R at the oracle's "
             "target minus R at the row's median end position, both level; attitude gap: R there, level, minus R there "
             "with the row's median end attitude; blocked: the share of slots with a device behind the RIS plane "
             "(every pair with it is lost). Means over layouts; a learned row is the mean of its seeds' models.", ""]
    lines += markdown_table(
        ("policy", "place gap (bps/Hz)", "attitude gap (bps/Hz)", "blocked, mean", "blocked, worst layout"),
        [(labels[k], signed(float(np.mean(place[k]))), signed(float(np.mean(tilt[k]))),
          pct(float(np.mean(block[k]))), pct(float(np.max(block[k])))) for k in keys], "lrrrr")
    per_hall = [k for k in ("dt-zero-shot", "dt-zero-shot-safe") if k in keys]
    if per_hall:
        lines += ["", "Per layout (place gap / attitude gap in bps/Hz, blocked slots):", ""]
        lines += markdown_table(("layout", *(labels[k] for k in per_hall)), [
            (lay, *(f"{signed(place[k][i])} / {signed(tilt[k][i])}, {pct(block[k][i])}" for k in per_hall))
            for i, lay in enumerate(layouts)], "l" + "r" * len(per_hall))
    learned = [k for k in keys if k in learned]
    worst = max(learned, key=lambda k: float(np.mean(block[k])), default=None)
    if worst is None:
        return lines, []
    over = [k for k in learned if float(np.mean(block[k])) > BLOCKING_LIMIT]
    # by the CI rule on the limit minus each row's share over halls: refuted where one row is over it
    verdicts = [verdict(s["ci_low"], s["ci_high"]) for s in (over_units(BLOCKING_LIMIT - np.asarray(block[k]))
                                                              for k in learned)]
    judged = NOT_MEASURED if len(layouts) < MIN_UNITS else every(*verdicts)
    claim = (f"- {where}: **no learned row blocks a device in more than {BLOCKING_LIMIT:.0%} of its slots "
             f"(each row's share over halls, its 95% CI below the limit)**: {judged} (most: {labels[worst]}, "
             f"{pct(float(np.mean(block[worst])))} of its slots on average"
             + (f"; above the limit: {', '.join(labels[k] for k in over)}" if over else "") + ").")
    return lines, [claim]


def value_section(results: dict[str, dict[str, Any]], first_seed: int = 0) -> list[str]:
    """The learned value's accuracy in the unseen halls (docs/places.md), a line per fit of ``V`` (one
    per pre-training seed), from the rows that record it
    (:func:`uavris.experiments.study.workers.value_accuracy`; a fit's rows record the same): the
    rank correlation of ``V`` with ``R`` over the poses the oracle valued, and ``R`` at ``V``'s
    argmax against ``R`` at the oracle's target (both level, on the same fresh draws), mean and
    worst hall. A fit is named by its pre-training seed, the study's ``first_seed`` plus its own."""
    layouts = list(results)
    keys = [k for k in (next(iter(results.values())) if layouts else {})
            if all("value_rank_correlation" in results[lay].get(k, {}) for lay in layouts)]
    by_seed: dict[int, str] = {}
    for k in keys:
        by_seed.setdefault(int(results[layouts[0]][k].get("seed") or 0), k)
    if not by_seed:
        return []
    rows = []
    for seed, k in sorted(by_seed.items()):
        # undefined over fewer than three poses: NaN, stored as None in a stage's record
        rho = [float(np.nan if (r := results[lay][k]["value_rank_correlation"]) is None else r) for lay in layouts]
        share = [float(results[lay][k]["value_target_rate_level"]) / float(results[lay][ORACLE]["plan_rate_level"])
                 for lay in layouts]
        rows.append((f"V of pre-training seed {first_seed + seed}" if len(by_seed) > 1 else "V", f"{np.mean(rho):.3f}",
                     f"{np.min(rho):.3f}", pct(float(np.mean(share))), pct(float(np.min(share)))))
    return ["", "### The learned value of a pose in the unseen halls", "",
            "Rank correlation (Spearman) of V with R over the level poses the oracle valued in each hall; R at V's "
            "argmax as a fraction of R at the oracle's target (both level, on the same fresh draws); a line per fit "
            "of V.", "",
            *markdown_table(("learned value", "rank correlation, mean", "worst hall",
                             "R at its argmax / oracle's, mean", "worst hall"), rows, "lrrrr")]


COUNT_ROWS = ("dt-goal-safe", "plan-learned", "plan-deployed", "dt-zero-shot-safe", "bc-safe", HOVER_OPTIMIZER,
              ZERO_ACTION)
PLAN_ROWS = (ORACLE, "plan-learned", "plan-deployed")  # the plans a hall's best plan found is the best of
ABOVE_ORACLE = 1.005  # no learned or deployed-place row above this fraction of the oracle by its CI (docs/places.md)


def count_label(devices: int, other: bool) -> str:
    """A column of :func:`counts_section`: halls of ``devices`` devices, of the study's generator or another's."""
    return f"{devices} devices" + (", another generator" if other else "")


def halls_below_hovering(results: dict[str, dict[str, Any]], episodes: Callable[[str, str], np.ndarray],
                         variant: str = "dt-goal-safe") -> str:
    """"B of N": how many of the N halls of ``results`` with row ``variant`` have a pre-training
    seed of it below hovering with optimised phases by its paired 95% CI over the evaluation
    episodes (``episodes(layout, row)``: a row's per-episode rates); "not measured" over fewer
    than :data:`~uavris.stats.MIN_UNITS` episodes."""
    below = with_row = 0
    for lay, res in results.items():
        seeds = [k for k, v in res.items() if v.get("variant") == variant]
        if not seeds or HOVER_OPTIMIZER not in res:
            continue
        hover = episodes(lay, HOVER_OPTIMIZER)
        if hover.size < MIN_UNITS:
            return f"{NOT_MEASURED} ({counted(hover.size, 'episode')})"
        with_row += 1
        below += any(over_units(episodes(lay, k) - hover)["ci_high"] < 0 for k in seeds)
    return f"{below} of {with_row}"


def counts_section(groups: dict[tuple[int, bool], dict[str, dict[str, Any]]], bounds: dict[str, float],
                   episodes: Callable[[str, str], np.ndarray] | None = None) -> list[str]:
    """Any number of devices (docs/places.md): per column (``groups``: ``{(devices, another
    generator's): {layout: results}}``, shown in order of devices, the study's generator first),
    each row's fraction of the oracle, mean [95% CI over halls], the place row minus hovering
    with optimised phases (paired, bps/Hz), the halls where a seed of the goal-conditioned DT is
    below hovering (:func:`halls_below_hovering`), the rows above :data:`ABOVE_ORACLE` of the
    oracle, and the best plan found in each hall as a fraction of the bound no controller can
    beat (``bounds``: its mean over the hall's evaluation episodes,
    :func:`uavris.agents.oracle.bound.episode_bounds`)."""
    scores = {count_label(*c): layout_scores(groups[c]) for c in sorted(groups) if groups[c]}
    by_label = {count_label(*c): g for c, g in groups.items()}
    if len(scores) < 2:
        return []
    keys = [r for r in COUNT_ROWS if all(r in s[lay] for s in scores.values() for lay in s)]
    labels = row_labels(next(g for g in by_label.values() if g))

    def fractions(c: str, r: str) -> list[float]:
        return [scores[c][lay][r] / scores[c][lay][ORACLE] for lay in scores[c]]

    rows = [(labels[r], *(with_ci(over_units(fractions(c, r)), pct) for c in scores)) for r in keys]
    if "dt-goal-safe" in keys:
        rows.append(("place row minus hovering with optimised phases (bps/Hz)",
                     *(with_ci(over_units([scores[c][lay]["dt-goal-safe"] - scores[c][lay][HOVER_OPTIMIZER]
                                           for lay in scores[c]]), signed) for c in scores)))
    rows.append(("oracle (bps/Hz)", *(f"{np.mean([scores[c][lay][ORACLE] for lay in scores[c]]):.2f}"
                                       for c in scores)))
    if all(lay in bounds for s in scores.values() for lay in s):
        # the best plan of each hall: of the oracle and of each seed's learned places (not their mean over seeds)
        rows.append(("best plan found / the bound no controller can beat",
                     *(with_ci(over_units([max(float(v["mean"]) for v in by_label[c][lay].values()
                                               if v.get("variant") in PLAN_ROWS) / bounds[lay]
                                           for lay in scores[c]]), pct) for c in scores)))
    if episodes is not None and "dt-goal-safe" in keys:
        rows.append(("halls where a seed of the goal-conditioned DT is below hovering with optimised phases (paired "
                     "95% CI over episodes)", *(halls_below_hovering(by_label[c], episodes) for c in scores)))
    learned = [r for r in keys if r not in (HOVER_OPTIMIZER, ZERO_ACTION)]
    cells = {(c, r): over_units(fractions(c, r)) for c in scores for r in learned}

    def named(test: Callable[[dict[str, float]], bool]) -> str:
        found = [f"{labels[r]} with {c} ({with_ci(s, pct)})" for (c, r), s in cells.items() if test(s)]
        return "; ".join(found) if found else "none"

    measured = {k for k, s in cells.items() if s["n"] >= MIN_UNITS}
    above = named(lambda s: s["n"] >= MIN_UNITS and s["ci_low"] > ABOVE_ORACLE)
    reaching = named(lambda s: s["n"] >= MIN_UNITS and s["ci_low"] <= ABOVE_ORACLE < s["ci_high"])
    few = named(lambda s: s["n"] < MIN_UNITS and s["mean"] > ABOVE_ORACLE)
    return ["", "### Any number of devices", "",
            "Fraction of the oracle, mean [95% CI over halls], in unseen halls of each device count (halls per "
            "column: " + ", ".join(f"{c}: {len(scores[c])}" for c in scores) + "). The bound (docs/model.md, "
            "\"The bound\") is loose: the best plan's fraction of it says how much room any controller could "
            "have left, not how good the plan is.", "",
            *markdown_table(("policy", *scores), rows, "l" + "r" * len(scores)), "",
            f"Learned or deployed-place rows above {pct(ABOVE_ORACLE)} of the oracle by their 95% CI over halls (a "
            f"ceiling that gives way): {above}. Not resolved (the CI reaches above {pct(ABOVE_ORACLE)}): {reaching}."
            + (f" Over fewer than {MIN_UNITS} halls, not measured, above it on average: {few}." if len(measured)
               < len(cells) else "")]
