"""The learned value of a pose, as runs: its labels in training halls of several device counts, and its fit.

Lives here: :class:`ValueLabelsConfig` and :func:`make_labels` (the poses and ``R`` of a
range of training halls of one count, written as a part a rerun reuses), :func:`read_labels`
(parts as :class:`~uavris.agents.place.value.ValueLabels`), :class:`ValueFitConfig` and
:func:`fit` (the network fitted to the labels, a checkpoint directory). Not here: the network
(:mod:`uavris.agents.place.value`), the poses and ``R`` of one hall
(:mod:`uavris.agents.place.labels`), the study's stages (:mod:`uavris.experiments.study.pipeline`).
"""

from __future__ import annotations

import dataclasses
import io
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from uavris.agents.place.checkpoint import save_value
from uavris.agents.place.labels import hall_labels
from uavris.agents.place.value import ValueConfig, ValueLabels, fit_value
from uavris.config import DictConfig, SystemConfig
from uavris.errors import ConfigError
from uavris.io import atomic_write_bytes, write_csv, write_json
from uavris.layouts import LayoutGenerator
from uavris.presets import PRESET, VALUE, VALUE_SEED, Preset, PresetConfig, check_preset, fill_from_preset
from uavris.runs import TIMING_FILE


@dataclass(frozen=True)
class ValueLabelsConfig(DictConfig):
    """Where the learned value's labels come from: ``halls`` training halls of each count in
    ``counts`` (the generator's ``layout-train-J``, of its ``layout_seed``), ``poses`` labelled
    poses each (:func:`uavris.agents.place.labels.hall_labels`)."""

    counts: tuple[int, ...] = (3, 4, 5, 6, 7, 8)  # devices per hall
    halls: int = 32  # training halls per count
    poses: int = 48  # labelled poses per hall
    layout_seed: int = 0  # the layout generator's seed (the study's)
    seed: int = VALUE_SEED  # the poses' and the labels' random numbers (hall j of count K: seed + 1000 K + j)
    tilted: bool = True  # each position labelled again with the surface turned towards the devices
    system: SystemConfig = dataclasses.field(default_factory=lambda: SystemConfig(observe_devices=True))

    def __post_init__(self) -> None:
        object.__setattr__(self, "counts", tuple(int(k) for k in self.counts))
        if not self.counts or any(k < 2 for k in self.counts):
            raise ConfigError(f"ValueLabelsConfig.counts must be device counts >= 2, got {list(self.counts)}")
        for name in ("halls", "poses"):
            if getattr(self, name) < 1:
                raise ConfigError(f"ValueLabelsConfig.{name} must be >= 1, got {getattr(self, name)}")

    def hall(self, count: int, j: int) -> tuple[str, SystemConfig]:
        """Training hall ``j`` of ``count`` devices: its name and system."""
        layout = LayoutGenerator(devices=count, seed=self.layout_seed).layout("train", j, self.system)
        return layout.name, layout.system(self.system)


def make_labels(cfg: ValueLabelsConfig, count: int, first: int, n: int, out: str | Path) -> Path:
    """The labels of training halls ``first .. first + n - 1`` of ``count`` devices, written to
    ``out`` (an ``.npz`` part, atomically: a part on disk is a finished one)."""
    users, positions, attitudes, rates, halls = [], [], [], [], []
    for j in range(first, first + n):
        name, system = cfg.hall(count, j)
        q, att, r = hall_labels(system, cfg.poses, cfg.seed + 1000 * count + j, cfg.tilted)
        users.append(np.broadcast_to(np.asarray(system.users), (len(q), count, 3)))
        positions.append(q)
        attitudes.append(att)
        rates.append(r)
        halls += [name] * len(q)
    return write_label_part(out, users=np.concatenate(users), position=np.concatenate(positions),
                            rate=np.concatenate(rates), hall=np.array(halls), attitude=np.concatenate(attitudes))


def write_label_part(out: str | Path, *, users: np.ndarray, position: np.ndarray, rate: np.ndarray,
                     hall: np.ndarray, attitude: np.ndarray | None = None) -> Path:
    """Labels of one count (devices ``(n, K, 3)``, positions ``(n, 3)``, ``R`` ``(n,)``, halls
    ``(n,)``, attitudes ``(n, 3)``, level where not given) as an ``.npz`` part, written
    atomically (a part on disk is a finished one)."""
    buf = io.BytesIO()
    np.savez(buf, users=users, position=position, rate=rate, hall=hall,
             attitude=np.zeros_like(position) if attitude is None else attitude)
    atomic_write_bytes(Path(out), buf.getvalue())
    return Path(out)


def read_labels(parts: Sequence[str | Path]) -> ValueLabels:
    """Label parts (:func:`make_labels`) as one set, by device count."""
    by: dict[int, dict[str, list[np.ndarray]]] = {}
    for path in parts:
        with np.load(path) as z:
            k = int(z["users"].shape[1])
            for key in ("users", "position", "rate", "hall"):
                by.setdefault(k, {}).setdefault(key, []).append(z[key])
            by[k].setdefault("attitude", []).append(z["attitude"] if "attitude" in z.files
                                                    else np.zeros_like(z["position"]))
    cat = {k: {key: np.concatenate(v) for key, v in d.items()} for k, d in by.items()}
    def field(key: str) -> dict[int, np.ndarray]:
        return {k: d[key] for k, d in cat.items()}

    return ValueLabels(users=field("users"), position=field("position"), rate=field("rate"), hall=field("hall"),
                       attitude=field("attitude"))


@dataclass(frozen=True)
class ValueFitConfig(PresetConfig):
    """A fit of the learned value. Fields left at ``PRESET`` take the preset's values
    (:data:`uavris.presets.VALUE`)."""

    preset: Preset = "quick"
    seed: int = 0  # the weights' and the batches' seed
    width: int = PRESET  # the network's width (ValueConfig.width)
    steps: int = PRESET  # gradient steps
    batch_size: int = 256  # poses per step (of one device count)
    learning_rate: float = 1e-3  # Adam's first rate (a cosine decay to zero)

    def __post_init__(self) -> None:
        check_preset(self.preset)
        fill_from_preset(self, {k: v for k, v in VALUE[self.preset].items() if k in ("width", "steps")})
        for name in ("width", "steps", "batch_size"):
            if getattr(self, name) < 1:
                raise ConfigError(f"ValueFitConfig.{name} must be >= 1, got {getattr(self, name)}")
        if not self.learning_rate > 0:
            raise ConfigError(f"ValueFitConfig.learning_rate must be > 0, got {self.learning_rate}")


def fit(cfg: ValueFitConfig, parts: Sequence[str | Path], out: str | Path) -> Path:
    """The learned value fitted to the label ``parts``, written to ``out`` (a checkpoint
    directory, :mod:`uavris.agents.place.checkpoint`) with its loss curve (``fit_log.csv``,
    every 100 steps), a done record and its wall clock (:data:`uavris.runs.TIMING_FILE`)."""
    out = Path(out)
    labels = read_labels(parts)
    log: list[dict[str, float]] = []
    window: list[float] = []
    t0 = time.perf_counter()

    def on_step(step: int, loss: float) -> None:
        window.append(loss)
        if step % 100 == 0 or step == cfg.steps:
            log.append({"step": step, "loss": float(np.mean(window))})
            window.clear()

    model = fit_value(labels, ValueConfig(width=cfg.width), steps=cfg.steps, batch=cfg.batch_size,
                      lr=cfg.learning_rate, seed=cfg.seed, on_step=on_step)
    write_csv(out / "fit_log.csv", ("step", "loss"), log)
    counts = {int(k): int(len(r)) for k, r in labels.rate.items()}
    save_value(model, out, {"fit": cfg.to_dict(), "labels": counts})
    write_json(out / "done.json", {"labels": counts, "final_loss": log[-1]["loss"] if log else float("nan")})
    # the wall clock beside the record, not in it: done.json (and the study's stage record of
    # it) is the same for the same labels and configuration
    write_json(out / TIMING_FILE, {"wall_clock_s": time.perf_counter() - t0})
    return out
