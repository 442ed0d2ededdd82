"""Decision Transformer checkpoints: safetensors weights plus JSON metadata, no pickle.

Lives here: :func:`save_dt`, :func:`load_dt` and :func:`read_dt_metadata`; :func:`dt_model_dir`
(the model a DT run directory stands for) and :func:`checkpoint_system` (the system a model
was trained on). Format: a directory with ``model.safetensors`` (every parameter and buffer)
and ``model.json`` (``kind``, ``format_version``, the :class:`~uavris.agents.dt.config.DTConfig`
and caller-supplied metadata), both written atomically. Not here: the trainer's state (its
optimiser and random streams, :mod:`.training`), the policy a model deploys as and the one
loader of it (:func:`uavris.agents.dt.policy.load_dt_policy`), writing run directories
(:mod:`uavris.experiments.training.dt_runs`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load, save

from uavris import runs
from uavris.agents.dt.config import DTConfig
from uavris.agents.dt.model import DecisionTransformer
from uavris.config import SystemConfig
from uavris.env.simulator import stored_system
from uavris.errors import CheckpointError, ConfigError, UavrisError
from uavris.io import atomic_write_bytes, read_checkpoint_meta, refuse_links_out, write_json

PRETRAIN_KIND = "uavris-dt-pretrain"  # the "kind" of a DT run directory's config.yaml
FINETUNE_KIND = "uavris-dt-finetune"
MODEL_KIND = "uavris-decision-transformer"
MODEL_FORMAT_VERSION = 1
WEIGHTS_FILE = "model.safetensors"
META_FILE = "model.json"


def save_dt(model: DecisionTransformer, directory: str | Path, metadata: dict[str, Any] | None = None) -> Path:
    """Write ``model.safetensors`` then ``model.json`` into ``directory``; returns it.

    The JSON goes last, so a directory whose ``model.json`` exists has matching weights.
    """
    directory = Path(directory)
    tensors = {k: v.detach().cpu().contiguous().clone() for k, v in model.state_dict().items()}
    atomic_write_bytes(directory / WEIGHTS_FILE, save(tensors))
    meta = {"kind": MODEL_KIND, "format_version": MODEL_FORMAT_VERSION, "config": model.cfg.to_dict(),
            **(metadata or {})}
    write_json(directory / META_FILE, meta)
    return directory


def read_dt_metadata(directory: str | Path) -> dict[str, Any]:
    """The ``model.json`` of a DT checkpoint directory, checked for kind and version."""
    return read_checkpoint_meta(directory, META_FILE, MODEL_KIND, MODEL_FORMAT_VERSION, "a DT checkpoint",
                                "a uavris Decision Transformer")


def load_dt(directory: str | Path, device: str = "cpu") -> tuple[DecisionTransformer, dict[str, Any]]:
    """Rebuild the model of a checkpoint directory (in eval mode, on ``device``) and return its metadata."""
    directory = Path(directory)
    meta = read_dt_metadata(directory)
    try:
        cfg = DTConfig.from_dict(meta.get("config"))
    except ConfigError as e:
        raise CheckpointError(f"{directory / META_FILE} has a bad model config: {e}") from None
    weights = directory / WEIGHTS_FILE
    if not weights.exists():
        raise CheckpointError(f"{weights} is missing")
    try:
        tensors = load(weights.read_bytes())
    except (SafetensorError, ValueError, OSError) as e:
        raise CheckpointError(f"{weights} is corrupt ({e})") from None
    model = DecisionTransformer(cfg)
    expected = model.state_dict()
    missing = sorted(set(expected) - set(tensors))
    extra = sorted(set(tensors) - set(expected))
    if missing or extra:
        raise CheckpointError(f"{weights} does not match its config (missing {missing[:3]}, unexpected {extra[:3]})")
    for name, t in tensors.items():
        if t.shape != expected[name].shape:
            raise CheckpointError(f"{weights}: {name} has shape {tuple(t.shape)}, "
                                  f"the config needs {tuple(expected[name].shape)}")
        if not torch.isfinite(t).all():
            raise CheckpointError(f"{weights}: {name} contains NaN or inf")
    model.load_state_dict(tensors)
    if float(model.return_scale) <= 0 or bool((model.state_std <= 0).any()):
        raise CheckpointError(f"{weights} has invalid normalisation (non-positive scale)")
    model.to(device).eval()
    return model, meta


def latest_checkpoint(run_dir: Path) -> tuple[int, Path] | None:
    """(step or round, directory) of a DT run's newest checkpoint, or None."""
    info = runs.read_pointer(run_dir, "step", "dir")
    if info is None:
        return None
    try:
        return int(info["step"]), run_dir / "checkpoints" / str(info["dir"])
    except (TypeError, ValueError):
        raise UavrisError(f"{run_dir / runs.POINTER} is corrupt") from None


def dt_model_dir(path: str | Path) -> Path | None:
    """The model directory of a DT target: the directory itself when it holds model.json,
    the latest checkpoint of an unfinished DT run, or None when ``path`` is not a DT target."""
    path = Path(path)
    if (path / META_FILE).exists():
        return path
    refuse_links_out(path, "a DT run")  # before its configuration is read
    saved = runs.read_config(path)
    if isinstance(saved, dict) and saved.get("kind") in (PRETRAIN_KIND, FINETUNE_KIND):
        latest = latest_checkpoint(path)
        if latest is None:
            raise UavrisError(f"{path} has no model yet (no {META_FILE} and no checkpoint)")
        return latest[1]
    return None


def checkpoint_system(meta: dict[str, Any], where: Path) -> SystemConfig:
    """The system a checkpoint was trained on, checked against today's observation layout."""
    if "system" not in meta:
        raise CheckpointError(f"{where} stores no system configuration")
    return stored_system(meta["system"], meta.get("observation_layout"), str(where), CheckpointError)


def dt_system(path: str | Path) -> SystemConfig:
    """The system of a DT target (run or model directory), read from its metadata alone."""
    model_dir = dt_model_dir(path)
    if model_dir is None:
        raise UavrisError(f"{path} is not a DT model directory (no {META_FILE})")
    return checkpoint_system(read_dt_metadata(model_dir), model_dir)
