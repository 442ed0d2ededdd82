"""The paper's first claim, DDPG trains the best expert (Fig. 2, Sec. V), from a comparison's runs.

Lives here: :func:`judge_comparison` (the claim from each algorithm's scores over its seeds),
:func:`comparison_scores` (those scores, final or at a budget), :func:`eval_curves`, and the
claims page's budget table and figure (:func:`budget_table`, :func:`budget_figure`). Not here:
the other claims (:mod:`.claims_tracks`), the table of every claim (:mod:`.claims`).

A cell is judged only where it is complete: each of the four algorithms with at least
:data:`uavris.stats.MIN_UNITS` seeds evaluated at that budget; otherwise it is "not measured"
and says which algorithm lacks seeds.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from uavris.agents.evaluation import evaluate
from uavris.agents.references import HOVER_OPTIMIZER, ORACLE, REFERENCES, ZERO_ACTION, reference_policy
from uavris.config import SystemConfig
from uavris.experiments.display.tables import markdown_table
from uavris.experiments.study.judgement import NOT_TESTED, Judgement
from uavris.experiments.study.stamp import make_stamp, stamped
from uavris.io import atomic_write_text, read_csv
from uavris.presets import EVAL_SEED
from uavris.stats import (
    HOLDS,
    MIN_UNITS,
    NOT_MEASURED,
    NOT_RESOLVED,
    REFUTED,
    over_units,
    paired_difference,
    t_p_value,
    welch_difference,
)

ALGORITHMS = ("ddpg", "ppo", "sac", "td3")  # the paper's comparison (Fig. 2)


def judge_comparison(scores: dict[str, Sequence[float]], track: str = "paper", budget: str = "") -> Judgement:
    """"DDPG is best" from each algorithm's final scores over its seeds (independent runs, so
    Welch's interval): holds where DDPG is above each other algorithm, refuted where another is
    above DDPG, each by a CI excluding zero; the estimate is DDPG minus the best other. Not
    measured unless all four algorithms have at least :data:`MIN_UNITS` seeds."""
    if "ddpg" not in scores or len(scores) < 2:
        return Judgement("ddpg-best", track, NOT_TESTED, text="the comparison has no DDPG run and another")
    seeds = ", ".join(f"{a.upper()} {len(scores.get(a, ()))}" for a in ALGORITHMS)
    others = {a: welch_difference(scores["ddpg"], s) for a, s in scores.items() if a != "ddpg"}
    closest = min(others, key=lambda a: others[a]["mean"])
    short = [a.upper() for a in ALGORITHMS if len(scores.get(a, ())) < MIN_UNITS]
    if short:
        return Judgement("ddpg-best", track, NOT_MEASURED, others[closest]["mean"],
                         n=min(len(scores.get(a, ())) for a in ALGORITHMS), unit="training seeds per algorithm",
                         units="seeds", text=f"DDPG minus the closest algorithm{budget}: fewer than {MIN_UNITS} "
                                             f"seeds of {', '.join(short)} (seeds: {seeds})")
    if any(d["verdict"] == REFUTED for d in others.values()):
        v = REFUTED
    elif all(d["verdict"] == HOLDS for d in others.values()):
        v = HOLDS
    else:
        v = NOT_RESOLVED
    n = min(len(s) for s in scores.values())
    above = ", ".join(f"{a.upper()} {d['mean']:+.2f} [{d['ci_low']:+.2f}, {d['ci_high']:+.2f}]"
                      for a, d in others.items())
    c = others[closest]
    # the p-value of the verdict: "above each" stands only if every test does (the largest p), "another is
    # above" if one does (the smallest p of those that are), neither: the closest algorithm's
    ps = {a: t_p_value(d["mean"], d["ci_low"], d["ci_high"], d["dof"]) for a, d in others.items()}
    p = max(ps.values()) if v == HOLDS else min(ps[a] for a, d in others.items() if d["verdict"] == REFUTED) \
        if v == REFUTED else ps[closest]
    return Judgement("ddpg-best", track, v, c["mean"], c["ci_low"], c["ci_high"], n, "training seeds per algorithm",
                     "seeds", f"DDPG minus each algorithm{budget} (seeds: {seeds}; Welch): {above}",
                     p)


def comparison_scores(cdir: Path, steps: int | None = None) -> dict[str, list[float]]:
    """Each algorithm's scores over its seeds in a comparison: the final evaluations
    (``final_per_run.csv``), or with ``steps`` the first periodic evaluation at or after that many environment
    steps (a run of N steps evaluated at B < N is the run of budget B: the schedules are constant)."""
    scores: dict[str, list[float]] = {}
    if steps is None:
        for r in read_csv(cdir / "final_per_run.csv"):
            scores.setdefault(r["algo"], []).append(float(r["final_eval_mean"]))
        return scores
    for algo, curves in eval_curves(cdir).items():
        for x, y in curves:
            at = y[x >= steps]
            if at.size:  # the first evaluation at or after the budget (PPO evaluates at the end of a rollout)
                scores.setdefault(algo, []).append(float(at[0]))
    return scores


def eval_curves(cdir: Path) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """Each algorithm's runs in a comparison, in seed order: their periodic evaluations
    (environment steps, mean over the episodes); a run without any yet is left out."""
    from uavris.experiments.training.train_expert import load_run_config

    runs: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for run in sorted((Path(cdir) / "runs").iterdir(), key=lambda r: load_run_config(r).seed):
        rows = read_csv(run / "evals.csv") if (run / "evals.csv").exists() else []
        if rows:
            runs.setdefault(load_run_config(run).algo, []).append(
                (np.array([float(r["env_steps"]) for r in rows]), np.array([float(r["mean"]) for r in rows])))
    return runs


def fig2_zero_action() -> dict[str, float]:
    """The zero action in ``fig2`` of the paper's system on the comparison's 32 episodes: its mean
    and the Student-t 95% interval of that mean over the episodes (``ci_low``, ``ci_high``)."""
    return over_units(evaluate(reference_policy(ZERO_ACTION, SystemConfig()), SystemConfig(), "fig2", 32,
                               EVAL_SEED).avg_sum_rate)


def budget_table(comparisons: Sequence[tuple[Path, Sequence[int]]], zero: dict[str, float]) -> list[str]:
    """Each algorithm of each comparison at each of its budgets: its seeds' mean with the Student-t
    95% CI over seeds, each seed's score, and its difference from doing nothing (``zero``, the zero
    action's mean on the same episodes) with that CI (markdown lines). Descriptive, not a verdict:
    the zero action's mean on these episodes is taken as fixed (its own interval over the episodes
    is stated above the table, not in the column) and the cells are not among the claims' (not
    corrected for their number), so the column reads "above" or "below" only where the interval
    over seeds excludes it, "-" otherwise or with fewer than :data:`MIN_UNITS` seeds."""
    rows = []
    for cdir, budgets in comparisons:
        for steps in budgets:
            for algo, scores in comparison_scores(Path(cdir), steps).items():
                d = paired_difference(scores, [zero["mean"]] * len(scores))
                ci = "" if math.isnan(d["ci_low"]) else f"[{d['ci_low'] + zero['mean']:.2f}, " \
                                                          f"{d['ci_high'] + zero['mean']:.2f}]"
                diff = f"{d['mean']:+.2f}" + ("" if math.isnan(d["ci_low"]) else
                                               f" [{d['ci_low']:+.2f}, {d['ci_high']:+.2f}]")
                side = {HOLDS: "above", REFUTED: "below"}.get(d["verdict"], "-") if len(scores) >= MIN_UNITS else "-"
                rows.append((f"{steps:,}", algo.upper(), len(scores), f"{np.mean(scores):.2f}", ci,
                             " ".join(f"{x:.2f}" for x in scores), diff, side))
    return [f"The zero action (doing nothing) in `fig2`: {zero['mean']:.2f} bps/Hz on the same 32 episodes (95% CI "
            f"over them [{zero['ci_low']:.2f}, {zero['ci_high']:.2f}]). The last two columns describe, they do not "
            "judge: the zero action's mean is taken as fixed and the cells are not corrected for their number.", "",
            *markdown_table(("env steps", "algorithm", "seeds", "mean", "95% CI (t, over seeds)", "each seed",
                             "minus the zero action [95% CI over seeds]", "CI beside the zero action's mean"),
                            rows, "lrrrllll")]


def budget_figure(cdir: Path, stem: Path, zero: float) -> list[Path]:
    """The periodic evaluations of a comparison's runs against environment steps (log axis):
    each seed thin, the mean of the seeds that reached a step thick, beside the zero action
    (``zero``, on the same episodes) (PNG and PDF)."""
    from uavris.experiments.display.plots import plt, reference_lines, save_figure

    fig, ax = plt.subplots(figsize=(5.4, 3.6))
    # the untrained policy's evaluation at step 0 has no place on a log axis
    runs = {algo: [(x[x > 0], y[x > 0]) for x, y in curves] for algo, curves in eval_curves(cdir).items()}
    for i, (algo, curves) in enumerate(sorted(runs.items())):
        for x, y in curves:
            ax.plot(x, y, "-", color=f"C{i}", lw=0.6, alpha=0.5)
        longest = max(curves, key=lambda c: c[0].size)[0]
        mean = [np.mean([y[j] for x, y in curves if x.size > j]) for j in range(longest.size)]
        seeds = f"{len(curves)} seed{'s' * (len(curves) != 1)}"
        ax.plot(longest, mean, "-", color=f"C{i}", lw=1.8, label=f"{algo.upper()} (mean of {seeds}; thin: each)")
    # hovering with optimised phases (36 bps/Hz) and the oracle (43) are far above: named in the page, not drawn
    reference_lines(ax, {ZERO_ACTION: (REFERENCES[ZERO_ACTION].label, zero)})
    ax.set_xscale("log")
    ticks = [t for t in (12_500, 25_000, 50_000, 100_000, 200_000, 400_000, 800_000, 1_600_000)
             if t <= max(c[0].max() for cs in runs.values() for c in cs) * 1.01]
    ax.set_xticks(ticks, [f"{t / 1000:g}k" for t in ticks])
    ax.xaxis.set_minor_formatter(plt.NullFormatter())
    ax.set_xlabel("environment steps of training")
    ax.set_ylabel("average sum rate, 32 episodes (bps/Hz)")
    ax.set_title("fig2: the periodic evaluations at every budget", fontsize=9)
    ax.legend(fontsize=6, frameon=False, loc="lower right")
    return save_figure(fig, stem)


def fig2_references() -> dict[str, dict[str, float]]:
    """Hovering with optimised phases and the oracle in ``fig2`` of the paper's system on the
    comparison's 32 episodes: mean and 95% CI over the episodes, by reference name."""
    return {name: over_units(evaluate(reference_policy(name, SystemConfig()), SystemConfig(), "fig2", 32,
                                      EVAL_SEED).avg_sum_rate) for name in (HOVER_OPTIMIZER, ORACLE)}


def write_budget_page(comparisons: Sequence[tuple[Path, Sequence[int]]], page: Path, preset: str,
                      made_by: Sequence[str] = ()) -> list[Path]:
    """The budget page (``docs/results/budget.md``, stamped): each comparison's algorithms at
    each of its budgets (:func:`budget_table`) beside the zero action, hovering with optimised
    phases and the oracle on the same episodes, the first comparison's periodic evaluations
    (:func:`budget_figure`) and DDPG against each algorithm at every budget where it ran, as
    estimates (the claims page judges them, corrected with its other cells). ``made_by``: the
    commands that made the comparisons. Returns the files written."""
    zero = fig2_zero_action()
    refs = fig2_references()
    figs = budget_figure(comparisons[-1][0], page.with_suffix(""), zero["mean"])
    budgets = sorted({b for _, bs in comparisons for b in bs})
    lines = ["# The training budget: Fig. 2 at " + ", ".join(f"{b:,}" for b in budgets) + " environment steps", "",
             "Each algorithm of the paper's comparison trained in `fig2` for longer than the study's budget and "
             "scored at each budget by its first periodic evaluation there (the study's 32 episodes; a run of N steps "
             "evaluated at B < N is the run of budget B: every schedule of the preset is constant).", "",
             *(["Made by:", "", "```bash", *made_by, "```", ""] if made_by else []),
             f"![budget]({figs[0].name})", "", *budget_table(comparisons, zero), "",
             "On the same episodes: " + "; ".join(
                 f"{REFERENCES[k].label} {refs[k]['mean']:.2f} [{refs[k]['ci_low']:.2f}, {refs[k]['ci_high']:.2f}]"
                 for k in (HOVER_OPTIMIZER, ORACLE)) + " bps/Hz (95% CI over the episodes).", "",
             "DDPG minus each other algorithm (Welch's 95% CI over seeds; estimates: the claims page judges "
             "\"DDPG trains the best expert\", corrected for its other cells):", ""]
    for cdir, bs in comparisons:
        for steps in bs:
            scores = comparison_scores(Path(cdir), steps)
            if "ddpg" not in scores:
                continue
            parts = []
            for algo, s in sorted(scores.items()):
                if algo == "ddpg":
                    continue
                d = welch_difference(scores["ddpg"], s)
                ci = "" if math.isnan(d["ci_low"]) else f" [{d['ci_low']:+.2f}, {d['ci_high']:+.2f}]"
                parts.append(f"{algo.upper()} {d['mean']:+.2f}{ci}")
            seeds = ", ".join(f"{a.upper()} {len(v)}" for a, v in sorted(scores.items()))
            lines.append(f"- {steps:,} steps ({Path(cdir).name}; seeds: {seeds}): " + "; ".join(parts) + ".")
    stamp = make_stamp("budget", [str(c) for c, _ in comparisons], preset, " && ".join(made_by))
    atomic_write_text(page, stamped(stamp, "\n".join(lines) + "\n"))
    return [page, *figs]
