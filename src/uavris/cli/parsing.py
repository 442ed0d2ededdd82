"""Turning argv into dataclasses with tyro (a config's flags), and a rejected command line into one line.

Lives here: :func:`parse` (tyro over a command's dataclass, its defaults given; a rejected
command line becomes one :class:`UsageError` line, built from tyro's parse-error event),
:func:`parse_built` (a command line parsed once and built into its config), the registry's
rule for lists of points (``--system.users``) and a ``--config`` file's overrides. Not here: the commands
themselves (:mod:`.training`, :mod:`.evaluation`), where they write (:mod:`.outputs`).

Why :func:`parse_built`: a few flags choose the defaults of many others (a preset every
budget, a config file every field, a model its system, a layout the hall), so a command parses
what its line wrote (:func:`uavris.cli.options.flags_of`: every flag None where not written)
and builds its config from layers (:func:`uavris.cli.options.layered`). Only ``--help`` looks
twice: it shows the defaults the line's choices make (``uavris train --preset paper --help`` the
paper preset's), so the line without it is parsed and built first.
"""

from __future__ import annotations

import contextlib
import inspect
import io
import re
import sys
from pathlib import Path
from typing import Annotated, Any, Callable, Literal, Optional, TypeVar, get_args, get_origin

import tyro
from tyro.constructors import ConstructorRegistry, PrimitiveConstructorSpec, PrimitiveTypeInfo

from uavris.cli.field_help import with_help
from uavris.errors import UavrisError
from uavris.io import read_yaml

try:  # tyro's parse-error events: private and experimental in tyro 1.0, whose version the project pins
    from tyro._errors import (
        BadValue,
        InstantiationFailure,
        InvalidChoice,
        MissingArgs,
        ParseErrorEvent,
        UnrecognizedArgs,
        on_parse_error,
    )
except ImportError:  # another tyro: its own boxed message, then exit 2 (still one failure, not a traceback)
    on_parse_error = None

T = TypeVar("T")

# An optional flag whose help says what leaving it out means (--out, --layout, --scenario, ...):
# its metavar without "{None}|" (typing None there means nothing) and no "(default: None)"
# after the help's own default.
Unset = Annotated[Optional[T], tyro.conf.DisallowNone, tyro.conf.arg(help_behavior_hint="")]
# Nested configs become flags without their parent's prefix only where the command says so;
# an Optional nested config (TrainConfig.imitation) stays at its default instead of turning
# into a subcommand.
TYRO_CONFIG = (tyro.conf.AvoidSubcommands,)
HELP = ("-h", "--help")
POINTS = tuple[tuple[float, float, float], ...]  # SystemConfig.users: x y z per device
REGISTRY = ConstructorRegistry()


class UsageError(UavrisError):
    """A command line that does not parse: unknown flag, wrong type, missing argument."""


@REGISTRY.primitive_rule
def _points(info: PrimitiveTypeInfo) -> PrimitiveConstructorSpec | None:
    """A list of points is typed as its numbers, x y z per point (``--system.users 15 5 1 20 8 1.5``)."""
    if info.type not in (POINTS, Optional[POINTS]):  # the field, or its flag (None: not written)
        return None

    def points(values: list[str]) -> POINTS:
        if len(values) % 3:
            raise ValueError(f"takes x y z per device: a multiple of 3 numbers, got {len(values)} value"
                             f"{'s' * (len(values) != 1)}: {' '.join(values)}")
        try:
            numbers = [float(v) for v in values]
        except ValueError:
            raise ValueError(f"takes numbers (x y z per device), got {' '.join(values)}") from None
        return tuple((numbers[i], numbers[i + 1], numbers[i + 2]) for i in range(0, len(numbers), 3))

    return PrimitiveConstructorSpec(nargs="*", metavar="X Y Z [X Y Z ...]", instance_from_str=points,
                                    is_instance=lambda x: isinstance(x, tuple),
                                    str_from_instance=lambda p: [str(c) for point in p for c in point])


def _literals(hint: Any) -> list[str]:
    """The values of the Literal types in ``hint`` (through Optional and unions), in their declared order."""
    if get_origin(hint) is Literal:
        return [str(v) for v in get_args(hint)]
    return [v for arg in get_args(hint) for v in _literals(arg)]


def _one_line(event: Any) -> str:
    """What a parse-error event says, as one line naming the flag."""
    if isinstance(event, MissingArgs):
        names = [a.arg.display_name() for a in event.missing_arguments]
        return f"missing required argument{'s' * (len(names) > 1)} {', '.join(names)}"
    if isinstance(event, InvalidChoice):
        declared = _literals(event.argument.field.type_stripped)
        choices = sorted((c for c in (event.argument.lowered.choices or event.choices) if c != "None"),
                         key=lambda c: declared.index(c) if c in declared else len(declared))
        return (f"invalid choice {event.value!r} for argument '{event.argument.display_name()}'; expected one of "
                f"{', '.join(repr(c) for c in choices)}")
    if isinstance(event, UnrecognizedArgs):
        return f"unrecognized option{'s' * (len(event.tokens) > 1)} {' '.join(event.tokens)}"
    if isinstance(event, BadValue):
        name = event.argument.display_name()
        if event.reason == "too_few_values":
            return f"{name} expects {event.argument.lowered.nargs} value(s)"
        return f"{name} takes no value, got {event.offending_value!r}"
    if isinstance(event, InstantiationFailure):
        message = " ".join(event.message.split("\n\n")[0].split())  # tyro's own detail follows a blank line
        if event.argument is None:
            return message
        name = event.argument.display_name()
        unread = re.fullmatch(r"no type matching (.*) could be instantiated from \[(.*)\]\.?", message)
        if unread:  # a flag's value of the wrong type (its flag is optional: not written is None)
            expected, got = unread.group(1), unread.group(2).replace("'", "")
            choices = re.fullmatch(r"\{([^{}\[\] ]+)\}", expected)  # {ddpg,ppo,sac,td3}
            expected = (f"one of {', '.join(choices.group(1).split(','))}" if choices
                        else expected.removeprefix("{").removesuffix("}"))
            return f"{name} expects {expected}, got {got}"
        return f"{name} {message}" if name.endswith("users") else f"{name}: {message}"
    return f"the command line does not parse ({type(event).__name__})"


def parse(cls: type[T], args: list[str], prog: str, description: str, default: T | None = None) -> T:
    """``tyro.cli(cls)`` on ``args``; a rejected command line raises one-line :class:`UsageError`.

    ``--help`` prints tyro's help on stdout and exits 0 as usual.
    """
    with_help(cls)

    def reject(event: ParseErrorEvent) -> None:
        raise UsageError(f"{_one_line(event)} (see {prog} --help)")

    hook = on_parse_error(reject) if on_parse_error is not None else contextlib.nullcontext()
    captured = io.StringIO()
    try:
        with hook, contextlib.redirect_stderr(captured):
            got = tyro.cli(cls, args=args, prog=prog, description=inspect.cleandoc(description), default=default,
                           config=TYRO_CONFIG, registry=REGISTRY)
    except SystemExit as e:
        sys.stderr.write(captured.getvalue())  # --help (exit 0), or another tyro's own message
        if e.code in (0, None):
            raise
        raise UsageError(f"the command line does not parse (see {prog} --help)") from None
    return got


def parse_built(cls: type[T], args: list[str], prog: str, description: str, build: Callable[[T, bool], T],
                show: Callable[[T | None, T | None], T]) -> T:
    """``args`` parsed once into ``cls`` and built (``build(parsed, False)``: the config its
    choices make, the flags written on top). With ``--help``, the line without it is parsed and
    built first (``build(parsed, True)``: required flags may be missing), and the help shows
    ``show(built, parsed)`` (either None where the line does not parse or build): the defaults
    the line's choices make, the flags it still requires."""
    if any(a in HELP for a in args):
        parsed = built = None
        with contextlib.suppress(UavrisError):
            parsed = parse(cls, [a for a in args if a not in HELP], prog, description)
            built = build(parsed, True)
        parse(cls, args, prog, description, default=show(built, parsed))  # prints the help and exits
    return build(parse(cls, args, prog, description), False)


def load_overrides(path: Path, kind: str) -> dict[str, Any]:
    """A YAML mapping of config fields (``--config``)."""
    try:
        data = read_yaml(path)  # a missing, unreadable or malformed file is already one line
    except UavrisError as e:
        raise UsageError(f"--config: {e}") from None
    if not isinstance(data, dict):
        raise UsageError(f"--config {path}: expected a mapping of {kind} fields, got {type(data).__name__}")
    return data
