"""How a command line becomes a command's config: what the line wrote, layered on the defaults.

Lives here: :func:`flags_of`, the flags of a config class (its fields, each None where the
line does not write it), :func:`written` (what a parsed line wrote) and :func:`layered` (a
config with it on top), the one rule by which every command builds its config: the library's
defaults, then the preset, then a file or a model's config, then the hall (:func:`in_hall`:
``--layout`` and the ``--system.*`` flags), then the flags written, then one check. Not here:
parsing itself (:mod:`.parsing`), where a command writes (:mod:`.outputs`), layouts
(:mod:`uavris.layouts`).

Why flags of their own: tyro builds what it parses, and a config checks itself when it is
made, against defaults the line's choices have not made yet (another preset's budgets, the
paper's hall). The flags are plain data that check nothing, so a flag given at its default
value is still known to be given, and the config is made once, from its layers.
"""

from __future__ import annotations

import typing
from dataclasses import MISSING, field, fields, is_dataclass, make_dataclass, replace
from typing import Annotated, Any, Literal, NamedTuple, Optional, Union

import tyro

from uavris.cli.field_help import get_field_docstring
from uavris.cli.parsing import HELP, POINTS, UsageError, parse
from uavris.config import Scenario, SystemConfig, nested_config, union_members
from uavris.io import INTERNAL
from uavris.layouts import Layout, resolve_layout, sets_room
from uavris.presets import PresetConfig

NONE_WRITTEN = "None"  # how a line writes None to a field that takes it (--system.max-active-pairs None)
_TAKES_NONE = "takes_none"  # a flag's metadata: its field takes None, so "None" written is None
_FLAGS: dict[type, type] = {}


def flags_of(config: type) -> type:
    """The flags of the config class ``config``: a frozen dataclass of the same name, a field per
    field of ``config`` (its type, its help), None where the line does not write it; a nested
    config's are its own flags (``--system.room``). A field tyro suppresses is none."""
    if config in _FLAGS:
        return _FLAGS[config]
    hints = typing.get_type_hints(config, include_extras=True)
    specs: list[tuple[str, Any, Any]] = []
    for f in fields(config):
        hint = hints[f.name]
        if tyro.conf.Suppress in getattr(hint, "__metadata__", ()) or f.metadata.get(INTERNAL):
            continue
        nested = nested_config(hint)
        if nested is not None:
            inner = flags_of(nested)
            specs.append((f.name, inner, field(default_factory=inner)))
            continue
        if typing.get_origin(hint) is Annotated:
            hint = typing.get_args(hint)[0]
        kinds = union_members(hint)
        nullable = type(None) in kinds
        if nullable:  # None is a value of it: written as "None"
            hint = Union[(Literal["None"], *(k for k in kinds if k is not type(None)))]
        arg = tyro.conf.arg(help=get_field_docstring(config, f.name, ()), metavar=_metavar(hint))
        specs.append((f.name, Annotated[Optional[hint], tyro.conf.DisallowNone, arg],
                      field(default=None, metadata={_TAKES_NONE: nullable})))
    flags = make_dataclass(config.__name__, specs, frozen=True, namespace={"__doc__": config.__doc__})
    flags.__module__ = config.__module__
    _FLAGS[config] = flags
    return flags


def _metavar(hint: Any) -> str | None:
    """A sequence's metavar as tyro writes it for the field itself (not as an optional value, in braces)."""
    if hint == POINTS:
        return "X Y Z [X Y Z ...]"
    kinds = typing.get_args(hint) if typing.get_origin(hint) is tuple else ()
    names = [k.__name__.upper() for k in kinds if k in (int, float, str)]
    if len(kinds) == 2 and kinds[1] is Ellipsis and names:
        return f"[{names[0]} [{names[0]} ...]]"
    return " ".join(names) if kinds and len(names) == len(kinds) else None


def written(flags: Any) -> dict[str, Any]:
    """What the parsed ``flags`` (:func:`flags_of`) hold: the fields the line wrote, by name, a
    nested config's as a dict of its own."""
    out: dict[str, Any] = {}
    for f in fields(flags):
        value = getattr(flags, f.name)
        if is_dataclass(value):
            inner = written(value)
            if inner:
                out[f.name] = inner
        elif value is not None:
            out[f.name] = None if f.metadata.get(_TAKES_NONE) and value == NONE_WRITTEN else value
    return out


def layered(base: Any, changes: dict[str, Any]) -> Any:
    """The config ``base`` with ``changes`` (:func:`written`) on top, a nested config's into the
    base's (a config the base has none of, such as an expert's imitation, from its defaults)."""
    hints = typing.get_type_hints(type(base))
    out = {}
    for name, value in changes.items():
        if isinstance(value, dict):
            under = getattr(base, name)
            value = layered(nested_config(hints[name])() if under is None else under, value)
        out[name] = value
    if isinstance(base, PresetConfig):  # a field written is the user's, even at the preset's value
        out["_from_preset"] = tuple((k, v) for k, v in base._from_preset if k not in out)
    return replace(base, **out)


def shown(flags: type, config: Any, required: tuple[str, ...] = ()) -> Any:
    """The flags ``flags`` holding ``config``'s values: what ``--help`` shows as their defaults
    (the fields ``required`` as required; a nested config the config has none of, its defaults)."""
    hints = typing.get_type_hints(type(config))
    values = {}
    for f in fields(flags):
        value = getattr(config, f.name)
        if f.default_factory is not MISSING:  # a nested config's flags
            value = shown(f.default_factory, nested_config(hints[f.name])() if value is None else value)
        values[f.name] = tyro.MISSING if f.name in required else value
    return flags(**values)


LAYOUT_HELP = ("the hall: paper (the paper's devices), layout-train-N / layout-unseen-N (generated; -kK: K "
               "devices, docs/study.md section 2) or a YAML layout file (devices, optionally start and room); it "
               "sets --system.users (and --system.room) and the start (unless --scenario is given); default: the "
               "devices of --system.users")
SystemFlags = flags_of(SystemConfig)  # every command's --system.* flags


class Hall(NamedTuple):
    """Where a command flies: its system (checked), the layout's start and the layout itself
    (None, None without ``--layout``)."""

    system: SystemConfig
    start: Scenario | None
    layout: Layout | None


def in_hall(layout: str | None, base: SystemConfig, flags: dict[str, Any]) -> Hall:
    """The system of a command: ``base`` (the target's, the study's, the paper's) with the
    ``--system.*`` flags the line wrote (``flags``, :func:`written`), in the hall ``layout``
    names, with that layout's start and the layout; without a layout, ``base`` with the flags;
    checked once, whole.

    The flags apply to the base system before the layout resolves (a generated hall is drawn
    in the room of ``--system.room``). A layout gives the devices and, a layout file may, the
    room: ``--layout`` with ``--system.users``, or a file with a room with ``--system.room``,
    gives them twice, which is one error line whatever the values (the paper's room given
    beside a file's room is no less a contradiction). A lower room caps the UAV's ceiling
    (:meth:`Layout.system`) unless ``--system.z-max`` is written: then the flag's ceiling is
    judged in that room."""
    if layout is not None and "users" in flags:
        raise UsageError("--layout and --system.users both give the device positions; pass one of them")
    if layout is not None and "room" in flags and sets_room(layout):
        raise UsageError(f"--layout {layout} sets the room; drop --system.room or the file's room")
    flagged = layered(base, flags)  # judged once in its hall: its room or pairs may fit only the layout's devices
    if layout is None:
        return Hall(flagged.check(), None, None)
    named = resolve_layout(layout, flagged)
    system, start = named.resolve(flagged)
    if "z_max" in flags and system.z_max != flags["z_max"]:  # the user's ceiling, not the room's cap
        system = system.replace(z_max=flags["z_max"])
        start.validate_for(system)
    return Hall(system, start, named)


def parse_in_hall(cls: type, args: list[str], prog: str, description: str) -> Any:
    """:func:`~uavris.cli.parsing.parse` of a command with ``--system.*`` flags (``cls.system``:
    :data:`SystemFlags`): its ``--help`` shows the paper's system as their defaults."""
    default = None
    if any(a in HELP for a in args):
        required = {f.name: tyro.MISSING for f in fields(cls) if f.default is MISSING and f.default_factory is MISSING}
        default = cls(**required, system=shown(SystemFlags, SystemConfig()))
    return parse(cls, args, prog, description, default=default)
