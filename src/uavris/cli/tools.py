"""The commands that look at a hall, a dataset or runs: ``plan``, ``collect``, ``demo`` and ``plot``.

Lives here: each command's flags (a small dataclass tyro reads) and the call into the
library. Not here: the plans, datasets and figures themselves (:mod:`uavris.experiments`),
the commands that score policies (:mod:`.evaluation`).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import ModuleType
from typing import Annotated, Literal

import tyro

from uavris.cli.evaluation import seed_note
from uavris.cli.options import SystemFlags, in_hall, parse_in_hall, written
from uavris.cli.outputs import writing
from uavris.cli.parsing import Unset, UsageError, parse
from uavris.config import ScenarioName, SystemConfig
from uavris.experiments.display.tables import counted
from uavris.experiments.tools.demo import run_demo
from uavris.experiments.tools.rows import read_controller, shipped_controller, write_controller
from uavris.experiments.tools.targets import LearnedValue
from uavris.io import file_part
from uavris.layouts import PAPER_LAYOUT, Layout, default_start
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
    """a learned value of a pose: a study's output folder (made by `uavris reproduce`; its pre-training seed 0's V),
    a value folder, or `pretrained` (the one shipped, with its deployed place): plan with the argmax of V instead of
    the exact planner, and map V (milliseconds)"""
    top_k: int = 0
    """with --learned: value its best K places (1-5) and the start by the exact R (semi-amortised; seconds)"""
    deployed: bool = False
    """with --learned: the deployed place (V proposes, R disposes: V's best places valued level and tilted by R's
    cheap estimate, the best refined, the finalists and staying valued by R; about a tenth of the oracle's time)"""
    controller: Unset[Path] = None
    """a controller directory (uavris export), or `pretrained` (the one shipped): plan with the learned planner its
    row is told its place by"""
    progress: bool = True
    """show a progress bar"""
    system: SystemFlags = field(default_factory=SystemFlags)
    """the system (the layout sets its devices and, if it has one, its room)"""


def _learned_value(a: PlanArgs) -> tuple[PlanArgs, Path | str | None]:
    """``a`` with ``--learned`` the value folder the user named (a study's seed 0's, the shipped
    controller's, a controller's) and ``--top-k`` / ``--deployed`` its row's; and the controller
    as the user typed it, for the line that tells them how to fly it."""
    named: Path | str | None = a.controller
    if a.learned is not None and a.controller is not None:
        raise UsageError("--controller and --learned both name a learned value; pass one of them")
    for given in (a.learned, a.controller):  # `pretrained`: the shipped controller, its learned value and planner
        if given is not None and (shipped := shipped_controller(given)) is not None:
            a, named = replace(a, learned=None, controller=shipped), str(given)
    if a.learned is not None:  # a learned value needs the train extra (torch), as the study's pipeline does
        finished = _finished()
        if (a.learned / finished.STUDY_FILE).is_file():  # a study: its pre-training seed 0's V
            a = replace(a, learned=finished.Study.open(a.learned).learned_value())
    if a.controller is not None:
        told = read_controller(a.controller).goal_from
        if not isinstance(told, LearnedValue):
            raise UsageError(f"--controller {a.controller}: its row is told no learned place (no learned value)")
        a = replace(a, learned=told.path, top_k=told.top_k, deployed=told.deployed)
    return a, named


def plan_command(args: list[str]) -> None:
    """Where should the UAV go in this hall? The planning oracle's plan and a map of the expected sum rate.

    Prints the target pose, its expected sum rate with optimised phases and the travel time
    from the start. Writes OUT.json (the plan) and OUT.png / OUT.pdf (the expected sum rate
    over the hall at the target's altitude, with the devices, their safety balls, the start
    and the target).
    """
    from uavris.experiments.tools.plan import check_devices, check_grid, plan_hall, planning_seconds

    a = parse_in_hall(PlanArgs, args, "uavris plan", plan_command.__doc__ or "")
    a, named = _learned_value(a)
    flags = written(a.system)
    hall, _, layout = in_hall(a.layout, SystemConfig(), flags)  # the flags written, in the layout's hall
    if layout is None:
        layout = PAPER_LAYOUT if hall.users == PAPER_LAYOUT.users else Layout("custom", hall.users, default_start(hall))
    check_grid(hall, a.grid_step)  # before anything is written
    if a.learned is None or a.top_k or a.deployed:
        check_devices(hall)
    if a.deployed and (a.learned is None or a.top_k):
        raise UsageError("--deployed needs --learned and no --top-k")
    if not 0 <= a.top_k <= 5 or (a.top_k and a.learned is None):
        raise UsageError(f"--top-k must be in 0-5 and needs --learned, got {a.top_k}"
                          + ("" if a.learned is not None else " without --learned"))
    value = LearnedValue.at(a.learned).planner_model() if a.learned is not None else None
    out = a.out or Path("runs/plans") / (layout.name + ("-learned" if value is not None else ""))
    with writing(out.parent, "--out's folder", files_only=True):
        if value is None and hall.num_users > 8:
            seconds = planning_seconds(hall.num_users)
            print(f"planning a hall of {hall.num_users} devices: about {seconds:.0f} s on one core", flush=True)
        plan, paths = plan_hall(layout, hall, out, a.grid_step, progress=a.progress, value=value,
                                top_k=a.top_k, controller=a.controller, deployed=a.deployed)
    t = plan["target"]
    if plan["expected_sum_rate"] is None:  # the learned planner's V: no R was computed
        worth = (f"learned value V there {plan['learned_value']:.2f} bps/Hz (at the start "
                 f"{plan['learned_value_start']:.2f}); V's episode average {plan['learned_episode_value']:.2f}")
    else:
        worth = (f"expected sum rate there {plan['expected_sum_rate']:.2f} +- {plan['expected_sum_rate_se']:.2f} "
                 f"(standard error) bps/Hz (at the start {plan['start_sum_rate']:.2f}); expected episode average "
                 f"{plan['expected_episode_average']:.2f}")
    print(f"{layout.name}: fly from {[round(v, 2) for v in plan['layout']['start']]} to "
          f"[{t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}] (attitude {[round(v, 1) for v in plan['attitude_deg']]} deg) in "
          f"{plan['travel_s']:.1f} s; {worth}; planned by the {plan['planner']} planner in "
          f"{1000 * plan['planning_s']:.0f} ms -> {', '.join(str(p) for p in paths)}")
    flight = plan.get("controller_flight")
    if flight is not None:
        if flight["warning"]:
            print(f"uavris: warning: {flight['warning']}", file=sys.stderr)
        print(f"{flight['row']}, told this place, ends episode seed {flight['seed']} at "
              f"[{', '.join(f'{v:.2f}' for v in flight['end'])}] with an average sum rate of "
              f"{flight['average_sum_rate']:.2f} bps/Hz (its whole flight: uavris evaluate {named} "
              f"--layout {layout.name if a.layout is None else a.layout} --trajectory)")


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
    trust_pickle: bool = False
    """load a run that holds only SB3's pickled archive (uavris 0.3's, or another tool's): reading it runs whatever
    it holds, so only for runs you trust (uavris's own runs are read from safetensors and JSON)"""


def collect_command(args: list[str]) -> None:
    """Roll expert runs out deterministically and write a Minari dataset for the Decision Transformer.

    Each expert acts in its own scenario without exploration noise. Writes OUT/data/
    (metadata.json + main_data.hdf5): per-episode scenario, expert and seed, the system
    configuration and the environment spec (minari's recover_environment() rebuilds the env).
    """
    from uavris.experiments.training.collect import collect, dataset_summary

    a = parse(CollectArgs, args, "uavris collect", collect_command.__doc__ or "")
    with writing(a.out):
        path = collect(a.experts, a.trajectories, a.out, seed=a.seed, force=a.force, progress=a.progress,
                       trust_pickle=a.trust_pickle)
    summary = dataset_summary(path)
    rates = ", ".join(f"{s} {v['avg_sum_rate']:.2f}" for s, v in summary["scenarios"].items())
    print(f"dataset {path} ({summary['dataset_id']}): {counted(summary['episodes'], 'episode')}, "
          f"{summary['slots']} slots; average sum rate per scenario (bps/Hz): {rates}")


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
    system: SystemFlags = field(default_factory=SystemFlags)
    """the system (the paper's, with these fields changed)"""


def demo_command(args: list[str]) -> None:
    """Roll out the zero action, random actions and a co-phasing hover, and print their average sum rate."""
    a = parse_in_hall(DemoArgs, args, "uavris demo", demo_command.__doc__ or "")
    system, hall, _ = in_hall(a.layout, SystemConfig(), written(a.system))
    run_demo(a.episodes, a.seed, a.scenario or hall or "fig2", system)


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
    with writing(a.out.parent, "--out's folder", files_only=True):
        paths = plot_runs(list(a.runs), a.out, list(a.labels) if a.labels else None)
    print("wrote " + ", ".join(str(p) for p in paths))


# ------------------------------------------------------------------------------------------- export
@dataclass(frozen=True)
class ExportArgs:
    study: Annotated[Path, tyro.conf.Positional, tyro.conf.arg(metavar="OUT")]
    """a study's output directory (uavris reproduce --out)"""
    row: str = "dt-goal-safe"
    """the row of the study's report to export (its key in the stage files): e.g. dt-goal-safe (the goal-conditioned
    DT told the deployed place, under the safety layer), dt-ensemble-safe, dt-zero-shot-safe@s1"""
    track: Literal["paper", "strong", "deployment"] = "deployment"
    """the row's track"""
    out: Unset[Path] = None
    """the controller directory to write (default: runs/controllers/ROW); evaluate, benchmark, sweep and plan
    --controller take it like a model"""


def export_command(args: list[str]) -> None:
    """Export a row of a study as one controller directory that `uavris evaluate`, `benchmark`, `sweep` and
    `plan --controller` take like any model: its models' weights and JSON (no pickle) and how the study evaluates
    them (the goal-conditioned DT with its learned planner, the safety layer, an ensemble), the same numbers as
    `uavris evaluate OUT --row ROW` in the same hall. A row that flies another hall's plan (transfer-...) is that
    hall's and cannot be exported. Writes --out/controller.json and its models' files.
    """
    a = parse(ExportArgs, args, "uavris export", export_command.__doc__ or "")
    study = _finished().Study.open(a.study)
    _, unseen = study.sites(a.track)
    row = study.row(a.row, a.track, unseen[0])  # a controller's models are the study's, whatever the hall
    out = a.out or Path("runs/controllers") / file_part(row.key)
    with writing(out):
        write_controller(row, out)
    print(f"exported {row.key} ({row.label_for()}) of {a.study} -> {out}")
    print(seed_note(row, study.seeds(row, a.track, unseen[0])), end="")


def _finished() -> ModuleType:
    """:mod:`uavris.experiments.study.finished`, where a study is opened: it loads the study's code
    (torch, the train extra), which ``plan`` without a study and every ``--help`` never need."""
    import uavris.experiments.study.finished

    return uavris.experiments.study.finished
