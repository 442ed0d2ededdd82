"""Each field's help, read from its class's source once per process and kept on the field.

Lives here: :func:`with_help` (a class's fields, and its nested configs', given their help in
their metadata) and :func:`get_field_docstring` (tyro's reading of one field's help). Not here:
parsing (:mod:`.parsing`), the flags of a config (:mod:`.options`).

Why: tyro reads a field's help from ``metadata["help"]`` before it looks in the class's
source, and it empties its caches after every parse, so without this every parse tokenises
the source of every class it parses again, about half a command line's parse
(``benchmarks/cli_parse.py``). The help is the same to the byte (tests/test_cli.py).
"""

from __future__ import annotations

import types
import typing
from dataclasses import fields, is_dataclass
from typing import Any, get_args

try:  # the help of a field and of a class, as tyro reads them: private in tyro 1.0, whose version the project pins
    from tyro._docstrings import get_callable_description, get_field_docstring
except ImportError:  # another tyro: it reads each field's help itself, every command still works
    def get_field_docstring(cls: type, name: str, markers: tuple) -> str | None:
        return None

    def get_callable_description(f: Any) -> str | None:
        return None

_HELPED: set[type] = set()


def with_help(cls: type) -> type:
    """``cls``, each of its fields (and its nested configs' fields) carrying its help in the
    field's metadata (``help``), read from the class's source the first time only. A group
    without a help of its own gets its class's description, as tyro falls back to."""
    if cls in _HELPED or not is_dataclass(cls):
        return cls
    _HELPED.add(cls)
    hints = typing.get_type_hints(cls, include_extras=True)
    for f in fields(cls):
        nested = _classes_in(hints[f.name])
        if "help" not in f.metadata:
            doc = get_field_docstring(cls, f.name, ())
            if doc is None and len(nested) == 1:  # a group's help: its class's, as tyro falls back to
                doc = get_callable_description(nested[0])
            if doc is not None:
                f.metadata = types.MappingProxyType({**f.metadata, "help": doc})
        for inner in nested:
            with_help(inner)
    return cls


def _classes_in(hint: Any) -> list[type]:
    """The dataclasses a field's type names (itself, or inside Annotated, Optional, a union)."""
    if is_dataclass(hint) and isinstance(hint, type):
        return [hint]
    return [c for arg in get_args(hint) for c in _classes_in(arg)]
