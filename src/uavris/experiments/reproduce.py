"""``uavris reproduce``: the paper's whole study, resumable, on a process pool or Ray.

Stages (each in ``OUT/stages/NAME-KEY``, keyed by its configuration and its inputs):

1. ``compare``: DDPG, PPO, SAC, TD3 over seeds in the Fig. 2 scenario (paper Fig. 2).
2. ``experts-train``: a DDPG expert in each of the eight training scenarios.
3. ``experts-unseen``: a scenario-specific DDPG expert in each unseen scenario.
4. ``dataset``: the experts' deterministic trajectories as a Minari dataset.
5. ``pretrain``: the Decision Transformer, offline (Algorithm 1, stage 1).
6. ``finetune-unseenX``: elite online fine-tuning in each unseen scenario (stage 2).
7. ``evaluate-unseenX``: the expert, the zero-shot DT, the fine-tuned DT and the DDPG
   experts of the nearest training scenarios (transferred), all on the same seeded
   evaluation episodes (paper Fig. 3).
8. ``report``: figures and ``OUT/report.md`` with every number read from the stage files.
"""

from __future__ import annotations

import dataclasses
import shutil
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uavris.config import SCENARIOS, TRAINING_SCENARIOS, UNSEEN_SCENARIOS, SystemConfig, get_scenario
from uavris.experiments.io import UavrisError, read_csv, read_json, write_csv, write_json
from uavris.experiments.jobs import BACKENDS, Job, JobResult, run_jobs
from uavris.experiments.stages import Pipeline, Stage, StageRecord
from uavris.experiments.training import PRESETS, TrainConfig, is_finished, preset_config

EVAL_SEED = 1_000_000
EVAL_EPISODES = {"smoke": 8, "quick": 32, "paper": 100}
COMPARE_SEEDS = {"smoke": 2, "quick": 5, "paper": 5}
TRAJECTORIES = {"smoke": 4, "quick": 100, "paper": 500}  # per training scenario (paper: 500)
TRANSFER_NEIGHBOURS = 2


@dataclasses.dataclass(frozen=True)
class ReproduceConfig:
    """Everything that determines the study (dumped into the report)."""

    preset: str = "quick"
    seed: int = 0
    compare_seeds: int | None = None
    eval_episodes: int | None = None
    trajectories: int | None = None
    system: SystemConfig = dataclasses.field(default_factory=SystemConfig)

    def __post_init__(self) -> None:
        if self.preset not in PRESETS:
            raise UavrisError(f"unknown preset {self.preset!r}; choose one of {', '.join(PRESETS)}")
        for name in ("compare_seeds", "eval_episodes", "trajectories"):
            v = getattr(self, name)
            if v is not None and v < 1:
                raise UavrisError(f"--{name.replace('_', '-')} must be >= 1, got {v}")

    @property
    def n_compare_seeds(self) -> int:
        return self.compare_seeds or COMPARE_SEEDS[self.preset]

    @property
    def n_eval(self) -> int:
        return self.eval_episodes or EVAL_EPISODES[self.preset]

    @property
    def n_trajectories(self) -> int:
        return self.trajectories or TRAJECTORIES[self.preset]


def nearest_training_scenarios(scenario: str, k: int = TRANSFER_NEIGHBOURS) -> list[str]:
    """The ``k`` training scenarios whose start is closest to ``scenario``'s (ties by name)."""
    start = np.asarray(get_scenario(scenario).start)
    dist = {s: float(np.linalg.norm(np.asarray(SCENARIOS[s].start) - start)) for s in TRAINING_SCENARIOS}
    return sorted(dist, key=lambda s: (round(dist[s], 9), s))[:k]


# ------------------------------------------------------------------------------------------ jobs
def expert_job(cfg_dict: dict[str, Any], run_dir: str) -> dict[str, Any]:
    """Worker entry point: train (or resume) one DDPG expert."""
    from uavris.experiments.compare import train_job

    return train_job(cfg_dict, run_dir)


def _expert_configs(rc: ReproduceConfig, scenarios: Sequence[str]) -> dict[str, TrainConfig]:
    return {s: preset_config("ddpg", s, rc.seed, rc.preset, eval_episodes=rc.n_eval, system=rc.system)
            for s in scenarios}


def _run_experts(stage_dir: Path, cfgs: dict[str, TrainConfig], ctx: "_Context") -> dict[str, Any]:
    jobs = [Job(f"ddpg-{s}", expert_job, (cfg.to_dict(), str(stage_dir / "runs" / s)), stage_dir / "logs" / f"{s}.log")
            for s, cfg in cfgs.items() if not is_finished(stage_dir / "runs" / s)]
    failures = ctx.run_jobs(jobs)
    if failures:
        raise UavrisError(f"{len(failures)} expert job(s) failed: "
                          + "; ".join(f"{f.name} ({f.error}; log {f.log})" for f in failures))
    return {s: read_json(stage_dir / "runs" / s / "done.json")["final_eval"] for s in cfgs}


class _Context:
    """Backend and progress shared by the stages."""

    def __init__(self, workers: int, backend: str, ray_address: str | None, bar: Any) -> None:
        self.workers, self.backend, self.ray_address, self.bar = workers, backend, ray_address, bar
        self.failures: list[JobResult] = []

    def run_jobs(self, jobs: list[Job]) -> list[JobResult]:
        if self.bar is not None:
            self.bar.total += len(jobs)
            self.bar.refresh()

        def done(res: JobResult) -> None:
            if self.bar is not None:
                self.bar.update(1)
                self.bar.write(f"  job {res.name}: " + ("done" if res.ok else f"FAILED ({res.error}); log: {res.log}"))

        results = run_jobs(jobs, self.workers, done, backend=self.backend, ray_address=self.ray_address)
        failed = [r for r in results if not r.ok]
        self.failures += failed
        return failed


# ------------------------------------------------------------------------------------------ stages
def build_pipeline(rc: ReproduceConfig, out: Path, ctx: _Context) -> Pipeline:
    from uavris.experiments import dt_pipeline as dtp

    sys_dict = rc.system.to_dict()
    train_cfgs = _expert_configs(rc, TRAINING_SCENARIOS)
    unseen_cfgs = _expert_configs(rc, UNSEEN_SCENARIOS)

    def compare(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        from uavris.experiments.compare import compare_algorithms

        compare_algorithms(preset=rc.preset, seeds=rc.n_compare_seeds, workers=ctx.workers, out=d,
                           eval_episodes=rc.n_eval, backend=ctx.backend, ray_address=ctx.ray_address,
                           progress=False)
        return {"rows": read_json(d / "summary.json")["rows"]}

    def dataset(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        experts = [deps["experts-train"] / "runs" / s for s in TRAINING_SCENARIOS]
        path = dtp.collect(experts, rc.n_trajectories, d / "dataset", force=True, progress=ctx.bar is None)
        return dtp.dataset_summary(path)

    def pretrain(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
        cfg = dtp.pretrain_config(deps["dataset"] / "dataset", rc.preset, rc.seed)
        dtp.pretrain(cfg, d / "model", resume=(d / "model").exists(), progress=False)
        return read_json(d / "model" / "done.json")

    def finetune(scenario: str):
        def run(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
            cfg = dtp.finetune_config(deps["pretrain"] / "model", scenario, rc.preset, rc.seed,
                                      eval_episodes=rc.n_eval)
            dtp.finetune(cfg, d / "model", resume=(d / "model").exists(), progress=False)
            return read_json(d / "model" / "done.json")
        return run

    def evaluate_unseen(scenario: str):
        def run(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
            return evaluate_policies(d, scenario, rc, deps)
        return run

    stages = [
        Stage("compare", {"preset": rc.preset, "seeds": rc.n_compare_seeds, "eval_episodes": rc.n_eval,
                          "system": sys_dict}, compare),
        Stage("experts-train", {s: c.to_dict() for s, c in train_cfgs.items()},
              lambda d, deps: _run_experts(d, train_cfgs, ctx)),
        Stage("experts-unseen", {s: c.to_dict() for s, c in unseen_cfgs.items()},
              lambda d, deps: _run_experts(d, unseen_cfgs, ctx)),
        Stage("dataset", {"trajectories": rc.n_trajectories, "seed": dtp.COLLECT_SEED}, dataset, ("experts-train",)),
        Stage("pretrain", dataclasses.asdict(dtp.pretrain_config("<dataset>", rc.preset, rc.seed)), pretrain,
              ("dataset",)),
    ]
    for s in UNSEEN_SCENARIOS:
        ft = dataclasses.asdict(dtp.finetune_config("<pretrain>", s, rc.preset, rc.seed, eval_episodes=rc.n_eval))
        stages.append(Stage(f"finetune-{s}", ft, finetune(s), ("pretrain",)))
    for s in UNSEEN_SCENARIOS:
        stages.append(Stage(f"evaluate-{s}", {"episodes": rc.n_eval, "seed": EVAL_SEED, "oracle": True,
                                              "transfer_from": nearest_training_scenarios(s)},
                            evaluate_unseen(s), ("experts-train", "experts-unseen", "pretrain", f"finetune-{s}")))
    return Pipeline(out, stages)


def evaluate_policies(d: Path, scenario: str, rc: ReproduceConfig, deps: dict[str, Path]) -> dict[str, Any]:
    """All four kinds of policy on the same seeded episodes of ``scenario``; per-episode CSVs."""
    from uavris.agents.dt_policy import dt_policy_from_checkpoint
    from uavris.agents.evaluation import evaluate
    from uavris.agents.experts import sb3_batch_policy
    from uavris.agents.oracle import oracle_policy
    from uavris.experiments.evaluate import write_results
    from uavris.experiments.stats import summarize
    from uavris.experiments.training import configure_torch_threads, final_model_path, load_model

    configure_torch_threads()
    policies: dict[str, tuple[str, Any]] = {}
    expert_dir = deps["experts-unseen"] / "runs" / scenario
    policies["expert"] = ("DDPG expert", sb3_batch_policy(load_model(final_model_path(expert_dir), "ddpg")))
    policies["dt-zero-shot"] = ("zero-shot DT", dt_policy_from_checkpoint(deps["pretrain"] / "model")[0])
    policies["dt-finetuned"] = ("fine-tuned DT", dt_policy_from_checkpoint(deps[f"finetune-{scenario}"] / "model")[0])
    for src in nearest_training_scenarios(scenario):
        model = load_model(final_model_path(deps["experts-train"] / "runs" / src), "ddpg")
        policies[f"transfer-{src}"] = (f"DDPG transferred from {src}", sb3_batch_policy(model))
    policies["oracle"] = ("oracle (reference)", oracle_policy())
    out: dict[str, Any] = {}
    for key, (label, policy) in policies.items():
        res = evaluate(policy, rc.system, scenario, rc.n_eval, EVAL_SEED)
        summary = {"policy": key, "label": label, "scenario": scenario, **res.summary(),
                   **{f"boot_{k}": v for k, v in summarize(res.avg_sum_rate).items()}}
        write_results(res, summary, d / key)
        out[key] = summary
    return out


# ------------------------------------------------------------------------------------------ entry point
def reproduce(rc: ReproduceConfig, out: str | Path, *, workers: int = 2, backend: str = "local",
              ray_address: str | None = None, force: Sequence[str] = (), progress: bool = True) -> Path:
    """Run (or resume) the whole study into ``out``; returns the report path.

    Raises :class:`UavrisError` at the end when any job or stage failed (after writing the
    report of everything that finished).
    """
    if backend not in BACKENDS:
        raise UavrisError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if workers < 1:
        raise UavrisError(f"--workers must be >= 1, got {workers}")
    out = Path(out)
    from tqdm.auto import tqdm

    ctx = _Context(workers, backend, ray_address, None)
    pipeline = build_pipeline(rc, out, ctx)
    unknown = [f for f in force if f not in pipeline.stages and f != "report"]
    if unknown:
        raise UavrisError(f"--force names unknown stage(s) {unknown}; stages: {list(pipeline.stages) + ['report']}")
    bar = tqdm(total=0, unit="step", desc="reproduce", dynamic_ncols=True, disable=not progress)
    ctx.bar = bar
    bar.total += len(pipeline.stages) + 1
    bar.refresh()

    def on_stage(rec: StageRecord) -> None:
        bar.update(1)
        extra = f" ({rec.error})" if rec.error else ""
        bar.write(f"stage {rec.name} [{rec.key}]: {rec.status} in {rec.wall_s / 60:.1f} min{extra}")

    t0 = time.perf_counter()
    records = pipeline.run(tuple(f for f in force if f != "report"), on_stage)
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


def copy_latest(src: Path, dst: Path) -> None:
    """Copy a file into the report folder (figures referenced by report.md)."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dst)


__all__ = ["ReproduceConfig", "nearest_training_scenarios", "reproduce", "write_csv", "read_csv"]
