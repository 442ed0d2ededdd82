"""Run directories: the guard against overwriting, the checkpoint pointer, the completion record.

Lives here: the one implementation of what every training command (expert training,
DT pre-training and fine-tuning) does with its run directory. Not here: what a run writes
besides (its logs, checkpoints and models, each written by its own command).

A run directory holds its configuration (``config.yaml``, :data:`CONFIG_FILE`, for every
kind of run), a
``checkpoints/latest.json`` pointer to the newest checkpoint (moved last and atomically,
so a kill at any moment leaves the previous checkpoint usable), ``timing.json`` (the
wall-clock time it took, over every session: the one file that differs between two runs
of the same configuration) and, once finished, ``done.json``. A finished run is never
redone without ``force``; an unfinished one is continued only with ``resume`` and the
same configuration.
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path
from typing import Any, Callable

from uavris.errors import UavrisError
from uavris.io import contents, read_json, read_yaml, to_plain, write_json, write_yaml

CONFIG_FILE = "config.yaml"
DONE_FILE = "done.json"
POINTER = Path("checkpoints") / "latest.json"
TIMING_FILE = "timing.json"  # wall-clock measurements: kept apart so every other file is reproducible to the bit


def is_finished(run_dir: str | Path) -> bool:
    return (Path(run_dir) / DONE_FILE).exists()


def config_path(run_dir: str | Path) -> Path | None:
    """The run's configuration file (:data:`CONFIG_FILE`), or None."""
    path = Path(run_dir) / CONFIG_FILE
    return path if path.is_file() else None


def read_config(run_dir: str | Path) -> Any:
    """The stored configuration of a run (a mapping, unless the file is not a run's), or None
    when the directory holds none."""
    path = config_path(run_dir)
    return None if path is None else read_yaml(path)


def prepare(run_dir: Path, record: dict[str, Any], *, resume: bool, force: bool, what: str = "uavris run",
            same: Callable[[Any], bool] | None = None) -> bool:
    """Check ``run_dir`` before training into it; returns True when an unfinished run is resumed.

    ``record`` is the run's configuration as a dict, written to :data:`CONFIG_FILE` for a new
    run; ``same(stored)`` says whether a stored one is the requested one (default: equal to
    ``record``). Raises :class:`UavrisError` for a finished run (unless ``force``), an
    existing run without ``resume`` or ``force``, a resume with another configuration, a file
    in the run directory's place, and a directory that is not a run (never deleted).
    """
    if run_dir.exists() and not run_dir.is_dir():
        raise UavrisError(f"{run_dir} exists and is not a directory")
    record = to_plain(record)
    has_config = config_path(run_dir) is not None
    if force and run_dir.exists() and not resume:
        if not has_config and contents(run_dir):
            raise UavrisError(f"{run_dir} exists and is not a {what} directory; refusing to overwrite it")
        for entry in contents(run_dir):  # the writer's lock stays: this process holds it
            shutil.rmtree(entry) if entry.is_dir() and not entry.is_symlink() else entry.unlink()
        has_config = False
    elif is_finished(run_dir):
        raise UavrisError(f"{run_dir} is a finished run; evaluate it, pass --force to redo it from scratch, or "
                          "--out DIR to run this configuration elsewhere")
    elif has_config and not resume:
        raise UavrisError(f"{run_dir} already holds a run; pass --resume to continue it or --force to start over")
    elif run_dir.exists() and not has_config and contents(run_dir):
        raise UavrisError(f"{run_dir} exists and is not a {what} directory")
    if has_config:
        stored = read_config(run_dir)
        if not (same(stored) if same is not None else stored == record):
            raise UavrisError(f"{run_dir} was started with a different configuration; resume it without changing "
                              "parameters, or pass --force to start over")
        return True
    run_dir.mkdir(parents=True, exist_ok=True)
    write_yaml(run_dir / CONFIG_FILE, record)
    return False


def write_pointer(run_dir: Path, info: dict[str, Any]) -> None:
    """Point ``checkpoints/latest.json`` at a checkpoint (call it after the checkpoint is complete)."""
    write_json(run_dir / POINTER, info)


def read_pointer(run_dir: Path, *fields: str) -> dict[str, Any] | None:
    """The latest checkpoint's pointer, or None when there is none; ``fields`` must be present."""
    path = run_dir / POINTER
    if not path.exists():
        return None
    info = read_json(path)
    if not isinstance(info, dict) or any(f not in info for f in fields):
        raise UavrisError(f"{path} is corrupt")
    return info


def write_done(run_dir: Path, record: dict[str, Any]) -> None:
    write_json(run_dir / DONE_FILE, record)


def read_done(run_dir: Path) -> dict[str, Any]:
    return read_json(Path(run_dir) / DONE_FILE)


def read_timing(run_dir: str | Path) -> dict[str, Any]:
    """The timing record of a run or stage directory (empty when there is none)."""
    path = Path(run_dir) / TIMING_FILE
    return read_json(path) if path.exists() else {}


class RunClock:
    """Wall-clock seconds a run has spent over all its sessions, kept in ``timing.json``.

    A resumed run adds the new session to what its last save recorded; the work lost after
    the last checkpoint of a killed session is not counted (it is redone, and counted then).
    """

    def __init__(self, run_dir: Path, resuming: bool) -> None:
        self.run_dir = Path(run_dir)
        self.before = float(read_timing(self.run_dir).get("wall_clock_s", 0.0)) if resuming else 0.0
        self.t0 = time.perf_counter()

    @property
    def seconds(self) -> float:
        return self.before + time.perf_counter() - self.t0

    def save(self, **extra: Any) -> None:
        write_json(self.run_dir / TIMING_FILE, {"wall_clock_s": self.seconds, **extra})
