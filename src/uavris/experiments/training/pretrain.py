"""Pre-training (paper Algorithm 1, stage 1): the Decision Transformer offline on an expert dataset.

Lives here: :class:`PretrainConfig` and :func:`pretrain`, the run: its data, its directory,
logs and checkpoints. Not here: the model (:mod:`uavris.agents.dt.model`, sized by
:class:`~uavris.agents.dt.config.DTConfig`) and its training, the windows, loss and steps
(:mod:`uavris.agents.dt.training`), the run directory's machinery (:mod:`.dt_runs`).

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
from typing import Mapping, Sequence

import numpy as np
import torch

from uavris.agents.dt.checkpoint import save_dt
from uavris.agents.dt.config import DTConfig
from uavris.agents.dt.dataset import ExpertDataset, load_dataset
from uavris.agents.dt.training import (
    MixedWindows,
    TrainingWindows,
    load_trainer_state,
    make_optimizer,
    model_for_data,
    train_steps,
)
from uavris.agents.dt.trajectories import default_target_return
from uavris.config import check_non_negative, check_positive
from uavris.env.simulator import layout_as_lists
from uavris.env.wrappers import action_dim_for
from uavris.errors import ConfigError
from uavris.experiments.display.progress import progress_bar, tb_writer
from uavris.experiments.training.dt_runs import (
    INT_COLUMNS,
    PRETRAIN_KIND,
    latest_checkpoint,
    prepare_run_dir,
    restore_weights,
    write_checkpoint,
)
from uavris.io import read_rows, write_csv
from uavris.presets import PRESET, PRETRAIN, Preset, PresetConfig, check_preset, fill_from_preset
from uavris.runs import RunClock, write_done

TARGET_QUANTILE = 0.9
LOG_HEADER = ("step", "loss", "learning_rate")  # throughput: TensorBoard (perf/samples_per_s) and timing.json


@dataclass(frozen=True)
class PretrainConfig(PresetConfig):
    """Everything that determines a pre-training run (dumped as config.yaml). Fields left at
    ``PRESET`` take the preset's values (:data:`uavris.presets.PRETRAIN`); ``model`` may be
    given as a mapping of the :class:`~uavris.agents.dt.config.DTConfig` fields that differ
    from the preset's model."""

    dataset: str  # a dataset directory written by `uavris collect`
    preset: Preset = "quick"  # the schedule's defaults: smoke (seconds), quick (minutes), paper (the DT paper's)
    seed: int = 0  # seed of the weights and of the sampled windows
    model: DTConfig = PRESET  # the model: its size, attention layout, state encoder, return conditioning
    steps: int = PRESET  # gradient steps
    batch_size: int = PRESET  # windows (banded attention: episodes) per step
    learning_rate: float = PRESET  # AdamW's rate after the warm-up
    weight_decay: float = 1e-4  # AdamW's decoupled weight decay (weight matrices only)
    warmup_steps: int = PRESET  # linear warm-up of the learning rate
    grad_clip: float = 0.25  # gradient-norm clipping
    checkpoint_every: int = PRESET  # steps between checkpoints
    log_every: int = PRESET  # steps between train_log.csv rows
    scenarios: tuple[str, ...] | None = None  # train on the episodes of these scenarios (layouts) only; None: all
    more_datasets: tuple[str, ...] = ()  # datasets of halls of other device counts, trained on too (device encoder)
    target_quantile: float = TARGET_QUANTILE  # the default target return: this quantile of the dataset's returns

    partial_fields = ("model",)  # DictConfig.from_dict: a mapping there changes the preset's model

    def __post_init__(self) -> None:
        check_preset(self.preset)
        table = PRETRAIN[self.preset]
        if isinstance(self.model, Mapping):  # the preset's model with these fields changed
            object.__setattr__(self, "model", DTConfig.from_dict({**table["model"], **self.model}))
        fill_from_preset(self, {**table, "model": DTConfig.from_dict(table["model"])})
        if not isinstance(self.model, DTConfig) or self.model.sized:
            raise ConfigError("PretrainConfig.model must be a DTConfig (or a mapping of its fields) without the "
                              f"data's sizes, which the dataset gives; got {self.model!r}")
        object.__setattr__(self, "dataset", str(self.dataset))
        check_positive("PretrainConfig", self, ("steps", "batch_size", "learning_rate", "warmup_steps", "grad_clip",
                                                 "checkpoint_every", "log_every"))
        check_non_negative("PretrainConfig", self, ("seed", "weight_decay"))
        if self.scenarios is not None:
            object.__setattr__(self, "scenarios", tuple(str(x) for x in self.scenarios))
            if not self.scenarios:
                raise ConfigError("PretrainConfig.scenarios must name at least one scenario (or be None: all)")
        object.__setattr__(self, "more_datasets", tuple(str(x) for x in self.more_datasets))
        if self.more_datasets and self.model.state_encoder != "devices":
            raise ConfigError("PretrainConfig.more_datasets needs the model's state_encoder 'devices' (only it reads "
                              "halls of several device counts)")
        if self.more_datasets and self.scenarios is not None:
            raise ConfigError("PretrainConfig.scenarios selects episodes of one dataset: not with more_datasets")
        if not 0 < self.target_quantile <= 1:
            raise ConfigError(f"PretrainConfig.target_quantile must be in (0, 1], got {self.target_quantile}")


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
    layout = "" if cfg.model.attention == "window" else f"-{cfg.model.attention}"
    return Path(root) / f"pretrain-{Path(cfg.dataset).name}-s{cfg.seed}-{cfg.preset}{layout}"


def pretrain(cfg: PretrainConfig, run_dir: str | Path, *, resume: bool = False, force: bool = False,
             progress: bool = True, interrupt_at: int | None = None, device: str = "cpu") -> Path:
    """Pre-train a DT on ``cfg.dataset`` (Algorithm 1, stage 1) on the torch ``device``; returns
    the model directory.

    ``interrupt_at`` is a test hook that stops training after that step.
    """
    run_dir = Path(run_dir)
    ds = training_subset(load_dataset(cfg.dataset), cfg.scenarios)
    more = [load_dataset(path) for path in cfg.more_datasets]
    check_mixable(ds, more)
    resuming = prepare_run_dir(run_dir, PRETRAIN_KIND, cfg.to_dict(), resume, force)
    system = ds.system
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    model = model_for_data(cfg.model.for_data(system, action_dim_for(system, ds.phase_control)),
                           ds.trajectories).to(device)
    opt = make_optimizer(model, cfg.learning_rate, cfg.weight_decay)
    windows: TrainingWindows | MixedWindows = TrainingWindows.for_model(ds.trajectories, model.cfg, system)
    if more:  # halls of several device counts: one set of windows per dataset, one model (.encoders)
        windows = MixedWindows([windows] + [TrainingWindows.for_model(d.trajectories, model.cfg, d.system)
                                            for d in more])
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
