"""The flags commands share, beside the config dataclasses tyro reads.

Lives here: :class:`RunOptions` (where a training run goes and whether it resumes) and
:func:`check_run_options`, the one place that says what ``--resume`` and ``--force`` mean
on the command line; :data:`LAYOUT_HELP` and :func:`layout_defaults`, the one place that
says what ``--layout`` does to a command's system and scenario. Not here: the run
directory itself (:mod:`uavris.runs`), layouts (:mod:`uavris.layouts`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from uavris.agents.torch_device import Device, resolve_device
from uavris.cli.parsing import UsageError, output_dir, peek
from uavris.config import Scenario, SystemConfig
from uavris.runs import CONFIG_FILE, config_path


@dataclass(frozen=True)
class RunOptions:
    """Where a training run is written and how it starts."""

    out: Optional[Path] = None
    """run directory (default: under runs/, named after the configuration)"""
    resume: bool = False
    """continue the interrupted run in OUT from its last checkpoint, with its stored configuration (train: OUT/
    config.yaml; flags given beside must agree with it); an error if OUT holds no run"""
    force: bool = False
    """delete the run in OUT and start from scratch"""
    device: Device = "cpu"
    """torch device (auto: CUDA when torch sees one)"""
    no_progress: bool = False
    """no progress bar"""


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


LAYOUT_HELP = ("the hall: paper (the paper's devices), layout-train-N / layout-unseen-N (generated, docs/model.md "
               "section 21) or a YAML layout file (devices, optionally start and room); it sets --system.users (and "
               "--system.room) and the start (unless --scenario is given)")


def layout_defaults(args: list[str], system: SystemConfig) -> tuple[SystemConfig, Scenario | None]:
    """``system`` in the hall ``--layout`` names in ``args`` and that layout's start; unchanged
    (and None) without ``--layout``. ``--layout`` with ``--system.users`` gives the devices
    twice, which is one error line."""
    from uavris.layouts import resolve_layout

    ref = peek(args, "--layout")
    if ref is None:
        return system, None
    if any(a == "--system.users" or a.startswith("--system.users=") for a in args):
        raise UsageError("--layout and --system.users both give the device positions; pass one of them")
    return resolve_layout(ref, system).resolve(system)
