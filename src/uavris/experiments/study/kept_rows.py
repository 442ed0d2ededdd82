"""A row's evaluation kept by its own inputs, so that a stage evaluated again runs only the rows that changed.

An evaluation stage's key covers all of its rows (:mod:`.pipeline`): a new row, or a new model
of one row, makes the stage run again. Each row's files (its per-episode CSV, its summary and
its first episode slot by slot) are also kept in the study's folder under ``rows/``, named by a
hash of what the row's numbers depend on (:func:`row_key`: the results format, the oracle's
version, the track, the hall and its system as the row sees it, the episodes and their seed, the
row's models by their folders, which carry their stages' keys, and what the row is). A stage
evaluated again copies a kept row's files instead of flying it: the same bytes, since a row's
evaluation depends on nothing else (:func:`uavris.experiments.study.workers.evaluate_row`).

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
from uavris.experiments.tools.targets import Row
from uavris.io import read_json
from uavris.layouts import Site
from uavris.presets import EVAL_SEED

KEPT_ROWS_DIR = "rows"  # in a study's folder
# a kept row's files, and where an evaluation stage keeps each (by the row's key)
_FILES = {"episodes.csv": "{row}.csv", "summary.json": "{row}.json", "slots.csv": "slots/{row}.csv"}


def row_key(site: Site, track: str, episodes: int, row: Row, results_format: int, study: Path) -> str:
    """What a row's numbers in ``site`` depend on, hashed: a folder name under :data:`KEPT_ROWS_DIR`.
    Its models are named by their folders relative to the ``study``'s (a study moved or copied
    keeps its rows)."""
    what = {"format": results_format, "oracle": ORACLE_VERSION, "track": track, "episodes": episodes,
            "seed": EVAL_SEED, "site": site.name, "start": list(site.scenario.start),
            "system": row.system(site.system).to_dict(), "row": row.origin(), "facts": row.facts(), "label": row.label}
    text = json.dumps(what, sort_keys=True, default=str)
    text = text.replace(json.dumps(str(Path(study).resolve()))[1:-1] + "/", "<study>/")
    return f"{row.key}-{hashlib.sha256(text.encode()).hexdigest()[:20]}"


def take(kept: Path, key: str, out: Path, row: Row) -> dict[str, Any] | None:
    """The kept row ``key``'s files copied into the evaluation stage's folder ``out``, and its
    summary; None where no such row is kept."""
    folder = kept / key
    if not all((folder / name).is_file() for name in _FILES):
        return None
    for name, dest in _FILES.items():
        target = out / dest.format(row=row.key)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(folder / name, target)
    return read_json(folder / "summary.json")


def keep(kept: Path, key: str, out: Path, row: Row) -> None:
    """Row ``row``'s files in ``out`` kept as ``key``: written into a new folder, then renamed into
    place whole (a kept row is a complete one; where another process kept it first, theirs stays)."""
    if (kept / key).exists():
        return
    kept.mkdir(parents=True, exist_ok=True)
    made = Path(tempfile.mkdtemp(prefix=".keeping-", dir=kept))
    for name, src in _FILES.items():
        shutil.copyfile(out / src.format(row=row.key), made / name)
    try:
        os.rename(made, kept / key)
    except OSError:  # kept meanwhile by another process
        shutil.rmtree(made, ignore_errors=True)
