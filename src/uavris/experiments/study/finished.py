"""A study's output directory, opened: ``Study.open(OUT)``, the one way to read a study once it ran.

Lives here: :class:`Study` (its configuration, its pipeline, a stage's directory and result by
the stage's name, a track's sites and its evaluation in a site, a row of a track in any site)
and :data:`STUDY_FILE`, which :func:`uavris.experiments.study.reproduce.reproduce` writes before
any stage runs. ``uavris evaluate OUT --row KEY``, ``uavris claims``, the report and the
benchmarks that read a study all open it here; a stage's key stays the pipeline's business
(:mod:`uavris.experiments.engine.stages`). Not here: running a study (:mod:`.reproduce`),
what a row is (:mod:`.tracks`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from uavris.errors import UavrisError
from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.engine.stages import Pipeline
from uavris.experiments.study.config import ReproduceConfig
from uavris.experiments.study.pipeline import TrackStages, build_pipeline, track_stages
from uavris.experiments.study.stage_names import (
    DATASET,
    EXPERTS_TRAIN,
    EXPERTS_UNSEEN,
    VALUE_LABELS,
    evaluation_stage,
    finetune_stage,
    places_stage,
    value_stage,
)
from uavris.experiments.study.tracks import TRACK_SPECS, Track
from uavris.experiments.study.workers import first_episode_slots
from uavris.experiments.tools.rows import Row
from uavris.io import read_json, read_yaml
from uavris.layouts import Site

STUDY_FILE = "study.yaml"  # a study's ReproduceConfig, written by reproduce() before any stage runs


@dataclass(frozen=True)
class Study:
    """A study's output directory ``out``: what it was asked to be (``config``) and its stages
    (``pipeline``), finished or not."""

    out: Path
    config: ReproduceConfig
    pipeline: Pipeline

    @classmethod
    def open(cls, out: str | Path, ctx: StudyContext | None = None) -> Study:
        """The study in ``out``; one line when it holds none."""
        path = Path(out) / STUDY_FILE
        if not path.is_file():
            raise UavrisError(f"{out} is not a study's output directory (no {STUDY_FILE}: written by uavris "
                              "reproduce)")
        config = ReproduceConfig.from_dict(read_yaml(path))
        return cls(Path(out), config, build_pipeline(config, Path(out), ctx or StudyContext(1, "local", None)))

    def directory(self, stage: str) -> Path:
        """The directory of stage ``stage`` (by its name), finished or not."""
        if stage not in self.pipeline.stages:
            raise UavrisError(f"the study in {self.out} has no stage {stage!r}")
        return self.pipeline.directory(stage)

    def done(self, stage: str) -> Path | None:
        """The directory of stage ``stage`` where it finished (None where it did not, or is not a stage here)."""
        return self.pipeline.directory(stage) if stage in self.pipeline.stages and self.pipeline.is_done(stage) \
            else None

    def result(self, stage: str) -> dict[str, Any] | None:
        """What a finished stage returned (its ``stage.json``'s result), None where it did not finish."""
        d = self.done(stage)
        return read_json(d / "stage.json")["result"] if d else None

    def sites(self, track: Track | str) -> tuple[list[Site], list[Site]]:
        """The training and the unseen sites of ``track`` in this study."""
        return self.config.sites(TRACK_SPECS[track] if isinstance(track, str) else track)

    def evaluation(self, track: Track, site: str) -> tuple[Path, dict[str, Any]] | None:
        """The evaluation stage of ``track`` in ``site`` (its directory and result), where it finished."""
        name = track.stage(evaluation_stage(site))
        d = self.done(name)
        return (d, read_json(d / "stage.json")["result"]) if d else None

    def experts(self, track: Track, unseen: bool = False) -> Path | None:
        """The directory of ``track``'s experts of its training (or ``unseen``) deployments, where
        they finished: one run each under ``runs/SITE``."""
        return self.done(track.stage(EXPERTS_UNSEEN if unseen else EXPERTS_TRAIN))

    def finetuned(self, track: Track, site: str) -> Path | None:
        """The directory of ``track``'s fine-tuning of the DT in ``site`` (its ``model``), where it finished."""
        return self.done(track.stage(finetune_stage(site)))

    def demonstrations(self, track: Track) -> dict[str, Any] | None:
        """What ``track``'s dataset stage recorded (its episodes, ``slots``, poses valued), where it finished."""
        return self.result(track.stage(DATASET))

    def value_labels(self, track: Track) -> dict[str, Any] | None:
        """What the learned value's labels stage recorded (halls, counts, poses), where it finished."""
        return self.result(track.stage(VALUE_LABELS))

    def learned_value(self, seed: int = 0) -> Path:
        """The learned value of a pose of pre-training seed ``seed`` (its ``value`` folder) of the
        study's track that chooses places; one line where the study has none or it did not finish."""
        track = next((t for t in self.config.tracks if t.places), None)
        if track is None:
            raise UavrisError(f"the study in {self.out} learns no value of a pose (no track that chooses places)")
        name = track.stage(value_stage(seed))
        d = self.done(name)
        if d is None:
            raise UavrisError(f"the study in {self.out} has no finished {name} stage (seed {seed}'s learned value)")
        return d / "value"

    def places_tried(self, track: Track, site: str, seed: int) -> tuple[Path, dict[str, Any]] | None:
        """Seed ``seed``'s fine-tuning by trying places in ``site`` (its directory and result), where it finished."""
        name = track.stage(places_stage(site, seed))
        d = self.done(name)
        return (d, read_json(d / "stage.json")["result"]) if d else None

    def first_episode(self, track: Track, site: str, row: str) -> Path | None:
        """Row ``row``'s first evaluation episode in ``site``, slot by slot (a CSV), where it exists."""
        found = self.evaluation(track, site)
        path = first_episode_slots(found[0], row) if found else None
        return path if path is not None and path.is_file() else None

    def track(self, name: str) -> TrackStages:
        """The stages of track ``name``; one line naming the tracks the study ran."""
        found = [t for t in track_stages(self.config, StudyContext(1, "local", None)) if t.track.name == name]
        if not found:
            raise UavrisError(f"--track {name}: the study in {self.out} ran "
                              f"{', '.join(t.name for t in self.config.tracks)}")
        return found[0]

    def row(self, key: str, track: str, site: Site) -> Row:
        """The row ``key`` of ``track`` in ``site`` (one of the study's halls or a user's), its
        models read from the study's stage directories; one line naming the rows there are, or
        the stage not finished."""
        rows = {r.key: r for r in self.track(track).rows_in(site, self.pipeline)}
        if key.endswith("@s0") and key[:-3] in rows:  # the first seed's key carries no suffix
            key = key[:-3]
        if key not in rows:
            raise UavrisError(f"--row {key}: no such row of the {track} track in {site.name}; its rows: "
                              f"{', '.join(rows)}")
        row = rows[key]
        for target in (*([row.target] if row.target is not None else []), *row.members):
            where = target.location()
            if where is not None and not where.exists():
                raise UavrisError(f"--row {key}: {where} does not exist yet (its stage has not finished; "
                                  f"rerun uavris reproduce --out {self.out})")
        return row

    def seeds(self, row: Row, track: str, site: Site) -> list[int]:
        """The seeds of ``row``'s variant in ``track`` (one entry per pre-training seed, sorted): the
        report's row of that name is their mean, ``row`` one of them."""
        return sorted(r.seed or 0 for r in self.track(track).rows_in(site, self.pipeline) if r.variant == row.variant)
