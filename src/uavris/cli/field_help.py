"""Each field's help, read from its class's source once per process and kept on the field.

Lives here: :func:`with_help` (a class's fields, and its nested configs', given their help in
their metadata) and :func:`get_field_docstring` (tyro's reading of one field's help). Not here:
parsing (:mod:`.parsing`), the flags of a config (:mod:`.options`).

Why: tyro reads a field's help from ``metadata["help"]`` before it looks in the class's
source, and it empties its caches after every parse, so without this every parse tokenises
the source of every class it parses again: about half of each parse after the first in one
process (the CLI's tests parse some 1,700 lines; ``benchmarks/cli_parse.py``), nothing for a
command run once from a shell, whose time is its imports. The help is the same to the byte
(tests/test_cli.py).
"""

from __future__ import annotations

import types
import typing
from dataclasses import fields, is_dataclass
from typing import Any, get_args

try:  # the help of a field and of a class, as tyro reads them: private in tyro 1.0, whose version the lock pins
    from tyro._docstrings import get_callable_description, get_field_docstring
except ImportError:  # another tyro: it reads each field's help itself, every command still works
    def get_field_docstring(cls: type, name: str, markers: tuple[Any, ...]) -> str | None:
        return None

    def get_callable_description(f: Any) -> str:
        return ""

# The classes given their help; a class is entered before its fields are, so that a nested
# config met twice (or a class that names itself) is visited once.
_HELPED: set[type] = set()


def with_help(cls: type) -> None:
    """Each field of ``cls`` (and of its nested configs) given its help in its metadata
    (``help``), read from the class's source the first time only. A group without a help of
    its own gets its class's description, as tyro falls back to. A field inherited from another
    class is shared with that class and its other subclasses: it gets its help only where that
    help is the same read from each (a subclass's docstring may describe it otherwise, and tyro
    then reads it at each parse)."""
    if cls in _HELPED or not is_dataclass(cls):
        return
    _HELPED.add(cls)
    hints = typing.get_type_hints(cls, include_extras=True)
    for f in fields(cls):
        nested = _classes_in(hints[f.name])
        if "help" not in f.metadata:
            doc = _read_help(cls, f.name, nested)
            owner = next(c for c in cls.__mro__ if f.name in vars(c).get("__annotations__", {}))
            if doc is not None and (owner is cls or doc == _read_help(owner, f.name, nested)):
                f.metadata = types.MappingProxyType({**f.metadata, "help": doc})
        for inner in nested:
            with_help(inner)


def _read_help(cls: type, name: str, nested: list[type]) -> str | None:
    """The help tyro gives the field ``name`` of ``cls`` (a group's: its class's description)."""
    doc = get_field_docstring(cls, name, ())
    return get_callable_description(nested[0]) if doc is None and len(nested) == 1 else doc


def _classes_in(hint: Any) -> list[type]:
    """The dataclasses a field's type names (itself, or inside Annotated, Optional, a union)."""
    if is_dataclass(hint) and isinstance(hint, type):
        return [hint]
    return [c for arg in get_args(hint) for c in _classes_in(arg)]
