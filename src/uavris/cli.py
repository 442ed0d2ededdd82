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

from uavris.errors import ConfigError

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
    phase_control: str = "agent",
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
        phase_control: agent (policy sets all 22 action entries) or optimizer (policy moves, optimiser sets phases).
        no_progress: no progress bar.
    """
    from uavris.experiments.train_expert import default_run_dir, preset_config, train

    cfg = preset_config(algo, scenario, seed, preset, total_steps=total_steps, eval_every=eval_every,
                        eval_episodes=eval_episodes, checkpoint_every=checkpoint_every,
                        system=_system(system) if system else None, phase_control=phase_control)
    if hp.as_dict():
        cfg = dataclasses.replace(cfg, hyperparams=cfg.hyperparams.replace(**hp.as_dict()))
    run_dir = out or default_run_dir(cfg)
    model = train(cfg, run_dir, resume=resume, force=force, progress=not no_progress)
    from uavris.io import read_json

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
    phase_control: Optional[str] = None,
) -> None:
    """Evaluate an expert run, a Decision Transformer or a baseline on seeded episodes (deterministic).

    Writes per-episode CSV and a JSON summary (mean, 95% CI, IQM) to RUN_DIR/eval/ (or --out).

    Args:
        target: run dir (train, pretrain-dt, finetune-dt), DT model dir, or a reference: hover (the zero action), random, hover-random-phases, hover-aligned, hover-optimizer, oracle, oracle-greedy (also as baseline:NAME).
        scenario: scenario to evaluate in (default: the run's own; required for baselines).
        episodes: number of evaluation episodes (seeds SEED .. SEED+EPISODES-1).
        seed: seed of the first evaluation episode.
        out: output directory.
        phase_control: optimizer replaces the policy's RIS phases by the per-slot optimiser's
            (default: as the run was trained).
    """
    from uavris.experiments.evaluate import evaluate_target

    summary, path = evaluate_target(target, scenario=scenario, episodes=episodes, seed=seed, out=out,
                                    phase_control=phase_control)
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
    backend: str = "local",
    ray_address: Optional[str] = None,
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
        backend: local (process pool) or ray (pip install 'uavris[ray]').
        ray_address: address of a running Ray cluster (default: start a local instance).
    """
    from uavris.experiments.compare import compare_algorithms

    report = compare_algorithms(preset=preset, seeds=seeds, workers=workers, out=out, algos=algos,
                                scenario=scenario, eval_episodes=eval_episodes, backend=backend,
                                ray_address=ray_address)
    print(f"report: {report}")


@app.command(name="demo")
def demo_cmd(episodes: int = 32, seed: int = 0, scenario: str = "fig2") -> None:
    """Roll out simple policies and print their average sum rate."""
    from uavris.demo import main as demo_main

    demo_main(["--episodes", str(episodes), "--seed", str(seed), "--scenario", scenario])


@app.command(name="collect")
def collect_cmd(
    experts: tuple[Path, ...],
    trajectories: int = 500,
    out: Path = Path("runs/datasets/experts-v0"),
    seed: int = 2_000_000,
    force: bool = False,
    no_progress: bool = False,
) -> None:
    """Roll expert runs out deterministically and write a Minari dataset for the Decision Transformer.

    Each expert acts in its own scenario without exploration noise; episodes are batched.
    The dataset (DIR/data/metadata.json + main_data.hdf5) records per-episode scenario,
    expert and seed, and the system configuration and observation layout it was made with.

    Args:
        experts: expert run directories made by `uavris train` (one per scenario).
        trajectories: episodes per expert (the paper uses 500).
        out: dataset directory.
        seed: seed of the first episode; expert k uses SEED + k*TRAJECTORIES onwards.
        force: replace an existing dataset.
        no_progress: no progress bar.
    """
    from uavris.experiments.collect import collect, dataset_summary

    path = collect(experts, trajectories, out, seed=seed, force=force, progress=not no_progress)
    summary = dataset_summary(path)
    rates = ", ".join(f"{s} {v['avg_sum_rate']:.2f}" for s, v in summary["scenarios"].items())
    print(f"dataset {path} ({summary['dataset_id']}): {summary['episodes']} episodes, {summary['slots']} slots; "
          f"average sum rate per scenario (bps/Hz): {rates}")


@app.command(name="pretrain-dt")
def pretrain_dt_cmd(
    dataset: Path,
    preset: str = "quick",
    seed: int = 0,
    out: Optional[Path] = None,
    resume: bool = False,
    force: bool = False,
    steps: Optional[int] = None,
    batch_size: Optional[int] = None,
    learning_rate: Optional[float] = None,
    warmup_steps: Optional[int] = None,
    checkpoint_every: Optional[int] = None,
    context: Optional[int] = None,
    width: Optional[int] = None,
    depth: Optional[int] = None,
    heads: Optional[int] = None,
    dropout: Optional[float] = None,
    attention: Optional[str] = None,
    no_progress: bool = False,
) -> None:
    """Pre-train a Decision Transformer offline on an expert dataset (paper Algorithm 1, stage 1).

    Writes a run directory (default runs/dt/pretrain-DATASET-sSEED-PRESET) with config.json,
    train_log.csv, TensorBoard logs (tb/), checkpoints (safetensors + JSON) and the final
    model.safetensors + model.json, which `uavris evaluate` and `uavris finetune-dt` accept.

    Args:
        dataset: dataset directory written by `uavris collect`.
        preset: smoke (seconds), quick (minutes), paper (the DT paper's 100,000 steps; hours).
        seed: seed of initialisation, window sampling and dropout.
        out: run directory.
        resume: continue an interrupted run from its last checkpoint.
        force: delete the run directory and train from scratch.
        steps: gradient steps (default: the preset's).
        batch_size: context windows per step (whole episodes with --attention banded; 16 of them cost about 64 windows).
        learning_rate: AdamW learning rate after warm-up.
        warmup_steps: linear warm-up steps.
        checkpoint_every: gradient steps between checkpoints.
        context: slots per context window (DT paper: 20).
        width: embedding width (DT paper: 128).
        depth: transformer blocks (DT paper: 3).
        heads: attention heads (DT paper: 1).
        dropout: dropout rate (DT paper: 0.1).
        attention: window (DT paper: re-reads the last context slots) or banded (sliding band, cached rollouts).
        no_progress: no progress bar.
    """
    from uavris.experiments.pretrain import default_pretrain_dir, pretrain, pretrain_config
    from uavris.io import read_json

    cfg = pretrain_config(dataset, preset, seed, steps=steps, batch_size=batch_size, learning_rate=learning_rate,
                          warmup_steps=warmup_steps, checkpoint_every=checkpoint_every, context=context, width=width,
                          depth=depth, heads=heads, dropout=dropout, attention=attention)
    run_dir = pretrain(cfg, out or default_pretrain_dir(cfg), resume=resume, force=force, progress=not no_progress)
    done = read_json(run_dir / "done.json")
    print(f"pre-trained {run_dir}: {done['gradient_steps']} steps, final action loss {done['final_loss']:.4f}, "
          f"default target return {done['target_return']:.1f}")


@app.command(name="finetune-dt")
def finetune_dt_cmd(
    model: Path,
    scenario: str,
    preset: str = "quick",
    seed: int = 0,
    out: Optional[Path] = None,
    resume: bool = False,
    force: bool = False,
    rounds: Optional[int] = None,
    candidates: Optional[int] = None,
    elites: Optional[int] = None,
    noise_sigma: Optional[float] = None,
    selection: Optional[str] = None,
    rollouts_per_seed: Optional[int] = None,
    epochs_per_round: Optional[int] = None,
    learning_rate: Optional[float] = None,
    target_return: Optional[float] = None,
    eval_episodes: Optional[int] = None,
    no_progress: bool = False,
) -> None:
    """Fine-tune a pre-trained Decision Transformer online in a scenario (paper Algorithm 1, stage 2).

    Each round collects CANDIDATES noisy trajectories, keeps the ELITES best by return and
    fine-tunes on them; the zero-shot policy (round 0) and every round are evaluated on the
    same seeded episodes. Writes finetune.csv (with the environment interactions used),
    TensorBoard logs, checkpoints and the final model to a run directory (default
    runs/dt/finetune-SCENARIO-sSEED-PRESET).

    Args:
        model: pre-trained model directory (a `uavris pretrain-dt` run directory or checkpoint).
        scenario: scenario to adapt to, e.g. unseen1 or unseen2.
        preset: smoke (seconds), quick (minutes), paper (H = 10 rounds).
        seed: seed of the exploration noise, window sampling and dropout.
        out: run directory.
        resume: continue an interrupted run from its last completed round.
        force: delete the run directory and start over.
        rounds: fine-tuning rounds H.
        candidates: trajectories collected per round N (paper: 80).
        elites: trajectories kept per round K (paper: 50).
        noise_sigma: standard deviation of the Gaussian exploration noise on actions.
        selection: elites: paired (largest return relative to the same episode seed's other rollouts; default) or return (the paper's top-K).
        rollouts_per_seed: noisy rollouts of each episode seed with paired selection (CANDIDATES / this = seeds per round).
        epochs_per_round: passes over the elite slots per round.
        learning_rate: AdamW learning rate after warm-up.
        target_return: target return R_hat_1 (default: the pre-trained model's).
        eval_episodes: evaluation episodes after each round.
        no_progress: no progress bar.
    """
    from uavris.experiments.finetune import default_finetune_dir, finetune, finetune_config
    from uavris.io import read_json

    cfg = finetune_config(model, scenario, preset, seed, rounds=rounds, candidates=candidates, elites=elites,
                          noise_sigma=noise_sigma, selection=selection, rollouts_per_seed=rollouts_per_seed,
                          epochs_per_round=epochs_per_round, learning_rate=learning_rate,
                          target_return=target_return, eval_episodes=eval_episodes)
    run_dir = finetune(cfg, out or default_finetune_dir(cfg), resume=resume, force=force, progress=not no_progress)
    done = read_json(run_dir / "done.json")
    z, f = done["zero_shot_eval"], done["final_eval"]
    print(f"fine-tuned {run_dir} in {scenario}: average sum rate {z['mean']:.2f} (zero-shot) -> {f['mean']:.2f} "
          f"bps/Hz after {done['rounds']} rounds, {done['env_interactions']} environment interactions")


@app.command(name="reproduce")
def reproduce_cmd(
    preset: str = "quick",
    out: Optional[Path] = None,
    workers: int = 2,
    backend: str = "local",
    ray_address: Optional[str] = None,
    force: tuple[str, ...] = (),
    seed: int = 0,
    compare_seeds: Optional[int] = None,
    eval_episodes: Optional[int] = None,
    trajectories: Optional[int] = None,
    system: tuple[str, ...] = (),
    track: str = "both",
    expert_algo: str = "auto",
    no_progress: bool = False,
) -> None:
    """Reproduce the paper's study end to end in two tracks: Fig. 2, experts, dataset, DT, Fig. 3, report.

    Paper track: compare, experts-train, experts-unseen, dataset, pretrain, finetune-unseen1/2,
    evaluate-unseen1/2 (experts: the comparison's winner). Strong track (learned motion, optimised
    phases, experts initialised from the oracle): the same stages prefixed strong-. Each stage is
    stored under OUT/stages/NAME-KEY (KEY = hash of its configuration and inputs): a rerun skips
    finished stages and resumes an interrupted one; independent stages run concurrently.
    Writes OUT/report.md and OUT/figures/.

    Args:
        preset: smoke (minutes), quick (< 60 min on 2 cores), paper (hours; sized like the paper).
        out: output directory (default runs/PRESET).
        workers: parallel job processes (local backend) or CPUs of a local Ray instance.
        backend: local (process pool) or ray (pip install 'uavris[ray]').
        ray_address: address of a running Ray cluster (default: start a local instance).
        force: stage(s) to rerun even if finished, e.g. --force pretrain.
        seed: seed of the experts and the DT.
        compare_seeds: seeds per algorithm in the comparison (default 2 smoke, 3 quick, 5 paper).
        eval_episodes: evaluation episodes per policy (default 8 smoke, 32 quick, 100 paper).
        trajectories: expert trajectories per training scenario (default 4 smoke, 100 quick, 500 paper).
        system: system-config overrides KEY=VALUE.
        track: both, paper (the published study) or strong (learned motion, optimised phases).
        expert_algo: paper track's expert algorithm: auto (the comparison's winner by IQM) or ddpg, ppo, sac, td3.
        no_progress: no progress bar.
    """
    from uavris.experiments.reproduce import ReproduceConfig, reproduce

    rc = ReproduceConfig(preset=preset, seed=seed, compare_seeds=compare_seeds, eval_episodes=eval_episodes,
                         trajectories=trajectories, track=track, expert_algo=expert_algo,
                         **({"system": _system(system)} if system else {}))
    report = reproduce(rc, out or Path("runs") / preset, workers=workers, backend=backend, ray_address=ray_address,
                       force=force, progress=not no_progress)
    print(f"report: {report}")


def main(argv: list[str] | None = None) -> int:
    from uavris.errors import UavrisError

    try:
        app.cli(prog="uavris", description="uavris: UAV-mounted RIS D2D simulator, DRL experts and Decision "
                "Transformer.", args=argv)
    except UavrisError as e:
        print(f"uavris: error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("uavris: interrupted; rerun with --resume to continue from the last checkpoint", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
