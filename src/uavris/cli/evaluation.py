"""The commands that roll policies out or look at runs: ``evaluate``, ``collect``, ``demo``, ``plot``.

Lives here: each command's flags (a small dataclass tyro reads) and the call into the
library. Not here: the rollouts, datasets and figures themselves (:mod:`uavris.experiments`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Optional

import tyro

from uavris.cli.parsing import output_dir, parse
from uavris.presets import COLLECT_SEED, EVAL_SEED


# ---------------------------------------------------------------------------------------- evaluate
@dataclass(frozen=True)
class EvaluateArgs:
    target: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="RUN|MODEL|REFERENCE")]
    """a run directory (train, pretrain-dt, finetune-dt), a DT model directory, or a reference:
    hover (the zero action), random, hover-random-phases, hover-aligned, hover-optimizer,
    oracle, oracle-greedy (also written baseline:NAME)"""
    scenario: Optional[str] = None
    """scenario to evaluate in (default: the run's own; required for references and pre-trained DTs)"""
    episodes: int = 100
    """evaluation episodes (seeds SEED .. SEED+EPISODES-1)"""
    seed: int = EVAL_SEED
    """seed of the first evaluation episode"""
    out: Optional[Path] = None
    """output directory (default RUN/eval, or runs/baselines/NAME/eval for a reference)"""
    phase_control: Optional[str] = None
    """optimizer: replace the policy's RIS phases by the per-slot optimiser's (default: as trained)"""
    device: str = "cpu"
    """torch device: cpu, cuda, or auto"""
    no_progress: bool = False
    """no progress bar"""


def evaluate_command(args: list[str]) -> None:
    """Evaluate a trained policy or a reference deterministically on seeded episodes.

    Writes OUT/SCENARIO-seedSEED-nEPISODES.csv (one row per episode: average sum rate,
    return, length, energy) and .json (mean, 95% CI, IQM) and prints the summary.
    """
    from uavris.agents.torch_device import resolve_device
    from uavris.experiments.evaluate import evaluate_target

    a = parse(EvaluateArgs, args, "uavris evaluate", evaluate_command.__doc__ or "")
    output_dir(a.out)
    summary, path = evaluate_target(a.target, scenario=a.scenario, episodes=a.episodes, seed=a.seed, out=a.out,
                                    phase_control=a.phase_control, device=resolve_device(a.device),
                                    progress=not a.no_progress)
    print(f"{a.target} in {summary['scenario']}: average sum rate {summary['mean']:.2f} bps/Hz "
          f"(95% CI {summary['ci_low']:.2f}-{summary['ci_high']:.2f}, IQM {summary['iqm']:.2f}, "
          f"{summary['episodes']} episodes) -> {path}")


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
    no_progress: bool = False
    """no progress bar"""


def collect_command(args: list[str]) -> None:
    """Roll expert runs out deterministically and write a Minari dataset for the Decision Transformer.

    Each expert acts in its own scenario without exploration noise. Writes OUT/data/
    (metadata.json + main_data.hdf5): per-episode scenario, expert and seed, the system
    configuration and the environment spec (minari's recover_environment() rebuilds the env).
    """
    from uavris.experiments.collect import collect, dataset_summary

    a = parse(CollectArgs, args, "uavris collect", collect_command.__doc__ or "")
    output_dir(a.out)
    path = collect(a.experts, a.trajectories, a.out, seed=a.seed, force=a.force, progress=not a.no_progress)
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
    scenario: str = "fig2"
    """start position: fig2, train1..train8, unseen1, unseen2"""


def demo_command(args: list[str]) -> None:
    """Roll out the zero action, random actions and a co-phasing hover, and print their average sum rate."""
    from uavris.demo import run_demo

    a = parse(DemoArgs, args, "uavris demo", demo_command.__doc__ or "")
    run_demo(a.episodes, a.seed, a.scenario)


# -------------------------------------------------------------------------------------------- plot
@dataclass(frozen=True)
class PlotArgs:
    runs: Annotated[tuple[Path, ...], tyro.conf.Positional, tyro.conf.arg(metavar="RUN")]
    """run directories written by train, pretrain-dt or finetune-dt (overlaid by kind)"""
    out: Path = Path("runs/plots/curves")
    """output file stem: writes OUT.png and OUT.pdf"""
    labels: Optional[tuple[str, ...]] = None
    """legend labels, one per run (default: the directory names)"""


def plot_command(args: list[str]) -> None:
    """Draw learning curves of one or more runs (training episodes, periodic evaluations with 95% CIs).

    Expert runs: average sum rate against environment steps; DT pre-training: action loss
    against gradient steps; DT fine-tuning: evaluation after each round. Writes OUT.png and
    OUT.pdf.
    """
    from uavris.experiments.run_curves import plot_runs

    a = parse(PlotArgs, args, "uavris plot", plot_command.__doc__ or "")
    output_dir(a.out.parent, "--out's folder")
    paths = plot_runs(list(a.runs), a.out, list(a.labels) if a.labels else None)
    print("wrote " + ", ".join(str(p) for p in paths))
