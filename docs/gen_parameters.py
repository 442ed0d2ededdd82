"""Print the Markdown table of :class:`uavris.config.SystemConfig`'s parameters.

One row per field of the dataclass, in its order: the field, its default (the dataclass's
own value) and its meaning, which is the field's inline comment in ``src/uavris/config.py``
(read with :mod:`ast` and :mod:`tokenize`, never typed here). A field without a comment
whose default is itself a config (``propulsion``) takes the first line of that class's
docstring. docs/environment.md holds this output; ``tests/test_docs.py`` fails when they differ.

Usage: ``python docs/gen_parameters.py``.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import io
import tokenize
from typing import Any

from uavris.config import SystemConfig


def field_comments(cls: type) -> dict[str, str]:
    """Each field of the dataclass ``cls`` and the comment at the end of its line."""
    source = inspect.getsource(inspect.getmodule(cls))
    comments = {tok.start[0]: tok.string.lstrip("#").strip()
                for tok in tokenize.generate_tokens(io.StringIO(source).readline) if tok.type == tokenize.COMMENT}
    tree = ast.parse(source)
    node = next(n for n in ast.walk(tree) if isinstance(n, ast.ClassDef) and n.name == cls.__name__)
    out = {}
    for stmt in node.body:
        if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name):
            lines = [comments[i] for i in range(stmt.lineno, stmt.end_lineno + 1) if i in comments]
            if lines:
                out[stmt.target.id] = " ".join(lines)
    return out


def default_of(f: dataclasses.Field) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    return f.default_factory()  # type: ignore[misc]


def show(value: Any) -> str:
    """A default as code: a config at its own defaults is ``Name()``, other values their repr."""
    if dataclasses.is_dataclass(value) and value == type(value)():
        return f"`{type(value).__name__}()`"
    return f"`{value!r}`"


def meaning(name: str, value: Any, comments: dict[str, str]) -> str:
    if name in comments:
        return comments[name]
    if dataclasses.is_dataclass(value):
        return (inspect.getdoc(type(value)) or "").splitlines()[0]
    return ""


def cell(text: str) -> str:
    return text.replace("|", "\\|")


def parameter_table(cls: type = SystemConfig) -> str:
    comments = field_comments(cls)
    rows = ["| field | default | meaning |", "|---|---|---|"]
    for f in dataclasses.fields(cls):
        value = default_of(f)
        rows.append(f"| `{f.name}` | {cell(show(value))} | {cell(meaning(f.name, value, comments))} |")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    print(parameter_table(), end="")
