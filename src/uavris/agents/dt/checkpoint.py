"""Decision Transformer checkpoints: safetensors weights plus JSON metadata, no pickle.

Lives here: :func:`save_dt`, :func:`load_dt` and :func:`read_dt_metadata`. Format: a
directory with ``model.safetensors`` (every parameter and buffer) and ``model.json``
(``kind``, ``format_version``, the :class:`~uavris.agents.dt.model.DTConfig` and
caller-supplied metadata), both written atomically. Not here: the trainer's state (its
optimiser and random streams, :mod:`.trainer`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch

from uavris.agents.dt.config import DTConfig
from uavris.agents.dt.model import DecisionTransformer
from uavris.errors import CheckpointError, ConfigError
from uavris.io import atomic_write_bytes, write_json

MODEL_KIND = "uavris-decision-transformer"
MODEL_FORMAT_VERSION = 1
WEIGHTS_FILE = "model.safetensors"
META_FILE = "model.json"


def save_dt(model: DecisionTransformer, directory: str | Path, metadata: dict[str, Any] | None = None) -> Path:
    """Write ``model.safetensors`` then ``model.json`` into ``directory``; returns it.

    The JSON goes last, so a directory whose ``model.json`` exists has matching weights.
    """
    from safetensors.torch import save

    directory = Path(directory)
    tensors = {k: v.detach().cpu().contiguous().clone() for k, v in model.state_dict().items()}
    atomic_write_bytes(directory / WEIGHTS_FILE, save(tensors))
    meta = {"kind": MODEL_KIND, "format_version": MODEL_FORMAT_VERSION, "config": model.cfg.to_dict(),
            **(metadata or {})}
    write_json(directory / META_FILE, meta)
    return directory


def read_dt_metadata(directory: str | Path) -> dict[str, Any]:
    """The ``model.json`` of a DT checkpoint directory, checked for kind and version."""
    path = Path(directory) / META_FILE
    if not path.exists():
        raise CheckpointError(f"{directory} is not a DT checkpoint (no {META_FILE})")
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CheckpointError(f"{path} is corrupt ({e})") from None
    if not isinstance(meta, dict) or meta.get("kind") != MODEL_KIND:
        raise CheckpointError(f"{path} does not describe a uavris Decision Transformer")
    if meta.get("format_version") != MODEL_FORMAT_VERSION:
        raise CheckpointError(f"{path} has format version {meta.get('format_version')!r}; "
                              f"this uavris reads version {MODEL_FORMAT_VERSION}")
    return meta


def load_dt(directory: str | Path, device: str = "cpu") -> tuple[DecisionTransformer, dict[str, Any]]:
    """Rebuild the model of a checkpoint directory (in eval mode, on ``device``) and return its metadata."""
    from safetensors import SafetensorError
    from safetensors.torch import load

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
