"""Algorithm comparison (paper Fig. 2): DDPG, PPO, SAC and TD3 over seeds.

Lives here: :func:`compare_algorithms` (train every run, then :func:`write_comparison`),
:func:`select_expert` (the algorithm the study's experts use), :func:`learning_curve_summary`
and :func:`render_report`. Not here: training one run (:mod:`.train_expert`), the figure
(:func:`uavris.experiments.display.plots.learning_curves`) and the statistics (:mod:`uavris.stats`).

Outputs in ``OUT``: ``runs/ALGO-sSEED`` (one training run each, resumable),
``learning_curves.{png,pdf}``, ``final_performance.csv``, ``final_per_run.csv``,
``summary.json``, ``report.md``.
"""

from __future__ import annotations

import dataclasses
import os
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import yaml

from uavris import runs
from uavris.agents.evaluation import evaluate
from uavris.agents.experts import ALGORITHMS, check_algorithm, hyperparams_for
from uavris.agents.references import HOVER_OPTIMIZER, ORACLE, REFERENCES, ZERO_ACTION, reference_policy
from uavris.config import SystemConfig, scenario_at
from uavris.errors import UavrisError
from uavris.experiments.display.plots import learning_curves
from uavris.experiments.display.progress import progress_bar
from uavris.experiments.display.tables import MISSING, counted, interval, markdown_table, num, pct
from uavris.experiments.engine.costs import train_cost
from uavris.experiments.engine.jobs import run_jobs
from uavris.experiments.engine.worker import Job, JobResult
from uavris.experiments.training.train_expert import TrainConfig, train_job
from uavris.io import atomic_write_text, read_csv, write_csv, write_json
from uavris.presets import PRESETS
from uavris.stats import summarize, t_band, versus

# The paper's converged average sum rates from [15, 20, 4.5], bps/Hz (docs/model.md).
PAPER_FIG2 = {"ddpg": 29.5, "ppo": 25.0, "td3": 20.5, "sac": 17.0}
# Reference rows of every comparison, in table order (uavris.agents.references).
COMPARISON_REFERENCES = (ZERO_ACTION, "random", "hover-random-phases", "hover-aligned", HOVER_OPTIMIZER, ORACLE)
FIGURE_REFERENCES = (ZERO_ACTION, HOVER_OPTIMIZER, ORACLE)


def _overlap(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return a["iqm_ci_low"] <= b["iqm_ci_high"] and b["iqm_ci_low"] <= a["iqm_ci_high"]


def expert_choice(rows: Sequence[dict[str, Any]], by_cost: bool = True) -> dict[str, Any]:
    """The expert algorithm, chosen as the paper's Sec. IV-B does (the DRL row with the largest
    IQM of the final evaluations over seeds), with one rule for a comparison that has not
    separated the algorithms (docs/model.md, departures): among those whose 95% CI of the IQM
    overlaps the winner's, the one with the least measured training time per env step
    (``s_per_step``). A clear winner is taken as it is; so is the winner when a tied
    algorithm's time is unknown, or with ``by_cost`` off. Returns ``expert`` (lower-case),
    ``winner``, ``tied`` and the sentence the report prints (``text``)."""
    drl = [r for r in rows if r["kind"] == "DRL"]
    if not drl:
        raise UavrisError("the comparison has no finished DRL run to choose an expert algorithm from")
    winner = max(drl, key=lambda r: r["iqm"])
    tied = [r for r in drl if r is winner or _overlap(r, winner)]
    name = str(winner["policy"])
    timed = all(np.isfinite(r.get("s_per_step", float("nan"))) for r in tied)
    if len(tied) == 1:
        text = f"{name} has the largest IQM and its 95% CI overlaps no other algorithm's: {name} is chosen."
        chosen = winner
    elif not by_cost or not timed:
        others = ", ".join(str(r["policy"]) for r in tied if r is not winner)
        why = "the cost rule is switched off" if not by_cost else "their training times were not measured"
        text = f"{name} has the largest IQM, tied within the 95% CIs with {others}; {name} is chosen ({why})."
        chosen = winner
    else:
        chosen = min(tied, key=lambda r: (r["s_per_step"], -r["iqm"]))
        names = [str(r["policy"]) for r in sorted(tied, key=lambda r: -r["iqm"])]
        times = ", ".join(f"{r['policy']} {r['s_per_step'] * 1e3:.2f}" for r in sorted(tied, key=lambda r: -r["iqm"]))
        text = (f"{', '.join(names[:-1])} and {names[-1]} are tied within their 95% CIs of the IQM; "
                f"{chosen['policy']} is chosen as the cheaper (ms per env step: {times}).")
    return {"expert": str(chosen["policy"]).lower(), "winner": name.lower(),
            "tied": [str(r["policy"]).lower() for r in tied], "by_cost": by_cost, "text": text}


def select_expert(rows: Sequence[dict[str, Any]], by_cost: bool = True) -> str:
    """The expert algorithm of :func:`expert_choice`, lower-case."""
    return expert_choice(rows, by_cost)["expert"]


def episode_rates(run_dir: Path) -> np.ndarray:
    """Average sum rate of every training episode of a run, in order."""
    return np.array([float(r["avg_sum_rate"]) for r in read_csv(run_dir / "episodes.csv")])


def _smoothed(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Moving average over 5% of the episodes; x is the episode count at each window's end."""
    w = max(1, y.size // 20)
    return np.arange(w, y.size + 1), np.convolve(y, np.ones(w) / w, mode="valid")


def learning_curve_summary(series: Sequence[np.ndarray], points: int = 100) -> tuple[np.ndarray, ...] | None:
    """(episodes, mean, low, high) across seeds, on the episodes all seeds reached."""
    raw = [_smoothed(y) for y in series if y.size]
    if not raw:
        return None
    end = min(x[-1] for x, _ in raw)
    start = max(x[0] for x, _ in raw)
    grid = np.unique(np.linspace(start, end, points).round().astype(int))
    curves = np.stack([np.interp(grid, x, y) for x, y in raw])
    mean, lo, hi = t_band(curves)
    return grid, mean, lo, hi


def default_compare_dir(preset: str) -> Path:
    """Where ``compare-algorithms`` writes without ``--out``."""
    return Path(f"runs/compare-{preset}")


def compare_algorithms(preset: str = "quick", seeds: int = 5, workers: int = 2, out: Path | None = None,
                       algos: Sequence[str] = ALGORITHMS, scenario: str = "fig2",
                       eval_episodes: int | None = None, backend: str = "local",
                       ray_address: str | None = None, progress: bool = True,
                       device: str = "cpu", system: SystemConfig | None = None,
                       start: tuple[float, float, float] | None = None,
                       submit: Callable[[list[Job]], list[JobResult]] | None = None,
                       steps: int | None = None, eval_every: int | None = None) -> Path:
    """Train ``algos`` x ``seeds`` in ``scenario`` (starting at ``start``, a layout's, when
    given) of ``system`` (default the paper's) for ``steps`` environment steps each (default
    the preset's training length) and write the comparison into ``out``; returns
    the report path. Jobs go to ``submit`` when given (a study's shared job runner), else to
    a pool of ``workers`` of their own."""
    if preset not in PRESETS:
        raise UavrisError(f"unknown preset {preset!r}; choose one of {', '.join(PRESETS)}")
    for flag, value in (("--seeds", seeds), ("--workers", workers), ("--eval-episodes", eval_episodes),
                        ("--steps", steps), ("--eval-every", eval_every)):
        if value is not None and value < 1:
            raise UavrisError(f"{flag} must be >= 1, got {value}")
    for a in algos:
        check_algorithm(a)
    system = (system or SystemConfig()).check()
    scenario_at(scenario, start).validate_for(system)
    out = Path(out or default_compare_dir(preset))
    if ray_address:  # a cluster's nodes write the runs where the driver has them: the same absolute paths
        out = Path(os.path.abspath(out))
    n_eval = eval_episodes or (100 if preset == "paper" else 32)
    cfgs = comparison_configs(preset, seeds, algos, scenario, n_eval, system, start, steps, eval_every)
    jobs = [Job(f"{a}-s{s}", train_job, (cfg.to_dict(), str(out / "runs" / f"{a}-s{s}"), device),
                out / "logs" / f"{a}-s{s}.log", train_cost(cfg), writes=(out / "runs" / f"{a}-s{s}",))
            for (a, s), cfg in cfgs.items()]
    t0 = time.perf_counter()
    bar = progress_bar(len(jobs), "compare-algorithms", "job", progress)
    bar.update(sum(runs.is_finished(Path(j.args[1])) for j in jobs))
    todo = [j for j in jobs if not runs.is_finished(Path(j.args[1]))]

    def done(res: JobResult) -> None:
        bar.update(1)
        status = "done" if res.ok else f"FAILED ({res.error}); log: {res.log}"
        bar.write(f"  {res.name}: {status}")

    if submit is not None:
        results = submit(todo)
    else:
        results = run_jobs(todo, workers, done, backend=backend, ray_address=ray_address)
    bar.close()
    failures = [r for r in results if not r.ok]
    report = write_comparison(out, cfgs, scenario, n_eval, time.perf_counter() - t0, failures)
    if failures:
        raise UavrisError(f"{len(failures)} of {len(jobs)} training jobs failed (see {report}); "
                          f"first: {failures[0].name}, log {failures[0].log}")
    return report


def comparison_configs(preset: str, seeds: int, algos: Sequence[str], scenario: str, eval_episodes: int,
                       system: SystemConfig, start: tuple[float, float, float] | None = None,
                       steps: int | None = None, eval_every: int | None = None
                       ) -> dict[tuple[str, int], TrainConfig]:
    """The training run of every (algorithm, seed) of a comparison, ``steps`` environment steps
    each and evaluated every ``eval_every`` (None: the preset's)."""
    length = {} if steps is None else {"total_steps": steps}
    if eval_every is not None:
        length["eval_every"] = eval_every
    return {(a, s): TrainConfig(algo=a, scenario=scenario, seed=s, preset=preset, eval_episodes=eval_episodes,
                                system=system, start=start, **length)
            for a in algos for s in range(seeds)}


def write_comparison(out: Path, cfgs: dict[tuple[str, int], TrainConfig], scenario: str, n_eval: int,
                     wall_s: float, failures: Sequence[JobResult] = ()) -> Path:
    """Figures, table and report from the finished runs under ``out/runs``."""
    algos = list(dict.fromkeys(a for a, _ in cfgs))
    any_cfg = next(iter(cfgs.values()))
    eval_seed = any_cfg.eval_seed
    curves, rows, per_run = {}, [], []
    for a in algos:
        dirs = [out / "runs" / f"{a}-s{s}" for (b, s) in cfgs if b == a]
        finished = [d for d in dirs if runs.is_finished(d)]
        if not finished:
            continue
        scores = [runs.read_done(d)["final_eval"]["mean"] for d in finished]
        per_run += [(a, d.name, sc) for d, sc in zip(finished, scores)]
        timings = [runs.read_timing(d) for d in finished]
        per_step = [t["wall_clock_s"] / t["env_steps"] for t in timings if t.get("env_steps")]
        series = [episode_rates(d) for d in finished]
        summ = learning_curve_summary(series)
        if summ is not None:
            curves[a] = summ
        last = [float(np.mean(y[-max(1, y.size // 10):])) for y in series if y.size]
        s = summarize(scores)
        rows.append({"policy": a.upper(), "kind": "DRL", **s, "train_last10pct": float(np.mean(last)) if last else
                     float("nan"), "paper": PAPER_FIG2.get(a, float("nan")),
                     # training time per env step, mean over the seeds (the expert choice's tie-break)
                     "s_per_step": float(np.mean(per_step)) if len(per_step) == len(finished) else float("nan")})
    for name in COMPARISON_REFERENCES:
        res = evaluate(reference_policy(name, any_cfg.system), any_cfg.system, any_cfg.resolved_scenario, n_eval,
                       eval_seed)
        s = summarize(res.avg_sum_rate)
        rows.append({"policy": name, "kind": "oracle" if name == ORACLE else "baseline", **s,
                     "train_last10pct": float("nan"), "paper": float("nan"), "s_per_step": float("nan")})
    by_name = {r["policy"]: r for r in rows}
    oracle_mean, zero = by_name[ORACLE]["mean"], by_name[ZERO_ACTION]["mean"]
    for r in rows:
        r["fraction_of_oracle"] = r["mean"] / oracle_mean if oracle_mean > 0 else float("nan")
        r["vs_zero_action"] = "-" if r["policy"] == ZERO_ACTION else versus(r["mean_ci_low"], r["mean_ci_high"], zero)
    header = list(rows[0].keys()) if rows else []
    write_csv(out / "final_performance.csv", header, [[r[h] for h in header] for r in rows])
    write_csv(out / "final_per_run.csv", ("algo", "run", "final_eval_mean"), per_run)
    figs = []
    if curves:
        refs = {name: (REFERENCES[name].label, by_name[name]["mean"]) for name in FIGURE_REFERENCES}
        figs = learning_curves(curves, out / "learning_curves",
                               f"{scenario} {any_cfg.resolved_scenario.start}: mean over seeds,\n"
                               "band: its 95% t interval over seeds, from 0",
                               PAPER_FIG2 if scenario == "fig2" else None, refs)
    choice = expert_choice(rows) if any(r["kind"] == "DRL" for r in rows) else None
    write_json(out / "summary.json", {"rows": rows, "expert": choice and choice["expert"], "expert_choice": choice,
                                      "failures": [dataclasses.asdict(f) | {"log": str(f.log), "value": None}
                                                   for f in failures]})
    write_json(out / runs.TIMING_FILE, {"wall_clock_s": wall_s})  # beside the results, not in them
    report = out / "report.md"
    atomic_write_text(report, render_report(rows, cfgs, scenario, n_eval, wall_s, figs, failures))
    return report


FIG2_HEADER = ("policy", "n", "mean", "95% CI (mean)", "IQM", "95% CI (IQM)", "vs zero action", "fraction of oracle",
               "training, last 10% of episodes", "paper")


def fig2_table(rows: Sequence[dict[str, Any]]) -> list[str]:
    """The comparison's table (paper Fig. 2's final scores) as Markdown lines, one row per
    algorithm and reference, with the paper's value where it gives one: the comparison's
    report and the study's report print this same table."""
    return markdown_table(FIG2_HEADER, [
        (r["policy"], r["n"], num(r["mean"]), interval(r["mean_ci_low"], r["mean_ci_high"]), num(r["iqm"]),
         interval(r["iqm_ci_low"], r["iqm_ci_high"]), r.get("vs_zero_action", MISSING),
         pct(r.get("fraction_of_oracle"), 0),
         num(r["train_last10pct"]), num(r["paper"], 1)) for r in rows], "lrrlrllrrr")


def render_report(rows: list[dict[str, Any]], cfgs: dict[tuple[str, int], TrainConfig], scenario: str, n_eval: int,
                  wall_s: float, figs: Sequence[Path], failures: Sequence[JobResult]) -> str:
    any_cfg = next(iter(cfgs.values()))
    seeds = sorted({s for _, s in cfgs})
    lines = [f"# Algorithm comparison (paper Fig. 2), preset `{any_cfg.preset}`", ""]
    lines.append(f"Scenario `{scenario}`, UAV starting at {list(any_cfg.resolved_scenario.start)}; seeds {seeds}; "
                 f"{any_cfg.total_steps:,} environment steps per run "
                 f"({counted(any_cfg.total_steps // any_cfg.system.horizon, 'episode', ',')} of "
                 f"{any_cfg.system.horizon} slots); "
                 f"final evaluation: deterministic policy on {counted(n_eval, 'seeded episode')} "
                 f"(seeds {any_cfg.eval_seed}..{any_cfg.eval_seed + n_eval - 1}), the same for every policy. "
                 f"Wall clock of this invocation: {wall_s / 60:.1f} min.")
    lines.append("")
    if figs:
        lines += [f"![learning curves]({Path(figs[0]).name})", ""]
    lines += ["## Final performance (average sum rate, bps/Hz)", "",
              "For DRL rows, statistics are over seeds (each seed's score is its mean over the evaluation "
              "episodes); for baselines and the oracle, over the evaluation episodes. CIs: 95% percentile "
              "bootstrap. `hover` is the zero action (doing nothing); the oracle (`uavris.agents.oracle`) "
              "optimises the phases every slot and flies to the best region it plans; every policy is shown "
              "against both: whether its CI lies above or below the zero action's mean (tie: not resolved), "
              "and as a fraction of the oracle.", "", *fig2_table(rows)]
    drl = [r for r in rows if r["kind"] == "DRL"]
    lines += ["", "## Verdict", ""]
    if drl:
        best = max(drl, key=lambda r: r["mean"])
        ranking = " > ".join(f"{r['policy']} ({r['mean']:.2f})" for r in sorted(drl, key=lambda r: -r["mean"]))
        lines.append(f"On our simulator the best algorithm is **{best['policy']}**; ranking by mean final score: "
                     f"{ranking}.")
        overlap = [r for r in drl if r is not best and r["mean_ci_high"] >= best["mean_ci_low"]]
        if overlap:
            lines.append(f"The 95% CIs of {', '.join(r['policy'] for r in overlap)} overlap the best one's, so the "
                         "ranking among those is not statistically settled with these seeds.")
        paper_rank = " > ".join(a.upper() for a in sorted(PAPER_FIG2, key=lambda a: -PAPER_FIG2[a]))
        agrees = best["policy"] == "DDPG"
        lines.append(f"The paper ranks {paper_rank} with DDPG best; "
                     + ("our result **agrees** on the winner." if agrees else
                        f"our result **does not agree**: {best['policy']} wins here."))
        chosen = select_expert(rows)
        lines.append(f"Expert algorithm chosen as the paper does (Sec. IV-B), by the largest IQM of the final "
                     f"evaluations: **{chosen.upper()}**.")
        zero = next(r for r in rows if r["policy"] == ZERO_ACTION)
        below = [r["policy"] for r in drl if r["vs_zero_action"] != "above"]
        if below:
            lines.append(f"Doing nothing (the zero action, {zero['mean']:.2f}) is not beaten by "
                         f"{', '.join(below)}: their 95% CIs do not lie above it.")
        base = {r["policy"]: r["mean"] for r in rows if r["kind"] == "baseline"}
        if base:
            lines.append(f"Baselines: {', '.join(f'{k} {v:.2f}' for k, v in base.items())} bps/Hz. "
                         f"Our absolute numbers differ from the paper's: its unstated parameters (noise power, slot "
                         f"length, energy budget, training length) differ from ours (docs/model.md).")
    if failures:
        lines += ["", "## Failed jobs", ""] + [f"- {f.name}: {f.error} (log: {f.log})" for f in failures]
    lines += ["", "## Parameters", "", "Hyperparameters per algorithm (the paper gives none; reasons in "
              "`uavris.agents.experts`):", ""]
    for a in dict.fromkeys(a for a, _ in cfgs):
        hp = cfgs[(a, seeds[0])].hyperparams
        lines.append(f"- **{a.upper()}**: " + ", ".join(f"{k}={v}" for k, v in hyperparams_for(a, hp).items()))
    lines += ["", "System configuration:", "", "```yaml"]

    lines += [yaml.safe_dump(any_cfg.system.to_dict(), sort_keys=False).rstrip(), "```", ""]
    return "\n".join(lines)
