"""A row's evaluation kept by its own inputs, so that a stage evaluated again flies only the rows that changed.

An evaluation stage's key covers all of its rows (:mod:`.pipeline`): a new row, or a new model
of one row, makes the stage run again. Each row's files (its per-episode CSV, its summary and
its first episode slot by slot) are also kept in the study's folder under ``rows/``, named by a
hash of what the row's numbers depend on (:func:`row_key`): the results format, the oracle's
version, the float path, the track, the hall and its system as the row sees it, the episodes and
their seed, what the row is, and the bytes of every file of its models (a stage run again with
``--force`` that trains another model gives its rows other keys). A stage evaluated again copies
a kept row's files instead of flying it: the same bytes, since a row's evaluation depends on
nothing else (:func:`uavris.experiments.study.workers.evaluate_row`). A row whose policy is a
module (``MODULE:NAME``) is not kept: its code is not a file the key can read. A study run with
``--force`` flies every row again and keeps what it flew (:func:`keep` replaces).

Lives here: :func:`row_key`, :func:`take` and :func:`keep`. Not here: the evaluation
(:mod:`.workers`), the stage (:mod:`.pipeline`).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from uavris.agents.oracle.planner import ORACLE_VERSION
from uavris.experiments.tools.rows import Row
from uavris.experiments.tools.targets import Target, UserPolicy
from uavris.float_paths import float_path
from uavris.io import read_json
from uavris.layouts import Site
from uavris.presets import EVAL_SEED

KEPT_ROWS_DIR = "rows"  # in a study's folder
# a kept row's files, and where an evaluation stage keeps each (by the row's key)
_FILES = {"episodes.csv": "{row}.csv", "summary.json": "{row}.json", "slots.csv": "slots/{row}.csv"}


def _targets(row: Row) -> list[Target]:
    return [t for t in (row.target, *row.members, row.goal_from) if t is not None]


def _files_hash(where: Path) -> str:
    """The bytes of every file in folder (or file) ``where``, by their paths within it."""
    h = hashlib.sha256()
    for path in sorted(p for p in ([where] if where.is_file() else where.rglob("*")) if p.is_file()):
        h.update(str(path.relative_to(where) if path != where else path.name).encode() + b"\0")
        h.update(hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()


def row_key(site: Site, track: str, episodes: int, row: Row, results_format: int) -> str | None:
    """What a row's numbers in ``site`` depend on, hashed: a folder name under :data:`KEPT_ROWS_DIR`;
    None where the row is not kept (a module's policy)."""
    models = []
    for t in _targets(row):
        where = t.location()
        if isinstance(t, UserPolicy):  # FILE.py:NAME is read from its file; MODULE:NAME from no file the key can read
            source = t.name.rsplit(":", 1)[0]
            if not source.endswith(".py"):
                return None
            where = Path(source)
        models.append(None if where is None else _files_hash(Path(where)))
    what = {"format": results_format, "oracle": ORACLE_VERSION, "floats": float_path(), "track": track,
            "episodes": episodes, "seed": EVAL_SEED, "site": site.name, "start": list(site.scenario.start),
            "system": row.system(site.system).to_dict(), "facts": row.facts(), "label": row.label,
            "kinds": [type(t).__name__ for t in _targets(row)], "exported": [_exported(t) for t in _targets(row)],
            "models": models}
    return f"{row.key}-{hashlib.sha256(json.dumps(what, sort_keys=True, default=str).encode()).hexdigest()[:20]}"


def _exported(t: Target) -> dict[str, Any]:
    """What a target is besides its files (a reference's name, a learned value's planner), not where it lies."""
    fields = {k: v for k, v in vars(t).items() if k not in ("name", "path")}
    return {k: str(v) for k, v in sorted(fields.items())}


def take(kept: Path, key: str, out: Path, row: Row) -> dict[str, Any] | None:
    """The kept row ``key``'s files copied into the evaluation stage's folder ``out``, and its
    summary; None where no such row is kept whole (or one of its files is a link)."""
    folder = kept / key
    if not all((folder / name).is_file() and not (folder / name).is_symlink() for name in _FILES):
        return None
    for name, dest in _FILES.items():
        target = out / dest.format(row=row.key)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(folder / name, target)
    return read_json(folder / "summary.json")


def keep(kept: Path, key: str, out: Path, row: Row) -> None:
    """Row ``row``'s files in ``out`` kept as ``key``, replacing what was kept under it: written into
    a new folder, then renamed into place whole (a kept row is a complete one). Keeping is a
    saving, not a result: where it fails (a full disk), the evaluation goes on without it."""
    made = None
    try:
        kept.mkdir(parents=True, exist_ok=True)
        made = Path(tempfile.mkdtemp(prefix=".keeping-", dir=kept))
        for name, src in _FILES.items():
            shutil.copyfile(out / src.format(row=row.key), made / name)
        if (kept / key).exists():
            aside = Path(tempfile.mkdtemp(prefix=".replaced-", dir=kept))
            os.rename(kept / key, aside / key)
            shutil.rmtree(aside, ignore_errors=True)
        os.rename(made, kept / key)
        made = None
    except OSError:
        pass
    finally:
        if made is not None:
            shutil.rmtree(made, ignore_errors=True)
