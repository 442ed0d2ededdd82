"""The paper's DT pipeline (Sec. IV, Algorithm 1): collect, pre-train, fine-tune.

**Collect** (:func:`collect`): each expert run directory (``uavris train``) is rolled out
deterministically, without exploration noise, in its own scenario, ``N`` episodes per
expert, batched; all trajectories go into one Minari dataset (:mod:`uavris.agents.dt_data`)
with per-episode scenario, expert and seed. Episode seeds are ``seed + k N + j`` for expert
k (default seed 2,000,000: never an evaluation seed, which start at 1,000,000, and never a
fine-tuning seed, which start at 3,000,000).

**Pre-train** (:func:`pretrain`, Algorithm 1 stage 1): the loss L_OFF (eq. 16) on
context windows of the dataset, AdamW with decoupled weight decay on the weight matrices,
a linear learning-rate warm-up then a constant rate, gradient-norm clipping. These are
the DT paper's settings (lr 1e-4, weight decay 1e-4, warm-up 10,000 steps, clip 0.25,
batch 64, 100,000 steps in ``paper``). The default target return of the model is the 0.9
quantile of the dataset's episode returns, stored in the checkpoint. With
``attention="banded"`` (:mod:`uavris.agents.dt_model`) a sample is a whole episode instead of
a window, and ``batch_size`` counts episodes.

**Fine-tune** (:func:`finetune`, Algorithm 1 stage 2) in one scenario, for H rounds:
collect N trajectories with Gaussian noise sigma on the DT's actions, keep K elites,
relabel their returns-to-go from the rewards actually received, and minimise L_FT (eq. 19)
on them. The paper fixes N = 80 and K = 50 and leaves the rest open; ours, with reasons:

- Elites (a departure, docs/model.md): by default (``selection="paired"``) the N candidates
  are N / 5 episode seeds with 5 noisy rollouts each, and the K kept are those with the
  largest return relative to the mean of their seed's rollouts. Rollouts of one seed share
  every channel and pairing draw, so the difference is what the actions did; the paper's
  plain top-K by return (eq. 18, ``selection="return"``) mostly keeps episodes that were
  lucky in which pairs were active.

- H = 10 rounds (``paper``), 3 (``quick``): 800 episodes = 80,000 slots of interaction in
  ``paper``, about 3% of one DDPG expert's 2.5 M training steps, which is the saving the
  paper claims for fine-tuning over training an expert.
- sigma = 0.1, the DDPG experts' own exploration noise (actions live in [-1, 1]).
- Learning rate 5e-5 after a 100-step warm-up, one AdamW for all rounds: half the
  pre-training rate, large enough to move within a few hundred steps per round, small
  enough not to erase the pre-trained policy in one round.
- Epochs per round: 5 (``paper``), 2 (``quick``), an epoch being ceil(elite slots / batch)
  sampled windows (banded DT: ceil(elites x context / batch) sampled episodes, about as
  many predicted actions); only the current round's elites are trained on, as in Algorithm 1.
- The target return stays the pre-trained model's default (or ``--target-return``), so
  zero-shot and fine-tuned policies are conditioned alike; the state normalisation and
  return scale of the pre-trained model are kept, so its inputs mean the same thing.
- Environment interactions = slots of the candidate trajectories (N per round, each up to
  T slots); evaluation episodes are reported separately and not counted.

Run directories (every file written atomically; ``--resume`` continues from the last
checkpoint with identical results; a finished run is never redone without ``--force``)::

    config.json          the resolved PretrainConfig / FinetuneConfig ("kind" says which)
    train_log.csv        pre-training: step, loss, learning rate, samples/s
    finetune.csv         fine-tuning: one row per round (round 0 = zero-shot)
    tb/                  TensorBoard logs
    checkpoints/step_N/  model.safetensors + model.json (a loadable model) and, for the
                         latest only, trainer.safetensors + trainer.json (optimizer, RNGs);
                         fine-tuning names them round_N, one per completed round
    checkpoints/latest.json
    model.safetensors, model.json, done.json   the final model and the completion record

A model directory (the run directory, or any ``checkpoints/step_N`` / ``round_N``) is what
``uavris evaluate``, ``uavris finetune-dt --model`` and :func:`load_dt_policy` accept.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from uavris.agents.dt_data import (
    DatasetError,
    TrainingWindows,
    Trajectory,
    default_target_return,
    layout_as_lists,
    load_dataset,
    normalisation_from,
    record_episodes,
    ELITE_RULES,
    select_elites,
    write_dataset,
)
from uavris.agents.dt_model import (
    CheckpointError,
    DecisionTransformer,
    DTConfig,
    load_dt,
    masked_action_loss,
    save_dt,
)
from uavris.agents.dt_policy import DTBatchPolicy
from uavris.agents.evaluation import evaluate
from uavris.agents.hybrid import action_dim_for
from uavris.config import ConfigError, SystemConfig, get_scenario
from uavris.experiments.io import UavrisError, atomic_write_bytes, read_csv, read_json, read_rows, write_csv, write_json
from uavris.experiments.training import (
    configure_torch_threads,
    final_model_path,
    load_model,
    load_run_config,
    run_policy,
)

PRESETS: tuple[str, ...] = ("smoke", "quick", "paper")
PRETRAIN_KIND = "uavris-dt-pretrain"
FINETUNE_KIND = "uavris-dt-finetune"
COLLECT_SEED = 2_000_000
FINETUNE_SEED = 3_000_000
EVAL_SEED = 1_000_000  # the seed `uavris evaluate` and expert training evaluate on
TARGET_QUANTILE = 0.9
LOG_HEADER = ("step", "loss", "learning_rate", "samples_per_s")
ROUND_HEADER = ("round", "env_interactions", "gradient_steps", "candidate_mean_return", "candidate_avg_sum_rate",
                "elite_mean_return", "elite_min_return", "loss", "eval_mean", "eval_ci_low", "eval_ci_high")


@contextlib.contextmanager
def user_errors() -> Iterator[None]:
    """Report dataset and checkpoint problems of the agents layer as one-line UavrisErrors."""
    try:
        yield
    except (DatasetError, CheckpointError) as e:
        raise UavrisError(str(e)) from None


def _check_positive(owner: str, cfg: Any, names: Sequence[str]) -> None:
    for name in names:
        v = getattr(cfg, name)
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 and math.isfinite(v)):
            raise ConfigError(f"{owner}.{name} must be > 0, got {v!r}")


def _check_preset(preset: str) -> None:
    if preset not in PRESETS:
        raise ConfigError(f"unknown preset {preset!r}; choose one of {', '.join(PRESETS)}")


# ============================================================================== collect
def collect(experts: Sequence[str | Path], trajectories: int, out: str | Path, *, seed: int = COLLECT_SEED,
            force: bool = False, progress: bool = True) -> Path:
    """Roll every expert out ``trajectories`` times in its own scenario and write a dataset."""
    configure_torch_threads()
    if not experts:
        raise UavrisError("give at least one expert run directory (--experts RUN_DIR ...)")
    if trajectories < 1:
        raise UavrisError(f"--trajectories must be >= 1, got {trajectories}")
    out = Path(out)
    runs = []
    for run_dir in experts:
        run_dir = Path(run_dir)
        if not run_dir.is_dir():
            raise UavrisError(f"{run_dir} is not a directory (expected an expert run directory)")
        runs.append((run_dir, load_run_config(run_dir)))
    system = runs[0][1].system
    phase_control = runs[0][1].phase_control
    for run_dir, cfg in runs[1:]:
        if cfg.system != system:
            raise UavrisError(f"{run_dir} was trained with a different system configuration than {runs[0][0]}; "
                              "a dataset holds one system")
        if cfg.phase_control != phase_control:
            raise UavrisError(f"{run_dir} sets the phases with phase control {cfg.phase_control!r}, {runs[0][0]} "
                              f"with {phase_control!r}; a dataset holds one action layout")
    if out.exists() and not force:  # checked before the rollouts, not only when writing
        raise UavrisError(f"{out} already exists; pass --force to replace it")
    bar = _bar(len(runs) * trajectories, "collect", "episode", progress)
    trajs: list[Trajectory] = []
    try:
        for k, (run_dir, cfg) in enumerate(runs):
            policy = run_policy(load_model(final_model_path(run_dir), cfg.algo), cfg)
            seeds = seed + k * trajectories + np.arange(trajectories)
            for start in range(0, trajectories, 256):
                batch = record_episodes(policy, system, cfg.scenario, seeds[start:start + 256], expert=str(run_dir),
                                        expert_algo=cfg.algo, phase_control=phase_control)
                trajs.extend(batch)
                if bar is not None:
                    bar.update(len(batch))
    finally:
        if bar is not None:
            bar.close()
    description = (f"uavris expert trajectories: {len(runs)} experts x {trajectories} deterministic episodes "
                   f"({', '.join(sorted({cfg.scenario for _, cfg in runs}))})")
    with user_errors():
        return write_dataset(out, trajs, system, description=description, force=force, phase_control=phase_control)


def dataset_summary(path: str | Path) -> dict[str, Any]:
    """Episodes, slots and mean average sum rate per scenario of a dataset."""
    with user_errors():
        ds = load_dataset(path)
    per = {}
    for scen in ds.scenarios:
        tr = [t for t in ds.trajectories if t.scenario == scen]
        per[scen] = {"episodes": len(tr), "avg_sum_rate": float(np.mean([t.episode_return / t.length for t in tr]))}
    return {"dataset_id": ds.dataset_id, "episodes": len(ds.trajectories), "slots": ds.num_slots, "scenarios": per}


# ============================================================================== configs
PRETRAIN_PRESETS: dict[str, dict[str, Any]] = {
    # smoke exercises the code in a second; quick is a few minutes on one core with the DT
    # paper's model size; paper is the DT paper's training schedule (hours on one core).
    "smoke": dict(steps=20, batch_size=8, warmup_steps=5, checkpoint_every=10, log_every=5, learning_rate=1e-3,
                  context=4, width=16, depth=1, heads=1),
    "quick": dict(steps=1500, batch_size=64, warmup_steps=150, checkpoint_every=500, log_every=50),
    "paper": dict(steps=100_000, batch_size=64, warmup_steps=10_000, checkpoint_every=5_000, log_every=200),
}


@dataclass(frozen=True)
class PretrainConfig:
    """Everything that determines a pre-training run (dumped as config.json)."""

    dataset: str
    preset: str = "quick"
    seed: int = 0
    steps: int = 1500
    batch_size: int = 64
    learning_rate: float = 1e-4
    weight_decay: float = 1e-4
    warmup_steps: int = 150
    grad_clip: float = 0.25
    checkpoint_every: int = 500
    log_every: int = 50
    context: int = 20
    width: int = 128
    depth: int = 3
    heads: int = 1
    dropout: float = 0.1
    attention: str = "window"
    target_quantile: float = TARGET_QUANTILE

    def __post_init__(self) -> None:
        _check_preset(self.preset)
        _check_positive("PretrainConfig", self, ("steps", "batch_size", "learning_rate", "warmup_steps", "grad_clip",
                                                 "checkpoint_every", "log_every"))
        if self.seed < 0 or self.weight_decay < 0:
            raise ConfigError("PretrainConfig.seed and weight_decay must be >= 0")
        if not 0 < self.target_quantile <= 1:
            raise ConfigError(f"PretrainConfig.target_quantile must be in (0, 1], got {self.target_quantile}")
        self.model_config(1, 1)  # validates the model size fields

    def model_config(self, state_dim: int, act_dim: int, max_timestep: int = 100) -> DTConfig:
        return DTConfig(state_dim, act_dim, context=self.context, width=self.width, depth=self.depth, heads=self.heads,
                        dropout=self.dropout, max_timestep=max_timestep, attention=self.attention)


def pretrain_config(dataset: str | Path, preset: str = "quick", seed: int = 0, **overrides: Any) -> PretrainConfig:
    """The named preset with optional field overrides (``None`` values are ignored)."""
    _check_preset(preset)
    base = dict(dataset=str(dataset), preset=preset, seed=seed, **PRETRAIN_PRESETS[preset])
    base.update({k: v for k, v in overrides.items() if v is not None})
    return PretrainConfig(**base)


FINETUNE_PRESETS: dict[str, dict[str, Any]] = {
    "smoke": dict(rounds=1, candidates=4, elites=2, rollouts_per_seed=2, epochs_per_round=1, batch_size=8,
                  warmup_steps=2, eval_episodes=2),
    "quick": dict(rounds=3, epochs_per_round=2, eval_episodes=16),
    "paper": dict(rounds=10, epochs_per_round=5, eval_episodes=100),
}


@dataclass(frozen=True)
class FinetuneConfig:
    """Everything that determines a fine-tuning run (dumped as config.json)."""

    model: str
    scenario: str
    preset: str = "quick"
    seed: int = 0
    rounds: int = 3  # H
    candidates: int = 80  # N
    elites: int = 50  # K
    noise_sigma: float = 0.1  # sigma
    selection: str = "paired"  # "return": eq. (18); "paired": within-seed ranking (docs/model.md)
    rollouts_per_seed: int = 5  # paired: candidates = seeds x rollouts_per_seed
    epochs_per_round: int = 2
    batch_size: int = 64
    learning_rate: float = 5e-5
    weight_decay: float = 1e-4
    warmup_steps: int = 100
    grad_clip: float = 0.25
    target_return: float | None = None  # None: the pre-trained model's default
    eval_episodes: int = 16
    eval_seed: int = EVAL_SEED
    collect_seed: int = FINETUNE_SEED

    def __post_init__(self) -> None:
        _check_preset(self.preset)
        get_scenario(self.scenario)
        _check_positive("FinetuneConfig", self, ("rounds", "candidates", "elites", "epochs_per_round", "batch_size",
                                                 "learning_rate", "warmup_steps", "grad_clip", "eval_episodes"))
        if self.elites > self.candidates:
            raise ConfigError(f"FinetuneConfig.elites ({self.elites}) must be <= candidates ({self.candidates})")
        if self.selection not in ELITE_RULES:
            raise ConfigError(f"FinetuneConfig.selection must be one of {', '.join(ELITE_RULES)}, "
                              f"got {self.selection!r}")
        if self.selection == "paired" and not (isinstance(self.rollouts_per_seed, int) and self.rollouts_per_seed >= 2
                                               and self.candidates % self.rollouts_per_seed == 0):
            raise ConfigError(f"FinetuneConfig.rollouts_per_seed must be an integer >= 2 dividing candidates "
                              f"({self.candidates}) for paired selection, got {self.rollouts_per_seed!r}")
        if self.noise_sigma < 0 or self.seed < 0 or self.weight_decay < 0:
            raise ConfigError("FinetuneConfig.noise_sigma, seed and weight_decay must be >= 0")
        if self.target_return is not None and not math.isfinite(self.target_return):
            raise ConfigError(f"FinetuneConfig.target_return must be finite, got {self.target_return}")


def finetune_config(model: str | Path, scenario: str, preset: str = "quick", seed: int = 0,
                    **overrides: Any) -> FinetuneConfig:
    """The named preset with optional field overrides (``None`` values are ignored)."""
    _check_preset(preset)
    base = dict(model=str(model), scenario=scenario, preset=preset, seed=seed, **FINETUNE_PRESETS[preset])
    base.update({k: v for k, v in overrides.items() if v is not None})
    return FinetuneConfig(**base)


def default_pretrain_dir(cfg: PretrainConfig, root: str | Path = "runs/dt") -> Path:
    layout = "" if cfg.attention == "window" else f"-{cfg.attention}"
    return Path(root) / f"pretrain-{Path(cfg.dataset).name}-s{cfg.seed}-{cfg.preset}{layout}"


def default_finetune_dir(cfg: FinetuneConfig, root: str | Path = "runs/dt") -> Path:
    return Path(root) / f"finetune-{cfg.scenario}-s{cfg.seed}-{cfg.preset}"


# ============================================================================== shared training machinery
def _bar(total: int, desc: str, unit: str, progress: bool, initial: int = 0):
    if not progress:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, unit=unit, desc=desc, dynamic_ncols=True)


def _prepare_run_dir(run_dir: Path, kind: str, cfg_dict: dict[str, Any], resume: bool, force: bool) -> bool:
    """Check the run directory like ``uavris train`` does; returns True when resuming."""
    cfg_path = run_dir / "config.json"
    has_config = cfg_path.exists()
    if force and run_dir.exists() and not resume:
        if not has_config and any(run_dir.iterdir()):
            raise UavrisError(f"{run_dir} exists and is not a uavris DT run directory; refusing to overwrite it")
        shutil.rmtree(run_dir)
        has_config = False
    elif (run_dir / "done.json").exists():
        raise UavrisError(f"{run_dir} is a finished run; evaluate it, or pass --force to redo it from scratch")
    elif has_config and not resume:
        raise UavrisError(f"{run_dir} already holds a run; pass --resume to continue it or --force to start over")
    elif run_dir.exists() and not has_config and any(run_dir.iterdir()):
        raise UavrisError(f"{run_dir} exists and is not a uavris DT run directory")
    if has_config:
        saved = read_json(cfg_path)
        if saved != {"kind": kind, **cfg_dict}:
            raise UavrisError(f"{run_dir} was started with a different configuration; resume it without changing "
                              "parameters, or pass --force to start over")
        return True
    run_dir.mkdir(parents=True, exist_ok=True)
    write_json(cfg_path, {"kind": kind, **cfg_dict})
    return False


def _make_optimizer(model: DecisionTransformer, lr: float, weight_decay: float):
    import torch

    # Decay the weight matrices only: biases, LayerNorm gains and the timestep table keep their scale.
    decay = [p for n, p in model.named_parameters() if p.ndim >= 2 and not n.startswith("embed_timestep")]
    keep = [p for n, p in model.named_parameters() if not (p.ndim >= 2 and not n.startswith("embed_timestep"))]
    return torch.optim.AdamW([{"params": decay, "weight_decay": weight_decay}, {"params": keep, "weight_decay": 0.0}],
                             lr=lr, betas=(0.9, 0.999))


def _train_steps(model: DecisionTransformer, opt: Any, windows: TrainingWindows, rng: np.random.Generator,
                 first_step: int, count: int, batch_size: int, lr: float, warmup: int, grad_clip: float,
                 on_step: Any = None) -> list[float]:
    """``count`` gradient steps of the masked action MSE (L_OFF / L_FT); returns the losses."""
    import torch

    model.train()
    losses = []
    for i in range(count):
        step = first_step + i
        for group in opt.param_groups:
            group["lr"] = lr * min(1.0, (step + 1) / warmup)  # linear warm-up, then constant
        batch = windows.sample(batch_size, rng)
        pred = model(batch["returns_to_go"], batch["states"], batch["actions"], batch["timesteps"], batch["valid"])
        loss = masked_action_loss(pred, batch["actions"], batch["valid"])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), grad_clip)
        opt.step()
        losses.append(float(loss.detach()))
        if on_step is not None:
            on_step(step + 1, losses[-1])
    model.eval()
    return losses


def _save_trainer_state(directory: Path, opt: Any, rng: np.random.Generator, extra: dict[str, Any]) -> None:
    """Optimizer moments and the torch RNG as safetensors, the rest as JSON (no pickle)."""
    import torch
    from safetensors.torch import save

    state = opt.state_dict()
    tensors = {"torch_rng": torch.get_rng_state()}
    for pid, st in state["state"].items():
        for key, value in st.items():
            tensors[f"optimizer.{pid}.{key}"] = value.detach().contiguous().clone()
    groups = [{k: (list(v) if isinstance(v, tuple) else v) for k, v in g.items()} for g in state["param_groups"]]
    atomic_write_bytes(directory / "trainer.safetensors", save(tensors))
    write_json(directory / "trainer.json", {"param_groups": groups, "numpy_rng": rng.bit_generator.state, **extra})


def _load_trainer_state(directory: Path, opt: Any, rng: np.random.Generator) -> dict[str, Any]:
    import torch
    from safetensors import SafetensorError
    from safetensors.torch import load

    path = directory / "trainer.safetensors"
    meta = read_json(directory / "trainer.json")
    try:
        tensors = load(path.read_bytes())
    except FileNotFoundError:
        raise UavrisError(f"{path} is missing; pass --force to start over") from None
    except (SafetensorError, ValueError) as e:
        raise UavrisError(f"{path} is corrupt ({e})") from None
    try:
        state: dict[int, dict[str, Any]] = {}
        for name, value in tensors.items():
            if name.startswith("optimizer."):
                _, pid, key = name.split(".", 2)
                state.setdefault(int(pid), {})[key] = value
        opt.load_state_dict({"state": state, "param_groups": meta["param_groups"]})
        rng.bit_generator.state = meta["numpy_rng"]
        torch.set_rng_state(tensors["torch_rng"])
    except (KeyError, ValueError, TypeError, RuntimeError) as e:
        raise UavrisError(f"{directory} holds an unusable trainer state ({type(e).__name__}: {e})") from None
    return meta


def _write_checkpoint(run_dir: Path, step: int, model: DecisionTransformer, model_meta: dict[str, Any], opt: Any,
                      rng: np.random.Generator, extra: dict[str, Any], prefix: str = "step") -> Path:
    """Model, trainer state, then the ``latest.json`` pointer; older trainer states are
    removed only after the pointer has moved, so a kill at any point leaves a usable one."""
    ck_root = run_dir / "checkpoints"
    ck = ck_root / f"{prefix}_{step}"
    save_dt(model, ck, model_meta)
    _save_trainer_state(ck, opt, rng, extra)
    write_json(ck_root / "latest.json", {"step": step, "dir": ck.name})
    for old in ck_root.glob(f"{prefix}_*"):
        if old != ck:
            for name in ("trainer.safetensors", "trainer.json"):
                (old / name).unlink(missing_ok=True)
    return ck


def _latest_checkpoint(run_dir: Path) -> tuple[int, Path] | None:
    latest = run_dir / "checkpoints" / "latest.json"
    if not latest.exists():
        return None
    info = read_json(latest)
    try:
        return int(info["step"]), run_dir / "checkpoints" / str(info["dir"])
    except (KeyError, TypeError, ValueError):
        raise UavrisError(f"{latest} is corrupt") from None


def _restore_weights(model: DecisionTransformer, ck: Path) -> None:
    with user_errors():
        saved, _ = load_dt(ck)
    model.load_state_dict(saved.state_dict())


_INT_COLUMNS = {"step", "round", "env_interactions", "gradient_steps"}


def _tb_writer(run_dir: Path, start: int):
    from torch.utils.tensorboard import SummaryWriter

    return SummaryWriter(str(run_dir / "tb"), purge_step=start if start > 0 else None)


# ============================================================================== pre-training
def pretrain(cfg: PretrainConfig, run_dir: str | Path, *, resume: bool = False, force: bool = False,
             progress: bool = True, interrupt_at: int | None = None) -> Path:
    """Pre-train a DT on ``cfg.dataset`` (Algorithm 1, stage 1); returns the model directory.

    ``interrupt_at`` is a test hook that stops training after that step.
    """
    import torch

    configure_torch_threads()
    run_dir = Path(run_dir)
    with user_errors():
        ds = load_dataset(cfg.dataset)
    resuming = _prepare_run_dir(run_dir, PRETRAIN_KIND, dataclasses.asdict(cfg), resume, force)
    system = ds.system
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    norm = normalisation_from(ds.trajectories)
    model = DecisionTransformer(cfg.model_config(system.observation_dim, action_dim_for(system, ds.phase_control),
                                                 system.horizon),
                                norm.state_mean, norm.state_std, norm.return_scale)
    opt = _make_optimizer(model, cfg.learning_rate, cfg.weight_decay)
    windows = TrainingWindows.for_model(ds.trajectories, model.cfg)
    model_meta = {
        "stage": "pretrain", "scenario": None, "scenarios": ds.scenarios, "dataset": str(cfg.dataset),
        "dataset_id": ds.dataset_id, "system": system.to_dict(), "observation_layout": layout_as_lists(system),
        "target_return": default_target_return(ds.trajectories, cfg.target_quantile),
        "target_return_rule": f"{cfg.target_quantile} quantile of the dataset's episode returns",
        "env_interactions": 0, "phase_control": ds.phase_control,
    }
    start, log = 0, []
    if resuming and (latest := _latest_checkpoint(run_dir)) is not None:
        start, ck = latest
        _restore_weights(model, ck)
        meta = _load_trainer_state(ck, opt, rng)
        log = read_rows(run_dir / "train_log.csv", LOG_HEADER, int(meta.get("log_rows", 0)), _INT_COLUMNS)
    writer = _tb_writer(run_dir, start)
    bar = _bar(cfg.steps, "pretrain-dt", "step", progress, start)
    t0 = time.perf_counter()
    window_losses: list[float] = []
    window_t = time.perf_counter()

    def on_step(step: int, loss: float) -> None:
        nonlocal window_t
        window_losses.append(loss)
        writer.add_scalar("train/loss", loss, step)
        if bar is not None:
            bar.update(1)
        if step % cfg.log_every == 0 or step == cfg.steps:
            now = time.perf_counter()
            rate = len(window_losses) * cfg.batch_size / max(now - window_t, 1e-9)
            lr = opt.param_groups[0]["lr"]
            log.append([step, float(np.mean(window_losses)), lr, rate])
            writer.add_scalar("train/learning_rate", lr, step)
            writer.add_scalar("perf/samples_per_s", rate, step)
            if bar is not None:
                bar.set_postfix(loss=f"{np.mean(window_losses):.4f}", refresh=False)
            window_losses.clear()
            window_t = now
        if step % cfg.checkpoint_every == 0 and step < cfg.steps:
            write_csv(run_dir / "train_log.csv", LOG_HEADER, log)
            _write_checkpoint(run_dir, step, model, {**model_meta, "gradient_steps": step}, opt, rng,
                              {"log_rows": len(log)})
        if interrupt_at is not None and step >= interrupt_at:
            raise KeyboardInterrupt(f"interrupted at step {step} (test hook)")

    try:
        losses = _train_steps(model, opt, windows, rng, start, cfg.steps - start, cfg.batch_size, cfg.learning_rate,
                              cfg.warmup_steps, cfg.grad_clip, on_step)
    finally:
        writer.close()
        if bar is not None:
            bar.close()
    write_csv(run_dir / "train_log.csv", LOG_HEADER, log)
    _write_checkpoint(run_dir, cfg.steps, model, {**model_meta, "gradient_steps": cfg.steps}, opt, rng,
                      {"log_rows": len(log)})
    save_dt(model, run_dir, {**model_meta, "gradient_steps": cfg.steps})
    final_loss = float(np.mean(losses[-cfg.log_every:])) if losses else (log[-1][1] if log else float("nan"))
    write_json(run_dir / "done.json", {"gradient_steps": cfg.steps, "final_loss": final_loss,
                                       "episodes": len(ds.trajectories), "slots": ds.num_slots,
                                       "target_return": model_meta["target_return"],
                                       "wall_clock_s_last_session": time.perf_counter() - t0})
    return run_dir


# ============================================================================== fine-tuning
def finetune(cfg: FinetuneConfig, run_dir: str | Path, *, resume: bool = False, force: bool = False,
             progress: bool = True, interrupt_after_round: int | None = None) -> Path:
    """Fine-tune a pre-trained DT in ``cfg.scenario`` (Algorithm 1, stage 2); returns the
    model directory. ``interrupt_after_round`` is a test hook."""
    import torch

    configure_torch_threads()
    run_dir = Path(run_dir)
    model_dir = dt_model_dir(cfg.model) or Path(cfg.model)  # a run directory stands for its final model
    with user_errors():
        model, pre_meta = load_dt(model_dir)
    system = _checked_system(pre_meta, model_dir)
    get_scenario(cfg.scenario).validate_for(system)
    target = cfg.target_return if cfg.target_return is not None else pre_meta.get("target_return")
    if target is None:
        raise UavrisError(f"{cfg.model} stores no target return; pass --target-return")
    resuming = _prepare_run_dir(run_dir, FINETUNE_KIND, dataclasses.asdict(cfg), resume, force)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    opt = _make_optimizer(model, cfg.learning_rate, cfg.weight_decay)
    model_meta = {**{k: v for k, v in pre_meta.items() if k not in ("kind", "format_version", "config")},
                  "stage": "finetune", "scenario": cfg.scenario, "pretrained_model": str(cfg.model),
                  "target_return": float(target)}
    phase_control = pre_meta.get("phase_control", "agent")

    def dt_policy(sigma: float = 0.0, noise_seed: int | None = None) -> DTBatchPolicy:
        return DTBatchPolicy(model, target, sigma, noise_seed, phase_control)

    done_round, steps, interactions, rows = 0, 0, 0, []
    if resuming and (latest := _latest_checkpoint(run_dir)) is not None:
        done_round, ck = latest
        _restore_weights(model, ck)
        meta = _load_trainer_state(ck, opt, rng)
        steps, interactions = int(meta["gradient_steps"]), int(meta["env_interactions"])
        rows = read_rows(run_dir / "finetune.csv", ROUND_HEADER, done_round + 1, _INT_COLUMNS)
    writer = _tb_writer(run_dir, done_round)
    model.eval()
    if not rows:  # round 0: the zero-shot policy
        ev = evaluate(dt_policy(), system, cfg.scenario, cfg.eval_episodes, cfg.eval_seed).summary()
        rows.append([0, 0, 0, *([float("nan")] * 5), ev["mean"], ev["ci_low"], ev["ci_high"]])
        writer.add_scalar("eval/avg_sum_rate", ev["mean"], 0)
        write_csv(run_dir / "finetune.csv", ROUND_HEADER, rows)
    bar = _bar(cfg.rounds, f"finetune-dt {cfg.scenario}", "round", progress, done_round)
    t0 = time.perf_counter()
    try:
        for h in range(done_round + 1, cfg.rounds + 1):
            # Noise seeded by (seed, round): a resumed run explores exactly as an uninterrupted one.
            noise_seed = int(np.random.SeedSequence([cfg.seed, h]).generate_state(1)[0])
            per_seed = cfg.rollouts_per_seed if cfg.selection == "paired" else 1
            distinct = cfg.candidates // per_seed
            seeds = np.repeat(cfg.collect_seed + (h - 1) * cfg.candidates + np.arange(distinct), per_seed)
            cands = record_episodes(dt_policy(cfg.noise_sigma, noise_seed), system, cfg.scenario, seeds,
                                    expert="dt-finetune", expert_algo="dt", phase_control=phase_control)
            interactions += sum(tr.length for tr in cands)
            elites = select_elites(cands, cfg.elites, cfg.selection)
            windows = TrainingWindows.for_model(elites, model.cfg)  # RTGs from the rewards actually received
            count = cfg.epochs_per_round * math.ceil(windows.samples_per_epoch / cfg.batch_size)
            losses = _train_steps(model, opt, windows, rng, steps, count, cfg.batch_size, cfg.learning_rate,
                                  cfg.warmup_steps, cfg.grad_clip)
            steps += count
            ev = evaluate(dt_policy(), system, cfg.scenario, cfg.eval_episodes, cfg.eval_seed).summary()
            ret = [tr.episode_return for tr in cands]
            rows.append([h, interactions, steps, float(np.mean(ret)),
                         float(np.mean([tr.episode_return / tr.length for tr in cands])),
                         float(np.mean([tr.episode_return for tr in elites])), float(elites[-1].episode_return),
                         float(np.mean(losses)), ev["mean"], ev["ci_low"], ev["ci_high"]])
            for name, value in (("eval/avg_sum_rate", ev["mean"]), ("rollout/candidate_mean_return", rows[-1][3]),
                                ("rollout/elite_mean_return", rows[-1][5]), ("train/loss", rows[-1][7]),
                                ("rollout/env_interactions", interactions)):
                writer.add_scalar(name, value, h)
            write_csv(run_dir / "finetune.csv", ROUND_HEADER, rows)
            _write_checkpoint(run_dir, h, model, {**model_meta, "env_interactions": interactions,
                                                  "finetune_rounds": h, "finetune_gradient_steps": steps}, opt, rng,
                              {"gradient_steps": steps, "env_interactions": interactions}, prefix="round")
            if bar is not None:
                bar.update(1)
                bar.set_postfix(eval=f"{ev['mean']:.2f}", refresh=False)
            if interrupt_after_round is not None and h >= interrupt_after_round:
                raise KeyboardInterrupt(f"interrupted after round {h} (test hook)")
    finally:
        writer.close()
        if bar is not None:
            bar.close()
    save_dt(model, run_dir, {**model_meta, "env_interactions": interactions, "finetune_rounds": cfg.rounds,
                             "finetune_gradient_steps": steps})
    write_json(run_dir / "done.json", {
        "rounds": cfg.rounds, "env_interactions": interactions, "gradient_steps": steps,
        "zero_shot_eval": {"mean": rows[0][8], "ci_low": rows[0][9], "ci_high": rows[0][10]},
        "final_eval": {"mean": rows[-1][8], "ci_low": rows[-1][9], "ci_high": rows[-1][10],
                       "episodes": cfg.eval_episodes, "seed": cfg.eval_seed},
        "target_return": float(target), "wall_clock_s_last_session": time.perf_counter() - t0})
    return run_dir


def _checked_system(meta: dict[str, Any], where: Path) -> SystemConfig:
    """The checkpoint's system config, checked against the current observation layout."""
    try:
        system = SystemConfig.from_stored(meta["system"])
    except (KeyError, TypeError, ConfigError) as e:
        raise UavrisError(f"{where} stores no valid system configuration ({e})") from None
    if meta.get("observation_layout") != layout_as_lists(system):
        raise UavrisError(f"{where} was trained on a different observation layout than the current environment's")
    return system


# ============================================================================== deployment
def dt_model_dir(path: str | Path) -> Path | None:
    """The model directory of a DT target: the directory itself when it holds model.json,
    the latest checkpoint of an unfinished DT run, or None when ``path`` is not a DT target."""
    path = Path(path)
    if (path / "model.json").exists():
        return path
    cfg = path / "config.json"
    if cfg.exists():
        saved = read_json(cfg)
        if isinstance(saved, dict) and saved.get("kind") in (PRETRAIN_KIND, FINETUNE_KIND):
            latest = _latest_checkpoint(path)
            if latest is None:
                raise UavrisError(f"{path} has no model yet (no model.json and no checkpoint)")
            return latest[1]
    return None


def load_dt_policy(path: str | Path, target_return: float | None = None) -> tuple[DTBatchPolicy, SystemConfig,
                                                                                     str | None]:
    """(deterministic batch policy, its system config, its own scenario or None) of a DT target."""
    configure_torch_threads()
    model_dir = dt_model_dir(path)
    if model_dir is None:
        raise UavrisError(f"{path} is not a DT model directory (no model.json)")
    with user_errors():
        model, meta = load_dt(model_dir)
    system = _checked_system(meta, model_dir)
    target = meta.get("target_return") if target_return is None else target_return
    if target is None:
        raise UavrisError(f"{model_dir} stores no target return")
    return (DTBatchPolicy(model, float(target), phase_control=meta.get("phase_control", "agent")), system,
            meta.get("scenario"))
