"""Decision Transformer run directories: the guard, checkpoints and resume.

Lives here: what DT pre-training and fine-tuning share about writing their run directories
(the guard, checkpoints of model plus trainer state, the latest-checkpoint pointer). Not
here: the training itself (:mod:`.pretrain`, :mod:`.finetune`, :mod:`uavris.agents.dt.training`),
reading a run or model directory back (:func:`uavris.agents.dt.checkpoint.dt_model_dir`,
:func:`uavris.agents.dt.policy.load_dt_policy`).

Run directories (every file written atomically; ``--resume`` continues from the last
checkpoint with identical results; a finished run is never redone without ``--force``)::

    config.yaml          the resolved PretrainConfig / FinetuneConfig ("kind" says which)
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
``uavris evaluate``, ``uavris finetune-dt --model`` and
:func:`uavris.agents.dt.policy.load_dt_policy` accept.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from uavris import runs
from uavris.agents.dt.checkpoint import FINETUNE_KIND, PRETRAIN_KIND, latest_checkpoint, load_dt, save_dt
from uavris.agents.dt.model import DecisionTransformer
from uavris.agents.dt.training import save_trainer_state

INT_COLUMNS = {"step", "round", "env_interactions", "gradient_steps"}
__all__ = ["FINETUNE_KIND", "INT_COLUMNS", "PRETRAIN_KIND", "latest_checkpoint", "prepare_run_dir",
           "restore_weights", "write_checkpoint"]


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


def restore_weights(model: DecisionTransformer, ck: Path) -> None:
    saved, _ = load_dt(ck)
    model.load_state_dict(saved.state_dict())
