"""Decision Transformer run directories: checkpoints, resume, and loading a DT for deployment.

Lives here: what DT pre-training and fine-tuning share about their run directories (the
guard, checkpoints of model plus trainer state, the latest-checkpoint pointer) and how a
DT target (a run directory or any model directory) becomes a policy. Not here: the training itself (:mod:`.pretrain`,
:mod:`.finetune`, :mod:`uavris.agents.dt.trainer`).

Run directories (every file written atomically; ``--resume`` continues from the last
checkpoint with identical results; a finished run is never redone without ``--force``)::

    config.yaml          the resolved PretrainConfig / FinetuneConfig ("kind" says which; config.json before 0.3)
    train_log.csv        pre-training: step, loss, learning rate (throughput: TensorBoard)
    finetune.csv         fine-tuning: one row per round (round 0 = zero-shot)
    tb/                  TensorBoard logs
    checkpoints/step_N/  model.safetensors + model.json (a loadable model) and, for the
                         latest only, trainer.safetensors + trainer.json (optimizer, RNGs);
                         fine-tuning names them round_N, one per completed round
    checkpoints/latest.json
    timing.json          wall-clock seconds over all sessions
    model.safetensors, model.json, done.json   the final model and the completion record

A model directory (the run directory, or any ``checkpoints/step_N`` / ``round_N``) is what
``uavris evaluate``, ``uavris finetune-dt --model`` and :func:`load_dt_policy` accept.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from uavris import runs
from uavris.agents.dt.checkpoint import load_dt, read_dt_metadata, save_dt
from uavris.agents.dt.model import DecisionTransformer
from uavris.agents.dt.policy import DTBatchPolicy, dt_policy_from_checkpoint
from uavris.agents.dt.trainer import save_trainer_state
from uavris.config import ConfigError, Scenario, SystemConfig, scenario_at
from uavris.env.simulator import stored_system
from uavris.errors import CheckpointError, UavrisError

PRETRAIN_KIND = "uavris-dt-pretrain"
FINETUNE_KIND = "uavris-dt-finetune"
INT_COLUMNS = {"step", "round", "env_interactions", "gradient_steps"}


def prepare_run_dir(run_dir: Path, kind: str, cfg_dict: dict[str, Any], resume: bool, force: bool) -> bool:
    """The run-directory guard (:func:`uavris.runs.prepare`) for a DT run; True when resuming."""
    return runs.prepare(run_dir, {"kind": kind, **cfg_dict}, resume=resume, force=force, what="uavris DT run")


def write_checkpoint(run_dir: Path, step: int, model: DecisionTransformer, model_meta: dict[str, Any], opt: Any,
                     rng: np.random.Generator, extra: dict[str, Any], prefix: str = "step",
                     clock: runs.RunClock | None = None) -> Path:
    """Model, trainer state, the run's timing, then the ``latest.json`` pointer; older trainer
    states are removed only after the pointer has moved, so a kill at any point leaves a usable one."""
    ck_root = run_dir / "checkpoints"
    ck = ck_root / f"{prefix}_{step}"
    save_dt(model, ck, model_meta)
    save_trainer_state(ck, opt, rng, extra)
    if clock is not None:
        clock.save(**{"round" if prefix == "round" else "gradient_steps": step})
    runs.write_pointer(run_dir, {"step": step, "dir": ck.name})
    for old in ck_root.glob(f"{prefix}_*"):
        if old != ck:
            for name in ("trainer.safetensors", "trainer.json"):
                (old / name).unlink(missing_ok=True)
    return ck


def latest_checkpoint(run_dir: Path) -> tuple[int, Path] | None:
    """(step or round, directory) of the newest checkpoint, or None."""
    info = runs.read_pointer(run_dir, "step", "dir")
    if info is None:
        return None
    try:
        return int(info["step"]), run_dir / "checkpoints" / str(info["dir"])
    except (TypeError, ValueError):
        raise UavrisError(f"{run_dir / runs.POINTER} is corrupt") from None


def restore_weights(model: DecisionTransformer, ck: Path) -> None:
    saved, _ = load_dt(ck)
    model.load_state_dict(saved.state_dict())


def checkpoint_system(meta: dict[str, Any], where: Path) -> SystemConfig:
    """The system a checkpoint was trained on, checked against today's observation layout."""
    if "system" not in meta:
        raise CheckpointError(f"{where} stores no system configuration")
    return stored_system(meta["system"], meta.get("observation_layout"), str(where), CheckpointError)


def dt_model_dir(path: str | Path) -> Path | None:
    """The model directory of a DT target: the directory itself when it holds model.json,
    the latest checkpoint of an unfinished DT run, or None when ``path`` is not a DT target."""
    path = Path(path)
    if (path / "model.json").exists():
        return path
    saved = runs.read_config(path)
    if saved is not None:
        if isinstance(saved, dict) and saved.get("kind") in (PRETRAIN_KIND, FINETUNE_KIND):
            latest = latest_checkpoint(path)
            if latest is None:
                raise UavrisError(f"{path} has no model yet (no model.json and no checkpoint)")
            return latest[1]
    return None


def dt_system(path: str | Path) -> SystemConfig:
    """The system of a DT target (run or model directory), read from its metadata alone."""
    model_dir = dt_model_dir(path)
    if model_dir is None:
        raise UavrisError(f"{path} is not a DT model directory (no model.json)")
    return checkpoint_system(read_dt_metadata(model_dir), model_dir)


def load_dt_policy(path: str | Path, target_return: float | None = None,
                   device: str = "cpu") -> tuple[DTBatchPolicy, SystemConfig, Scenario | None]:
    """(deterministic batch policy, its system config, its own scenario or None) of a DT target:
    a fine-tuned model's system and scenario are those it was fine-tuned in, a pre-trained
    model has no scenario of its own."""
    from uavris.experiments.engine.jobs import configure_threads

    configure_threads()
    model_dir = dt_model_dir(path)
    if model_dir is None:
        raise UavrisError(f"{path} is not a DT model directory (no model.json)")
    policy, meta = dt_policy_from_checkpoint(model_dir, target_return, device=device)
    name = meta.get("scenario")
    try:
        scenario = None if name is None else scenario_at(str(name), meta.get("start"))
    except ConfigError as e:
        raise CheckpointError(f"{model_dir}: stored scenario is invalid ({e})") from None
    return policy, checkpoint_system(meta, model_dir), scenario
