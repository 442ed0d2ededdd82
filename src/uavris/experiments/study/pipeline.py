"""The study's pipeline: its stages, their configurations (the stage keys), inputs and expected costs.

Lives here: :func:`build_pipeline`, which turns a :class:`~.config.ReproduceConfig` into the
stages below, and :class:`TrackStages`, the stages of one track (a
:class:`~.tracks.Track`: its parameters). Not here: what a stage's jobs do
(:mod:`.workers`), running the pipeline (:mod:`.reproduce`; keying, skipping and ordering
stages: :mod:`uavris.experiments.engine`).

Stages (each in ``OUT/stages/NAME-KEY``, keyed by its configuration and its inputs):

1. ``compare``: DDPG, PPO, SAC, TD3 over seeds in the Fig. 2 scenario (paper Fig. 2).
2. ``experts-train``: an expert in each of the eight training scenarios, of the algorithm
   the comparison picks (largest IQM, as the paper's Sec. IV-B) or ``expert_algo``.
3. ``experts-unseen``: a scenario-specific expert in each unseen scenario.
4. ``dataset``: the experts' deterministic trajectories as a Minari dataset.
5. ``pretrain``: the Decision Transformer, offline (Algorithm 1, stage 1).
6. ``finetune-unseenX``: elite online fine-tuning in each unseen scenario (stage 2).
7. ``evaluate-unseenX``: the expert, the zero-shot DT, the fine-tuned DT, the experts of the
   nearest training scenarios (transferred) and the references (zero action, hover with
   the optimiser's phases, oracle), all on the same seeded evaluation episodes (Fig. 3).
8. ``report``: figures and ``OUT/report.md`` with every number read from the stage files.

Stages 2-7 exist once per track: the paper track as above, and the strong track (learned
motion, optimised phases) with the same names prefixed ``strong-``. The deployment track
(``deploy-``) is the same pipeline with other parameters (:mod:`.tracks`): its dataset is the
planning oracle's demonstrations in many generated halls (``deploy-dataset``); the learned
value of a pose is labelled (``deploy-value-labels``) and fitted once per pre-training seed
(``deploy-value``, ``deploy-value-sK``, :mod:`.places`); its learned rows are over several
pre-training seeds (``deploy-pretrain``, ``deploy-bc``, ``deploy-goal`` (the goal-conditioned
DT), each with ``-sK`` copies), and it
deploys to unseen halls (``deploy-evaluate-LAYOUT``). With ``--ablation`` the ablation's rows
join them (``-pretrain-nN``, the data curve; ``-flat``; ``deploy-dataset-mixed`` with
``-mixed-dt`` and ``-mixed-bc``), over the same seeds, with the fine-tuning of the
return-conditioned DT (``deploy-finetune-LAYOUT``) and fine-tuning that tries places
(``deploy-finetune-places-LAYOUT[-sK]``) in the halls of the study's own. Stages whose inputs
are ready run at the same time, and all their jobs share the study's workers, so the tracks
interleave.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, Sequence

from uavris import runs
from uavris.agents.dt.dataset import DATASET_FORMAT_VERSION
from uavris.agents.experts import ALGORITHMS
from uavris.agents.oracle import planner as oracle_planner
from uavris.experiments.engine.costs import (
    dataset_cost,
    demonstration_cost,
    evaluate_cost,
    finetune_cost,
    pretrain_cost,
    train_cost,
)
from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.engine.stages import Pipeline, Stage, study_folder
from uavris.experiments.engine.worker import Job
from uavris.experiments.study.config import AUTO, ReproduceConfig
from uavris.experiments.study.kept_rows import KEPT_ROWS_DIR
from uavris.experiments.study.places import PlaceStages
from uavris.experiments.study.stage_names import (
    COMPARE,
    DATASET,
    DATASET_BEST,
    DATASET_MIXED,
    EXPERTS_TRAIN,
    EXPERTS_UNSEEN,
    PRETRAIN,
    evaluation_stage,
    finetune_stage,
    places_stage,
    value_stage,
)
from uavris.experiments.study.tracks import (
    REFERENCE_ROWS,
    Track,
    TrainedModel,
    strong_expert_config,
    track_rows,
    trained_models,
    transfer_sources,
    zero_shot_only,
)
from uavris.experiments.study.workers import (
    RESULTS_FORMAT,
    best_demonstrations_job,
    dataset_job,
    demonstrations_job,
    evaluate_job,
    finetune_job,
    merge_demonstrations,
    pretrain_job,
)
from uavris.experiments.tools.rows import Row
from uavris.experiments.tools.targets import DTModel
from uavris.experiments.training.demonstrations import DemonstrationConfig
from uavris.experiments.training.finetune import FinetuneConfig
from uavris.experiments.training.pretrain import PretrainConfig
from uavris.experiments.training.train_expert import TrainConfig, train_job
from uavris.io import read_json
from uavris.layouts import Site
from uavris.presets import COLLECT_SEED, DEMONSTRATION_CHUNK, EVAL_SEED, TRACK_FINETUNE, TRACK_PRETRAIN

# The experts' run directories: 2 holds the policy as safetensors + JSON (what the study's later stages
# read; uavris 0.3's runs held SB3's pickled archive only). Part of the experts stages' keys.
EXPERT_FORMAT = 2
BEST_FRACTION = 0.1  # filtered behaviour cloning keeps the best tenth of the demonstrations by return


@dataclass(frozen=True)
class StageKind:
    """A kind of stage a study runs beside its tracks' own, added from outside uavris's modules
    (:func:`register_stage_kind`): the stages it makes for a study (``stages``: their names are
    what ``--force`` and ``--estimate`` show, their configurations their keys, their ``run``
    what they write), and its section of the report (``section``: the lines under the heading
    ``title``, read from the study, e.g. :meth:`~.finished.Study.result` of its stages)."""

    name: str
    title: str
    stages: Callable[[ReproduceConfig, StudyContext], list[Stage]]
    section: Callable[[Any], list[str]]  # of the study (a finished.Study, which reads this module)


STAGE_KINDS: list[StageKind] = []  # the registered kinds, in the order they were registered


def register_stage_kind(kind: StageKind) -> StageKind:
    """Add ``kind`` to every study built from now on in this process (its stages after the
    tracks', its section after theirs in the report: "not run" where its stages did not
    finish); registering a kind of the same name again replaces it."""
    STAGE_KINDS[:] = [k for k in STAGE_KINDS if k.name != kind.name] + [kind]
    return kind


def build_pipeline(rc: ReproduceConfig, out: Path, ctx: StudyContext) -> Pipeline:
    """The study's stages in dependency order: the comparison (paper track), then every
    track's experts, then every track's dataset, pre-training, fine-tuning and evaluation,
    then the stages of each registered :class:`StageKind`."""
    stages = []
    if any(t.name == "paper" for t in rc.tracks):
        stages.append(dataclasses.replace(_compare_stage(rc, ctx), group=COMPARE))
    tracks = track_stages(rc, ctx)
    for part in ("experts", "dt"):
        for t in tracks:
            stages += [dataclasses.replace(st, group=t.track.name) for st in getattr(t, part)()]
    for kind in STAGE_KINDS:
        stages += [dataclasses.replace(st, group=kind.name) for st in kind.stages(rc, ctx)]
    return Pipeline(out, stages)  # which refuses two stages of one name


def track_stages(rc: ReproduceConfig, ctx: StudyContext) -> list[TrackStages]:
    return [TrackStages(rc, track, ctx) for track in rc.tracks]


def _compare() -> ModuleType:
    """:mod:`uavris.experiments.training.compare`, imported where the comparison's stage is built:
    its figures load matplotlib, which a pipeline without that stage never needs."""
    import uavris.experiments.training.compare

    return uavris.experiments.training.compare


def _compare_stage(rc: ReproduceConfig, ctx: StudyContext) -> Stage:
    configs = _compare().comparison_configs(rc.preset, rc.compare_seeds, ALGORITHMS, "fig2", rc.eval_episodes,
                                            rc.system, steps=rc.compare_steps)
    costs = tuple(train_cost(c) for c in configs.values())
    return Stage(COMPARE, {"preset": rc.preset, "seeds": rc.compare_seeds, "steps": rc.compare_steps,
                             "eval_episodes": rc.eval_episodes, "system": rc.system.to_dict()},
                 partial(_run_compare, rc, ctx), costs=costs)


def _run_compare(rc: ReproduceConfig, ctx: StudyContext, d: Path, deps: dict[str, Path]) -> dict[str, Any]:
    _compare().compare_algorithms(preset=rc.preset, seeds=rc.compare_seeds, workers=ctx.workers, out=d,
                                  eval_episodes=rc.eval_episodes, progress=False, device=ctx.device,
                                  system=rc.system, submit=lambda jobs: ctx.submit(COMPARE, jobs),
                                  steps=rc.compare_steps)
    return compare_record(read_json(d / "summary.json"))


MEASURED_TIMES = ("s_per_step",)  # a comparison row's wall-clock measurements (summary.json keeps them)


def compare_record(summary: dict[str, Any]) -> dict[str, Any]:
    """The comparison stage's result: its rows and the expert chosen, without what was timed.

    The rows' training times per env step and the choice's sentence (which quotes them when
    the algorithms tie) are wall-clock measurements: they differ between two runs of the same
    inputs, so they stay in the comparison's ``summary.json`` (which the report reads), out
    of the stage's record."""
    choice = summary["expert_choice"]
    return {"rows": [{k: v for k, v in r.items() if k not in MEASURED_TIMES} for r in summary["rows"]],
            "expert": summary["expert"],
            "expert_choice": None if choice is None else {k: v for k, v in choice.items() if k != "text"}}


class TrackStages(PlaceStages):
    """The stages of one track: experts, dataset, pre-training, fine-tuning, evaluation.

    Each ``*_stage`` method returns a :class:`~uavris.experiments.engine.stages.Stage`
    whose ``run`` is a method of this object bound to its parameters; it submits the
    stage's jobs (:mod:`.workers`) to the study's shared runner (``ctx``).
    """

    def __init__(self, rc: ReproduceConfig, track: Track, ctx: StudyContext) -> None:
        self.rc, self.track, self.ctx = rc, track, ctx
        self.t = track.stage  # a stage's name in this track
        self.train, self.unseen = rc.sites(track)
        self.horizon, self.control = rc.system.horizon, track.phase_control
        self.pretrain_fields = TRACK_PRETRAIN[track.name][rc.preset]  # the track's DT (one home: uavris.presets)
        self.model = self._pretrain_config("<dataset>", None).model  # what fine-tuning's cost scales with
        self.models = trained_models(track, [w.name for w in self.train], rc.scaling,
                                     rc.dt_seeds if track.seeded else 1, rc.ablation)
        # the stages the evaluation reads beside each site's fine-tuning
        self.inputs = [*([EXPERTS_TRAIN] if not track.demonstrations else []),
                       *([EXPERTS_UNSEEN] if track.unseen_experts else []), *(m.stage for m in self.models),
                       *(value_stage(s) for s in (self.value_seeds() if track.places else []))]
        # the return-conditioned DT's fine-tuning: the paper's; where the track tries places, the ablation's
        self.finetunes_returns = not track.places or rc.ablation
        # fine-tuning that tries places: the ablation's too (docs/places.md: in a quick run it ended below the
        # zero-shot goal-conditioned DT it started from, for 48 fine-tuning runs, about 14 core-minutes)
        self.tries_places = track.places and rc.ablation

    # ------------------------------------------------------------------ experts
    def experts(self) -> list[Stage]:
        """Experts of the training (and, where the track has them, the unseen) deployments."""
        stages = []
        for name, where in ((EXPERTS_TRAIN, self.train if not self.track.demonstrations else []),
                            (EXPERTS_UNSEEN, self.unseen if self.track.unseen_experts else [])):
            if not where:
                continue
            if self.track.phase_control == "optimizer":  # the strong recipe: imitation of the planning oracle
                cfgs = {d.name: strong_expert_config(d.name, self.rc.seed, self.rc.preset, self.rc.eval_episodes,
                                                     d.system, d.start, curve=name == EXPERTS_UNSEEN) for d in where}
                config = {"runs": {s: c.to_dict() for s, c in cfgs.items()}, "format": EXPERT_FORMAT,
                          "oracle": oracle_planner.ORACLE_VERSION}
                stages.append(Stage(self.t(name), config,
                                    partial(self._run_experts, self.t(name), cfgs),
                                    costs=tuple(train_cost(c) for c in cfgs.values())))
            else:
                stages.append(self._paper_experts_stage(name, where))
        return stages

    def _expert_configs(self, algo: str, where: Sequence[Site]) -> dict[str, TrainConfig]:
        return {w.name: TrainConfig(algo=algo, scenario=w.name, seed=self.rc.seed, preset=self.rc.preset,
                                    eval_episodes=self.rc.eval_episodes, system=w.system) for w in where}

    def _paper_experts_stage(self, name: str, where: Sequence[Site]) -> Stage:
        """The paper track's experts, of the comparison's algorithm (or ``--expert-algo``).
        Before the comparison has chosen, their cost is the dearest algorithm's for the order
        (the chain through the comparison is then sure to go first) and the mean over the
        algorithms for the progress bar, which takes the chosen one's when its jobs come."""
        rc = self.rc
        guesses = [rc.expert_algo] if rc.expert_algo != AUTO else list(ALGORITHMS)
        by_algo = [tuple(train_cost(c) for c in self._expert_configs(a, where).values()) for a in guesses]
        config = {"algo": rc.expert_algo, "scenarios": [w.name for w in where], "seed": rc.seed, "preset": rc.preset,
                  "eval_episodes": rc.eval_episodes, "system": rc.system.to_dict(), "format": EXPERT_FORMAT}
        return Stage(name, config, partial(self._run_paper_experts, name, tuple(where)),
                     (COMPARE,) if rc.expert_algo == AUTO else (), max(by_algo, key=sum),
                     sum(map(sum, by_algo)) / len(by_algo))

    def _run_paper_experts(self, stage: str, where: Sequence[Site], d: Path,
                           deps: dict[str, Path]) -> dict[str, Any]:
        algo = self.rc.expert_algo
        if algo == AUTO:
            algo = read_json(deps[COMPARE] / "summary.json")["expert"]
        return self._run_experts(stage, self._expert_configs(algo, where), d, deps)

    def _run_experts(self, stage: str, cfgs: dict[str, TrainConfig], d: Path, deps: dict[str, Path]
                     ) -> dict[str, Any]:
        jobs = [Job(f"{cfg.algo}-{s}", train_job, (cfg.to_dict(), str(d / "runs" / s), self.ctx.device),
                    d / "logs" / f"{s}.log", train_cost(cfg), writes=(d / "runs" / s,))
                for s, cfg in cfgs.items() if not runs.is_finished(d / "runs" / s)]
        self.ctx.run_all(stage, jobs, "expert job")
        algos = sorted({cfg.algo for cfg in cfgs.values()})
        return {"algo": "+".join(algos), "final_evals": {s: runs.read_done(d / "runs" / s)["final_eval"]
                                                         for s in cfgs}}

    # ------------------------------------------------------------------ dataset, pre-training, fine-tuning, evaluation
    def dt(self) -> list[Stage]:
        """Dataset, pre-training (the DT, behaviour cloning, the data curve and, with the
        ablation, its rows over several seeds), fine-tuning and evaluation."""
        stages = self.datasets()
        for m in self.models:
            cfg = self._pretrain_config("<dataset>", m)
            stages.append(Stage(self.t(m.stage), cfg.to_dict(), partial(self._run_pretrain, m),
                                (self.t(m.dataset),), (pretrain_cost(cfg),)))
        if self.track.places:
            stages += self.value_stages() + (self.places_finetune_stages() if self.tries_places else [])
        for w in (w for w in self.unseen if not zero_shot_only(w, self.rc.system) and self.finetunes_returns):
            ft = self.finetune_config("<pretrain>", w)
            stages.append(Stage(self.t(finetune_stage(w.name)), ft.to_dict(), partial(self._run_finetune, w),
                                (self.t(PRETRAIN),),
                                (finetune_cost(ft, self.horizon, self.control, self.model),)))
        for w in self.unseen:
            stages.append(self._evaluate_stage(w))
        return stages

    def datasets(self) -> list[Stage]:
        """The track's dataset: its experts' trajectories, or the planning oracle's demonstrations
        in its training halls (jobs of :data:`DEMONSTRATION_CHUNK` halls, each a finished part on
        disk that a rerun reuses), and, with the ablation, the mixed-quality demonstrations."""
        t, episodes = self.t, self.rc.trajectories_for(self.track)
        if not self.track.demonstrations:
            cost = dataset_cost(len(self.train) * episodes, self.horizon, self.control)
            config = {"trajectories": episodes, "seed": COLLECT_SEED, "format": DATASET_FORMAT_VERSION}
            return [Stage(t(DATASET), config, partial(self._run_collect, episodes, cost), (t(EXPERTS_TRAIN),),
                          (cost,))]
        system = self.rc.system.replace(observe_devices=True)
        # a track that learns places fits its value to the level poses the teacher's plans valued with R
        oracle = DemonstrationConfig(halls=len(self.train), episodes=episodes, layout_seed=self.rc.layout_seed,
                                     system=system, value_labels=self.track.places)
        stages = [self._demonstrations_stage(DATASET, oracle)]
        if self.track.places:  # filtered behaviour cloning's data: the best demonstrations by return
            config = {"fraction": BEST_FRACTION, "format": DATASET_FORMAT_VERSION}
            stages.append(Stage(self.t(DATASET_BEST), config, partial(self._run_best, oracle), (self.t(DATASET),),
                                (2.0,)))
        if self.track.ablation and self.rc.ablation:
            stages.append(self._demonstrations_stage(DATASET_MIXED, dataclasses.replace(
                oracle, halls=min(self.rc.mixed_layouts, len(self.train)), quality="mixed")))
        return stages

    def _run_best(self, cfg: DemonstrationConfig, d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        source = deps[self.t(DATASET)] / "dataset"
        return self.ctx.run_one(self.t(DATASET_BEST), best_demonstrations_job,
                                (cfg.to_dict(), str(source), BEST_FRACTION, str(d / "dataset")), d / "job.log", 2.0,
                                reads=(source,), writes=(d / "dataset",))

    def _run_collect(self, episodes: int, cost: float, d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        experts = [deps[self.t(EXPERTS_TRAIN)] / "runs" / w.name for w in self.train]
        return self.ctx.run_one(self.t(DATASET), dataset_job, ([str(e) for e in experts], episodes,
                                                                 str(d / "dataset")),
                                d / "job.log", cost, reads=tuple(experts), writes=(d / "dataset",))

    @staticmethod
    def _chunks(cfg: DemonstrationConfig) -> list[tuple[int, int]]:
        return [(first, min(DEMONSTRATION_CHUNK, cfg.halls - first)) for first in range(0, cfg.halls,
                                                                                         DEMONSTRATION_CHUNK)]

    def _demonstrations_stage(self, name: str, cfg: DemonstrationConfig) -> Stage:
        costs = tuple(demonstration_cost(n, cfg.episodes * len(cfg.behaviours), self.horizon, cfg.exact_plans)
                      for _, n in self._chunks(cfg))
        # the dataset format, the planner's version and the teacher's settings are part of the key: a stage
        # of another format, or flown by another planner, is not read, it is made again
        config = {**cfg.to_dict(), "format": DATASET_FORMAT_VERSION, "oracle": oracle_planner.ORACLE_VERSION,
                  "teacher": dataclasses.asdict(cfg.teacher)}
        return Stage(self.t(name), config, partial(self._run_demonstrations, name, cfg, costs), (), costs)

    def _run_demonstrations(self, name: str, cfg: DemonstrationConfig, costs: tuple[float, ...], d: Path,
                            deps: dict[str, Path]) -> dict[str, Any]:
        chunks = self._chunks(cfg)
        parts = [d / "parts" / f"halls-{first}" for first, _ in chunks]
        # a part, and where the plans are exact the poses they valued (labels beside the parts)
        jobs = [Job(f"halls-{first}", demonstrations_job, (cfg.to_dict(), first, n, str(part)),
                    d / "logs" / f"halls-{first}.log", cost, writes=(part, d / "labels" / f"{part.name}.npz"))
                for (first, n), part, cost in zip(chunks, parts, costs) if not part.exists()]
        self.ctx.run_all(self.t(name), jobs, "demonstration job")
        return self.ctx.run_one(self.t(name), merge_demonstrations, (cfg.to_dict(), [str(p) for p in parts],
                                                                        str(d / "dataset")), d / "merge.log", 1.0,
                                reads=tuple(parts), writes=(d / "dataset",))

    def _pretrain_config(self, data: Path | str, model: TrainedModel | None) -> PretrainConfig:
        fields = self.pretrain_fields if model is None else model.pretrain_fields(self.pretrain_fields)
        return PretrainConfig(dataset=data, preset=self.rc.preset, seed=self.rc.seed + (model.seed if model else 0),
                              **fields)

    def _run_pretrain(self, model: TrainedModel, d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        cfg = self._pretrain_config(deps[self.t(model.dataset)] / "dataset", model)
        return self.ctx.run_one(self.t(model.stage), pretrain_job, (cfg.to_dict(), str(d / "model"), self.ctx.device),
                                d / "job.log", pretrain_cost(cfg), reads=(Path(cfg.dataset),), writes=(d / "model",))

    def finetune_config(self, model: Path | str, where: Site, extra: dict[str, Any] | None = None) -> FinetuneConfig:
        # fine-tuning evaluates each round on the study's episodes unless the track's table says otherwise
        own = {"eval_episodes": self.rc.eval_episodes, **TRACK_FINETUNE[self.track.name][self.rc.preset],
               **(extra or {}),
               **({} if not self.track.layouts else {"system": where.system, "start": where.start})}
        return FinetuneConfig(model=model, scenario=where.name, preset=self.rc.preset, seed=self.rc.seed, **own)

    def _run_finetune(self, where: Site, d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        cfg = self.finetune_config(deps[self.t(PRETRAIN)] / "model", where)
        return self.ctx.run_one(self.t(finetune_stage(where.name)), finetune_job,
                                (cfg.to_dict(), str(d / "model"), self.ctx.device), d / "job.log",
                                finetune_cost(cfg, self.horizon, self.control, self.model),
                                reads=(Path(cfg.model),), writes=(d / "model",))

    def finetunes(self, site: Site) -> list[str]:
        """The fine-tuning stages of ``site`` (none in a hall evaluated zero-shot only)."""
        if zero_shot_only(site, self.rc.system):
            return []
        places = [places_stage(site.name, m.seed) for m in self.models if m.row == "dt-goal" and self.tries_places]
        return [*([finetune_stage(site.name)] if self.finetunes_returns else []), *places]

    def _evaluate_stage(self, where: Site) -> Stage:
        sources = transfer_sources(self.track, where, self.train)
        keys = [*self.inputs, *self.finetunes(where)]
        rows = self._rows(where, sources, {k: Path() for k in keys})
        dt_forwards = sum(isinstance(r.target, DTModel) + len(r.members) for r in rows)
        cost = evaluate_cost(len(rows) - len(REFERENCE_ROWS), self.rc.eval_episodes, self.horizon, self.control,
                             where.devices, 1 + (self.track.front_margin_deg is not None), self.track.layouts,
                             int(self.track.demonstrations), dt_forwards, self.model)
        # the hall it reads (its devices, room and start), not only its name: a changed generator or
        # layout is evaluated again instead of read back from an older run
        config = {"episodes": self.rc.eval_episodes, "seed": EVAL_SEED, "track": self.track.name,
                  "format": RESULTS_FORMAT, "oracle": oracle_planner.ORACLE_VERSION,
                  "hall": {"system": where.system.to_dict(), "start": list(where.scenario.start)},
                  "rows": [r.key for r in rows], "transfer_from": [s for s, _ in sources],
                  **({"front_margin_deg": self.track.front_margin_deg} if self.track.front_margin_deg else {})}
        return Stage(self.t(evaluation_stage(where.name)), config,
                     partial(self._run_evaluate, where, sources, keys, cost), tuple(self.t(k) for k in keys), (cost,))

    def _rows(self, where: Site, sources: list[tuple[str, float]], dirs: dict[str, Path]) -> list[Row]:
        return track_rows(self.track, where, sources, dirs, self.models, self.train, self.rc.ablation)

    def rows_in(self, site: Site, pipeline: Pipeline) -> list[Row]:
        """The rows of this track in any ``site`` (a user's hall included), reading the models of
        ``pipeline``'s stage directories; a fine-tuned row only where the study fine-tuned."""
        keys = [*self.inputs, *(k for k in self.finetunes(site) if self.t(k) in pipeline.stages)]
        return self._rows(site, transfer_sources(self.track, site, self.train),
                          {k: pipeline.directory(self.t(k)) for k in keys})

    def _run_evaluate(self, where: Site, sources: list[tuple[str, float]], keys: list[str], cost: float,
                      d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        rows = self._rows(where, sources, {k: deps[self.t(k)] for k in keys})
        # its rows' models are in the stages it depends on; its results go to its own folder, and each row's
        # to the study's kept rows too (a cluster's nodes may not share the study's folder: not there)
        kept = None if self.ctx.ray_address else str(study_folder(d) / KEPT_ROWS_DIR)
        return self.ctx.run_one(self.t(evaluation_stage(where.name)), evaluate_job,
                                (str(d), where, self.track.name, self.rc.eval_episodes, rows, kept, self.ctx.reuse),
                                d / "job.log", cost, reads=tuple(deps.values()), writes=(d,))
