"""The commands that roll policies out or look at runs: ``evaluate``, ``collect``, ``demo``, ``plot``.

Lives here: each command's flags (a small dataclass tyro reads) and the call into the
library. Not here: the rollouts, datasets and figures themselves (:mod:`uavris.experiments`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import tyro

from uavris.agents.torch_device import Device
from uavris.cli.parsing import Unset, UsageError, output_dir, parse
from uavris.config import ScenarioName, SystemConfig
from uavris.env.wrappers import PhaseControl
from uavris.experiments.engine.jobs import Backend
from uavris.experiments.tools.benchmark import Cells
from uavris.presets import COLLECT_SEED, EVAL_SEED, STUDY, Preset

DEFAULT_EPISODES = STUDY["quick"]["eval_episodes"]  # uavris evaluate's: the quick report's
TrackName = Literal["paper", "strong", "deployment"]


# ---------------------------------------------------------------------------------------- evaluate
@dataclass(frozen=True)
class EvaluateArgs:
    target: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="RUN|MODEL|REFERENCE|MODULE:NAME")]
    """a run directory (train, pretrain-dt, finetune-dt), a DT model directory, a reference:
    zero-action (hover, level, equal phases), random, hover-random-phases, hover-aligned, hover-optimizer,
    oracle, oracle-greedy (also written baseline:NAME), or your own policy: pkg.module:NAME or
    path/to/file.py:NAME (a policy obs -> actions, or a factory that takes no argument or system and
    returns one; docs/controller.md)"""
    scenario: Unset[ScenarioName] = None
    """scenario to evaluate in (default: the run's own, or the layout's start; required for references, user
    policies and pre-trained DTs without --layout)"""
    layout: Unset[str] = None
    """the hall: paper, layout-train-N / layout-unseen-N (-kK: K devices), or a YAML layout file (devices,
    optionally start and room; --system.* flags apply first) (default: the target's own)"""
    episodes: Unset[int] = None
    """evaluation episodes (seeds SEED .. SEED+EPISODES-1) (default: 32, the quick report's; with --row the
    study's)"""
    seed: int = EVAL_SEED
    """seed of the first evaluation episode"""
    out: Unset[Path] = None
    """output directory (default: RUN/eval, or runs/baselines/NAME/eval for a reference)"""
    phase_control: Unset[PhaseControl] = None
    """optimizer: replace the policy's RIS phases by the per-slot optimiser's (default: as trained)"""
    device: Device = "cpu"
    """torch device (auto: CUDA when torch sees one)"""
    progress: bool = True
    """show a progress bar"""
    system: SystemConfig = SystemConfig()
    """the system evaluated in: the target's own, with these fields changed"""
    row: Unset[str] = None
    """a row of a study's report, TARGET being the study's output directory (uavris reproduce --out): its key in
    the stage files, e.g. dt-zero-shot-safe, dt-zero-shot-safe@s1, dt-ensemble-safe, dt-zero-shot-level,
    transfer-layout-train-5, oracle-safe, expert; evaluated as the report does, in the hall of --layout (its
    start) or at --scenario, on the study's episodes unless --episodes is given"""
    track: Unset[TrackName] = None
    """the track of --row (default: deployment where the study ran it, else its last track)"""
    references: bool = True
    """score the zero action, hovering with the optimiser's phases and the oracle beside the target on the same
    episodes (a reference alone: never)"""
    trajectory: bool = False
    """also write every slot (OUT/...-slots.csv: position, attitude, active pairs, sum rate, energy), draw the first
    episode's flight in the hall (...-trajectory.png) and split the rate by the number of active pairs"""


def evaluate_command(args: list[str]) -> None:
    """Evaluate a trained policy, a reference or your own policy deterministically on seeded episodes.

    The target's own system is the default of every --system.* flag; --layout puts it in
    another hall (the flags change the system first: --layout paper --system.room 40 40 8).
    Writes OUT/TARGET-SCENARIO-seedSEED-nEPISODES-KEY.csv (one row per episode: average sum
    rate, return, length, energy) and .json (mean, 95% CI, IQM, the system) and prints the
    summary; TARGET (the reference, policy or row) and KEY (8 hex digits of the system, phase
    control and start) keep evaluations of other targets and systems in the same OUT apart.
    Every target but a reference is scored with the zero action, hovering with the optimiser's
    phases and the oracle beside it on the same episodes (in the JSON under "references";
    --no-references: not); your own policy is MODULE:NAME or FILE.py:NAME (default OUT
    runs/policies/TARGET/eval). For the study's whole protocol use `uavris benchmark`.
    A row of a study's report (--row, TARGET the study's OUT) is evaluated as the report
    evaluates it, here or in a hall of your own (default OUT runs/rows/ROW).
    """
    from uavris.agents.torch_device import resolve_device
    from uavris.cli.options import layout_defaults
    from uavris.experiments.tools.evaluate import evaluate_target
    from uavris.experiments.tools.targets import resolve_target

    doc = evaluate_command.__doc__ or ""
    # Two passes: the first finds the target, whose own system is the default the flags change.
    first = parse(EvaluateArgs, args, "uavris evaluate", doc)
    if first.row is not None:
        return _evaluate_row(first, args, doc)
    target = resolve_target(first.target)
    own = target.own_system()
    if first.scenario is not None and first.layout is None:  # a named scenario is a start in the paper's hall
        own = paper_hall(own)
    system, hall = layout_defaults(args, own, "uavris evaluate")
    a = parse(EvaluateArgs, args, "uavris evaluate", doc, default=EvaluateArgs(first.target, system=system))
    output_dir(a.out)
    episodes = DEFAULT_EPISODES if a.episodes is None else a.episodes
    summary, path = evaluate_target(target, scenario=a.scenario or hall, episodes=episodes, seed=a.seed, out=a.out,
                                    phase_control=a.phase_control, device=resolve_device(a.device),
                                    progress=a.progress, system=a.system, trajectory=a.trajectory,
                                    references=a.references)
    _print_evaluation(a.target, summary, path)


def paper_hall(system: SystemConfig) -> SystemConfig:
    """``system`` in the paper's hall (its devices and room): where the named scenarios (fig2,
    train1..8, unseen1..2) are, whatever hall a model was trained in (the --system.* flags still
    apply on top)."""
    from uavris.layouts import resolve_layout

    return resolve_layout("paper", system).resolve(system)[0]


def _evaluate_row(first: EvaluateArgs, args: list[str], doc: str) -> None:
    """``uavris evaluate OUT --row KEY``: a row of the study in OUT, in the site the flags name."""
    from uavris.agents.torch_device import resolve_device
    from uavris.cli.options import layout_defaults
    from uavris.experiments.study.rows import read_study, study_row
    from uavris.experiments.study.tracks import TRACK_SPECS
    from uavris.experiments.tools.evaluate import evaluate_target
    from uavris.layouts import Site

    rc = read_study(first.target)
    ran = [t.name for t in rc.tracks]
    track = first.track or ("deployment" if "deployment" in ran else ran[-1])
    base = rc.system.replace(observe_devices=True) if TRACK_SPECS[track].layouts else rc.system
    system, hall = layout_defaults(args, base, "uavris evaluate")
    a = parse(EvaluateArgs, args, "uavris evaluate", doc, default=EvaluateArgs(first.target, system=system))
    output_dir(a.out)
    if hall is None and a.scenario is None:
        raise UsageError("--row: name where to evaluate it: --layout HALL (its devices and start) or --scenario NAME")
    site = Site(a.scenario or hall.name, a.system, None if a.scenario else hall.start)
    site.scenario.validate_for(site.system)
    row = study_row(first.target, str(a.row), track, site)
    episodes = rc.eval_episodes if a.episodes is None else a.episodes
    summary, path = evaluate_target(row, scenario=site.scenario, episodes=episodes, seed=a.seed, out=a.out,
                                    phase_control=a.phase_control, device=resolve_device(a.device),
                                    progress=a.progress, system=site.system, trajectory=a.trajectory,
                                    references=a.references)
    _print_evaluation(f"{row.key} ({summary['label']}, {track} track)", summary, path)


def _print_evaluation(what: str, summary: dict, path: Path) -> None:
    import sys

    from uavris.experiments.display.tables import rate_interval

    if summary.get("warning"):
        print(f"uavris: warning: {summary['warning']}", file=sys.stderr)
    print(f"{what} in {summary['scenario']} ({summary['hall']}): average sum rate {summary['mean']:.2f} bps/Hz "
          f"(95% CI {rate_interval(summary['ci_low'], summary['ci_high'])}, IQM {summary['iqm']:.2f}, "
          f"{summary['episodes']} episodes) -> {path}")
    for m, part in summary.get("active_pairs", {}).items():
        print(f"  slots with {m} active pair{'s' * (m != '1')}: {part['share']:.0%} of the slots, mean sum rate "
              f"{part['rate']:.2f} bps/Hz")
    for name, ref in summary.get("references", {}).items():
        print(f"  beside it on the same episodes: {name} {ref['mean']:.2f} bps/Hz "
              f"(95% CI {rate_interval(ref['ci_low'], ref['ci_high'])})")
    if summary.get("fraction_of_oracle") is not None:
        print(f"  {what} reaches {100 * summary['fraction_of_oracle']:.1f}% of the oracle")


# --------------------------------------------------------------------------------------- benchmark
@dataclass(frozen=True)
class BenchmarkArgs:
    target: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="RUN|MODEL|REFERENCE|MODULE:NAME")]
    """what `uavris evaluate` takes: a run or DT model directory, a reference, or your own policy"""
    preset: Preset = "quick"
    """whose protocol: its report's evaluation episodes and number of unseen layouts (quick: 32 episodes, 16
    layouts)"""
    cells: Cells = "all"
    """scenarios: the paper's unseen scenarios; layouts: the deployment track's unseen layouts; all: both"""
    layout: Unset[str] = None
    """your own hall instead of the protocol's cells: a YAML layout file (devices, optionally start and room) or
    a generated name (layout-unseen-N, -kK); the preset's episodes, beside the zero action and the oracle"""
    out: Unset[Path] = None
    """output directory (default: runs/benchmarks/TARGET)"""
    phase_control: Unset[PhaseControl] = None
    """optimizer: the target's motion with the per-slot optimiser's phases (default: as trained)"""
    device: Device = "cpu"
    """torch device (auto: CUDA when torch sees one)"""
    progress: bool = True
    """show a progress bar"""
    system: SystemConfig = SystemConfig()
    """the system: the target's own, with these fields changed"""


def benchmark_command(args: list[str]) -> None:
    """Score a target on the study's protocol: the paper's unseen scenarios and the unseen layouts.

    The episodes and seeds are the report's (--preset), so each row compares with the same row
    of runs/PRESET/report.md. In every cell the zero action and the oracle are evaluated on the
    same episodes. Writes OUT/benchmark.md (the table: fraction of the oracle, difference to the
    zero action with its paired 95% CI, means over cells), benchmark.csv, benchmark.json and
    each cell's per-episode CSVs.
    """
    from uavris.agents.torch_device import resolve_device
    from uavris.experiments.tools.benchmark import benchmark
    from uavris.experiments.tools.targets import resolve_target

    doc = benchmark_command.__doc__ or ""
    first = parse(BenchmarkArgs, args, "uavris benchmark", doc)
    default = BenchmarkArgs(first.target, system=resolve_target(first.target).own_system())
    a = parse(BenchmarkArgs, args, "uavris benchmark", doc, default=default)
    output_dir(a.out)
    _, md = benchmark(a.target, a.preset, a.cells, a.out, resolve_device(a.device), progress=a.progress,
                      system=a.system, phase_control=a.phase_control, layout=a.layout)
    print(md.read_text(), end="")
    print(f"-> {md}")


# ------------------------------------------------------------------------------------------- sweep
@dataclass(frozen=True)
class SweepArgs:
    targets: Annotated[tuple[str, ...], tyro.conf.Positional, tyro.conf.arg(metavar="POLICY")]
    """what `uavris evaluate` takes, one or more: a reference (hover-optimizer, oracle, ...), a run or DT model
    directory, or your own policy (MODULE:NAME, FILE.py:NAME)"""
    param: Annotated[tuple[tuple[str, str], ...], tyro.conf.UseAppendAction,
                     tyro.conf.arg(metavar="NAME VALUES")] = ()
    """a system parameter and its values, once or twice: NAME a SystemConfig field (system.rician-factor,
    system.nx, ...) or system.tx-power-dbm, system.ris-size (n x n), system.devices (generated halls);
    VALUES start:stop:step (stop included) or v1,v2,..."""
    scenario: Unset[ScenarioName] = None
    """the start in the paper's hall (default fig2, or --layout's start; a devices sweep uses each generated hall's
    own)"""
    layout: Unset[str] = None
    """the hall: paper, layout-train-N / layout-unseen-N (-kK: K devices), or a YAML layout file (devices,
    optionally start and room): its devices, room and start in every cell (default: the paper's hall)"""
    episodes: int = 16
    """evaluation episodes per cell and policy (seeds 1,000,000 ..., the same in every cell)"""
    halls: int = 4
    """generated halls per cell of a devices sweep (the interval is then over halls)"""
    out: Unset[Path] = None
    """output directory (default runs/sweeps/NAME: the parameters and a hash of the whole configuration); a rerun
    skips the cells it finds there"""
    workers: int = 2
    """parallel job processes (local backend) or CPUs of a local Ray instance"""
    backend: Backend = "local"
    """local (process pool) or ray (pip install 'uavris[ray]')"""
    progress: bool = True
    """show a progress bar"""
    system: SystemConfig = SystemConfig()
    """the system the grid varies"""


def sweep_command(args: list[str]) -> None:
    """The sum rate of policies over a grid of one or two system parameters: a CSV and a figure.

    Every policy is scored on the same seeded episodes in every cell, with its 95% CI over
    the episodes (over the halls, for a devices sweep). Cells run in parallel and are kept
    under OUT/cells/, so a rerun skips the finished ones. Writes OUT/sweep.csv (policy,
    parameter values, mean and CI), OUT/sweep.png and .pdf (the sum rate against the first
    parameter, a line and band per policy and per value of the second) and OUT/sweep.json.
    Example: uavris sweep hover-optimizer oracle --param system.tx-power-dbm -10:30:10
    --param system.ris-size 2,4,8
    """
    import hashlib

    from uavris.cli.options import layout_defaults
    from uavris.experiments.tools.sweep import parse_axis, sweep

    system, hall = layout_defaults(args, SystemConfig(), "uavris sweep")
    a = parse(SweepArgs, args, "uavris sweep", sweep_command.__doc__ or "", default=SweepArgs((), system=system))
    if not a.param:
        raise UsageError("sweep: give one or two --param NAME VALUES (see uavris sweep --help)")
    axes = [parse_axis(name, spec) for name, spec in a.param]
    if a.out is None:
        whole = repr((a.targets, a.param, a.scenario, a.layout, a.episodes, a.halls, a.system.to_dict())).encode()
        name = "-".join(ax.name for ax in axes) + "-" + hashlib.sha256(whole).hexdigest()[:8]
        out = Path("runs/sweeps") / name
    else:
        out = a.out
    output_dir(out)
    paths = sweep(a.targets, axes, out, base=a.system, scenario=a.scenario or hall, episodes=a.episodes, halls=a.halls,
                  workers=a.workers, backend=a.backend, progress=a.progress)
    print("wrote " + ", ".join(str(p) for p in paths))


# -------------------------------------------------------------------------------------------- plan
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
