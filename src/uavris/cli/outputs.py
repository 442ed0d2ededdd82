"""Where a command writes: its output checked before any work, held by one writer, and a training run's options.

Lives here: :func:`output_dir` (an output folder that can be written, found before any work),
:func:`writing` (the command's output held for its writing: one writer at a time),
:class:`RunOptions` and :func:`check_run_options` (what ``--out``, ``--resume``, ``--force`` and
``--device`` mean for a training run). Not here: the run directory itself (:mod:`uavris.runs`),
how a line is parsed (:mod:`.parsing`) and built into a config (:mod:`.options`).
"""

from __future__ import annotations

import contextlib
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from uavris.agents.torch_device import Device, resolve_device
from uavris.cli.parsing import Unset, UsageError
from uavris.runs import CONFIG_FILE, config_path
from uavris.runs.lock import locked

NAME_MAX = 255  # bytes in one file or folder name (Linux, macOS); results add their own names inside


def output_dir(path: Path | None, flag: str = "--out") -> None:
    """An output directory may exist (as a directory) or not yet; a file in its place is an
    error, and so is one that cannot be written (read-only, immutable, another user's): found
    before any work, by writing a file into its nearest existing folder (None: ``runs/``, where
    the commands write by default)."""
    target = Path("runs") if path is None else Path(path)
    long = [part for part in target.parts if len(part.encode()) > NAME_MAX]
    if long:  # found before any work, not when the first result is written
        raise UsageError(f"{flag}: a folder name of {len(long[0].encode())} bytes ({long[0][:40]}...); a file system "
                         f"takes at most {NAME_MAX}")
    if target.exists() and not target.is_dir():
        raise UsageError(f"{flag} {path}: exists and is not a directory")
    folder = target.absolute()
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        raise UsageError(f"{flag} {target}: {folder} is not a directory")

    try:
        with tempfile.TemporaryFile(dir=folder, prefix=".uavris-probe-"):
            pass
    except OSError as e:
        what = f"--out (default {target})" if path is None else f"{flag} {target}"
        raise UsageError(f"{what}: {folder} cannot be written ({e.strerror or e})") from None


@contextlib.contextmanager
def writing(path: Path, flag: str = "--out", files_only: bool = False) -> Iterator[Path]:
    """The command's output ``path`` checked (:func:`output_dir`) and held for the block: one
    writer at a time (:func:`uavris.runs.lock.locked`), so a second command into the same
    output is one line instead of a silent replacement of the first's results. Every command
    that writes takes it around all of its writing (``reproduce`` and ``sweep`` inside the
    library, which their workers share). ``files_only``: the command writes files into ``path``
    itself (a plot's folder), never into its subfolders, which may then be links."""
    output_dir(path, flag)
    with locked(path, links=files_only):
        yield Path(path)


@dataclass(frozen=True)
class RunOptions:
    """Where a training run is written and how it starts."""

    out: Unset[Path] = None
    """run directory (default: under runs/, named after the configuration)"""
    resume: bool = False
    """continue the interrupted run in OUT from its last checkpoint, with its stored configuration (train: OUT/
    config.yaml; flags given beside must agree with it); an error if OUT holds no run"""
    force: bool = False
    """delete the run in OUT and start from scratch"""
    device: Device = "cpu"
    """torch device (auto: CUDA when torch sees one)"""
    progress: bool = True
    """show a progress bar"""


def check_run_options(opts: RunOptions, run_dir: Path) -> str:
    """Reject contradictory or empty resumes; returns the resolved torch device.

    The library's ``resume=True`` means "continue if there is something to continue" (the
    study relies on it); a user who types ``--resume`` means "continue this run", so here a
    resume with nothing to continue is an error rather than a silent fresh start.
    """
    output_dir(run_dir)
    if opts.resume and opts.force:
        raise UsageError("--resume (continue the run) and --force (delete it and start over) contradict each "
                         "other; pass one of them")
    if opts.resume:
        if not run_dir.exists():
            raise UsageError(f"--resume: {run_dir} does not exist, so there is no run to resume; drop --resume to "
                             "start a new run")
        if config_path(run_dir) is None:
            raise UsageError(f"--resume: {run_dir} holds no run ({CONFIG_FILE} is missing); drop --resume to start "
                             "a new run")
    return resolve_device(opts.device)
