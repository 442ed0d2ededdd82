"""``uavris reproduce``: the paper's whole study in three tracks, resumable, on a process pool or Ray.

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

Stages 2-7 exist once per track (:mod:`.study`, built by :mod:`.track_stages`): the paper
track as above, and the strong track (learned motion, optimised phases) with the same names
prefixed ``strong-``. The deployment track (``deploy-``) is the same pipeline with other
parameters (:class:`~uavris.experiments.study.Track`): its dataset is the planning oracle's
demonstrations in many generated halls (``deploy-dataset``, and ``deploy-dataset-mixed`` of
mixed quality), its pre-training stages are the ablation's rows over several seeds
(``deploy-pretrain``, ``-bc``, ``-flat``, ``-pretrain-nN``, ``-mixed-dt``, ``-mixed-bc``, each
with ``-sK`` copies), and it deploys to unseen halls. Stages whose inputs are ready run at
the same time, and all their jobs share ``workers`` processes, so the tracks interleave.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any, Literal, Sequence, get_args

from uavris.agents.experts import ALGORITHMS
from uavris.config import SystemConfig
from uavris.errors import UavrisError
from uavris.experiments.costs import (
    train_cost,
)
from uavris.experiments.forecast import expected_schedule
from uavris.experiments.jobs import BACKENDS, configure_threads
from uavris.experiments.scheduling import StudyContext
from uavris.experiments.stages import Pipeline, Stage
from uavris.experiments.study import (
    TRACK_SPECS,
    TRACKS,
    Deployment,
    Track,
    deployments,
    nearest_training_scenarios,
)
from uavris.experiments.track_stages import AUTO, dt_stages, expert_stages
from uavris.io import read_json, write_json
from uavris.presets import (
    STUDY_COMPARE_SEEDS,
    STUDY_DT_SEEDS,
    STUDY_EVAL_EPISODES,
    STUDY_LAYOUT_TRAJECTORIES,
    STUDY_MIXED_LAYOUTS,
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
SIZE_BOUNDS = {"compare_seeds": 100, "eval_episodes": 100_000, "trajectories": 100_000, "train_layouts": 100_000,
               "unseen_layouts": 10_000, "dt_seeds": 100, "mixed_layouts": 100_000}
assert set(TRACK_CHOICES) == set(TRACK_SETS) | set(TRACKS) and set(get_args(ExpertAlgo)) == {"auto", *ALGORITHMS}


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
    dt_seeds: int | None = None  # deployment track: pre-training seeds of every learned row (default: the preset's)
    mixed_layouts: int | None = None  # deployment track: halls of the mixed-quality dataset (default: the preset's)
    system: SystemConfig = dataclasses.field(default_factory=SystemConfig)

    def __post_init__(self) -> None:
        check_preset(self.preset)
        if self.track not in TRACK_CHOICES:
            raise UavrisError(f"unknown track {self.track!r}; choose one of {', '.join(TRACK_CHOICES)}")
        if self.expert_algo not in (AUTO,) + ALGORITHMS:
            raise UavrisError(f"unknown expert algorithm {self.expert_algo!r}; choose {AUTO} (the comparison's "
                              f"winner) or one of {', '.join(ALGORITHMS)}")
        for name, top in SIZE_BOUNDS.items():  # a typo's bound: beyond it a run exhausts memory or days
            v = getattr(self, name)
            if v is not None and not 1 <= v <= top:
                raise UavrisError(f"--{name.replace('_', '-')} must be in [1, {top:,}], got {v}")
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
    def n_dt_seeds(self) -> int:
        return self.dt_seeds or STUDY_DT_SEEDS[self.preset]

    @property
    def n_mixed_layouts(self) -> int:
        return self.mixed_layouts or STUDY_MIXED_LAYOUTS[self.preset]

    @property
    def scaling_points(self) -> tuple[int, ...]:
        return self.scaling if self.scaling is not None else STUDY_SCALING[self.preset]

    def trajectories_for(self, track: Track) -> int:
        """Expert trajectories (or demonstrations) per training deployment: a generated hall
        gets the preset's few (many halls, few episodes each: docs/model.md section 21),
        unless ``--trajectories`` says otherwise."""
        if not track.layouts:
            return self.n_trajectories
        return self.trajectories or STUDY_LAYOUT_TRAJECTORIES[self.preset]

    @property
    def tracks(self) -> tuple[Track, ...]:
        return tuple(TRACK_SPECS[t] for t in TRACK_SETS.get(self.track, (self.track,)))

    def deployments(self, track: Track) -> tuple[list[Deployment], list[Deployment]]:
        return deployments(track, self.system, self.n_train_layouts, self.n_unseen_layouts, self.layout_seed)


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
        stages += expert_stages(rc, track, ctx)
    for track in tracks:
        stages += dt_stages(rc, track, ctx)
    return Pipeline(out, stages)


# ------------------------------------------------------------------------------------------ entry point
def estimate(rc: ReproduceConfig, workers: int) -> str:
    """The study's stages with their expected core-minutes and expected start and end on
    ``workers`` workers, and the expected wall clock (:func:`~.forecast.expected_schedule`),
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
               bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}{postfix}]")
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

    if progress and records and all(r.status == "skipped" for r in records):
        bar.write("every stage was done earlier: only the report and its figures are drawn again")

    write_json(out / "schedule.json", {"workers": workers, "origin": origin, "jobs": ctx.schedule(origin),
                                       "eta": ctx.etas(origin)})
    report = write_report(out, rc, pipeline, records, time.perf_counter() - t0, origin)
    bar.close()
    failed = [r for r in records if r.status == "failed"]
    if failed or ctx.failures:
        logs = "; ".join(f"{f.name}: {f.log}" for f in ctx.failures)
        raise UavrisError(f"{len(failed)} stage(s) failed ({', '.join(r.name for r in failed)}); "
                          f"report of the rest: {report}" + (f"; failed job logs: {logs}" if logs else ""))
    return report


__all__ = ["ReproduceConfig", "nearest_training_scenarios", "reproduce"]
