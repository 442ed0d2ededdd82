"""Learning curves of individual runs, several overlaid (``uavris plot RUN...``).

Lives here: reading what a run logged and drawing it: an expert run's training episodes
(dots) and periodic deterministic evaluations (mean with its 95% CI band) against
environment steps; a DT pre-training run's action loss against gradient steps; a DT
fine-tuning run's evaluation after each round against environment interactions. Not
here: the study's figures (:mod:`uavris.experiments.study.report.figures`), the comparison's
seed-averaged curves (:func:`uavris.experiments.display.plots.learning_curves`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from uavris.errors import UavrisError
from uavris.experiments.display.plots import plt, save_figure
from uavris.io import read_csv

# What a run directory logs, by the file that identifies its kind.
KINDS = {"evals.csv": "expert", "train_log.csv": "pretrain", "finetune.csv": "finetune"}
PANELS = {
    "expert": ("environment steps", "average sum rate (bps/Hz)", "expert training"),
    "pretrain": ("gradient step", "action loss (MSE)", "DT pre-training"),
    "finetune": ("environment interactions", "average sum rate (bps/Hz)", "DT fine-tuning"),
}


def run_kind(run_dir: Path) -> str:
    """``expert``, ``pretrain`` or ``finetune``; a clear error for anything else."""
    if not run_dir.is_dir():
        raise UavrisError(f"{run_dir} is not a directory")
    for file, kind in KINDS.items():
        if (run_dir / file).exists():
            return kind
    raise UavrisError(f"{run_dir} is not a run directory with logs ({', '.join(KINDS)}); "
                      "pass directories written by train, pretrain-dt or finetune-dt")


def _column(rows: list[dict[str, Any]], name: str) -> np.ndarray:
    return np.array([float(r[name]) for r in rows], dtype=float)


def _draw(ax: Any, run_dir: Path, kind: str, label: str, color: Any) -> None:
    if kind == "expert":
        episodes = read_csv(run_dir / "episodes.csv") if (run_dir / "episodes.csv").exists() else []
        if episodes:
            # Batched envs finish episodes at the same step: dots, not a line through them.
            ax.scatter(_column(episodes, "env_steps"), _column(episodes, "avg_sum_rate"), color=color, s=2,
                       alpha=0.3, lw=0)
        evals = read_csv(run_dir / "evals.csv")
        if evals:
            x = _column(evals, "env_steps")
            ax.fill_between(x, _column(evals, "ci_low"), _column(evals, "ci_high"), color=color, alpha=0.2, lw=0)
            ax.plot(x, _column(evals, "mean"), color=color, lw=1.4, marker="o", ms=2.5, label=label)
    elif kind == "pretrain":
        log = read_csv(run_dir / "train_log.csv")
        ax.plot(_column(log, "step"), _column(log, "loss"), color=color, lw=1.2, label=label)
        ax.set_yscale("log")
    else:
        rounds = read_csv(run_dir / "finetune.csv")
        x = _column(rounds, "env_interactions")
        ax.fill_between(x, _column(rounds, "eval_ci_low"), _column(rounds, "eval_ci_high"), color=color, alpha=0.2,
                        lw=0)
        ax.plot(x, _column(rounds, "eval_mean"), color=color, lw=1.4, marker="o", ms=3, label=label)


def plot_runs(run_dirs: list[Path], stem: Path, labels: list[str] | None = None) -> list[Path]:
    """One panel per kind of run among ``run_dirs``, every run of that kind overlaid; writes
    ``stem.png`` and ``stem.pdf`` and returns both paths."""
    if not run_dirs:
        raise UavrisError("pass at least one run directory")
    if labels is not None and len(labels) != len(run_dirs):
        raise UavrisError(f"--labels gives {len(labels)} names for {len(run_dirs)} runs")
    kinds = [run_kind(Path(d)) for d in run_dirs]
    present = [k for k in PANELS if k in kinds]
    fig, axes = plt.subplots(1, len(present), figsize=(4.8 * len(present), 3.6), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (d, kind) in enumerate(zip(run_dirs, kinds)):
        ax = axes[0, present.index(kind)]
        label = labels[i] if labels else Path(d).name
        _draw(ax, Path(d), kind, label, colors[i % len(colors)])
    for ax, kind in zip(axes[0], present):
        xlabel, ylabel, title = PANELS[kind]
        ax.set(xlabel=xlabel, ylabel=ylabel)
        ax.set_title(title + (" (dots: training episodes; band: 95% CI)" if kind == "expert" else ""), fontsize=8)
        ax.legend(fontsize=7, frameon=False)
    Path(stem).parent.mkdir(parents=True, exist_ok=True)
    return save_figure(fig, Path(stem))
