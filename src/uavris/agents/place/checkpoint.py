"""Checkpoints of the learned value: safetensors weights plus JSON metadata, no pickle.

Lives here: :func:`save_value`, :func:`load_value` and :func:`is_value_dir`. Format: a
directory with ``value.safetensors`` (every parameter) and ``value.json`` (``kind``,
``format_version``, the :class:`~.value.ValueConfig` and caller-supplied metadata, e.g. the
labels it was fitted to), written atomically, the JSON last. Not here: the network (:mod:`.value`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load, save

from uavris.agents.place.value import PoseValue, ValueConfig
from uavris.errors import CheckpointError, ConfigError
from uavris.io import atomic_write_bytes, read_checkpoint_meta, write_json

VALUE_KIND = "uavris-pose-value"
VALUE_FORMAT_VERSION = 1
WEIGHTS_FILE, META_FILE = "value.safetensors", "value.json"


def save_value(model: PoseValue, directory: str | Path, metadata: dict[str, Any] | None = None) -> Path:
    """Write ``value.safetensors`` then ``value.json`` into ``directory``; returns it."""
    directory = Path(directory)
    tensors = {k: v.detach().cpu().contiguous().clone() for k, v in model.state_dict().items()}
    atomic_write_bytes(directory / WEIGHTS_FILE, save(tensors))
    write_json(directory / META_FILE, {"kind": VALUE_KIND, "format_version": VALUE_FORMAT_VERSION,
                                       "config": model.cfg.to_dict(), **(metadata or {})})
    return directory


def is_value_dir(path: str | Path) -> bool:
    return (Path(path) / META_FILE).is_file()


def load_value(directory: str | Path) -> tuple[PoseValue, dict[str, Any]]:
    """The learned value of a checkpoint directory (in eval mode) and its metadata; one
    :class:`~uavris.errors.CheckpointError` line naming what is wrong with it."""
    directory = Path(directory)
    meta = read_checkpoint_meta(directory, META_FILE, VALUE_KIND, VALUE_FORMAT_VERSION, "a learned value",
                                "a uavris learned value")
    path = directory / META_FILE
    try:
        model = PoseValue(ValueConfig.from_dict(meta.get("config", {})))
    except ConfigError as e:
        raise CheckpointError(f"{path} has a bad config: {e}") from None
    try:
        tensors = load((directory / WEIGHTS_FILE).read_bytes())
        model.load_state_dict(tensors)
    except (OSError, SafetensorError, RuntimeError, ValueError) as e:
        raise CheckpointError(f"{directory / WEIGHTS_FILE} is missing, corrupt or of another size "
                              f"({type(e).__name__})") from None
    if not all(torch.isfinite(t).all() for t in tensors.values()):
        raise CheckpointError(f"{directory / WEIGHTS_FILE} contains NaN or inf")
    return model.eval(), meta
