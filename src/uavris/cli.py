"""Command-line interface: ``uavris train | evaluate | compare-algorithms | demo``.

Bad input (an unknown algorithm or scenario, a directory that is not a run, a corrupt
checkpoint) prints one line ``uavris: error: ...`` and exits with code 2.
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Optional

import tyro
import yaml

from uavris.config import ConfigError

EXIT_BAD_INPUT = 2


@dataclass(frozen=True)
class HyperparamOverrides:
    """Override any hyperparameter of the preset (unset: the preset's documented value)."""

    net_arch: Optional[tuple[int, ...]] = None
    """hidden layer sizes of actor and critic, e.g. --hp.net-arch 256 256"""
    learning_rate: Optional[float] = None
    gamma: Optional[float] = None
    reward_scale: Optional[float] = None
    """multiplies the sum-rate reward seen by the learner"""
    n_envs: Optional[int] = None
    """parallel systems in the batched training env"""
    batch_size: Optional[int] = None
    buffer_size: Optional[int] = None
    learning_starts: Optional[int] = None
    tau: Optional[float] = None
    gradient_steps: Optional[int] = None
    """gradient steps per vector step (off-policy)"""
    action_noise: Optional[float] = None
    """Gaussian exploration sigma of DDPG/TD3"""
    policy_delay: Optional[int] = None
    target_policy_noise: Optional[float] = None
    ent_coef: Optional[str] = None
    n_steps: Optional[int] = None
    """PPO rollout length per env"""
    n_epochs: Optional[int] = None
    gae_lambda: Optional[float] = None
    clip_range: Optional[float] = None

    def as_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if getattr(self, f.name) is not None}


def parse_system_overrides(items: tuple[str, ...]) -> dict[str, Any]:
    """``KEY=VALUE`` pairs for :class:`SystemConfig` fields; values parsed as YAML."""
    out: dict[str, Any] = {}
    for item in items:
        if "=" not in item:
            raise ConfigError(f"--system expects KEY=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        out[key.strip()] = yaml.safe_load(value)
    return out


def _system(items: tuple[str, ...]):
    from uavris.config import SystemConfig

    overrides = parse_system_overrides(items)
    try:
        return SystemConfig.from_dict({**SystemConfig().to_dict(), **overrides})
    except TypeError as e:
        raise ConfigError(f"bad --system value: {e}") from None


app = tyro.extras.SubcommandApp()


@app.command(name="train")
def train_cmd(
    algo: str = "ddpg",
    scenario: str = "fig2",
    seed: int = 0,
    preset: str = "quick",
    out: Optional[Path] = None,
    resume: bool = False,
    force: bool = False,
    total_steps: Optional[int] = None,
    eval_every: Optional[int] = None,
    eval_episodes: Optional[int] = None,
    checkpoint_every: Optional[int] = None,
    hp: HyperparamOverrides = HyperparamOverrides(),
    system: tuple[str, ...] = (),
    no_progress: bool = False,
) -> None:
    """Train a DRL expert (ddpg, ppo, sac or td3) on a scenario.

    Writes a run directory (default runs/train/ALGO-SCENARIO-sSEED-PRESET) with config.yaml,
    episodes.csv, evals.csv, TensorBoard logs (tb/), checkpoints and model.zip.

    Args:
        algo: ddpg, ppo, sac or td3.
        scenario: fig2, train1..train8, unseen1, unseen2.
        seed: training seed (network initialisation, exploration and training episodes).
        preset: smoke (seconds), quick (minutes), paper (hours; sized like the paper).
        out: run directory.
        resume: continue an interrupted run from its last checkpoint.
        force: delete the run directory and train from scratch.
        total_steps: environment steps (default: the preset's).
        eval_every: environment steps between deterministic evaluations.
        eval_episodes: episodes per evaluation.
        checkpoint_every: environment steps between checkpoints.
        hp: hyperparameter overrides.
        system: system-config overrides KEY=VALUE, e.g. --system noise_dbm=-90 horizon=50.
        no_progress: no progress bar.
    """
    from uavris.experiments.training import default_run_dir, preset_config, train

    cfg = preset_config(algo, scenario, seed, preset, total_steps=total_steps, eval_every=eval_every,
                        eval_episodes=eval_episodes, checkpoint_every=checkpoint_every, system=_system(system) if system else None)
    if hp.as_dict():
        cfg = dataclasses.replace(cfg, hyperparams=cfg.hyperparams.replace(**hp.as_dict()))
    run_dir = out or default_run_dir(cfg)
    model = train(cfg, run_dir, resume=resume, force=force, progress=not no_progress)
    from uavris.experiments.io import read_json

    final = read_json(Path(run_dir) / "done.json")["final_eval"]
    print(f"trained {model}: average sum rate {final['mean']:.2f} bps/Hz "
          f"(95% CI {final['ci_low']:.2f}-{final['ci_high']:.2f}, {final['episodes']} episodes)")


@app.command(name="evaluate")
def evaluate_cmd(
    target: Annotated[str, tyro.conf.Positional],
    scenario: Optional[str] = None,
    episodes: int = 100,
    seed: int = 1_000_000,
    out: Optional[Path] = None,
) -> None:
    """Evaluate a trained run (deterministic policy) or a baseline on seeded episodes.

    Writes per-episode CSV and a JSON summary (mean, 95% CI, IQM) to RUN_DIR/eval/ (or --out).

    Args:
        target: a run directory, or baseline:random, baseline:hover-random-phases, baseline:hover-aligned.
        scenario: scenario to evaluate in (default: the run's own; required for baselines).
        episodes: number of evaluation episodes (seeds SEED .. SEED+EPISODES-1).
        seed: seed of the first evaluation episode.
        out: output directory.
    """
    from uavris.experiments.evaluate import evaluate_target

    summary, path = evaluate_target(target, scenario=scenario, episodes=episodes, seed=seed, out=out)
    print(f"{target} in {summary['scenario']}: average sum rate {summary['mean']:.2f} bps/Hz "
          f"(95% CI {summary['ci_low']:.2f}-{summary['ci_high']:.2f}, IQM {summary['iqm']:.2f}, "
          f"{summary['episodes']} episodes) -> {path}")


@app.command(name="compare-algorithms")
def compare_cmd(
    preset: str = "quick",
    seeds: int = 5,
    workers: int = 2,
    out: Optional[Path] = None,
    algos: tuple[str, ...] = ("ddpg", "ppo", "sac", "td3"),
    scenario: str = "fig2",
    eval_episodes: Optional[int] = None,
) -> None:
    """Train DDPG, PPO, SAC and TD3 over several seeds and compare them (paper Fig. 2).

    Writes learning curves (PNG, PDF), a results table (CSV, Markdown) with mean, IQM and
    bootstrap CIs, the baselines and the paper's values side by side, to OUT/report.md.
    Finished jobs are skipped on a rerun; interrupted ones resume from their checkpoints.

    Args:
        preset: smoke, quick (< 30 min on 2 cores) or paper (hours).
        seeds: seeds per algorithm.
        workers: parallel training processes.
        out: output directory (default runs/compare-PRESET).
        algos: algorithms to compare.
        scenario: scenario (the paper's Fig. 2 uses fig2 = [15, 20, 4.5]).
        eval_episodes: final evaluation episodes per run (default: 32 smoke/quick, 100 paper).
    """
    from uavris.experiments.compare import compare_algorithms

    report = compare_algorithms(preset=preset, seeds=seeds, workers=workers, out=out, algos=algos,
                                scenario=scenario, eval_episodes=eval_episodes)
    print(f"report: {report}")


@app.command(name="demo")
def demo_cmd(episodes: int = 32, seed: int = 0, scenario: str = "fig2") -> None:
    """Roll out simple policies and print their average sum rate."""
    from uavris.demo import main as demo_main

    demo_main(["--episodes", str(episodes), "--seed", str(seed), "--scenario", scenario])


def main(argv: list[str] | None = None) -> int:
    from uavris.experiments.io import UavrisError

    try:
        app.cli(prog="uavris", description="uavris: UAV-mounted RIS D2D simulator, DRL experts and Decision "
                "Transformer.", args=argv)
    except (UavrisError, ConfigError) as e:
        print(f"uavris: error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("uavris: interrupted; rerun with --resume to continue from the last checkpoint", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
