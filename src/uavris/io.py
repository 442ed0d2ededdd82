"""Reading and writing files: atomically, as CSV, JSON or YAML, with one-line errors.

Lives here: :func:`atomic_write_bytes`, the one primitive every layer that writes files
shares (a temporary file in the same directory, fsync, rename: a reader, or a killed
writer, sees the old file or the new one, never half of either), and the text formats on
top of it. Not here: what the files mean (run directories: :mod:`uavris.runs`).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import yaml

from uavris.errors import CheckpointError, UavrisError


def _default_mode() -> int:
    """0o666 minus the process umask: what ``open(path, "w")`` would have given."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


# Read once at import: os.umask can only be read by setting it, which is not thread-safe.
_FILE_MODE = _default_mode()


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write to a temporary file in the same directory, fsync, rename over ``path``: a
    reader (or a killed writer) sees the old file or the new one, never half of either."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        # mkstemp creates 0600 files; results are meant to be shared like any other file
        os.fchmod(fd, _FILE_MODE)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write_bytes(path, text.encode("utf-8"))


def replace_folder(made: Path, dest: Path, aside: Path) -> None:
    """Put the finished folder ``made`` in the place of ``dest`` whole (the old one moved to
    ``aside`` first, then removed): a reader sees the old folder or the new one, never a mix."""
    shutil.rmtree(aside, ignore_errors=True)
    if dest.exists():
        dest.rename(aside)
    made.rename(dest)
    shutil.rmtree(aside, ignore_errors=True)


def atomic_save(path: str | Path, save: Callable[[Path], Any]) -> None:
    """A file another library writes (SB3's archive, its replay buffer) made atomic: ``save(tmp)``
    writes a temporary file beside ``path`` (of the same suffix, which such libraries read),
    renamed over ``path``; a write that fails (a full disk) leaves nothing behind."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    try:
        save(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


OMIT_DEFAULT = "omit_default"  # dataclass field metadata: left out of to_plain at its default
INTERNAL = "internal"  # dataclass field metadata: what a config keeps for itself, never written nor a flag


def to_plain(obj: Any) -> Any:
    """Dataclasses, tuples and numpy scalars to plain YAML/JSON-able values."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        # A field added after a release is written only when set (metadata OMIT_DEFAULT), so the
        # stage keys hashed from a config (uavris.experiments.engine.stages) stay those of earlier runs.
        return {f.name: to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                if not (f.metadata.get(INTERNAL) or f.metadata.get(OMIT_DEFAULT) and getattr(obj, f.name) == f.default)}
    if isinstance(obj, dict):
        return {str(k): to_plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_plain(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item):
        return obj.item()
    return obj


def write_yaml(path: str | Path, obj: Any) -> None:
    atomic_write_text(path, yaml.safe_dump(to_plain(obj), sort_keys=False))


def _read(path: str | Path, parse: Any, errors: tuple[type[Exception], ...], kind: str,
          newline: str | None = None) -> Any:
    try:
        with open(path, encoding="utf-8", newline=newline) as f:
            return parse(f)
    except FileNotFoundError:
        raise UavrisError(f"{path} does not exist") from None
    except IsADirectoryError:
        raise UavrisError(f"{path} is a directory, not a {kind} file") from None
    except UnicodeDecodeError:
        raise UavrisError(f"{path} is not a {kind} file (not UTF-8 text)") from None
    except errors as e:
        mark = getattr(e, "problem_mark", None)  # YAML's position of the problem (JSON's message has its own)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        problem = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise UavrisError(f"{path} is not valid {kind}{where}: {problem}") from None


def read_yaml(path: str | Path) -> Any:
    return _read(path, yaml.safe_load, (yaml.YAMLError,), "YAML")


def write_json(path: str | Path, obj: Any) -> None:
    atomic_write_text(path, json.dumps(to_plain(obj), indent=2) + "\n")


def read_json(path: str | Path) -> Any:
    return _read(path, json.load, (json.JSONDecodeError,), "JSON")


def other_inputs(path: str | Path, inputs: Any, key: str | None = None) -> Any:
    """What the result file ``path`` was made from (the whole JSON, or its ``key``) when that is
    not ``inputs``; None when the file does not exist or was made from the same: a command that
    writes its results into a folder refuses to replace another invocation's (sweep, benchmark,
    claims)."""
    if not Path(path).exists():
        return None
    stored = read_json(path)
    stored = stored.get(key) if key is not None and isinstance(stored, dict) else stored
    return None if to_plain(stored) == to_plain(inputs) else stored


def write_csv(path: str | Path, header: Sequence[str], rows: Iterable[Sequence[Any] | Mapping[str, Any]]) -> None:
    """A CSV file of ``rows`` under ``header``; a row is a sequence in header order or a
    mapping from the header's names (a log's record)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows([r[h] for h in header] if isinstance(r, Mapping) else r for r in rows)
    atomic_write_text(path, buf.getvalue())


def read_rows(path: str | Path, header: Sequence[str], limit: int, int_columns: set[str]) -> list[dict[str, Any]]:
    """The first ``limit`` rows of a CSV log as records ``{column: value}`` of ``header``'s
    columns (ints where named, floats otherwise).

    Used on resume: a log may hold rows written after the checkpoint being resumed, and
    those are dropped so they are not counted twice.
    """
    path = Path(path)
    if not path.exists():
        return []
    out = []
    for r in read_csv(path)[:limit]:
        try:
            out.append({h: int(r[h]) if h in int_columns else float(r[h]) for h in header})
        except (KeyError, TypeError, ValueError):
            raise UavrisError(f"{path} is corrupt (bad row {r})") from None
    return out


def read_csv(path: str | Path) -> list[dict[str, str]]:
    return _read(path, lambda f: list(csv.DictReader(f)), (csv.Error,), "CSV", newline="")


def file_part(text: str, fallback: str = "policy") -> str:
    """``text`` as one part of a file's name: letters, digits, ``_``, ``-`` and ``@`` (no folder,
    no dot that a suffix could be taken from), safe for any file system."""
    return re.sub(r"[^\w@-]+", "_", text).strip("_") or fallback


LOCK_FILE = ".uavris.lock"  # the one-writer lock of an output directory (uavris.runs.lock)


def contents(directory: str | Path) -> list[Path]:
    """What ``directory`` holds besides its writer's lock: a directory with nothing else is
    empty to every check that asks whether it holds a run, a dataset or a user's files."""
    return [p for p in Path(directory).iterdir() if p.name != LOCK_FILE]


def link_out(directory: str | Path) -> tuple[Path, str] | None:
    """The first link under ``directory`` (at any depth, to a file or a folder, links not
    followed) that resolves outside it, with where it leads (or why it leads nowhere); None where
    every link stays inside. The directory itself may be a link: it is what the user named."""
    root = Path(directory).resolve()
    for here, folders, files in os.walk(directory):
        for name in sorted((*folders, *files)):
            path = Path(here) / name
            if path.is_symlink():
                try:
                    target = path.resolve()
                except (OSError, RuntimeError):  # a loop of links
                    return path, "nowhere (a loop of links)"
                if not target.is_relative_to(root):
                    return path, str(target)
    return None


def refuse_links_out(directory: str | Path, what: str) -> None:
    """One :class:`~uavris.errors.CheckpointError` line where a link in ``directory`` (``what``: a
    controller, a DT model, an expert's run, a learned value) leads outside it: such a folder reads
    only its own files, and the link is refused before anything in the folder is opened."""
    if Path(directory).is_dir() and (out := link_out(directory)) is not None:
        raise CheckpointError(f"{out[0]} is a link to {out[1]}, outside {directory}: {what} reads only its own "
                              "files (copy it in)")


def read_checkpoint_meta(directory: str | Path, meta_file: str, kind: str, version: int, what: str,
                         described: str) -> dict[str, Any]:
    """A checkpoint directory's JSON metadata (``meta_file``), checked for its ``kind`` and
    ``format_version``; one :class:`~uavris.errors.CheckpointError` line when it is missing
    (``directory`` is not ``what``), corrupt, of another kind (it does not describe
    ``described``) or of another version, and before anything is opened when a link in it leads
    outside it (a controller, model, run or value folder reads only its own files)."""
    refuse_links_out(directory, what)
    path = Path(directory) / meta_file
    if not path.is_file():
        raise CheckpointError(f"{directory} is not {what} (no {meta_file})")
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CheckpointError(f"{path} is corrupt ({e})") from None
    if not isinstance(meta, dict) or meta.get("kind") != kind:
        raise CheckpointError(f"{path} does not describe {described}")
    if meta.get("format_version") != version:
        raise CheckpointError(f"{path} has format version {meta.get('format_version')!r}; "
                              f"this uavris reads version {version}")
    return meta
