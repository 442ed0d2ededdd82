"""The flags commands share, beside the config dataclasses tyro reads.

Lives here: :class:`RunOptions` (where a training run goes and whether it resumes) and
:func:`check_run_options`, the one place that says what ``--resume`` and ``--force`` mean
on the command line; :data:`LAYOUT_HELP` and :func:`in_hall`, the one place that says what
``--layout`` and the ``--system.*`` flags do to a command's system and start; :func:`with_flags`,
the one place that says which fields a command line gives (a command parses its line once, then
builds its config: the defaults its choices make, the flags written on top). Not here: the run
directory itself (:mod:`uavris.runs`), layouts (:mod:`uavris.layouts`).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass, replace
from pathlib import Path
from typing import Any, TypeVar

from uavris.agents.torch_device import Device, resolve_device
from uavris.cli.parsing import Unset, UsageError, output_dir
from uavris.config import Scenario, SystemConfig
from uavris.layouts import resolve_layout, sets_room
from uavris.runs import CONFIG_FILE, config_path

T = TypeVar("T")


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


LAYOUT_HELP = ("the hall: paper (the paper's devices), layout-train-N / layout-unseen-N (generated; -kK: K "
               "devices, docs/study.md section 2) or a YAML layout file (devices, optionally start and room); it "
               "sets --system.users (and --system.room) and the start (unless --scenario is given); default: the "
               "devices of --system.users")


def given_flags(args: list[str]) -> set[str]:
    """The flags written on the command line (``--system.room``, also as ``--system.room=...``; a
    name's underscores as dashes): a flag given with its default value is still given."""
    return {a.split("=", 1)[0].replace("_", "-") for a in args if a.startswith("--")}


def _check_beside_layout(named: str | None, args: list[str]) -> None:
    """The layout ``named`` (None: none) refused in one line beside a flag of ``args`` that gives what
    it gives: ``--system.users`` (the devices), ``--system.room`` where the layout sets its room."""
    given = given_flags(args)
    if named is None:
        return
    if "--system.users" in given:
        raise UsageError("--layout and --system.users both give the device positions; pass one of them")
    if "--system.room" in given and sets_room(named):
        raise UsageError(f"--layout {named} sets the room; drop --system.room or the file's room")


def _given_fields(base: Any, parsed: Any, given: set[str], prefix: str) -> dict[str, Any]:
    """The fields of the dataclass ``parsed`` whose flag (``PREFIX.NAME``, a boolean's ``PREFIX.no-NAME``; ``--NAME``
    without a prefix) was written, by name; a nested dataclass (the propulsion parameters) as ``base``'s with its own
    written ones."""
    out: dict[str, Any] = {}
    for f in fields(parsed):
        name = f.name.replace("_", "-")
        flag, negated = (f"{prefix}.{name}", f"{prefix}.no-{name}") if prefix else (f"--{name}", f"--no-{name}")
        value, under = getattr(parsed, f.name), getattr(base, f.name)
        if is_dataclass(value) and is_dataclass(under):
            inner = _given_fields(under, value, given, flag)
            if inner:
                out[f.name] = replace(under, **inner)
        elif is_dataclass(value) and any(g.startswith(f"{flag}.") for g in given):
            out[f.name] = _checked(value)  # a nested config the base has none of (an expert's imitation), asked for
        elif flag in given or negated in given:
            out[f.name] = _checked(value)
    return out


_LOOSE: dict[type, type] = {}  # a config class -> its form that checks nothing
_REAL: dict[type, type] = {}  # and back


def unchecked(config: T, **changes: Any) -> T:
    """``config`` as the one parse's default of a command that builds its config afterwards: the same
    fields, nested configs included, in subclasses whose ``__post_init__`` judges nothing. tyro keeps
    the default's classes, so the parse takes the line's values without checking them against the
    parse's own defaults (another preset's budgets and hyperparameters, a placeholder scenario, the
    paper's hall); the command's build makes the real config, every check run there
    (:func:`with_flags`, :func:`in_hall`). ``changes``: fields given other values (a nested config the
    defaults have none of, whose flags the parse and the help still offer)."""
    cls = _REAL.get(type(config), type(config))  # a form that checks nothing already: its real class's
    if cls not in _LOOSE:
        public = next(c for c in cls.__mro__ if not c.__name__.startswith("_"))  # its help is the public class's
        loose = type(public.__name__, (cls,), {"__post_init__": lambda self: None, "__doc__": public.__doc__,
                                               "__module__": public.__module__})
        _LOOSE[cls], _REAL[loose] = loose, public
    out = object.__new__(_LOOSE[cls])
    for f in fields(config):
        value = changes.get(f.name, getattr(config, f.name))
        object.__setattr__(out, f.name, unchecked(value) if is_dataclass(value) else value)
    return out


def _checked(value: Any) -> Any:
    """The real, checked config of a parsed one (:func:`unchecked`); any other value as it is."""
    real = _REAL.get(type(value))
    if real is None:
        return value
    return real(**{f.name: _checked(getattr(value, f.name)) for f in fields(value) if f.init})


def with_flags(base: Any, parsed: Any, args: list[str], skip: tuple[str, ...] = ()) -> Any:
    """The config ``base`` (the defaults a command's choices make: its preset, a file, a model, a
    hall) with every field whose flag is written in ``args`` taken from ``parsed``, the command's one
    parse of its flattened config (a flag given at its default value still counts; a nested
    config's flags change that config's fields); the fields in ``skip`` stay ``base``'s."""
    changes = _given_fields(base, parsed, given_flags(args), "")
    return replace(base, **{k: v for k, v in changes.items() if k not in skip})


def in_hall(layout: str | None, base: SystemConfig, parsed: SystemConfig,
            args: list[str]) -> tuple[SystemConfig, Scenario | None]:
    """The system of a command parsed once: ``base`` (the target's, the study's, the paper's) with
    the ``--system.*`` flags written in ``args`` (their values read from ``parsed``, the command's
    parsed system, so a flag given at its default value still counts), in the hall ``layout``
    names, and that layout's start; without a layout, ``base`` with the flags and None.

    The flags apply to the base system before the layout resolves (a generated hall is drawn
    in the room of ``--system.room``). A layout gives the devices and, a layout file may, the
    room: ``--layout`` with ``--system.users``, or a file with a room with ``--system.room``,
    gives them twice, which is one error line whatever the values (the paper's room given
    beside a file's room is no less a contradiction). A lower room caps the UAV's ceiling
    (:meth:`Layout.system`) unless ``--system.z-max`` is written: then the flag's ceiling is
    judged in that room."""
    _check_beside_layout(layout, args)
    written = _given_fields(base, parsed, given_flags(args), "--system")
    flagged = replace(base, **written)  # judged once in its hall: its room or pairs may fit only the layout's devices
    if layout is None:
        return flagged.check(), None
    system, start = resolve_layout(layout, flagged).resolve(flagged)
    if "z_max" in written and system.z_max != written["z_max"]:  # the user's ceiling, not the room's cap
        system = system.replace(z_max=written["z_max"])
        start.validate_for(system)
    return system, start


def seed_note(row: Any, seeds: list[int]) -> str:
    """A line saying which of its seeds a row of several is (the report's row of that name is their
    mean), and how to name the others; nothing for a row of one seed."""
    if len(seeds) < 2:
        return ""
    others = ", ".join(f"{row.variant}@s{s}" for s in seeds if s != (row.seed or 0))
    return (f"note: this is seed {row.seed or 0} of the row's {len(seeds)} seeds ({', '.join(map(str, seeds))}); the "
            f"report's {row.variant} is their mean; the others are {others}\n")
