"""The stages of a track that chooses places (issue 36): the learned value's labels and fit, and
fine-tuning that tries places.

Lives here: :func:`value_stages` (``values``: the labels of training halls of several device
counts, in parts a rerun reuses; ``value``: the fit, on them and on the poses the reference
planner valued in the demonstrations' halls) and :func:`places_finetune_stages` (per unseen
hall and goal-conditioned DT seed, fine-tuning whose candidates fly to the learned planner's
best places). Not here: the rest of a track's stages and the pipeline
(:mod:`.pipeline`), the rows that read these stages (:func:`.tracks.track_rows`), the work of
each job (:mod:`.workers`).
"""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from uavris.experiments.engine.costs import finetune_cost, value_fit_cost, value_labels_cost
from uavris.experiments.engine.jobs import Job
from uavris.experiments.engine.stages import Stage
from uavris.experiments.study.tracks import places_stage, zero_shot_only
from uavris.experiments.study.workers import finetune_job, value_fit_job, value_labels_job
from uavris.experiments.training.finetune import FinetuneConfig
from uavris.experiments.training.values import ValueFitConfig, ValueLabelsConfig
from uavris.layouts import Site
from uavris.presets import PLACES_FINETUNE, VALUE

if TYPE_CHECKING:
    from uavris.experiments.study.pipeline import TrackStages

LABEL_CHUNK = 8  # training halls per labels job (a job writes its part)


def _labels_config(ts: TrackStages) -> ValueLabelsConfig:
    v = VALUE[ts.rc.preset]
    return ValueLabelsConfig(counts=tuple(v["counts"]), halls=v["halls"], poses=v["poses"],
                             layout_seed=ts.rc.layout_seed, system=ts.rc.system.replace(observe_devices=True))


def _chunks(cfg: ValueLabelsConfig) -> list[tuple[int, int, int]]:
    return [(k, first, min(LABEL_CHUNK, cfg.halls - first)) for k in cfg.counts
            for first in range(0, cfg.halls, LABEL_CHUNK)]


def value_stages(ts: TrackStages) -> list[Stage]:
    """``values`` (the labels) and ``value`` (the fit; module docstring)."""
    labels = _labels_config(ts)
    costs = tuple(value_labels_cost(k, n, labels.poses) for k, _, n in _chunks(labels))
    fit = ValueFitConfig(preset=ts.rc.preset, seed=ts.rc.seed)
    return [Stage(ts.t("values"), labels.to_dict(), partial(_run_labels, ts, labels, costs), (), costs),
            Stage(ts.t("value"), fit.to_dict(), partial(_run_fit, ts, fit), (ts.t("values"), ts.t("dataset")),
                  (value_fit_cost(fit.steps, fit.width),))]


def _run_labels(ts: TrackStages, cfg: ValueLabelsConfig, costs: tuple[float, ...], d: Path,
                deps: dict[str, Path]) -> dict[str, Any]:
    parts = [d / "parts" / f"k{k}-halls-{first}.npz" for k, first, _ in _chunks(cfg)]
    jobs = [Job(part.stem, value_labels_job, (cfg.to_dict(), k, first, n, str(part)), d / "logs" / f"{part.stem}.log",
                cost) for (k, first, n), part, cost in zip(_chunks(cfg), parts, costs) if not part.exists()]
    ts.ctx.run_all(ts.t("values"), jobs, "value labels job")
    return {"parts": [p.name for p in parts], "counts": list(cfg.counts), "halls": cfg.halls, "poses": cfg.poses}


def _run_fit(ts: TrackStages, cfg: ValueFitConfig, d: Path, deps: dict[str, Path]) -> dict[str, Any]:
    # the labels stage's parts, and the poses the reference planner valued in the demonstrations' halls
    parts = sorted((deps[ts.t("values")] / "parts").glob("*.npz"))
    parts += sorted((deps[ts.t("dataset")] / "labels").glob("*.npz"))
    return ts.ctx.run_one(ts.t("value"), value_fit_job, (cfg.to_dict(), [str(p) for p in parts], str(d / "value")),
                          d / "job.log", value_fit_cost(cfg.steps, cfg.width))


def places_config(ts: TrackStages, model: Path | str, value: Path | str, where: Site) -> FinetuneConfig:
    """Fine-tuning of a goal-conditioned DT in ``where`` by trying places: the track's
    fine-tuning (:data:`uavris.presets.TRACK_FINETUNE`) with the places of
    :data:`uavris.presets.PLACES_FINETUNE` (the start and that many of the best places by ``V``)."""
    return ts.finetune_config(model, where, {**PLACES_FINETUNE[ts.rc.preset], "value": str(value)})


def places_finetune_stages(ts: TrackStages) -> list[Stage]:
    """Per unseen hall of the study's generator and goal-conditioned DT, fine-tuning that tries places."""
    stages = []
    for w in (w for w in ts.unseen if not zero_shot_only(w.name)):
        for m in (m for m in ts.models if m.row == "dt-goal"):
            cfg = places_config(ts, "<goal>", "<value>", w)
            stages.append(Stage(ts.t(places_stage(w.name, m.seed)), cfg.to_dict(),
                                partial(_run_places, ts, w, m.stage, m.seed),
                                (ts.t(m.stage), ts.t("value")),
                                (finetune_cost(cfg, ts.horizon, ts.control, ts.model),)))
    return stages


def _run_places(ts: TrackStages, where: Site, model_stage: str, seed: int, d: Path,
                deps: dict[str, Path]) -> dict[str, Any]:
    cfg = places_config(ts, deps[ts.t(model_stage)] / "model", deps[ts.t("value")] / "value", where)
    name = ts.t(places_stage(where.name, seed))
    return ts.ctx.run_one(name, finetune_job, (cfg.to_dict(), str(d / "model"), ts.ctx.device), d / "job.log",
                          finetune_cost(cfg, ts.horizon, ts.control, ts.model))
