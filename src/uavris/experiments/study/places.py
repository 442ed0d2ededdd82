"""The stages of a track that chooses places (docs/places.md): the learned value's labels and fit, and
fine-tuning that tries places.

Lives here: :class:`PlaceStages`, the part of a track's stages that
:class:`.pipeline.TrackStages` inherits: :meth:`~PlaceStages.value_stages` (``value-labels``: the
labels of training halls of several device counts, in parts a rerun reuses; ``value`` and
``value-sK``: a fit per pre-training seed, on them and on the poses the reference planner
valued in the demonstrations' halls) and
:meth:`~PlaceStages.places_finetune_stages` (per unseen hall and goal-conditioned DT seed,
fine-tuning whose candidates fly to the learned planner's best places). Not here: the rest of
a track's stages and the pipeline (:mod:`.pipeline`), the rows that read these stages
(:func:`.tracks.track_rows`), the work of each job (:mod:`.workers`).
"""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Any, Callable

from uavris.agents.oracle import planner as oracle_planner
from uavris.experiments.engine.costs import finetune_cost, value_fit_cost, value_labels_cost
from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.engine.stages import Stage
from uavris.experiments.engine.worker import Job
from uavris.experiments.study.config import ReproduceConfig
from uavris.experiments.study.stage_names import DATASET, VALUE_LABELS, places_stage, value_stage
from uavris.experiments.study.tracks import TrainedModel, zero_shot_only
from uavris.experiments.study.workers import finetune_job, value_fit_job, value_labels_job
from uavris.experiments.training.finetune import FinetuneConfig
from uavris.experiments.training.values import ValueFitConfig, ValueLabelsConfig
from uavris.layouts import Site
from uavris.presets import PLACES_FINETUNE, VALUE

LABEL_CHUNK = 8  # training halls per labels job (a job writes its part)


def _chunks(cfg: ValueLabelsConfig) -> list[tuple[int, int, int]]:
    return [(k, first, min(LABEL_CHUNK, cfg.halls - first)) for k in cfg.counts
            for first in range(0, cfg.halls, LABEL_CHUNK)]


class PlaceStages:
    """The stages of a track that chooses places, made from its track's attributes below (set
    by :class:`.pipeline.TrackStages`)."""

    rc: ReproduceConfig
    ctx: StudyContext
    t: Callable[[str], str]  # a stage's name in the track
    unseen: list[Site]
    models: list[TrainedModel]
    horizon: int
    control: str
    model: Any  # the track's DT configuration (what fine-tuning's cost scales with)

    def finetune_config(self, model: Path | str, where: Site, extra: dict[str, Any] | None = None
                        ) -> FinetuneConfig:  # the track's fine-tuning (TrackStages)
        raise NotImplementedError

    def value_stages(self) -> list[Stage]:
        """``value-labels`` (the labels) and ``value`` (the fit; module docstring)."""
        v = VALUE[self.rc.preset]
        labels = ValueLabelsConfig(counts=tuple(v["counts"]), halls=v["halls"], poses=v["poses"],
                                   layout_seed=self.rc.layout_seed, system=self.rc.system.replace(observe_devices=True))
        costs = tuple(value_labels_cost(k, n, labels.poses, labels.tilted) for k, _, n in _chunks(labels))
        # the labels are the planner's screen and rate of poses: a new oracle labels them again
        stages = [Stage(self.t(VALUE_LABELS), {**labels.to_dict(), "oracle": oracle_planner.ORACLE_VERSION},
                        partial(self._run_labels, labels, costs), (), costs)]
        for seed in self.value_seeds():  # one fit per pre-training seed, on the same labels
            fit = ValueFitConfig(preset=self.rc.preset, seed=self.rc.seed + seed)
            stages.append(Stage(self.t(value_stage(seed)), fit.to_dict(), partial(self._run_fit, seed, fit),
                                (self.t(VALUE_LABELS), self.t(DATASET)), (value_fit_cost(fit.steps, fit.width),)))
        return stages

    def value_seeds(self) -> list[int]:
        """The pre-training seeds of the track's models: each has its own fit of ``V`` (:func:`.tracks.value_stage`)."""
        return sorted({m.seed for m in self.models})

    def _run_labels(self, cfg: ValueLabelsConfig, costs: tuple[float, ...], d: Path, deps: dict[str, Path]
                    ) -> dict[str, Any]:
        parts = [d / "parts" / f"k{k}-halls-{first}.npz" for k, first, _ in _chunks(cfg)]
        jobs = [Job(part.stem, value_labels_job, (cfg.to_dict(), k, first, n, str(part)),
                    d / "logs" / f"{part.stem}.log", cost, writes=(part,))
                for (k, first, n), part, cost in zip(_chunks(cfg), parts, costs) if not part.exists()]
        self.ctx.run_all(self.t(VALUE_LABELS), jobs, "value labels job")
        return {"parts": [p.name for p in parts], "counts": list(cfg.counts), "halls": cfg.halls, "poses": cfg.poses}

    def _run_fit(self, seed: int, cfg: ValueFitConfig, d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        # the labels stage's parts, and the poses the reference planner valued in the demonstrations' halls
        parts = sorted((deps[self.t(VALUE_LABELS)] / "parts").glob("*.npz"))
        parts += sorted((deps[self.t(DATASET)] / "labels").glob("*.npz"))
        return self.ctx.run_one(self.t(value_stage(seed)), value_fit_job, (cfg.to_dict(), [str(p) for p in parts],
                                                                 str(d / "value")),
                                d / "job.log", value_fit_cost(cfg.steps, cfg.width), reads=tuple(parts),
                                writes=(d / "value",))

    def places_config(self, model: Path | str, value: Path | str, where: Site) -> FinetuneConfig:
        """Fine-tuning of a goal-conditioned DT in ``where`` by trying places: the track's
        fine-tuning (:data:`uavris.presets.TRACK_FINETUNE`) with the places of
        :data:`uavris.presets.PLACES_FINETUNE` (the start and that many of the best places by ``V``)."""
        return self.finetune_config(model, where, {**PLACES_FINETUNE[self.rc.preset], "value": str(value)})

    def places_finetune_stages(self) -> list[Stage]:
        """Per unseen hall of the study's own and goal-conditioned DT, fine-tuning that tries places."""
        stages = []
        for w in (w for w in self.unseen if not zero_shot_only(w, self.rc.system)):
            for m in (m for m in self.models if m.row == "dt-goal"):
                cfg = self.places_config("<goal>", "<value>", w)
                stages.append(Stage(self.t(places_stage(w.name, m.seed)), cfg.to_dict(),
                                    partial(self._run_places, w, m.stage, m.seed),
                                    (self.t(m.stage), self.t(value_stage(m.seed))),
                                    (finetune_cost(cfg, self.horizon, self.control, self.model),)))
        return stages

    def _run_places(self, where: Site, model_stage: str, seed: int, d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        cfg = self.places_config(deps[self.t(model_stage)] / "model", deps[self.t(value_stage(seed))] / "value", where)
        name = self.t(places_stage(where.name, seed))
        return self.ctx.run_one(name, finetune_job, (cfg.to_dict(), str(d / "model"), self.ctx.device),
                                d / "job.log", finetune_cost(cfg, self.horizon, self.control, self.model),
                                reads=(Path(cfg.model), Path(cfg.value)), writes=(d / "model",))
