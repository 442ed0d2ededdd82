"""The commands that score policies: ``evaluate``, ``benchmark`` and ``sweep``.

Lives here: each command's flags (a small dataclass tyro reads) and the call into the
library. Not here: the rollouts, datasets and figures themselves (:mod:`uavris.experiments`).
"""

from __future__ import annotations

import hashlib
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import ModuleType
from typing import Annotated, Any, Literal

import tyro

from uavris.agents.torch_device import Device, resolve_device
from uavris.cli.options import SystemFlags, in_hall, layered, parse_in_hall, written
from uavris.cli.outputs import output_dir, writing
from uavris.cli.parsing import Unset, UsageError
from uavris.config import ScenarioName, SystemConfig
from uavris.env.wrappers import PhaseControl
from uavris.experiments.display.tables import counted, interval, rate_interval, signed
from uavris.experiments.engine.jobs import Backend
from uavris.experiments.tools.benchmark import Cells, benchmark, default_benchmark_dir
from uavris.experiments.tools.evaluate import evaluate_target, results_dir
from uavris.experiments.tools.rows import resolve_target, write_controller
from uavris.layouts import PAPER_LAYOUT, Site
from uavris.presets import EVAL_SEED, STUDY, Preset

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
    """output directory (default: RUN/eval for a run or model, runs/baselines/NAME/eval for a reference,
    runs/policies/FILE_py_NAME/eval for your own policy, runs/rows/ROW with --row)"""
    phase_control: Unset[PhaseControl] = None
    """optimizer: replace the policy's RIS phases by the per-slot optimiser's (default: as trained)"""
    device: Device = "cpu"
    """torch device (auto: CUDA when torch sees one)"""
    progress: bool = True
    """show a progress bar"""
    system: SystemFlags = field(default_factory=SystemFlags)
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
    trust_pickle: bool = False
    """load a run that holds only SB3's pickled archive (uavris 0.3's, or another tool's): reading it runs whatever
    it holds, so only for runs you trust (uavris's own runs are read from safetensors and JSON)"""


def evaluate_command(args: list[str]) -> None:
    """Evaluate a trained policy, a reference or your own policy deterministically on seeded episodes.

    The target's own system is the default of every --system.* flag; --layout puts it in
    another hall (the flags change the system first: --layout paper --system.room 40 40 8).
    Writes OUT/TARGET-SCENARIO-seedSEED-nEPISODES-KEY.csv (one row per episode: average sum
    rate, return, length, energy) and .json (mean, 95% CI, IQM, the hall and the model) and
    prints the summary; TARGET (the reference, policy or row) and KEY (8 hex digits of the
    system, phase control, start and model) keep evaluations of other targets and systems in
    the same OUT apart.
    Every target but a reference is scored with the zero action, hovering with the optimiser's
    phases and the oracle beside it on the same episodes (in the JSON under "references";
    --no-references: not); your own policy is MODULE:NAME or FILE.py:NAME (default OUT
    runs/policies/FILE_py_NAME/eval). For the study's whole protocol use `uavris benchmark`.
    A row of a study's report (--row, TARGET the study's OUT) is evaluated as the report
    evaluates it, here or in a hall of your own (default OUT runs/rows/ROW).
    """
    a = parse_in_hall(EvaluateArgs, args, "uavris evaluate", evaluate_command.__doc__ or "")
    check_one_start(a.scenario, a.layout)
    if a.row is not None:
        return _evaluate_row(a, args)
    if a.track is not None:
        raise UsageError("--track chooses the track of --row; give --row KEY (and TARGET the study's output directory)")
    target = resolve_target(a.target, a.trust_pickle)
    own = target.own_system()  # the system the --system.* flags change
    if a.scenario is not None and a.layout is None:  # a named scenario is a start in the paper's hall
        own = paper_hall(own)
    system = in_hall(a.layout, own, written(a.system)).system
    episodes = DEFAULT_EPISODES if a.episodes is None else a.episodes
    with writing(a.out or results_dir(target)) as out:
        # the layout again (resolving it in its own hall changes nothing): the result records it
        summary, path = evaluate_target(target, scenario=a.scenario, layout=a.layout, episodes=episodes,
                                        seed=a.seed, out=out, phase_control=a.phase_control,
                                        device=resolve_device(a.device), progress=a.progress, system=system,
                                        trajectory=a.trajectory, references=a.references)
    _print_evaluation(a.target, summary, path)


def _row_controller(study: str | Path, key: str, track: str, dest: Path) -> Path:
    """Row ``key`` of ``track`` of the study in ``study`` as a controller directory at ``dest``."""
    opened = _finished().Study.open(study)
    _, unseen = opened.sites(track)
    return write_controller(opened.row(key, track, unseen[0]), dest)


def _finished() -> ModuleType:
    """:mod:`uavris.experiments.study.finished`, where a study's row is scored or exported: it loads
    the study's code (torch, the train extra), which scoring a policy never needs."""
    import uavris.experiments.study.finished

    return uavris.experiments.study.finished


def check_one_start(scenario: str | None, layout: str | None) -> None:
    """A named scenario is a start in the paper's hall (docs/halls.md), a layout a hall with its
    start: both at once would mix the paper's start with another hall's devices."""
    if scenario is not None and layout is not None:
        raise UsageError(f"--scenario {scenario} is a start in the paper's hall and --layout {layout} a hall with its "
                         "own start; pass one of them")


def paper_hall(system: SystemConfig) -> SystemConfig:
    """``system`` with the paper's devices: where the named scenarios (fig2, train1..8,
    unseen1..2) are, whatever hall a model was trained in; judged once the --system.* flags
    apply on top (a model of a smaller room flies there with ``--system.room 40 40 8``)."""
    return replace(system, users=PAPER_LAYOUT.users)


def _evaluate_row(a: EvaluateArgs, args: list[str]) -> None:
    """``uavris evaluate OUT --row KEY``: a row of the study in OUT, in the site the flags name."""
    study = _finished().Study.open(a.target)
    rc = study.config
    ran = {t.name: t for t in rc.tracks}
    track = a.track or ("deployment" if "deployment" in ran else list(ran)[-1])
    if track not in ran:
        raise UsageError(f"--track {track}: the study in {a.target} ran {', '.join(ran)}")
    base = rc.system.replace(observe_devices=True) if ran[track].layouts else rc.system
    system, hall, _ = in_hall(a.layout, base, written(a.system))
    if hall is None and a.scenario is None:
        raise UsageError("--row: name where to evaluate it: --layout HALL (its devices and start) or --scenario NAME")
    site = Site(a.scenario or hall.name, system, None if a.scenario else hall.start)
    site.scenario.validate_for(site.system)
    row = study.row(str(a.row), track, site)
    print(seed_note(row, study.seeds(row, track, site)), end="", file=sys.stderr)
    episodes = rc.eval_episodes if a.episodes is None else a.episodes
    with writing(a.out or results_dir(row)) as out:
        summary, path = evaluate_target(row, scenario=site.scenario, layout=a.layout, episodes=episodes,
                                        seed=a.seed, out=out,
                                        phase_control=a.phase_control, device=resolve_device(a.device),
                                        progress=a.progress, system=site.system, trajectory=a.trajectory,
                                        references=a.references)
    _print_evaluation(f"{row.key} ({summary['label']}, {track} track)", summary, path)


def _print_evaluation(what: str, summary: dict, path: Path) -> None:
    if summary.get("warning"):
        print(f"uavris: warning: {summary['warning']}", file=sys.stderr)
    print(f"{what} in {summary['scenario']} ({summary['hall']}): average sum rate {summary['mean']:.2f} bps/Hz "
          f"(95% CI {rate_interval(summary['ci_low'], summary['ci_high'])}, IQM {summary['iqm']:.2f}, "
          f"{counted(summary['episodes'], 'episode')}) -> {path}")
    for m, part in summary.get("active_pairs", {}).items():
        print(f"  slots with {m} active pair{'s' * (m != '1')}: {part['share']:.0%} of the slots, mean sum rate "
              f"{part['rate']:.2f} bps/Hz")
    for name, ref in summary.get("references", {}).items():
        d = summary["paired"][name]  # the target minus the reference, paired on the same episodes
        print(f"  beside it on the same episodes: {name} {ref['mean']:.2f} bps/Hz "
              f"(95% CI {rate_interval(ref['ci_low'], ref['ci_high'])}); {what} minus it "
              f"{signed(d['mean'])} {interval(d['ci_low'], d['ci_high'], signed)} (paired, 95% CI)")
    if summary.get("fraction_of_oracle") is not None:
        print(f"  {what} reaches {100 * summary['fraction_of_oracle']:.1f}% of the oracle")
    if "bound" in summary:
        print(f"  no controller can exceed {summary['bound']['mean']:.2f} bps/Hz on these episodes (the bound, "
              f"docs/model.md); {what} reaches {100 * summary['fraction_of_bound']:.1f}% of it")


@dataclass(frozen=True, kw_only=True)
class StudyRowFlags:
    """The flags that score a row of a study (benchmark, sweep): the row, its track, and whether to trust a pickle."""

    row: Unset[str] = None
    """a row of a study's report, the target being the study's output directory: exported as a controller into
    OUT/controller (uavris export) and scored as the study scores it"""
    track: TrackName = "deployment"
    """the track of --row"""
    trust_pickle: bool = False
    """load a run that holds only SB3's pickled archive (uavris 0.3's, or another tool's): reading it runs whatever
    it holds, so only for runs you trust (uavris's own runs are read from safetensors and JSON)"""


# --------------------------------------------------------------------------------------- benchmark
@dataclass(frozen=True)
class BenchmarkArgs(StudyRowFlags):
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
    system: SystemFlags = field(default_factory=SystemFlags)
    """the system: the target's own, with these fields changed"""


def benchmark_command(args: list[str]) -> None:
    """Score a target on the study's protocol: the paper's unseen scenarios and the unseen layouts.

    The episodes and seeds are the report's (--preset), so each row compares with the same row
    of runs/PRESET/report.md. In every cell the zero action and the oracle are evaluated on the
    same episodes. Writes OUT/benchmark.md (the table: fraction of the oracle, difference to the
    zero action with its paired 95% CI, means over cells), benchmark.csv, benchmark.json and
    each cell's per-episode CSVs.
    """
    a = parse_in_hall(BenchmarkArgs, args, "uavris benchmark", benchmark_command.__doc__ or "")
    if a.layout is not None and a.cells != "all":
        raise UsageError(f"--cells {a.cells} chooses among the protocol's cells and --layout is a cell of its own; "
                         "pass one of them")
    flags = written(a.system)
    layered(SystemConfig(), flags)  # each flag's own range judged before anything is written
    with writing(a.out or default_benchmark_dir(a.target if a.row is None else a.row)) as out:
        if a.row is not None:  # the study's row as a controller of its own, kept beside the results
            a = replace(a, target=str(_row_controller(a.target, a.row, a.track, out / "controller")))
        system = in_hall(a.layout, resolve_target(a.target).own_system(), flags).system  # --layout: one cell
        rows, md = benchmark(a.target, a.preset, a.cells, out, resolve_device(a.device), progress=a.progress,
                             system=system, phase_control=a.phase_control, layout=a.layout,
                             trust_pickle=a.trust_pickle)
    for warning in dict.fromkeys(r["warning"] for r in rows if r.get("warning")):  # each once
        print(f"uavris: warning: {warning}", file=sys.stderr)
    print(md.read_text(), end="")
    print(f"-> {md}")


# ------------------------------------------------------------------------------------------- sweep
@dataclass(frozen=True)
class SweepArgs(StudyRowFlags):
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
    system: SystemFlags = field(default_factory=SystemFlags)
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
    from uavris.experiments.tools.sweep import parse_axis, sweep

    a = parse_in_hall(SweepArgs, args, "uavris sweep", sweep_command.__doc__ or "")
    system, hall, _ = in_hall(a.layout, SystemConfig(), written(a.system))
    row_of = None
    if a.row is not None:
        if len(a.targets) != 1:
            raise UsageError(f"--row {a.row}: name one study (its output directory) as the policy, got "
                             f"{len(a.targets)}")
        row_of = a.targets[0]
    if not a.param:
        raise UsageError("sweep: give one or two --param NAME VALUES (see uavris sweep --help)")
    check_one_start(a.scenario, a.layout)
    twice = sorted({t for t in a.targets if a.targets.count(t) > 1})
    if twice:
        raise UsageError(f"sweep: {', '.join(twice)} named more than once; name each policy once")
    axes = [parse_axis(name, spec) for name, spec in a.param]
    if a.layout is not None and any(ax.name == "devices" for ax in axes):
        raise UsageError(f"--param system.devices sweeps generated halls of each count, --layout {a.layout} is one "
                         "hall; pass one of them")
    if a.out is None:
        whole = repr((a.targets, a.param, a.scenario, a.layout, a.episodes, a.halls, system.to_dict())).encode()
        name = "-".join(ax.name for ax in axes) + "-" + hashlib.sha256(whole).hexdigest()[:8]
        out = Path("runs/sweeps") / name
    else:
        out = a.out
    output_dir(out)
    if row_of is not None:  # the study's row as a controller of its own, kept beside the results
        with writing(out):  # sweep() holds the lock for the sweep itself
            a = replace(a, targets=(str(_row_controller(row_of, a.row, a.track, out / "controller")),))
    paths = sweep(a.targets, axes, out, base=system, scenario=a.scenario or hall, episodes=a.episodes, halls=a.halls,
                  workers=a.workers, backend=a.backend, progress=a.progress, trust_pickle=a.trust_pickle,
                  warn=lambda w: print(f"uavris: warning: {w}", file=sys.stderr), layout=a.layout)
    print("wrote " + ", ".join(str(p) for p in paths))


# -------------------------------------------------------------------------- a row of several seeds


def seed_note(row: Any, seeds: list[int]) -> str:
    """A line saying which of its seeds a row of several is (the report's row of that name is their
    mean), and how to name the others; nothing for a row of one seed."""
    if len(seeds) < 2:
        return ""
    others = ", ".join(f"{row.variant}@s{s}" for s in seeds if s != (row.seed or 0))
    return (f"note: this is seed {row.seed or 0} of the row's {len(seeds)} seeds ({', '.join(map(str, seeds))}); the "
            f"report's {row.variant} is their mean; the others are {others}\n")
