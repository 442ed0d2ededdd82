"""Figures of the study's report: Fig. 3 per track, interactions, a 3-D trajectory.

Lives here: :func:`fig3`, :func:`interactions_figure`, :func:`trajectory_figure` and the
style of each kind of policy (:data:`KIND_STYLE`). Not here: saving and the shared styles
(:mod:`uavris.experiments.display.plots`) and the report's text (:mod:`uavris.experiments.study.report`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from uavris import physics as ph
from uavris.agents.references import REFERENCES
from uavris.config import get_scenario
from uavris.experiments.display.plots import REFERENCE_STYLE, plt, reference_lines, save_figure
from uavris.experiments.study.claims_tracks import LEVEL, expert_curve, finetune_curve, interactions_needed
from uavris.io import read_csv, read_json

KIND_STYLE = {"expert": ("#1f77b4", "-"), "dt-finetuned": ("#2ca02c", "-"), "dt-zero-shot": ("#ff7f0e", "-"),
              "transfer": ("#7f7f7f", "--")}


def fig3(scenario: str, stage_dir: Path, stem: Path, track: str) -> list[Path]:
    """Average sum rate per evaluation episode of every learned policy (paper Fig. 3), with the
    references (zero action, hover with optimised phases, oracle) as lines at their means."""
    fig, ax = plt.subplots(figsize=(4.8, 3.6))
    transfer_styles = iter(["--", ":", "-."] * 3)
    refs = {}
    for csv in sorted(stage_dir.glob("*.csv")):
        key = csv.stem
        summary = read_json(csv.with_suffix(".json"))
        if key in REFERENCE_STYLE:
            refs[key] = (REFERENCES[key].label, summary["mean"])
            continue
        y = [float(r["avg_sum_rate"]) for r in read_csv(csv)]
        transfer = summary["kind"] == "transfer"
        color, ls = KIND_STYLE.get("transfer" if transfer else key, ("k", "-"))
        if transfer:
            ls = next(transfer_styles)
        ax.plot(np.arange(1, len(y) + 1), y, ls, color=color, lw=1.1, alpha=0.9 if ls == "-" else 0.7,
                label=f"{summary['label']} ({summary['mean']:.2f})")
    reference_lines(ax, dict(sorted(refs.items())))
    s = get_scenario(scenario)
    ax.set_xlabel("evaluation episode")
    ax.set_ylabel("average sum rate (bps/Hz)")
    ax.set_title(f"{track} track, unseen scenario {list(s.start)}", fontsize=9)
    ax.legend(fontsize=6, frameon=False, loc="center left", bbox_to_anchor=(1.0, 0.5))
    return save_figure(fig, stem)


def interactions_figure(scenario: str, finetune_dir: Path, expert_dir: Path, stem: Path,
                        expert_label: str = "expert") -> tuple[list[Path], dict[str, float]]:
    """Sum rate against environment interactions: DT fine-tuning versus the expert's training."""
    fx, fy = finetune_curve(finetune_dir)
    ex_x, ex_y = expert_curve(expert_dir)
    fig, ax = plt.subplots(figsize=(4.8, 3.4))
    # linear axis: the zero-shot DT sits at 0 interactions, which a log axis cannot show
    ax.plot(fx, fy, "o-", color=KIND_STYLE["dt-finetuned"][0], label="DT fine-tuning (at 0: zero-shot)")
    ax.plot(ex_x, ex_y, "s-", color=KIND_STYLE["expert"][0], label=expert_label)
    final = float(read_json(expert_dir / "done.json")["final_eval"]["mean"])
    need = interactions_needed((ex_x, ex_y), (fx, fy), final)
    # the level both sides are charged to reach (docs/results/claims.md, "fewer interactions")
    ax.axhline(need["level"], color="0.5", lw=0.8, ls="--", label=f"{LEVEL:.0%} of the expert's final level")
    ax.set_xlim(left=0)
    ax.set_xlabel("environment interactions (slots)")
    ax.set_ylabel("average sum rate (bps/Hz)")
    ax.set_title(f"{scenario}: interactions needed", fontsize=9)
    ax.legend(fontsize=7, frameon=False)
    info = {"level": need["level"], "finetune_to_level": need["finetune"], "expert_to_level": need["expert"]}
    return save_figure(fig, stem), info


def trajectory_figure(scenario: str, slots: Path, system: Any, stem: Path, seed: int) -> list[Path]:
    """3-D view of one evaluation episode of a DT, as its evaluation stage recorded it slot by
    slot (``slots``: :func:`uavris.experiments.tools.trajectory.write_slots`): UAV path, RIS
    normal every few slots, devices and their safety balls (as circles at the floor of the region)."""
    rows = read_csv(slots)
    pos = np.array([[float(r[c]) for c in ("x", "y", "z")] for r in rows])
    normals = np.array([ph.ris_axes(np.radians([float(r[c]) for c in ("yaw_deg", "pitch_deg", "roll_deg")]))[:, 2]
                        for r in rows])
    fig = plt.figure(figsize=(4.8, 4.0))
    ax = fig.add_subplot(projection="3d")
    users = np.array(system.users)
    ax.scatter(users[:, 0], users[:, 1], users[:, 2], marker="^", color="k", label="D2D devices")
    if system.safety_distance > 0:
        ring = np.linspace(0, 2 * np.pi, 60)
        for u in users:
            dz = system.z_min - u[2]
            r = np.sqrt(max(system.safety_distance ** 2 - dz ** 2, 0.0))
            ax.plot(u[0] + r * np.cos(ring), u[1] + r * np.sin(ring), np.full(ring.shape, system.z_min), color="0.6",
                    lw=0.6)
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
