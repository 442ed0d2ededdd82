"""Figures and ``report.md`` of ``uavris reproduce``; every number is read from stage files."""

from __future__ import annotations

import math
import shutil
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import yaml

from uavris.config import UNSEEN_SCENARIOS, get_scenario
from uavris.experiments.io import atomic_write_text, read_csv, read_json
from uavris.experiments.plots import plt, save_figure
from uavris.experiments.stages import Pipeline, StageRecord

PAPER_FIG2 = {"DDPG": 29.5, "PPO": 25.0, "TD3": 20.5, "SAC": 17.0}
KIND_STYLE = {"expert": ("#1f77b4", "-"), "dt-finetuned": ("#2ca02c", "-"), "dt-zero-shot": ("#ff7f0e", "-"),
              "transfer": ("#7f7f7f", "--"), "oracle": ("k", ":")}
WITHIN_EXPERT = 0.05  # "nearly the same performance": within 5% of the expert's mean


def _fmt(x: float, nd: int = 2) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{nd}f}"


def fig3(scenario: str, stage_dir: Path, stem: Path) -> list[Path]:
    """Average sum rate per evaluation episode for the four kinds of policy (paper Fig. 3)."""
    fig, ax = plt.subplots(figsize=(4.8, 3.4))
    transfer_styles = iter(["--", ":", "-."] * 3)
    for csv in sorted(stage_dir.glob("*.csv")):
        key = csv.stem
        summary = read_json(csv.with_suffix(".json"))
        y = [float(r["avg_sum_rate"]) for r in read_csv(csv)]
        color, ls = KIND_STYLE.get("transfer" if key.startswith("transfer") else key, ("k", "-"))
        if key.startswith("transfer"):
            ls = next(transfer_styles)
        ax.plot(np.arange(1, len(y) + 1), y, ls, color=color, lw=1.1, alpha=0.9 if ls == "-" else 0.7,
                label=f"{summary['label']} ({summary['mean']:.2f})")
    s = get_scenario(scenario)
    ax.set_xlabel("evaluation episode")
    ax.set_ylabel("average sum rate (bps/Hz)")
    ax.set_title(f"unseen scenario {list(s.start)}", fontsize=9)
    ax.legend(fontsize=7, frameon=False, loc="best")
    return save_figure(fig, stem)


def interactions_figure(scenario: str, finetune_dir: Path, expert_dir: Path, stem: Path) -> tuple[list[Path], dict]:
    """Sum rate against environment interactions: DT fine-tuning versus the expert from scratch."""
    ft = read_csv(finetune_dir / "finetune.csv")
    ex = read_csv(expert_dir / "evals.csv")
    fx = np.array([float(r["env_interactions"]) for r in ft])
    fy = np.array([float(r["eval_mean"]) for r in ft])
    ex_x = np.array([float(r["env_steps"]) for r in ex])
    ex_y = np.array([float(r["mean"]) for r in ex])
    fig, ax = plt.subplots(figsize=(4.8, 3.4))
    # linear axis: the zero-shot DT sits at 0 interactions, which a log axis cannot show
    ax.plot(fx, fy, "o-", color=KIND_STYLE["dt-finetuned"][0], label="DT fine-tuning (at 0: zero-shot)")
    ax.plot(ex_x, ex_y, "s-", color=KIND_STYLE["expert"][0], label="DDPG expert trained from scratch")
    ax.set_xlim(left=0)
    ax.set_xlabel("environment interactions (slots)")
    ax.set_ylabel("average sum rate (bps/Hz)")
    ax.set_title(f"{scenario}: interactions needed", fontsize=9)
    ax.legend(fontsize=7, frameon=False)
    info = {"finetune_interactions": float(fx[-1]) if fx.size else float("nan"),
            "finetune_final": float(fy[-1]) if fy.size else float("nan"),
            "expert_steps": float(ex_x[-1]) if ex_x.size else float("nan"),
            "expert_final": float(ex_y[-1]) if ex_y.size else float("nan")}
    # interactions the expert needed to first reach the fine-tuned DT's level
    reached = ex_x[ex_y >= info["finetune_final"]] if fy.size else np.array([])
    info["expert_steps_to_match"] = float(reached[0]) if reached.size else float("nan")
    return save_figure(fig, stem), info


def trajectory_figure(scenario: str, model_dir: Path, system: Any, stem: Path, seed: int) -> list[Path]:
    """3-D view of one evaluation episode: UAV path, RIS normal every few slots, users."""
    from uavris import physics as ph
    from uavris.agents.dt_policy import dt_policy_from_checkpoint
    from uavris.env.simulator import BatchedSimulator

    policy, _ = dt_policy_from_checkpoint(model_dir)
    sim = BatchedSimulator(system, scenario, 1)
    sim.seed(np.array([seed]))
    sim.reset()
    pos, normals = [sim.pos[0].copy()], [ph.ris_axes(sim.att[0])[:, 2]]
    for _ in range(system.horizon):
        _, term, trunc, _ = sim.step(policy(sim.observe(), sim))
        pos.append(sim.pos[0].copy())
        normals.append(ph.ris_axes(sim.att[0])[:, 2])
        if term[0] or trunc[0]:
            break
    pos, normals = np.array(pos), np.array(normals)
    fig = plt.figure(figsize=(4.8, 4.0))
    ax = fig.add_subplot(projection="3d")
    users = np.array(system.users)
    ax.scatter(users[:, 0], users[:, 1], users[:, 2], marker="^", color="k", label="D2D users")
    ax.plot(pos[:, 0], pos[:, 1], pos[:, 2], color="#2ca02c", lw=1.4, label="UAV path")
    ax.scatter(*pos[0], color="#2ca02c", marker="o", label="start")
    step = max(1, len(pos) // 12)
    ax.quiver(pos[::step, 0], pos[::step, 1], pos[::step, 2], normals[::step, 0], normals[::step, 1],
              normals[::step, 2], length=2.0, color="#d62728", lw=0.8, label="RIS normal")
    ax.set_xlim(0, system.room[0])
    ax.set_ylim(0, system.room[1])
    ax.set_zlim(0, system.room[2])
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.set_title(f"fine-tuned DT, {scenario}, episode seed {seed}", fontsize=9)
    ax.legend(fontsize=7, frameon=False, loc="upper left")
    return save_figure(fig, stem)


def write_report(out: Path, rc: Any, pipeline: Pipeline, records: Sequence[StageRecord], wall_s: float) -> Path:
    figs = out / "figures"
    figs.mkdir(parents=True, exist_ok=True)
    status = {r.name: r for r in records}
    ok = {r.name for r in records if r.status in ("done", "skipped")}
    lines = [f"# uavris reproduction of the paper, preset `{rc.preset}`", ""]
    lines.append(f"Everything below is read from the stage files under `{out / 'stages'}`; rerunning "
                 "`uavris reproduce` with the same parameters skips finished stages. Evaluation: deterministic "
                 f"policies on {rc.n_eval} seeded episodes (seeds 1000000..{1000000 + rc.n_eval - 1}), the same "
                 "episodes for every policy of a scenario.")
    lines += ["", "## Stages", "", "| stage | key | status | wall clock (min) |", "|---|---|---|---:|"]
    for r in records:
        lines.append(f"| {r.name} | `{r.key}` | {r.status}{' (' + r.error + ')' if r.error else ''} | "
                     f"{r.wall_s / 60:.1f} |")
    lines.append(f"\nTotal wall clock of this invocation: {wall_s / 60:.1f} min (finished stages skipped "
                 "count 0 here; their own time is in the table).")

    claims: list[str] = []
    # ---------------------------------------------------------------- Fig. 2
    lines += ["", "## Algorithm comparison (paper Fig. 2)", ""]
    if "compare" in ok:
        cdir = pipeline.directory("compare")
        for ext in ("png", "pdf"):
            if (cdir / f"learning_curves.{ext}").exists():
                shutil.copyfile(cdir / f"learning_curves.{ext}", figs / f"fig2_learning_curves.{ext}")
        lines += ["![Fig. 2](figures/fig2_learning_curves.png)", ""]
        rows = read_json(cdir / "summary.json")["rows"]
        lines += ["| policy | mean | 95% CI | IQM | 95% CI (IQM) | fraction of oracle | paper |",
                  "|---|---:|---|---:|---|---:|---:|"]
        for r in rows:
            frac = r.get("fraction_of_oracle", float("nan"))
            lines.append(f"| {r['policy']} | {_fmt(r['mean'])} | [{_fmt(r['mean_ci_low'])}, {_fmt(r['mean_ci_high'])}] "
                         f"| {_fmt(r['iqm'])} | [{_fmt(r['iqm_ci_low'])}, {_fmt(r['iqm_ci_high'])}] | "
                         f"{'n/a' if math.isnan(frac) else f'{frac:.0%}'} | "
                         f"{_fmt(PAPER_FIG2.get(r['policy'], float('nan')), 1)} |")
        drl = [r for r in rows if r["kind"] == "DRL"]
        if drl:
            best = max(drl, key=lambda r: r["mean"])
            verdict = "holds" if best["policy"] == "DDPG" else "does not hold"
            claims.append(f"- **DDPG is the best of the four** (paper: DDPG 29.5 > PPO 25.0 > TD3 20.5 > SAC 17.0): "
                          f"**{verdict}** on our simulator; best is {best['policy']} ({best['mean']:.2f} bps/Hz); "
                          + ", ".join(f"{r['policy']} {r['mean']:.2f}" for r in drl) + ". Full table: "
                          f"`{cdir / 'report.md'}`.")
    else:
        lines.append("Not available: the `compare` stage did not finish.")

    # ---------------------------------------------------------------- Fig. 3
    for i, scenario in enumerate(UNSEEN_SCENARIOS):
        name = f"evaluate-{scenario}"
        label = "ab"[i]
        lines += ["", f"## Unseen scenario {scenario} {list(get_scenario(scenario).start)} (paper Fig. 3{label})", ""]
        if name not in ok:
            lines.append(f"Not available: the `{name}` stage did not finish.")
            continue
        edir = pipeline.directory(name)
        fig3(scenario, edir, figs / f"fig3{label}_{scenario}")
        lines += [f"![Fig. 3{label}](figures/fig3{label}_{scenario}.png)", ""]
        res = read_json(edir / "stage.json")["result"]
        oracle = res.get("oracle", {}).get("mean", float("nan"))
        lines += ["| policy | mean | 95% CI (t) | IQM | 95% CI (IQM, bootstrap) | fraction of oracle |",
                  "|---|---:|---|---:|---|---:|"]
        for key, s in res.items():
            frac = s["mean"] / oracle if oracle and not math.isnan(oracle) else float("nan")
            lines.append(f"| {s['label']} | {s['mean']:.2f} | [{s['ci_low']:.2f}, {s['ci_high']:.2f}] | "
                         f"{s['iqm']:.2f} | [{s['boot_iqm_ci_low']:.2f}, {s['boot_iqm_ci_high']:.2f}] | "
                         f"{'n/a' if math.isnan(frac) else f'{frac:.0%}'} |")
        zs, ft, ex = res["dt-zero-shot"], res["dt-finetuned"], res["expert"]
        transfers = [s for k, s in res.items() if k.startswith("transfer")]
        best_tr = max(transfers, key=lambda s: s["mean"])
        above = zs["mean"] > best_tr["mean"]
        separated = zs["ci_low"] > best_tr["ci_high"] or zs["ci_high"] < best_tr["ci_low"]
        claims.append(f"- {scenario}: **zero-shot DT above transferred DDPG**: "
                      f"{'holds' if above else 'does not hold'} (zero-shot {zs['mean']:.2f} vs best transferred "
                      f"{best_tr['mean']:.2f}, {best_tr['label']}; 95% CIs "
                      f"{'do not overlap' if separated else 'overlap'}).")
        gap = (ft["mean"] - ex["mean"]) / ex["mean"] if ex["mean"] else float("nan")
        interactions = ""
        fdir, xdir = pipeline.directory(f"finetune-{scenario}"), pipeline.directory("experts-unseen")
        if (fdir / "model" / "finetune.csv").exists() and (xdir / "runs" / scenario / "evals.csv").exists():
            _, info = interactions_figure(scenario, fdir / "model", xdir / "runs" / scenario,
                                          figs / f"interactions_{scenario}")
            lines += ["", f"![interactions](figures/interactions_{scenario}.png)"]
            interactions = (f" Fine-tuning used {info['finetune_interactions']:,.0f} environment interactions; the "
                            f"expert was trained with {info['expert_steps']:,.0f}"
                            + (f" and first reached the fine-tuned DT's level after {info['expert_steps_to_match']:,.0f}"
                               if not math.isnan(info["expert_steps_to_match"]) else
                               " and never reached the fine-tuned DT's level in its periodic evaluations") + ".")
        claims.append(f"- {scenario}: **fine-tuned DT within {WITHIN_EXPERT:.0%} of the expert**: "
                      f"{'holds' if abs(gap) <= WITHIN_EXPERT or gap > 0 else 'does not hold'} (fine-tuned "
                      f"{ft['mean']:.2f} vs expert {ex['mean']:.2f}, {gap:+.1%}).{interactions}")
        if i == 0 and (pipeline.directory(f"finetune-{scenario}") / "model" / "done.json").exists():
            trajectory_figure(scenario, pipeline.directory(f"finetune-{scenario}") / "model", rc.system,
                              figs / f"trajectory_{scenario}", 1_000_000)
            lines += ["", f"![trajectory](figures/trajectory_{scenario}.png)"]

    lines += ["", "## The paper's claims, checked", ""] + (claims or ["No claim could be checked: stages failed."])
    lines += ["", "The paper's numbers come from its own, unstated parameters (noise power, slot length, energy "
              "budget, training length); ours are in `docs/model.md` and below. Where a claim does not hold here, "
              "that is the finding on this simulator, not a tuning target."]
    lines += ["", "## Parameters", "", "```yaml",
              yaml.safe_dump({"preset": rc.preset, "seed": rc.seed, "compare_seeds": rc.n_compare_seeds,
                              "eval_episodes": rc.n_eval, "trajectories_per_scenario": rc.n_trajectories},
                             sort_keys=False).rstrip(), "```", ""]
    lines.append("Stage configurations (hyperparameters, DT and fine-tuning settings) are in each "
                 "`stages/NAME-KEY/stage.json`. System configuration:")
    lines += ["", "```yaml", yaml.safe_dump(rc.system.to_dict(), sort_keys=False).rstrip(), "```", ""]
    failed = [r for r in records if r.status == "failed"]
    if failed:
        lines += ["## Failures", ""] + [f"- {r.name}: {r.error}" for r in failed]
    report = out / "report.md"
    atomic_write_text(report, "\n".join(lines) + "\n")
    return report
