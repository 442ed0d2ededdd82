"""The commands that train: ``train``, ``compare-algorithms``, ``pretrain-dt``, ``finetune-dt``, ``reproduce``.

Lives here: for each command, the dataclass tyro reads (the flags of the library's config,
:func:`~uavris.cli.options.flags_of`, flattened, plus :class:`~uavris.cli.outputs.RunOptions`),
the build of its config and the function that runs it. The flags *are* the config's fields: a
preset (``--preset``), a YAML file (``train --config``) or a model (``finetune-dt --model``)
supplies the defaults, and every field written on the command line is taken over them.
Not here: what the commands do (:mod:`uavris.experiments`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any, Callable

import tyro

from uavris.agents.dt.checkpoint import dt_system
from uavris.agents.experts import Algorithm
from uavris.agents.torch_device import Device, resolve_device
from uavris.cli.options import (
    LAYOUT_HELP,
    SystemFlags,
    flags_of,
    in_hall,
    layered,
    parse_in_hall,
    shown,
    written,
)
from uavris.cli.outputs import RunOptions, check_run_options, output_dir, writing
from uavris.cli.parsing import Unset, UsageError, load_overrides, parse_built
from uavris.config import ScenarioName, SystemConfig
from uavris.experiments.display.tables import counted, rate_interval
from uavris.experiments.engine.jobs import Backend
from uavris.experiments.study.config import ReproduceConfig
from uavris.experiments.study.reproduce import estimate, reproduce
from uavris.experiments.training.finetune import FinetuneConfig, default_finetune_dir, finetune
from uavris.experiments.training.pretrain import PretrainConfig, default_pretrain_dir, pretrain
from uavris.experiments.training.train_expert import TrainConfig, default_run_dir, train
from uavris.presets import STUDY, Preset
from uavris.runs import read_done

Flat = tyro.conf.arg(name="")  # the config's fields become the command's own flags


def _missing(name: str, prog: str, alternative: str = "") -> UsageError:
    return UsageError(f"missing required argument --{name}{alternative} (see {prog} --help)")


# ------------------------------------------------------------------------------------------ train
TrainFlags = flags_of(TrainConfig)


@dataclass(frozen=True)
class TrainArgs:
    run: Annotated[TrainFlags, Flat] = field(default_factory=TrainFlags)  # once built: the TrainConfig
    options: Annotated[RunOptions, Flat] = RunOptions()
    config: Unset[Path] = None
    """YAML file of TrainConfig fields (e.g. RUN/config.yaml); the preset fills what it leaves out, flags override it
    (default: none, the preset's)"""
    layout: Annotated[Unset[str], tyro.conf.arg(help=LAYOUT_HELP)] = None
    trust_pickle: bool = False
    """with --resume: resume from checkpoints this uavris did not write (SB3's archive and the pickles beside it
    are read by unpickling, which runs whatever they hold; uavris resumes its own, sealed, without this)"""


def _nested_update(base: dict[str, Any], changes: dict[str, Any], where: str) -> dict[str, Any]:
    out = dict(base)
    for key, value in changes.items():
        if key not in base:
            raise UsageError(f"{where}: unknown field {key!r}; known: {', '.join(base)}")
        if isinstance(base[key], dict) and isinstance(value, dict):
            out[key] = _nested_update(base[key], value, f"{where}.{key}")
        else:
            out[key] = value
    return out


def train_config(a: TrainArgs) -> TrainConfig:
    """The run ``uavris train``'s line asks for: the algorithm, preset and scenario it chooses (or
    ``--config`` does), the file's fields on top, in the hall of ``--layout``, and every flag
    written on the line over them. ``--resume`` without ``--config`` continues with the run's
    own ``OUT/config.yaml``."""
    line = written(a.run)
    file, out = a.config, a.options.out
    if file is None and a.options.resume and out is not None and (out / "config.yaml").is_file():
        file = out / "config.yaml"  # the resumed run's configuration, not the preset's defaults
    data = load_overrides(file, "TrainConfig") if file else {}
    chosen = {k: line[k] for k in ("algo", "preset", "scenario") if k in line}
    base = TrainConfig(**{**{k: data[k] for k in ("algo", "preset", "scenario") if k in data}, **chosen})
    if data:
        base = TrainConfig.from_dict({**_nested_update(base.to_dict(), data, f"--config {file}"), **chosen})
    system, hall, _ = in_hall(a.layout, base.system, line.pop("system", {}))
    # a layout's own start, unless a named scenario starts in its hall
    where = {} if hall is None or "scenario" in line else {"scenario": hall.name, "start": hall.start}
    return layered(replace(base, system=system, **where), line).check()


def parse_train(args: list[str]) -> TrainArgs:
    """``uavris train``'s line, parsed once and built (:func:`train_config`)."""
    return parse_built(TrainArgs, args, "uavris train", train_command.__doc__ or "",
                       build=lambda parsed, _: replace(parsed, run=train_config(parsed)),
                       show=lambda built, _: replace(built or TrainArgs(), run=shown(
                           TrainFlags, built.run if built else TrainConfig())))


def train_command(args: list[str]) -> None:
    """Train a DRL expert (ddpg, ppo, sac or td3) in one scenario.

    Writes the run directory OUT (default runs/train/ALGO-SCENARIO-sSEED-PRESET): config.yaml
    (rerun it with --config), episodes.csv, evals.csv, TensorBoard logs (tb/), checkpoints/
    and model.zip. Every TrainConfig field is a flag; --preset and --algo choose the defaults.
    """
    a = parse_train(args)
    run_dir = a.options.out or default_run_dir(a.run)
    device = check_run_options(a.options, run_dir)
    with writing(run_dir):
        model = train(a.run, run_dir, resume=a.options.resume, force=a.options.force,
                      progress=a.options.progress, device=device, trust_pickle=a.trust_pickle)
        final = read_done(run_dir)["final_eval"]
    print(f"trained {model}: average sum rate {final['mean']:.2f} bps/Hz "
          f"(95% CI {rate_interval(final['ci_low'], final['ci_high'])}, {counted(final['episodes'], 'episode')})")


# ------------------------------------------------------------------------------ compare-algorithms
@dataclass(frozen=True)
class CompareArgs:
    layout: Annotated[Unset[str], tyro.conf.arg(help=LAYOUT_HELP)] = None
    preset: Preset = "quick"
    """budgets: smoke (seconds), quick (minutes per run), paper (hours per run)"""
    seeds: Unset[int] = None
    """seeds per algorithm (default: the preset's, as in the study: 2 smoke, 3 quick, 5 paper)"""
    steps: Unset[int] = None
    """environment steps per run (default: the preset's, as in the study: 640 smoke, 25,000 quick,
    2,500,000 paper)"""
    workers: int = 2
    """parallel training processes"""
    out: Unset[Path] = None
    """output directory (default: runs/compare-PRESET)"""
    algos: tuple[Algorithm, ...] = ("ddpg", "ppo", "sac", "td3")
    """algorithms to compare"""
    scenario: Unset[ScenarioName | str] = None
    """scenario (default: the paper's Fig. 2, fig2, [15, 20, 4.5]; with --layout: the layout's start)"""
    eval_episodes: Unset[int] = None
    """final evaluation episodes per run (default: 32 smoke/quick, 100 paper)"""
    eval_every: Unset[int] = None
    """environment steps between the periodic evaluations of each run (default: the preset's,
    10,000 quick); every multiple is a budget the run is scored at (docs/results/budget.md)"""
    backend: Backend = "local"
    """local (process pool) or ray (pip install 'uavris[ray]')"""
    ray_address: Unset[str] = None
    """address of a running Ray cluster (default: start a local instance)"""
    device: Device = "cpu"
    """torch device (auto: CUDA when torch sees one)"""
    progress: bool = True
    """show a progress bar"""
    system: SystemFlags = field(default_factory=SystemFlags)
    """the system trained and evaluated in"""


def compare_command(args: list[str]) -> None:
    """Train several algorithms over several seeds in one scenario and compare them (paper Fig. 2).

    Writes to OUT: learning curves (PNG, PDF), a results table (CSV, Markdown) with mean, IQM
    and bootstrap CIs beside the zero action, the references and the paper's values, and
    report.md. Finished jobs are skipped on a rerun; interrupted ones resume.
    """
    from uavris.experiments.training.compare import compare_algorithms, default_compare_dir

    a = parse_in_hall(CompareArgs, args, "uavris compare-algorithms", compare_command.__doc__ or "")
    system, hall, _ = in_hall(a.layout, SystemConfig(), written(a.system))
    scenario = a.scenario or ("fig2" if hall is None else hall.name)
    start = hall.start if hall is not None and scenario == hall.name else None
    seeds = STUDY[a.preset]["compare_seeds"] if a.seeds is None else a.seeds
    steps = STUDY[a.preset]["compare_steps"] if a.steps is None else a.steps
    with writing(a.out or default_compare_dir(a.preset)) as out:
        report = compare_algorithms(preset=a.preset, seeds=seeds, workers=a.workers, out=out, algos=a.algos,
                                    scenario=scenario, eval_episodes=a.eval_episodes, backend=a.backend,
                                    ray_address=a.ray_address, device=resolve_device(a.device), system=system,
                                    start=start, steps=steps, eval_every=a.eval_every, progress=a.progress)
    print(f"report: {report}")


def _run_dt(fn: Callable[..., Path], cfg: Any, opts: RunOptions, default_dir: Callable[[Any], Path]) -> Path:
    """Run a DT stage (pre-training or fine-tuning) as the options say; its run directory."""
    run_dir = opts.out or default_dir(cfg)
    device = check_run_options(opts, run_dir)
    with writing(run_dir):
        return fn(cfg, run_dir, resume=opts.resume, force=opts.force, progress=opts.progress, device=device)


# ------------------------------------------------------------------------------------- pretrain-dt
PretrainFlags = flags_of(PretrainConfig)


@dataclass(frozen=True)
class PretrainArgs:
    run: Annotated[PretrainFlags, Flat] = field(default_factory=PretrainFlags)  # once built: the PretrainConfig
    options: Annotated[RunOptions, Flat] = RunOptions()


def parse_pretrain(args: list[str]) -> PretrainArgs:
    """``uavris pretrain-dt``'s line, parsed once and built: the preset's run, the flags written on top."""
    prog = "uavris pretrain-dt"

    def build(parsed: PretrainArgs, for_help: bool) -> PretrainArgs:
        line = written(parsed.run)
        if "dataset" not in line and not for_help:
            raise _missing("dataset", prog)
        run = PretrainConfig(dataset=line.pop("dataset", ""), preset=line.pop("preset", "quick"))
        return replace(parsed, run=layered(run, line).check())

    def show(built: PretrainArgs | None, parsed: PretrainArgs | None) -> PretrainArgs:
        given = parsed is not None and parsed.run.dataset is not None
        run = built.run if built is not None else PretrainConfig(dataset="")
        return replace(built or PretrainArgs(), run=shown(PretrainFlags, run, required=() if given else ("dataset",)))

    return parse_built(PretrainArgs, args, prog, pretrain_command.__doc__ or "", build=build, show=show)


def pretrain_command(args: list[str]) -> None:
    """Pre-train a Decision Transformer offline on an expert dataset (paper Algorithm 1, stage 1).

    --dataset is a directory written by `uavris collect`. Writes the run directory OUT
    (default runs/dt/pretrain-DATASET-sSEED-PRESET): config.yaml, train_log.csv, TensorBoard
    logs (tb/), checkpoints/ and model/ (model.safetensors + model.json), which `uavris
    evaluate` and `uavris finetune-dt --model` accept.
    """
    a = parse_pretrain(args)
    run_dir = _run_dt(pretrain, a.run, a.options, default_pretrain_dir)
    done = read_done(run_dir)
    print(f"pre-trained {run_dir}: {done['gradient_steps']} steps, final action loss {done['final_loss']:.4f}, "
          f"default target return {done['target_return']:.1f}")


# ------------------------------------------------------------------------------------- finetune-dt
FinetuneFlags = flags_of(FinetuneConfig)


@dataclass(frozen=True)
class FinetuneArgs:
    run: Annotated[FinetuneFlags, Flat] = field(default_factory=FinetuneFlags)  # once built: the FinetuneConfig
    options: Annotated[RunOptions, Flat] = RunOptions()
    layout: Annotated[Unset[str], tyro.conf.arg(help=LAYOUT_HELP)] = None


def parse_finetune(args: list[str]) -> FinetuneArgs:
    """``uavris finetune-dt``'s line, parsed once and built: the preset's fine-tuning of the model in
    its own system (in the hall of --layout, with its start unless a scenario is named there), the
    flags written on top."""
    prog = "uavris finetune-dt"

    def build(parsed: FinetuneArgs, for_help: bool) -> FinetuneArgs:
        line = written(parsed.run)
        model = line.pop("model", None)
        if model is None and not for_help:
            raise _missing("model", prog)
        system, hall, _ = in_hall(parsed.layout, dt_system(model) if model else SystemConfig(), line.pop("system", {}))
        if hall is None and "scenario" not in line and not for_help:
            raise _missing("scenario", prog, " (or a --layout to adapt to)")
        where = ({"scenario": line.pop("scenario")} if "scenario" in line else
                 {"scenario": hall.name, "start": hall.start} if hall is not None else {"scenario": "unseen1"})
        run = FinetuneConfig(model=model or "", preset=line.pop("preset", "quick"), system=system, **where)
        return replace(parsed, run=layered(run, line).check())

    def show(built: FinetuneArgs | None, parsed: FinetuneArgs | None) -> FinetuneArgs:
        given = written(parsed.run) if parsed is not None else {}
        required = tuple(n for n in ("model", "scenario") if n not in given
                         and not (n == "scenario" and parsed is not None and parsed.layout is not None))
        run = built.run if built is not None else FinetuneConfig(model="", scenario="unseen1", system=SystemConfig())
        return replace(built or FinetuneArgs(), run=shown(FinetuneFlags, run, required=required))

    return parse_built(FinetuneArgs, args, prog, finetune_command.__doc__ or "", build=build, show=show)


def finetune_command(args: list[str]) -> None:
    """Fine-tune a pre-trained Decision Transformer online in a scenario (paper Algorithm 1, stage 2).

    --model is a `uavris pretrain-dt` run or model directory, --scenario the one to adapt
    to. Each round collects CANDIDATES noisy trajectories, keeps ELITES of them (by
    --selection) and fine-tunes on them; the zero-shot policy and every round are evaluated
    on the same seeded episodes. Writes OUT (default runs/dt/finetune-SCENARIO-sSEED-PRESET):
    finetune.csv (with the environment interactions used), TensorBoard logs, checkpoints/
    and model/.
    """
    a = parse_finetune(args)
    run_dir = _run_dt(finetune, a.run, a.options, default_finetune_dir)
    done = read_done(run_dir)
    z, f = done["zero_shot_eval"], done["final_eval"]
    print(f"fine-tuned {run_dir} in {a.run.scenario}: average sum rate {z['mean']:.2f} (zero-shot) -> "
          f"{f['mean']:.2f} bps/Hz after {done['rounds']} rounds, {done['env_interactions']} environment "
          "interactions")


# --------------------------------------------------------------------------------------- reproduce
ReproduceFlags = flags_of(ReproduceConfig)


@dataclass(frozen=True)
class ReproduceArgs:
    study: Annotated[ReproduceFlags, Flat] = field(default_factory=ReproduceFlags)  # once built: the ReproduceConfig
    layout: Annotated[Unset[str], tyro.conf.arg(help="the hall of the paper and strong tracks (their scenarios "
                                                "start in it): paper, layout-train-N / layout-unseen-N "
                                                "(-kK: K devices), or a YAML layout file; it sets --system.users "
                                                "(and --system.room); default: the devices of --system.users")] = None
    out: Unset[Path] = None
    """output directory (default: runs/PRESET); a rerun skips finished stages and resumes the rest"""
    workers: int = 2
    """parallel job processes (local backend) or CPUs of a local Ray instance"""
    backend: Backend = "local"
    """local (process pool) or ray (pip install 'uavris[ray]')"""
    ray_address: Unset[str] = None
    """address of a running Ray cluster (default: start a local instance)"""
    force: tuple[str, ...] = ()
    """stage(s) to rerun even if finished, with every stage that depends on them, e.g. --force pretrain"""
    device: Device = "cpu"
    """torch device (auto: CUDA when torch sees one)"""
    progress: bool = True
    """show a progress bar"""
    report_only: bool = False
    """run nothing: write OUT/report.md and its figures from the stages OUT holds, of the study OUT/study.yaml
    says (its last invocation's parameters; the study's flags are not read): a study stopped part-way"""
    estimate: bool = False
    """print each stage's expected core-minutes and the expected wall clock on --workers, and exit (nothing run
    or written; the stages OUT already holds are "done" and the clock is that of the rest; the cost model of
    uavris.experiments.engine.costs, its unit costs measured on one machine: docs/timings.md)"""


def parse_reproduce(args: list[str]) -> ReproduceArgs:
    """``uavris reproduce``'s line, parsed once and built: the preset's study in the hall, the flags written on top."""
    def build(parsed: ReproduceArgs, _: bool) -> ReproduceArgs:
        line = written(parsed.study)
        system = in_hall(parsed.layout, SystemConfig(), line.pop("system", {})).system
        study = ReproduceConfig(system=system, preset=line.pop("preset", "quick"))
        return replace(parsed, study=layered(study, line).check())

    return parse_built(ReproduceArgs, args, "uavris reproduce", reproduce_command.__doc__ or "", build=build,
                       show=lambda built, _: replace(built or ReproduceArgs(), study=shown(
                           ReproduceFlags, built.study if built else ReproduceConfig())))


def reproduce_command(args: list[str]) -> None:
    """Reproduce the paper's study end to end, in three tracks, and write the report.

    Paper track: compare, experts-train, experts-unseen, dataset, pretrain, finetune-unseen1/2,
    evaluate-unseen1/2 (experts: the comparison's winner). Strong track (learned motion,
    optimised phases, experts imitating the oracle): the same stages prefixed strong-.
    Deployment track (the planning oracle's demonstrations in generated halls, docs/study.md
    section 2): deploy-dataset, deploy-dataset-best (its best 10% by return), deploy-value-labels
    (the learned value's labels), and for each pre-training seed deploy-value (the learned value's
    fit), deploy-pretrain, deploy-bc (behaviour cloning), deploy-goal (the goal-conditioned DT),
    deploy-goal-mlp (the same without attention over time) and deploy-bc-best (filtered behaviour
    cloning) (seed K's: -sK), and
    deploy-evaluate-LAYOUT per unseen layout; with
    --ablation also fine-tuning that tries places (deploy-finetune-places-LAYOUT, per seed), the
    return-conditioned DT's fine-tuning (deploy-finetune-LAYOUT), the data curve
    (deploy-pretrain-nN), the flat encoder (deploy-flat) and the mixed-quality dataset
    (deploy-dataset-mixed, deploy-mixed-dt, deploy-mixed-bc); with --device-counts 3 6 8 10 every
    row zero-shot in unseen halls of those counts too (deploy-evaluate-LAYOUT-kK, docs/places.md), and
    with --count-other-layouts N in N halls of another generator at each of them
    (deploy-evaluate-layout-other-J-kK).
    Each stage is stored under OUT/stages/NAME-KEY (KEY: a hash of its configuration and
    inputs); independent stages run concurrently.
    Writes OUT/report.md and OUT/figures/.
    """
    a = parse_reproduce(args)
    out = a.out or Path("runs") / a.study.preset
    if a.report_only and (a.estimate or a.force):
        raise UsageError("--report-only runs nothing: it takes neither --estimate nor --force")
    if a.estimate:
        print(estimate(a.study, a.workers, out, a.force), end="")
        return
    output_dir(a.out)
    if a.report_only:
        print(f"report: {reproduce(a.study, out, report_only=True)}")
        return
    report = reproduce(a.study, out, workers=a.workers, backend=a.backend, ray_address=a.ray_address, force=a.force,
                       progress=a.progress, device=resolve_device(a.device))
    print(f"report: {report}")


