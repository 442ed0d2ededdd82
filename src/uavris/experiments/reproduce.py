"""``uavris reproduce``: the paper's whole study in two tracks, resumable, on a process pool or Ray.

Lives here: :class:`ReproduceConfig`, :func:`build_pipeline` (the stages below, their
configurations and dependencies) and :func:`reproduce`. Not here: the work of each stage and
what sets the tracks apart (:mod:`.study`), keying and skipping stages (:mod:`.stages`), the
processes (:mod:`.jobs`) and the report (:mod:`.report`).

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

Stages 2-7 exist once per track (:mod:`.study`): the paper track as above, and the strong
track (learned motion, optimised phases) with the same names prefixed ``strong-``. Stages
whose inputs are ready run at the same time, and all their jobs share ``workers``
processes, so the two tracks interleave.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any, Literal, Sequence, get_args

from uavris import runs
from uavris.agents.experts import ALGORITHMS
from uavris.config import SystemConfig
from uavris.errors import UavrisError
from uavris.experiments.costs import dataset_cost, evaluate_cost, finetune_cost, pretrain_cost, train_cost
from uavris.experiments.jobs import BACKENDS, Job, configure_threads
from uavris.experiments.scheduling import StudyContext, expected_schedule
from uavris.experiments.stages import Pipeline, Stage
from uavris.experiments.study import (
    TRACK_SPECS,
    TRACKS,
    Deployment,
    Track,
    dataset_job,
    deployments,
    evaluate_job,
    finetune_job,
    nearest_training_scenarios,
    pretrain_job,
    strong_expert_config,
    transfer_sources,
)
from uavris.experiments.train_expert import TrainConfig, preset_config, train_job
from uavris.io import read_json, write_json
from uavris.presets import (
    COLLECT_SEED,
    EVAL_SEED,
    STUDY_COMPARE_SEEDS,
    STUDY_EVAL_EPISODES,
    STUDY_LAYOUT_TRAJECTORIES,
    STUDY_SCALING,
    STUDY_TRAIN_LAYOUTS,
    STUDY_TRAJECTORIES,
    STUDY_UNSEEN_LAYOUTS,
    Preset,
    check_preset,
)

# "all": the three tracks; "both": the paper and the strong track (the study before layouts).
TrackChoice = Literal["all", "both", "paper", "strong", "deployment"]
TRACK_CHOICES: tuple[str, ...] = get_args(TrackChoice)
ExpertAlgo = Literal["auto", "ddpg", "ppo", "sac", "td3"]
TRACK_SETS = {"all": TRACKS, "both": ("paper", "strong")}
assert set(TRACK_CHOICES) == set(TRACK_SETS) | set(TRACKS) and set(get_args(ExpertAlgo)) == {"auto", *ALGORITHMS}
AUTO = "auto"


@dataclasses.dataclass(frozen=True)
class ReproduceConfig:
    """Everything that determines the study (dumped into the report)."""

    preset: Preset = "quick"  # smoke (seconds, for tests), quick (under an hour on 2 cores) or paper (days)
    seed: int = 0  # seed of every training run (experts, DT); evaluation episodes have their own
    compare_seeds: int | None = None  # paper track: seeds per algorithm in the comparison (default: the preset's)
    eval_episodes: int | None = None  # evaluation episodes per policy and scenario (default: the preset's)
    trajectories: int | None = None  # expert trajectories per training scenario or layout (default: the preset's)
    track: TrackChoice = "all"  # all, both (paper and strong), paper, strong or deployment
    expert_algo: ExpertAlgo = AUTO  # paper track: auto (the comparison's choice) or one of the four
    train_layouts: int | None = None  # deployment track: training layouts (default: the preset's)
    unseen_layouts: int | None = None  # deployment track: unseen layouts (default: the preset's)
    layout_seed: int = 0  # deployment track: seed of the layout generator
    scaling: tuple[int, ...] | None = None  # deployment track: smaller training sets of the data curve
    system: SystemConfig = dataclasses.field(default_factory=SystemConfig)

    def __post_init__(self) -> None:
        check_preset(self.preset)
        if self.track not in TRACK_CHOICES:
            raise UavrisError(f"unknown track {self.track!r}; choose one of {', '.join(TRACK_CHOICES)}")
        if self.expert_algo not in (AUTO,) + ALGORITHMS:
            raise UavrisError(f"unknown expert algorithm {self.expert_algo!r}; choose {AUTO} (the comparison's "
                              f"winner) or one of {', '.join(ALGORITHMS)}")
        for name in ("compare_seeds", "eval_episodes", "trajectories", "train_layouts", "unseen_layouts"):
            v = getattr(self, name)
            if v is not None and v < 1:
                raise UavrisError(f"--{name.replace('_', '-')} must be >= 1, got {v}")
        if self.unseen_layouts is not None and self.unseen_layouts < 2:
            raise UavrisError(f"--unseen-layouts must be >= 2 (a CI over layouts needs two), got {self.unseen_layouts}")
        for name in ("seed", "layout_seed"):
            if getattr(self, name) < 0:
                raise UavrisError(f"--{name.replace('_', '-')} must be >= 0, got {getattr(self, name)}")
        if self.scaling is not None:
            object.__setattr__(self, "scaling", tuple(int(n) for n in self.scaling))
        bad = [n for n in self.scaling_points if not 1 <= n < self.n_train_layouts]
        if bad:
            raise UavrisError(f"--scaling {list(self.scaling_points)}: each must be >= 1 and below "
                              f"--train-layouts ({self.n_train_layouts}), got {bad}")

    @property
    def n_compare_seeds(self) -> int:
        return self.compare_seeds or STUDY_COMPARE_SEEDS[self.preset]

    @property
    def n_eval(self) -> int:
        return self.eval_episodes or STUDY_EVAL_EPISODES[self.preset]

    @property
    def n_trajectories(self) -> int:
        return self.trajectories or STUDY_TRAJECTORIES[self.preset]

    @property
    def n_train_layouts(self) -> int:
        return self.train_layouts or STUDY_TRAIN_LAYOUTS[self.preset]

    @property
    def n_unseen_layouts(self) -> int:
        return self.unseen_layouts or STUDY_UNSEEN_LAYOUTS[self.preset]

    @property
    def scaling_points(self) -> tuple[int, ...]:
        return self.scaling if self.scaling is not None else STUDY_SCALING[self.preset]

    def trajectories_for(self, track: Track) -> int:
        """Expert trajectories per training deployment: a layout gets as many as keep the
        dataset the size of the paper track's (8 scenarios x the preset's), unless
        ``--trajectories`` says otherwise."""
        if not track.layouts:
            return self.n_trajectories
        return self.trajectories or STUDY_LAYOUT_TRAJECTORIES[self.preset]

    @property
    def tracks(self) -> tuple[Track, ...]:
        return tuple(TRACK_SPECS[t] for t in TRACK_SETS.get(self.track, (self.track,)))

    def deployments(self, track: Track) -> tuple[list[Deployment], list[Deployment]]:
        return deployments(track, self.system, self.n_train_layouts, self.n_unseen_layouts, self.layout_seed)


# ------------------------------------------------------------------------------------------ stages
def _run_experts(stage: str, stage_dir: Path, cfgs: dict[str, TrainConfig], ctx: StudyContext) -> dict[str, Any]:
    jobs = [Job(f"{cfg.algo}-{s}", train_job, (cfg.to_dict(), str(stage_dir / "runs" / s), ctx.device),
                stage_dir / "logs" / f"{s}.log", train_cost(cfg))
            for s, cfg in cfgs.items() if not runs.is_finished(stage_dir / "runs" / s)]
    failures = [r for r in ctx.submit(stage, jobs) if not r.ok]
    if failures:
        raise UavrisError(f"{len(failures)} expert job(s) failed: "
                          + "; ".join(f"{f.name} ({f.error}; log {f.log})" for f in failures))
    algos = sorted({cfg.algo for cfg in cfgs.values()})
    return {"algo": "+".join(algos), "final_evals": {s: runs.read_done(stage_dir / "runs" / s)["final_eval"]
                                                     for s in cfgs}}


def _expert_stages(rc: ReproduceConfig, track: Track, ctx: StudyContext) -> list[Stage]:
    """Experts of the training (and, where the track has them, the unseen) deployments of ``track``."""
    train, unseen = rc.deployments(track)
    stages = []
    for name, where in (("experts-train", train), ("experts-unseen", unseen if track.unseen_experts else [])):
        if not where:
            continue
        stage = track.stage(name)
        if track.phase_control == "optimizer":  # the strong recipe: imitation of the planning oracle
            cfgs = {d.name: strong_expert_config(d.name, rc.seed, rc.preset, rc.n_eval, d.system, d.start)
                    for d in where}
            stages.append(Stage(stage, {s: c.to_dict() for s, c in cfgs.items()},
                                lambda d, deps, cfgs=cfgs, stage=stage: _run_experts(stage, d, cfgs, ctx),
                                costs=tuple(train_cost(c) for c in cfgs.values())))
            continue

        def configs(algo: str, where: Sequence[Deployment] = where) -> dict[str, TrainConfig]:
            return {w.name: preset_config(algo, w.name, rc.seed, rc.preset, eval_episodes=rc.n_eval, system=w.system)
                    for w in where}

        def run(d: Path, deps: dict[str, Path], configs: Any = configs, stage: str = stage) -> dict[str, Any]:
            algo = rc.expert_algo if rc.expert_algo != AUTO else read_json(deps["compare"] / "summary.json")["expert"]
            return _run_experts(stage, d, configs(algo), ctx)

        # Before the comparison has chosen, the experts' cost is the dearest algorithm's for the
        # order (the chain through the comparison is then sure to go first) and the mean over
        # the algorithms for the progress bar, which takes the chosen one's when its jobs come.
        guesses = [rc.expert_algo] if rc.expert_algo != AUTO else list(ALGORITHMS)
        by_algo = [tuple(train_cost(c) for c in configs(a).values()) for a in guesses]
        config = {"algo": rc.expert_algo, "scenarios": [w.name for w in where], "seed": rc.seed, "preset": rc.preset,
                  "eval_episodes": rc.n_eval, "system": rc.system.to_dict()}
        stages.append(Stage(name, config, run, ("compare",) if rc.expert_algo == AUTO else (), max(by_algo, key=sum),
                            sum(map(sum, by_algo)) / len(by_algo)))
    return stages


def _dt_stages(rc: ReproduceConfig, track: Track, ctx: StudyContext) -> list[Stage]:
    """Dataset, pre-training (and behaviour cloning, and the data curve), fine-tuning and
    evaluation of ``track``."""
    from uavris.experiments.finetune import finetune_config
    from uavris.experiments.pretrain import pretrain_config

    t = track.stage
    train, unseen = rc.deployments(track)
    trajectories = rc.trajectories_for(track)
    horizon, control = rc.system.horizon, track.phase_control

    def dataset(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        experts = [str(deps[t("experts-train")] / "runs" / w.name) for w in train]
        return ctx.run_one(t("dataset"), dataset_job, (experts, trajectories, str(d / "dataset")), d / "job.log",
                           dataset_cost(len(train) * trajectories, horizon, control))

    # The DT, behaviour cloning with the same model and budget, and the DT on fewer training
    # layouts (the data curve): one pre-training stage each, on the same dataset.
    schedule = dict(track.pretrain)
    preset_context = pretrain_config("<dataset>", rc.preset, rc.seed).context
    if "context" in schedule:  # a track's shorter context never lengthens a preset's (smoke reads 4 slots)
        schedule["context"] = min(schedule["context"], preset_context)
    context = schedule.get("context", preset_context)  # what the pre-trained and fine-tuned models read
    models: dict[str, dict[str, Any]] = {"pretrain": schedule}
    if track.behaviour_cloning:
        models["bc"] = {**schedule, "condition_on_return": False}
    if track.layouts:
        models.update({f"pretrain-n{n}": {**schedule, "scenarios": tuple(w.name for w in train[:n])}
                       for n in rc.scaling_points})

    def pretrain(name: str, overrides: dict[str, Any]):
        def run(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
            cfg = pretrain_config(deps[t("dataset")] / "dataset", rc.preset, rc.seed, **overrides)
            return ctx.run_one(t(name), pretrain_job, (dataclasses.asdict(cfg), str(d / "model"), ctx.device),
                               d / "job.log", pretrain_cost(cfg))
        return run

    def finetune(where: Deployment):
        def run(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
            cfg = _finetune_config(deps[t("pretrain")] / "model", where)
            return ctx.run_one(t(f"finetune-{where.name}"), finetune_job,
                               (dataclasses.asdict(cfg), str(d / "model"), ctx.device), d / "job.log",
                               finetune_cost(cfg, horizon, control, context))
        return run

    def _finetune_config(model: Path | str, where: Deployment):
        own = {} if not track.layouts else {"system": where.system, "start": where.start}
        return finetune_config(model, where.name, rc.preset, rc.seed, eval_episodes=rc.n_eval, **own)

    inputs = ["experts-train", *(["experts-unseen"] if track.unseen_experts else []), *models]

    def evaluate(where: Deployment, sources: list[tuple[str, float]]):
        keys = [*inputs, f"finetune-{where.name}"]
        cost = evaluate_cost(len(_evaluated_policies(track, where, sources, {k: Path() for k in keys})), rc.n_eval,
                             horizon, control)

        def run(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
            policies = _evaluated_policies(track, where, sources, {k: deps[t(k)] for k in keys})
            return ctx.run_one(t(f"evaluate-{where.name}"), evaluate_job,
                               (str(d), where.to_dict(), track.name, rc.n_eval, policies), d / "job.log", cost)
        return run, keys, cost

    stages = [Stage(t("dataset"), {"trajectories": trajectories, "seed": COLLECT_SEED}, dataset,
                    (t("experts-train"),), (dataset_cost(len(train) * trajectories, horizon, control),))]
    for name, overrides in models.items():
        cfg = pretrain_config("<dataset>", rc.preset, rc.seed, **overrides)
        stages.append(Stage(t(name), dataclasses.asdict(cfg), pretrain(name, overrides), (t("dataset"),),
                            (pretrain_cost(cfg),)))
    for w in unseen:
        ft = _finetune_config("<pretrain>", w)
        stages.append(Stage(t(f"finetune-{w.name}"), dataclasses.asdict(ft), finetune(w), (t("pretrain"),),
                            (finetune_cost(ft, horizon, control, context),)))
    for w in unseen:
        sources = transfer_sources(track, w, train)
        run, keys, cost = evaluate(w, sources)
        stages.append(Stage(t(f"evaluate-{w.name}"), {"episodes": rc.n_eval, "seed": EVAL_SEED, "track": track.name,
                                                      "references": ["hover", "hover-optimizer", "oracle"],
                                                      "transfer_from": [s for s, _ in sources]},
                            run, tuple(t(k) for k in keys), (cost,)))
    return stages


def _evaluated_policies(track: Track, where: Deployment, sources: list[tuple[str, float]],
                        dirs: dict[str, Path]) -> dict[str, tuple[str, str, str]]:
    """What a track's evaluation stage scores in ``where`` beside the references:
    ``{key: (label, kind, path)}`` (:func:`uavris.experiments.study.evaluate_policies`)."""
    policies: dict[str, tuple[str, str, str]] = {}
    if track.unseen_experts:
        policies["expert"] = ("expert trained in the scenario", "expert",
                              str(dirs["experts-unseen"] / "runs" / where.name))
    policies["dt-zero-shot"] = ("zero-shot DT", "dt", str(dirs["pretrain"] / "model"))
    policies["dt-finetuned"] = ("fine-tuned DT", "dt", str(dirs[f"finetune-{where.name}"] / "model"))
    if "bc" in dirs:
        policies["bc"] = ("behaviour cloning (the DT without return conditioning)", "dt", str(dirs["bc"] / "model"))
    for name in sorted((k for k in dirs if k.startswith("pretrain-n")), key=lambda k: int(k[len("pretrain-n"):])):
        n = name[len("pretrain-n"):]
        policies[f"dt-zero-shot-n{n}"] = (f"zero-shot DT, {n} training layout{'s' * (n != '1')}", "dt",
                                          str(dirs[name] / "model"))
    for rank, (src, dist) in enumerate(sources):
        near = " (nearest)" if track.layouts and rank == 0 else ""
        label = f"transferred from {src}{near}" + (f", {dist:.1f} m" if track.layouts else "")
        policies[f"transfer-{src}"] = (label, "expert", str(dirs["experts-train"] / "runs" / src))
    return policies


def build_pipeline(rc: ReproduceConfig, out: Path, ctx: StudyContext) -> Pipeline:
    def compare(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        from uavris.experiments.compare import compare_algorithms

        compare_algorithms(preset=rc.preset, seeds=rc.n_compare_seeds, workers=ctx.workers, out=d,
                           eval_episodes=rc.n_eval, progress=False, device=ctx.device, system=rc.system,
                           submit=lambda jobs: ctx.submit("compare", jobs))
        summary = read_json(d / "summary.json")
        return {"rows": summary["rows"], "expert": summary["expert"], "expert_choice": summary["expert_choice"]}

    tracks = rc.tracks
    stages = []
    if any(t.name == "paper" for t in tracks):
        from uavris.experiments.compare import comparison_configs

        costs = tuple(train_cost(c) for c in comparison_configs(rc.preset, rc.n_compare_seeds, ALGORITHMS, "fig2",
                                                                rc.n_eval, rc.system).values())
        stages.append(Stage("compare", {"preset": rc.preset, "seeds": rc.n_compare_seeds, "eval_episodes": rc.n_eval,
                                        "system": rc.system.to_dict()}, compare, costs=costs))
    for track in tracks:
        stages += _expert_stages(rc, track, ctx)
    for track in tracks:
        stages += _dt_stages(rc, track, ctx)
    return Pipeline(out, stages)


# ------------------------------------------------------------------------------------------ entry point
def estimate(rc: ReproduceConfig, workers: int) -> str:
    """The study's stages with their expected core-minutes and expected start and end on
    ``workers`` workers, and the expected wall clock (:func:`~.scheduling.expected_schedule`),
    as markdown. Nothing is run or written."""
    if workers < 1:
        raise UavrisError(f"--workers must be >= 1, got {workers}")
    pipeline = build_pipeline(rc, Path("<estimate>"), StudyContext(workers, "local", None))
    wall, spans = expected_schedule(pipeline, workers)
    algo = rc.expert_algo if rc.expert_algo != AUTO else "the dearest algorithm (SAC) until the comparison chooses"
    lines = [f"expected wall clock of `uavris reproduce --preset {rc.preset} --track {rc.track}` on {workers} "
             f"worker(s): {wall / 3600:.1f} h ({wall / 60:.0f} min); paper-track experts: {algo}", "",
             "| stage | jobs | core-min | expected start (min) | expected end (min) |", "|---|---:|---:|---:|---:|"]
    for name, st in pipeline.stages.items():
        start, end = spans[name]
        lines.append(f"| {name} | {len(st.costs)} | {sum(st.costs) / 60:.1f} | {start / 60:.1f} | {end / 60:.1f} |")
    total = sum(sum(st.costs) for st in pipeline.stages.values())
    lines += ["", f"total work {total / 3600:.1f} core-hours; unit costs measured on a 2-core AMD EPYC, one job per "
              "core (uavris.experiments.costs); an estimate, not a promise", ""]
    return "\n".join(lines)


def reproduce(rc: ReproduceConfig, out: str | Path, *, workers: int = 2, backend: str = "local",
              ray_address: str | None = None, force: Sequence[str] = (), progress: bool = True,
              device: str = "cpu") -> Path:
    """Run (or resume) the whole study into ``out`` (torch on ``device``); returns the report path.

    Raises :class:`UavrisError` at the end when any job or stage failed (after writing the
    report of everything that finished).
    """
    if backend not in BACKENDS:
        raise UavrisError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if workers < 1:
        raise UavrisError(f"--workers must be >= 1, got {workers}")
    out = Path(out)
    from tqdm.auto import tqdm

    configure_threads()  # before any worker starts: they inherit it, and jobs run here with one worker
    # The bar counts expected seconds of work (uavris.experiments.scheduling), shown as a share.
    bar = tqdm(total=0, desc="reproduce", dynamic_ncols=True, disable=not progress,
               bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}]")
    ctx = StudyContext(workers, backend, ray_address, bar, device)
    pipeline = build_pipeline(rc, out, ctx)
    unknown = [f for f in force if f not in pipeline.stages and f != "report"]
    if unknown:
        bar.close()
        raise UavrisError(f"--force names unknown stage(s) {unknown}; stages: {list(pipeline.stages) + ['report']}")
    ctx.plan(pipeline)
    t0, origin = time.perf_counter(), time.time()
    try:
        records = pipeline.run(tuple(f for f in force if f != "report"), ctx.stage_done)
    finally:
        ctx.close()
    from uavris.experiments.report import write_report

    write_json(out / "schedule.json", {"workers": workers, "origin": origin, "jobs": ctx.schedule(origin)})
    report = write_report(out, rc, pipeline, records, time.perf_counter() - t0, origin)
    bar.close()
    failed = [r for r in records if r.status == "failed"]
    if failed or ctx.failures:
        logs = "; ".join(f"{f.name}: {f.log}" for f in ctx.failures)
        raise UavrisError(f"{len(failed)} stage(s) failed ({', '.join(r.name for r in failed)}); "
                          f"report of the rest: {report}" + (f"; failed job logs: {logs}" if logs else ""))
    return report


__all__ = ["ReproduceConfig", "nearest_training_scenarios", "reproduce"]
