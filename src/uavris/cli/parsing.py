"""Turning argv into config dataclasses with tyro, and argv mistakes into one line.

Lives here: :func:`parse` (tyro over a dataclass whose defaults come from a preset or a
file; tyro's boxed usage errors become one :class:`UsageError` line), :func:`peek` (the
few flags that choose those defaults, read before tyro runs) and the checks of paths and
devices that every command shares. Not here: the commands themselves (:mod:`.training`,
:mod:`.evaluation`).
"""

from __future__ import annotations

import contextlib
import inspect
import io
import re
import sys
from pathlib import Path
from typing import Annotated, Any, Optional, TypeVar

import tyro

from uavris.errors import UavrisError

T = TypeVar("T")

# An optional flag whose help says what leaving it out means (--out, --layout, --scenario, ...):
# its metavar without "{None}|" (typing None there means nothing) and no "(default: None)"
# after the help's own default.
Unset = Annotated[Optional[T], tyro.conf.DisallowNone, tyro.conf.arg(help_behavior_hint="")]
# Nested configs become flags without their parent's prefix only where the command says so;
# an Optional nested config (TrainConfig.imitation) stays at its default instead of turning
# into a subcommand.
TYRO_CONFIG = (tyro.conf.AvoidSubcommands,)
# tyro draws its errors in a box, with Unicode or ASCII lines depending on the terminal.
_EDGES = re.compile(r"^[\s│|╭╮╰╯+]*(.*?)[\s│|╭╮╰╯+]*$")
_RULE = re.compile(r"^[\s─\-│|╭╮╰╯+=]*$")
# A list of points (--system.users) whose values do not come in threes: tyro only says it found no parse.
_POINTS = re.compile(r"Error parsing (--[\w.-]*users): Could not find valid parse for arguments: \[(.*)\]")


class UsageError(UavrisError):
    """A command line that does not parse: unknown flag, wrong type, missing argument."""


def _first_message(text: str) -> str:
    """tyro's boxed error as one line: the box's first section, re-joined where it wrapped."""
    body: list[str] = []
    for line in text.splitlines()[1:]:  # the first line is the box's top edge with its title
        if _RULE.match(line):  # the box's separator: the first section is over
            if body:
                break
            continue
        body.append(_EDGES.match(line).group(1))  # type: ignore[union-attr]  # matches any string
    if not body:
        return "could not parse the command line"
    if body[0].startswith("Missing from") and len(body) > 1:
        return f"missing required argument {body[1]}"
    message = " ".join(body).rstrip(".")
    # The command's wrapper dataclass names its flattened config "run" or "study"; users never see it.
    return re.sub(r"Error parsing (run|study|options)\.?", "Error parsing ", message).replace("parsing :", "parsing:")


def parse(cls: type[T], args: list[str], prog: str, description: str, default: T | None = None,
          known_only: bool = False) -> T:
    """``tyro.cli(cls)`` on ``args``; a parse error raises one-line :class:`UsageError`.

    ``--help`` prints tyro's help on stdout and exits 0 as usual. ``known_only``: the
    arguments ``cls`` does not know are left alone (they belong to the rest of the command).
    """
    captured = io.StringIO()
    try:
        with contextlib.redirect_stderr(captured):
            got = tyro.cli(cls, args=args, prog=prog, description=inspect.cleandoc(description), default=default,
                           config=TYRO_CONFIG, return_unknown_args=known_only)
            return got[0] if known_only else got  # type: ignore[index,return-value]
    except SystemExit as e:
        if e.code in (0, None):
            sys.stderr.write(captured.getvalue())
            raise
        message = _first_message(captured.getvalue())
        points = _POINTS.fullmatch(message)
        if points:
            values = [v.strip(" '\"") for v in points.group(2).split(",") if v.strip()]
            message = (f"{points.group(1)} takes x y z per device: a multiple of 3 numbers, got {len(values)} "
                       f"value{'s' * (len(values) != 1)}: {' '.join(values)}")
        raise UsageError(f"{message} (see {prog} --help)") from None


def peek(args: list[str], name: str, default: str | None = None) -> str | None:
    """The value of ``--name VALUE`` or ``--name=VALUE`` in ``args`` (the last one wins)."""
    value = default
    for i, arg in enumerate(args):
        if arg == name and i + 1 < len(args):
            value = args[i + 1]
        elif arg.startswith(name + "="):
            value = arg.split("=", 1)[1]
    return value


def peek_int(args: list[str], name: str, default: int) -> int:
    raw = peek(args, name)
    if raw is None:
        return default
    try:
        return int(raw)
    except ValueError:
        raise UsageError(f"{name} expects an integer, got {raw!r}") from None


def peek_preset(args: list[str]) -> str:
    """The ``--preset`` in ``args``, whose table gives every other field its default; an
    unknown one reads as ``quick`` here, so that tyro then reports it with the choices."""
    from uavris.presets import PRESETS

    preset = peek(args, "--preset", "quick")
    return preset if preset in PRESETS else "quick"


def output_dir(path: Path | None, flag: str = "--out") -> None:
    """An output directory may exist (as a directory) or not yet; a file in its place is an error."""
    if path is not None and Path(path).exists() and not Path(path).is_dir():
        raise UsageError(f"{flag} {path}: exists and is not a directory")


def load_overrides(path: Path, kind: str) -> dict[str, Any]:
    """A YAML mapping of config fields (``--config``)."""
    from uavris.io import read_yaml

    try:
        data = read_yaml(path)  # a missing, unreadable or malformed file is already one line
    except UavrisError as e:
        raise UsageError(f"--config: {e}") from None
    if not isinstance(data, dict):
        raise UsageError(f"--config {path}: expected a mapping of {kind} fields, got {type(data).__name__}")
    return data
