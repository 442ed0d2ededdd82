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
import threading
import time
from pathlib import Path
from typing import Any, Sequence

from uavris import runs
from uavris.agents.experts import ALGORITHMS
from uavris.config import TRAINING_SCENARIOS, UNSEEN_SCENARIOS, SystemConfig
from uavris.errors import UavrisError
from uavris.experiments.jobs import BACKENDS, Job, JobResult, JobRunner
from uavris.experiments.stages import Pipeline, Stage, StageRecord
from uavris.experiments.study import (
    TRACK_SPECS,
    TRACKS,
    Track,
    dataset_job,
    evaluate_job,
    finetune_job,
    nearest_training_scenarios,
    pretrain_job,
    strong_expert_config,
)
from uavris.experiments.train_expert import TrainConfig, preset_config, train_job
from uavris.io import read_json
from uavris.presets import (
    COLLECT_SEED,
    EVAL_SEED,
    STUDY_COMPARE_SEEDS,
    STUDY_EVAL_EPISODES,
    STUDY_TRAJECTORIES,
    check_preset,
)

TRACK_CHOICES = ("both",) + TRACKS
AUTO = "auto"
# Job priorities: a free worker takes DT-chain jobs first, then experts, then the comparison's
# runs, so the chains that follow the experts do not wait behind independent training jobs.
PRIORITY_EXPERTS, PRIORITY_DT = 1, 2


@dataclasses.dataclass(frozen=True)
class ReproduceConfig:
    """Everything that determines the study (dumped into the report)."""

    preset: str = "quick"
    seed: int = 0
    compare_seeds: int | None = None
    eval_episodes: int | None = None
    trajectories: int | None = None
    track: str = "both"  # both, paper or strong
    expert_algo: str = AUTO  # paper track: "auto" = the comparison's winner, or one of the four
    system: SystemConfig = dataclasses.field(default_factory=SystemConfig)

    def __post_init__(self) -> None:
        check_preset(self.preset)
        if self.track not in TRACK_CHOICES:
            raise UavrisError(f"unknown track {self.track!r}; choose one of {', '.join(TRACK_CHOICES)}")
        if self.expert_algo not in (AUTO,) + ALGORITHMS:
            raise UavrisError(f"unknown expert algorithm {self.expert_algo!r}; choose {AUTO} (the comparison's "
                              f"winner) or one of {', '.join(ALGORITHMS)}")
        for name in ("compare_seeds", "eval_episodes", "trajectories"):
            v = getattr(self, name)
            if v is not None and v < 1:
                raise UavrisError(f"--{name.replace('_', '-')} must be >= 1, got {v}")
        if self.seed < 0:
            raise UavrisError(f"--seed must be >= 0, got {self.seed}")

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
    def tracks(self) -> tuple[Track, ...]:
        return tuple(TRACK_SPECS[t] for t in (TRACKS if self.track == "both" else (self.track,)))


class _Context:
    """The job runner and the progress bar shared by the stages (which may run concurrently)."""

    def __init__(self, workers: int, backend: str, ray_address: str | None, bar: Any, device: str = "cpu") -> None:
        self.workers, self.backend, self.ray_address, self.bar = workers, backend, ray_address, bar
        self.device = device
        self.runner = JobRunner(workers, backend, ray_address)
        self.failures: list[JobResult] = []
        self._lock = threading.Lock()

    def run_jobs(self, jobs: list[Job], priority: int = 0) -> list[JobResult]:
        with self._lock:
            if self.bar is not None:
                self.bar.total += len(jobs)
                self.bar.refresh()

        def done(res: JobResult) -> None:
            with self._lock:
                if self.bar is not None:
                    self.bar.update(1)
                    status = "done" if res.ok else f"FAILED ({res.error}); log: {res.log}"
                    self.bar.write(f"  job {res.name}: {status}")

        results = self.runner.run(jobs, done, priority)
        failed = [r for r in results if not r.ok]
        with self._lock:
            self.failures += failed
        return failed

    def run_one(self, name: str, fn: Any, args: tuple[Any, ...], log: Path) -> Any:
        """One job of a DT stage (the study's longest chains: they go before waiting training
        jobs); its value, or a :class:`UavrisError` naming its log when it failed."""
        results = self.runner.run([Job(name, fn, args, log)], priority=PRIORITY_DT)
        res = results[0]
        if not res.ok:
            with self._lock:
                self.failures.append(res)
            raise UavrisError(f"{res.error}; log {res.log}")
        return res.value


# ------------------------------------------------------------------------------------------ stages
def _run_experts(stage_dir: Path, cfgs: dict[str, TrainConfig], ctx: _Context) -> dict[str, Any]:
    jobs = [Job(f"{cfg.algo}-{s}", train_job, (cfg.to_dict(), str(stage_dir / "runs" / s), ctx.device),
                stage_dir / "logs" / f"{s}.log")
            for s, cfg in cfgs.items() if not runs.is_finished(stage_dir / "runs" / s)]
    failures = ctx.run_jobs(jobs, PRIORITY_EXPERTS)
    if failures:
        raise UavrisError(f"{len(failures)} expert job(s) failed: "
                          + "; ".join(f"{f.name} ({f.error}; log {f.log})" for f in failures))
    algos = sorted({cfg.algo for cfg in cfgs.values()})
    return {"algo": "+".join(algos), "final_evals": {s: runs.read_done(stage_dir / "runs" / s)["final_eval"]
                                                     for s in cfgs}}


def _expert_stages(rc: ReproduceConfig, track: Track, ctx: _Context) -> list[Stage]:
    """Experts of the training and of the unseen scenarios for ``track``."""
    stages = []
    for name, scenarios in (("experts-train", TRAINING_SCENARIOS), ("experts-unseen", UNSEEN_SCENARIOS)):
        if track.name == "strong":
            cfgs = {s: strong_expert_config(s, rc.seed, rc.preset, rc.n_eval, rc.system) for s in scenarios}
            stages.append(Stage(track.stage(name), {s: c.to_dict() for s, c in cfgs.items()},
                                lambda d, deps, cfgs=cfgs: _run_experts(d, cfgs, ctx)))
            continue

        def run(d: Path, deps: dict[str, Path], scenarios: Sequence[str] = scenarios) -> dict[str, Any]:
            algo = rc.expert_algo if rc.expert_algo != AUTO else read_json(deps["compare"] / "summary.json")["expert"]
            cfgs = {s: preset_config(algo, s, rc.seed, rc.preset, eval_episodes=rc.n_eval, system=rc.system)
                    for s in scenarios}
            return _run_experts(d, cfgs, ctx)

        config = {"algo": rc.expert_algo, "scenarios": list(scenarios), "seed": rc.seed, "preset": rc.preset,
                  "eval_episodes": rc.n_eval, "system": rc.system.to_dict()}
        stages.append(Stage(name, config, run, ("compare",) if rc.expert_algo == AUTO else ()))
    return stages


def _dt_stages(rc: ReproduceConfig, track: Track, ctx: _Context) -> list[Stage]:
    """Dataset, pre-training, fine-tuning and evaluation of ``track``."""
    from uavris.experiments.finetune import finetune_config
    from uavris.experiments.pretrain import pretrain_config

    t = track.stage

    def dataset(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        experts = [str(deps[t("experts-train")] / "runs" / s) for s in TRAINING_SCENARIOS]
        return ctx.run_one(t("dataset"), dataset_job, (experts, rc.n_trajectories, str(d / "dataset")),
                           d / "job.log")

    def pretrain(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        cfg = pretrain_config(deps[t("dataset")] / "dataset", rc.preset, rc.seed)
        return ctx.run_one(t("pretrain"), pretrain_job, (dataclasses.asdict(cfg), str(d / "model"), ctx.device),
                           d / "job.log")

    def finetune(scenario: str):
        def run(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
            cfg = finetune_config(deps[t("pretrain")] / "model", scenario, rc.preset, rc.seed,
                                  eval_episodes=rc.n_eval)
            return ctx.run_one(t(f"finetune-{scenario}"), finetune_job,
                               (dataclasses.asdict(cfg), str(d / "model"), ctx.device),
                               d / "job.log")
        return run

    def evaluate(scenario: str):
        def run(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
            dirs = {name: str(deps[t(name)]) for name in ("experts-train", "experts-unseen", "pretrain")}
            dirs["finetune"] = str(deps[t(f"finetune-{scenario}")])
            return ctx.run_one(t(f"evaluate-{scenario}"), evaluate_job,
                               (str(d), scenario, track.name, rc.system.to_dict(), rc.n_eval, dirs), d / "job.log")
        return run

    stages = [
        Stage(t("dataset"), {"trajectories": rc.n_trajectories, "seed": COLLECT_SEED}, dataset,
              (t("experts-train"),)),
        Stage(t("pretrain"), dataclasses.asdict(pretrain_config("<dataset>", rc.preset, rc.seed)), pretrain,
              (t("dataset"),)),
    ]
    for s in UNSEEN_SCENARIOS:
        ft = dataclasses.asdict(finetune_config("<pretrain>", s, rc.preset, rc.seed, eval_episodes=rc.n_eval))
        stages.append(Stage(t(f"finetune-{s}"), ft, finetune(s), (t("pretrain"),)))
    for s in UNSEEN_SCENARIOS:
        stages.append(Stage(t(f"evaluate-{s}"), {"episodes": rc.n_eval, "seed": EVAL_SEED, "track": track.name,
                                                 "references": ["hover", "hover-optimizer", "oracle"],
                                                 "transfer_from": nearest_training_scenarios(s)},
                            evaluate(s), (t("experts-train"), t("experts-unseen"), t("pretrain"),
                                          t(f"finetune-{s}"))))
    return stages


def build_pipeline(rc: ReproduceConfig, out: Path, ctx: _Context) -> Pipeline:
    def compare(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        from uavris.experiments.compare import compare_algorithms

        compare_algorithms(preset=rc.preset, seeds=rc.n_compare_seeds, workers=ctx.workers, out=d,
                           eval_episodes=rc.n_eval, progress=False, runner=ctx.runner, device=ctx.device)
        summary = read_json(d / "summary.json")
        return {"rows": summary["rows"], "expert": summary["expert"]}

    tracks = rc.tracks
    stages = []
    if any(t.name == "paper" for t in tracks):
        stages.append(Stage("compare", {"preset": rc.preset, "seeds": rc.n_compare_seeds, "eval_episodes": rc.n_eval,
                                        "system": rc.system.to_dict()}, compare))
    for track in tracks:
        stages += _expert_stages(rc, track, ctx)
    for track in tracks:
        stages += _dt_stages(rc, track, ctx)
    return Pipeline(out, stages)


# ------------------------------------------------------------------------------------------ entry point
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

    ctx = _Context(workers, backend, ray_address, None, device)
    pipeline = build_pipeline(rc, out, ctx)
    unknown = [f for f in force if f not in pipeline.stages and f != "report"]
    if unknown:
        raise UavrisError(f"--force names unknown stage(s) {unknown}; stages: {list(pipeline.stages) + ['report']}")
    bar = tqdm(total=0, unit="step", desc="reproduce", dynamic_ncols=True, disable=not progress)
    ctx.bar = bar
    bar.total += len(pipeline.stages) + 1
    bar.refresh()

    def on_stage(rec: StageRecord) -> None:
        with ctx._lock:
            bar.update(1)
            extra = f" ({rec.error})" if rec.error else ""
            bar.write(f"stage {rec.name} [{rec.key}]: {rec.status} in {rec.wall_s / 60:.1f} min{extra}")

    t0 = time.perf_counter()
    try:
        records = pipeline.run(tuple(f for f in force if f != "report"), on_stage)
    finally:
        ctx.runner.close()
    from uavris.experiments.report import write_report

    report = write_report(out, rc, pipeline, records, time.perf_counter() - t0)
    bar.update(1)
    bar.close()
    failed = [r for r in records if r.status == "failed"]
    if failed or ctx.failures:
        logs = "; ".join(f"{f.name}: {f.log}" for f in ctx.failures)
        raise UavrisError(f"{len(failed)} stage(s) failed ({', '.join(r.name for r in failed)}); "
                          f"report of the rest: {report}" + (f"; failed job logs: {logs}" if logs else ""))
    return report


__all__ = ["ReproduceConfig", "nearest_training_scenarios", "reproduce"]
