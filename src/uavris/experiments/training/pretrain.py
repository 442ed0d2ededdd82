"""Pre-training (paper Algorithm 1, stage 1): the Decision Transformer offline on an expert dataset.

Lives here: :class:`PretrainConfig` and :func:`pretrain`. Not here: the model and its
training step (:mod:`uavris.agents.dt`), the run directory's machinery (:mod:`.dt_runs`).

The loss L_OFF (eq. 16) on
context windows of the dataset, AdamW with decoupled weight decay on the weight matrices,
a linear learning-rate warm-up then a constant rate, gradient-norm clipping. These are
the DT paper's settings (lr 1e-4, weight decay 1e-4, warm-up 10,000 steps, clip 0.25,
batch 64, 100,000 steps in ``paper``). The default target return of the model is the 0.9
quantile of the dataset's episode returns, stored in the checkpoint. With
``attention="banded"`` (:mod:`uavris.agents.dt.model`) a sample is a whole episode instead of
a window, and ``batch_size`` counts episodes.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from uavris.agents.dt.checkpoint import save_dt
from uavris.agents.dt.config import Attention, DTConfig
from uavris.agents.dt.dataset import ExpertDataset, load_dataset
from uavris.agents.dt.encoders import STATE_ENCODERS, StateEncoder, pooled_over_devices
from uavris.agents.dt.model import DecisionTransformer
from uavris.agents.dt.trainer import load_trainer_state, make_optimizer, train_steps
from uavris.agents.dt.trajectories import MixedWindows, TrainingWindows, default_target_return, normalisation_from
from uavris.config import PRESET, DictConfig, SystemConfig, check_non_negative, check_positive, fill_from_preset
from uavris.env.simulator import layout_as_lists
from uavris.env.wrappers import action_dim_for
from uavris.errors import ConfigError
from uavris.experiments.display.progress import progress_bar, tb_writer
from uavris.experiments.engine.jobs import configure_threads
from uavris.experiments.training.dt_runs import (
    INT_COLUMNS,
    PRETRAIN_KIND,
    latest_checkpoint,
    prepare_run_dir,
    restore_weights,
    write_checkpoint,
)
from uavris.io import read_rows, write_csv
from uavris.presets import PRETRAIN, Preset, check_preset
from uavris.runs import RunClock, write_done

TARGET_QUANTILE = 0.9
LOG_HEADER = ("step", "loss", "learning_rate")  # throughput: TensorBoard (perf/samples_per_s) and timing.json


@dataclass(frozen=True)
class PretrainConfig(DictConfig):
    """Everything that determines a pre-training run (dumped as config.json). Fields left at
    ``PRESET`` take the preset's values (:data:`uavris.presets.PRETRAIN`)."""

    dataset: str  # a dataset directory written by `uavris collect`
    preset: Preset = "quick"  # the schedule's defaults: smoke (seconds), quick (minutes), paper (the DT paper's)
    seed: int = 0  # seed of the weights and of the sampled windows
    steps: int = PRESET  # gradient steps
    batch_size: int = PRESET  # windows (banded attention: episodes) per step
    learning_rate: float = PRESET  # AdamW's rate after the warm-up
    weight_decay: float = 1e-4  # AdamW's decoupled weight decay (weight matrices only)
    warmup_steps: int = PRESET  # linear warm-up of the learning rate
    grad_clip: float = 0.25  # gradient-norm clipping
    checkpoint_every: int = PRESET  # steps between checkpoints
    log_every: int = PRESET  # steps between train_log.csv rows
    context: int = PRESET  # slots the model reads (3 tokens each)
    width: int = PRESET  # embedding width
    depth: int = PRESET  # transformer blocks
    heads: int = PRESET  # attention heads
    dropout: float = 0.1  # dropout rate in training
    attention: Attention = "window"  # window (the DT paper's) or banded (cached deployment)
    condition_on_return: bool = True  # False: behaviour cloning with the same model and budget
    state_encoder: StateEncoder = "flat"  # flat (the DT paper's) or devices (a hall as a set; needs observed devices)
    ris_frame: bool = False  # the device encoder also reads each device's elevation above the RIS plane
    scenarios: tuple[str, ...] | None = None  # train on the episodes of these scenarios (layouts) only; None: all
    more_datasets: tuple[str, ...] = ()  # datasets of halls of other device counts, trained on too (device encoder)
    target_quantile: float = TARGET_QUANTILE  # the default target return: this quantile of the dataset's returns

    def __post_init__(self) -> None:
        check_preset(self.preset)
        fill_from_preset(self, PRETRAIN[self.preset])
        object.__setattr__(self, "dataset", str(self.dataset))
        check_positive("PretrainConfig", self, ("steps", "batch_size", "learning_rate", "warmup_steps", "grad_clip",
                                                 "checkpoint_every", "log_every"))
        check_non_negative("PretrainConfig", self, ("seed", "weight_decay"))
        if self.scenarios is not None:
            object.__setattr__(self, "scenarios", tuple(str(x) for x in self.scenarios))
            if not self.scenarios:
                raise ConfigError("PretrainConfig.scenarios must name at least one scenario (or be None: all)")
        object.__setattr__(self, "more_datasets", tuple(str(x) for x in self.more_datasets))
        if self.more_datasets and self.state_encoder != "devices":
            raise ConfigError("PretrainConfig.more_datasets needs state_encoder 'devices' (only it reads halls of "
                              "several device counts)")
        if self.more_datasets and self.scenarios is not None:
            raise ConfigError("PretrainConfig.scenarios selects episodes of one dataset: not with more_datasets")
        if not 0 < self.target_quantile <= 1:
            raise ConfigError(f"PretrainConfig.target_quantile must be in (0, 1], got {self.target_quantile}")
        if self.ris_frame and self.state_encoder != "devices":
            raise ConfigError("PretrainConfig.ris_frame needs state_encoder 'devices' (a feature of each device)")
        if self.state_encoder not in STATE_ENCODERS:
            raise ConfigError(f"PretrainConfig.state_encoder must be one of {', '.join(STATE_ENCODERS)}, "
                              f"got {self.state_encoder!r}")
        DTConfig(1, 1, context=self.context, width=self.width, depth=self.depth, heads=self.heads, dropout=self.dropout,
                 attention=self.attention, condition_on_return=self.condition_on_return)  # validates the model size

    def model_config(self, system: SystemConfig, act_dim: int) -> DTConfig:
        """The model of this run for a dataset of ``system``; the device encoder needs its devices observed."""
        if self.state_encoder == "devices" and not system.observe_devices:
            raise ConfigError("PretrainConfig.state_encoder 'devices' needs a dataset whose observations hold the "
                              "devices (SystemConfig.observe_devices, the deployment track's)")
        sized = dict(devices=system.num_users, elements=system.num_elements) if self.state_encoder == "devices" else {}
        return DTConfig(system.observation_dim, act_dim, context=self.context, width=self.width, depth=self.depth,
                        heads=self.heads, dropout=self.dropout, max_timestep=system.horizon, attention=self.attention,
                        condition_on_return=self.condition_on_return, state_encoder=self.state_encoder,
                        ris_frame=self.ris_frame, **sized)


def training_subset(ds: ExpertDataset, scenarios: Sequence[str] | None) -> ExpertDataset:
    """The episodes of ``ds`` in ``scenarios`` (all of them for None); an unknown name is one error line."""
    if scenarios is None:
        return ds
    unknown = sorted(set(scenarios) - set(ds.scenarios))
    if unknown:
        raise ConfigError(f"PretrainConfig.scenarios: {unknown} not in the dataset {ds.path} (it holds {ds.scenarios})")
    return dataclasses.replace(ds, trajectories=[tr for tr in ds.trajectories if tr.scenario in set(scenarios)])


def check_mixable(ds: ExpertDataset, more: Sequence[ExpertDataset]) -> None:
    """Datasets trained on together (``more_datasets``): the same RIS, actions and observation
    kind, only the number of devices may differ; one line naming the first that does not fit."""
    def kind(d: ExpertDataset) -> tuple:
        return d.system.num_elements, d.system.observe_devices, d.phase_control, d.system.horizon
    for d in more:
        if kind(d) != kind(ds):
            raise ConfigError(f"PretrainConfig.more_datasets: {d.path} (RIS elements, devices observed, phase "
                              f"control, horizon {kind(d)}) does not fit {ds.path} ({kind(ds)})")


def default_pretrain_dir(cfg: PretrainConfig, root: str | Path = "runs/dt") -> Path:
    layout = "" if cfg.attention == "window" else f"-{cfg.attention}"
    return Path(root) / f"pretrain-{Path(cfg.dataset).name}-s{cfg.seed}-{cfg.preset}{layout}"


def pretrain(cfg: PretrainConfig, run_dir: str | Path, *, resume: bool = False, force: bool = False,
             progress: bool = True, interrupt_at: int | None = None, device: str = "cpu") -> Path:
    """Pre-train a DT on ``cfg.dataset`` (Algorithm 1, stage 1) on the torch ``device``; returns
    the model directory.

    ``interrupt_at`` is a test hook that stops training after that step.
    """
    import torch

    configure_threads()
    run_dir = Path(run_dir)
    ds = training_subset(load_dataset(cfg.dataset), cfg.scenarios)
    more = [load_dataset(path) for path in cfg.more_datasets]
    check_mixable(ds, more)
    resuming = prepare_run_dir(run_dir, PRETRAIN_KIND, cfg.to_dict(), resume, force)
    system = ds.system
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    model_cfg = cfg.model_config(system, action_dim_for(system, ds.phase_control))
    norm = normalisation_from(ds.trajectories)
    mean, std = norm.state_mean, norm.state_std
    if model_cfg.state_encoder == "devices":  # statistics that do not depend on a device's index (.encoders)
        mean, std = pooled_over_devices(mean, std, model_cfg.devices, model_cfg.elements)
    model = DecisionTransformer(model_cfg, mean, std, norm.return_scale).to(device)
    opt = make_optimizer(model, cfg.learning_rate, cfg.weight_decay)
    windows: TrainingWindows | MixedWindows = TrainingWindows.for_model(ds.trajectories, model.cfg)
    if more:  # halls of several device counts: one set of windows per dataset, one model (.encoders)
        windows = MixedWindows([windows] + [TrainingWindows.for_model(d.trajectories, model.cfg) for d in more])
    everything = [tr for d in [ds, *more] for tr in d.trajectories]
    model_meta = {
        "stage": "pretrain", "scenario": None, "scenarios": ds.scenarios, "dataset": str(cfg.dataset),
        "dataset_id": ds.dataset_id, "system": system.to_dict(), "observation_layout": layout_as_lists(system),
        "target_return": default_target_return(everything, cfg.target_quantile),
        "target_return_rule": f"{cfg.target_quantile} quantile of the dataset's episode returns",
        "env_interactions": 0, "phase_control": ds.phase_control,
    }
    start, log = 0, []
    if resuming and (latest := latest_checkpoint(run_dir)) is not None:
        start, ck = latest
        restore_weights(model, ck)
        meta = load_trainer_state(ck, opt, rng)
        log = read_rows(run_dir / "train_log.csv", LOG_HEADER, int(meta.get("log_rows", 0)), INT_COLUMNS)
    writer = tb_writer(run_dir, start)
    bar = progress_bar(cfg.steps, "pretrain-dt", "step", progress, start)
    clock = RunClock(run_dir, resuming)
    window_losses: list[float] = []
    window_t = time.perf_counter()

    def on_step(step: int, loss: float) -> None:
        nonlocal window_t
        window_losses.append(loss)
        writer.add_scalar("train/loss", loss, step)
        bar.update(1)
        if step % cfg.log_every == 0 or step == cfg.steps:
            now = time.perf_counter()
            rate = len(window_losses) * cfg.batch_size / max(now - window_t, 1e-9)
            lr = opt.param_groups[0]["lr"]
            log.append({"step": step, "loss": float(np.mean(window_losses)), "learning_rate": lr})
            writer.add_scalar("train/learning_rate", lr, step)
            writer.add_scalar("perf/samples_per_s", rate, step)
            bar.set_postfix(loss=f"{np.mean(window_losses):.4f}", refresh=False)
            window_losses.clear()
            window_t = now
        if step % cfg.checkpoint_every == 0 and step < cfg.steps:
            write_csv(run_dir / "train_log.csv", LOG_HEADER, log)
            write_checkpoint(run_dir, step, model, {**model_meta, "gradient_steps": step}, opt, rng,
                              {"log_rows": len(log)}, clock=clock)
        if interrupt_at is not None and step >= interrupt_at:
            raise KeyboardInterrupt(f"interrupted at step {step} (test hook)")

    try:
        losses = train_steps(model, opt, windows, rng, start, cfg.steps - start, cfg.batch_size, cfg.learning_rate,
                              cfg.warmup_steps, cfg.grad_clip, on_step)
    finally:
        writer.close()
        bar.close()
    write_csv(run_dir / "train_log.csv", LOG_HEADER, log)
    write_checkpoint(run_dir, cfg.steps, model, {**model_meta, "gradient_steps": cfg.steps}, opt, rng,
                      {"log_rows": len(log)}, clock=clock)
    save_dt(model, run_dir, {**model_meta, "gradient_steps": cfg.steps})
    final_loss = float(np.mean(losses[-cfg.log_every:])) if losses else (log[-1]["loss"] if log else float("nan"))
    clock.save(gradient_steps=cfg.steps)
    write_done(run_dir, {"gradient_steps": cfg.steps, "final_loss": final_loss, "episodes": len(ds.trajectories),
                         "slots": ds.num_slots, "target_return": model_meta["target_return"]})
    return run_dir
