"""A row of a study's report, evaluated again from its output directory: ``uavris evaluate OUT --row KEY``.

Lives here: :func:`read_study` (the :class:`~.config.ReproduceConfig` a study directory holds)
and :func:`study_row` (one of a track's rows, :func:`~.tracks.track_rows`, reading the
study's models, in any site: one of the study's or a user's hall). Not here: the rows
themselves (:mod:`.tracks`), evaluating a row (:mod:`uavris.experiments.tools.evaluate`).
"""

from __future__ import annotations

from pathlib import Path

from uavris.errors import UavrisError
from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.study.config import ReproduceConfig
from uavris.experiments.study.pipeline import build_pipeline, track_stages
from uavris.experiments.tools.targets import Row
from uavris.io import read_yaml
from uavris.layouts import Site

STUDY_FILE = "study.yaml"  # a study's ReproduceConfig, written by reproduce() before any stage runs


def is_study(path: str | Path) -> bool:
    return (Path(path) / STUDY_FILE).is_file()


def read_study(out: str | Path) -> ReproduceConfig:
    """The study of output directory ``out``; one line when it holds none."""
    path = Path(out) / STUDY_FILE
    if not path.is_file():
        raise UavrisError(f"{out} is not a study's output directory (no {STUDY_FILE}: written by uavris reproduce)")
    return ReproduceConfig.from_dict(read_yaml(path))


def study_row(out: str | Path, key: str, track: str, site: Site) -> Row:
    """The row ``key`` of ``track`` of the study in ``out``, in ``site``, its models read from the
    study's stage directories; one line naming the rows there are, or the stage not finished."""
    rc = read_study(out)
    chosen = [t for t in track_stages(rc, StudyContext(1, "local", None)) if t.track.name == track]
    if not chosen:
        raise UavrisError(f"--track {track}: the study in {out} ran {', '.join(t.name for t in rc.tracks)}")
    pipeline = build_pipeline(rc, Path(out), StudyContext(1, "local", None))
    rows = {r.key: r for r in chosen[0].rows_in(site, pipeline)}
    if key not in rows:
        raise UavrisError(f"--row {key}: no such row of the {track} track in {site.name}; its rows: {', '.join(rows)}")
    row = rows[key]
    for target in (*([row.target] if row.target is not None else []), *row.members):
        if target.path is not None and not target.path.exists():
            raise UavrisError(f"--row {key}: {target.path} does not exist yet (its stage has not finished; rerun "
                              f"uavris reproduce --out {out})")
    return row
