"""The commands that look at a hall, a dataset or runs: ``plan``, ``collect``, ``demo`` and ``plot``.

Lives here: each command's flags (a small dataclass tyro reads) and the call into the
library. Not here: the plans, datasets and figures themselves (:mod:`uavris.experiments`),
the commands that score policies (:mod:`.evaluation`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import tyro

from uavris.cli.parsing import Unset, UsageError, output_dir, parse
from uavris.config import ScenarioName, SystemConfig
from uavris.presets import COLLECT_SEED


@dataclass(frozen=True)
class PlanArgs:
    layout: Annotated[Unset[str], tyro.conf.Positional, tyro.conf.arg(metavar="LAYOUT")] = None
    """the hall: paper, layout-train-N / layout-unseen-N (generated; -kK: K devices), or a YAML layout file
    (devices, optionally start and room); default: the devices of --system.users (the paper's unless given),
    starting above the middle of the floor"""
    out: Unset[Path] = None
    """output file stem: writes OUT.json, OUT.png and OUT.pdf (default: runs/plans/LAYOUT)"""
    grid_step: float = 2.0
    """spacing of the rate map's grid, m (1.0 takes about four times as long)"""
    learned: Unset[Path] = None
    """a learned value of a pose (a study's stages/value-* folder, made by `uavris reproduce --track
    deployment`): plan with the argmax of V instead of the exact planner, and map V (milliseconds)"""
    top_k: int = 0
    """with --learned: value its best K places (1-5) and the start by the exact R (semi-amortised; seconds)"""
    progress: bool = True
    """show a progress bar"""
    system: SystemConfig = SystemConfig()
    """the system (the layout sets its devices and, if it has one, its room)"""


def plan_command(args: list[str]) -> None:
    """Where should the UAV go in this hall? The planning oracle's plan and a map of the expected sum rate.

    Prints the target pose, its expected sum rate with optimised phases and the travel time
    from the start. Writes OUT.json (the plan) and OUT.png / OUT.pdf (the expected sum rate
    over the hall at the target's altitude, with the devices, their safety balls, the start
    and the target).
    """
    from uavris.cli.options import layout_defaults
    from uavris.experiments.tools.plan import check_grid, plan_hall
    from uavris.layouts import PAPER_LAYOUT, Layout, default_start, resolve_layout

    a = parse(PlanArgs, args, "uavris plan", plan_command.__doc__ or "")
    if a.layout is None:
        layout = PAPER_LAYOUT if a.system.users == PAPER_LAYOUT.users else Layout(
            "custom", a.system.users, default_start(a.system))
    else:
        layout_defaults(["--layout", a.layout, *args], a.system)  # --system.users beside a layout: one line
        layout = resolve_layout(a.layout, a.system)
    check_grid(layout.system(a.system), a.grid_step)  # before anything is written
    if not 0 <= a.top_k <= 5 or (a.top_k and a.learned is None):
        raise UsageError(f"--top-k must be in 0-5 and needs --learned, got {a.top_k}"
                          + ("" if a.learned is not None else " without --learned"))
    value = None
    if a.learned is not None:
        from uavris.agents.place.checkpoint import load_value
        value, _ = load_value(a.learned)
    out = a.out or Path("runs/plans") / (layout.name + ("-learned" if value is not None else ""))
    output_dir(out.parent, "--out's folder")
    plan, paths = plan_hall(layout, a.system, out, a.grid_step, progress=a.progress, value=value, top_k=a.top_k)
    t = plan["target"]
    se = plan["expected_sum_rate_se"]
    where = "expected sum rate there" if se is not None else "learned value V there"
    print(f"{layout.name}: fly from {[round(v, 2) for v in plan['layout']['start']]} to "
          f"[{t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}] (attitude {[round(v, 1) for v in plan['attitude_deg']]} deg) in "
          f"{plan['travel_s']:.1f} s; {where} {plan['expected_sum_rate']:.2f} "
          + (f"+- {se:.2f} (standard error) " if se is not None else "")
          + f"bps/Hz (at the start {plan['start_sum_rate']:.2f}); expected episode average "
          f"{plan['expected_episode_average']:.2f}; planned by the {plan['planner']} planner in "
          f"{1000 * plan['planning_s']:.0f} ms -> {', '.join(str(p) for p in paths)}")


# ----------------------------------------------------------------------------------------- collect
@dataclass(frozen=True)
class CollectArgs:
    experts: tuple[Path, ...] = ()
    """expert run directories made by `uavris train` (one per scenario)"""
    trajectories: int = 500
    """episodes per expert (the paper uses 500)"""
    out: Path = Path("runs/datasets/experts-v0")
    """dataset directory"""
    seed: int = COLLECT_SEED
    """seed of the first episode; expert k uses SEED + k*TRAJECTORIES onwards"""
    force: bool = False
    """replace an existing dataset"""
    progress: bool = True
    """show a progress bar"""


def collect_command(args: list[str]) -> None:
    """Roll expert runs out deterministically and write a Minari dataset for the Decision Transformer.

    Each expert acts in its own scenario without exploration noise. Writes OUT/data/
    (metadata.json + main_data.hdf5): per-episode scenario, expert and seed, the system
    configuration and the environment spec (minari's recover_environment() rebuilds the env).
    """
    from uavris.experiments.training.collect import collect, dataset_summary

    a = parse(CollectArgs, args, "uavris collect", collect_command.__doc__ or "")
    output_dir(a.out)
    path = collect(a.experts, a.trajectories, a.out, seed=a.seed, force=a.force, progress=a.progress)
    summary = dataset_summary(path)
    rates = ", ".join(f"{s} {v['avg_sum_rate']:.2f}" for s, v in summary["scenarios"].items())
    print(f"dataset {path} ({summary['dataset_id']}): {summary['episodes']} episodes, {summary['slots']} slots; "
          f"average sum rate per scenario (bps/Hz): {rates}")


# -------------------------------------------------------------------------------------------- demo
@dataclass(frozen=True)
class DemoArgs:
    episodes: int = 32
    """episodes per policy"""
    seed: int = 0
    """seed of the first episode"""
    scenario: Unset[ScenarioName] = None
    """start position (default: fig2, or the layout's start)"""
    layout: Unset[str] = None
    """the hall: paper, layout-train-N / layout-unseen-N (-kK: K devices), or a YAML layout file (devices,
    optionally start and room; --system.* flags apply first) (default: the devices of --system.users, the paper's
    unless given)"""
    system: SystemConfig = SystemConfig()
    """the system (the paper's, with these fields changed)"""


def demo_command(args: list[str]) -> None:
    """Roll out the zero action, random actions and a co-phasing hover, and print their average sum rate."""
    from uavris.cli.options import layout_defaults
    from uavris.experiments.tools.demo import run_demo

    system, hall = layout_defaults(args, SystemConfig(), "uavris demo")
    a = parse(DemoArgs, args, "uavris demo", demo_command.__doc__ or "", default=DemoArgs(system=system))
    run_demo(a.episodes, a.seed, a.scenario or hall or "fig2", a.system)


# -------------------------------------------------------------------------------------------- plot
@dataclass(frozen=True)
class PlotArgs:
    runs: Annotated[tuple[Path, ...], tyro.conf.Positional, tyro.conf.arg(metavar="RUN")]
    """run directories written by train, pretrain-dt or finetune-dt (overlaid by kind)"""
    out: Path = Path("runs/plots/curves")
    """output file stem: writes OUT.png and OUT.pdf"""
    labels: Unset[tuple[str, ...]] = None
    """legend labels, one per run (default: the directory names)"""


def plot_command(args: list[str]) -> None:
    """Draw learning curves of one or more runs (training episodes, periodic evaluations with 95% CIs).

    Expert runs: average sum rate against environment steps; DT pre-training: action loss
    against gradient steps; DT fine-tuning: evaluation after each round. Writes OUT.png and
    OUT.pdf.
    """
    from uavris.experiments.tools.run_curves import plot_runs

    a = parse(PlotArgs, args, "uavris plot", plot_command.__doc__ or "")
    output_dir(a.out.parent, "--out's folder")
    paths = plot_runs(list(a.runs), a.out, list(a.labels) if a.labels else None)
    print("wrote " + ", ".join(str(p) for p in paths))
