"""The stages of one track of the study: experts, dataset, pre-training, fine-tuning, evaluation.

Lives here: :func:`expert_stages` and :func:`dt_stages`, which turn a track
(:class:`uavris.experiments.study.Track`: its parameters) and the study's configuration into
the pipeline's stages, with their configurations (the stage keys), dependencies and expected
costs. Not here: the pipeline itself and its entry point (:mod:`.reproduce`), the work each
stage's jobs do (:mod:`.study`), the job runner (:mod:`.jobs`, :mod:`.scheduling`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

from uavris import runs
from uavris.agents.experts import ALGORITHMS
from uavris.errors import UavrisError
from uavris.experiments.costs import (
    dataset_cost,
    demonstration_cost,
    evaluate_cost,
    finetune_cost,
    pretrain_cost,
    train_cost,
)
from uavris.experiments.jobs import Job
from uavris.experiments.scheduling import StudyContext
from uavris.experiments.stages import Stage
from uavris.experiments.study import (
    Deployment,
    Track,
    dataset_job,
    demonstrations_job,
    evaluate_job,
    evaluated_policies,
    finetune_job,
    merge_demonstrations,
    pretrain_job,
    pretraining_stages,
    strong_expert_config,
    transfer_sources,
)
from uavris.experiments.train_expert import TrainConfig, preset_config, train_job
from uavris.io import read_json
from uavris.presets import COLLECT_SEED, DEMONSTRATION_CHUNK, EVAL_SEED

if TYPE_CHECKING:
    from uavris.experiments.reproduce import ReproduceConfig

AUTO = "auto"


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


def expert_stages(rc: ReproduceConfig, track: Track, ctx: StudyContext) -> list[Stage]:
    """Experts of the training (and, where the track has them, the unseen) deployments of ``track``."""
    train, unseen = rc.deployments(track)
    stages = []
    for name, where in (("experts-train", train if not track.demonstrations else []),
                        ("experts-unseen", unseen if track.unseen_experts else [])):
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


def _dataset_stages(rc: ReproduceConfig, track: Track, ctx: StudyContext, train: list[Deployment]) -> list[Stage]:
    """The track's dataset: its experts' trajectories, or the planning oracle's demonstrations in
    its training halls (jobs of :data:`DEMONSTRATION_CHUNK` halls, each a finished part on disk
    that a rerun reuses), and, with the ablation, the mixed-quality demonstrations."""
    from uavris.experiments.demonstrations import DemonstrationConfig

    t, horizon, control = track.stage, rc.system.horizon, track.phase_control
    episodes = rc.trajectories_for(track)
    if not track.demonstrations:
        def collect(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
            experts = [str(deps[t("experts-train")] / "runs" / w.name) for w in train]
            return ctx.run_one(t("dataset"), dataset_job, (experts, episodes, str(d / "dataset")), d / "job.log",
                               dataset_cost(len(train) * episodes, horizon, control))

        return [Stage(t("dataset"), {"trajectories": episodes, "seed": COLLECT_SEED}, collect, (t("experts-train"),),
                      (dataset_cost(len(train) * episodes, horizon, control),))]

    def demonstrations(name: str, cfg: DemonstrationConfig) -> Stage:
        chunks = [(first, min(DEMONSTRATION_CHUNK, cfg.halls - first))
                  for first in range(0, cfg.halls, DEMONSTRATION_CHUNK)]
        costs = tuple(demonstration_cost(n, cfg.episodes * len(cfg.behaviours), horizon) for _, n in chunks)

        def run(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
            parts = [d / "parts" / f"halls-{first}" for first, _ in chunks]
            jobs = [Job(f"halls-{first}", demonstrations_job, (cfg.to_dict(), first, n, str(part)),
                        d / "logs" / f"halls-{first}.log", cost)
                    for (first, n), part, cost in zip(chunks, parts, costs) if not part.exists()]
            failures = [r for r in ctx.submit(t(name), jobs) if not r.ok]
            if failures:
                raise UavrisError(f"{len(failures)} demonstration job(s) failed: "
                                  + "; ".join(f"{f.name} ({f.error}; log {f.log})" for f in failures))
            return ctx.run_one(t(name), merge_demonstrations, (cfg.to_dict(), [str(p) for p in parts],
                                                                 str(d / "dataset")), d / "merge.log", 1.0)

        return Stage(t(name), cfg.to_dict(), run, (), costs)

    system = rc.system.replace(observe_devices=True)
    oracle = DemonstrationConfig(halls=len(train), episodes=episodes, layout_seed=rc.layout_seed, system=system)
    stages = [demonstrations("dataset", oracle)]
    if track.ablation:
        stages.append(demonstrations("dataset-mixed", dataclasses.replace(
            oracle, halls=min(rc.n_mixed_layouts, len(train)), quality="mixed")))
    return stages


def dt_stages(rc: ReproduceConfig, track: Track, ctx: StudyContext) -> list[Stage]:
    """Dataset, pre-training (the DT, behaviour cloning, the data curve and, with the ablation,
    its rows over several seeds), fine-tuning and evaluation of ``track``."""
    from uavris.experiments.finetune import finetune_config
    from uavris.experiments.pretrain import pretrain_config

    t = track.stage
    train, unseen = rc.deployments(track)
    horizon, control = rc.system.horizon, track.phase_control

    schedule = dict(track.pretrain)
    preset_cfg = pretrain_config("<dataset>", rc.preset, rc.seed)
    for size in ("context", "width", "depth"):  # a track's smaller model never grows a preset's (smoke's is tiny)
        if size in schedule:
            schedule[size] = min(schedule[size], getattr(preset_cfg, size))
    context = schedule.get("context", preset_cfg.context)  # what the pre-trained and fine-tuned models read
    models = pretraining_stages(track, schedule, [w.name for w in train], rc.scaling_points,
                                rc.n_dt_seeds if track.ablation else 1)

    def model_config(data: Path | str, overrides: dict[str, Any]):
        seed = rc.seed + overrides.get("seed", 0)
        return pretrain_config(data, rc.preset, seed, **{k: v for k, v in overrides.items() if k != "seed"})

    def pretrain(name: str, data: str, overrides: dict[str, Any]):
        def run(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
            cfg = model_config(deps[t(data)] / "dataset", overrides)
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

    inputs = [*(["experts-train"] if not track.demonstrations else []),
              *(["experts-unseen"] if track.unseen_experts else []), *models]

    def evaluate(where: Deployment, sources: list[tuple[str, float]]):
        keys = [*inputs, f"finetune-{where.name}"]
        cost = evaluate_cost(len(evaluated_policies(track, where, sources, {k: Path() for k in keys}, train)),
                             rc.n_eval, horizon, control)

        def run(d: Path, deps: dict[str, Path]) -> dict[str, Any]:
            policies = evaluated_policies(track, where, sources, {k: deps[t(k)] for k in keys}, train)
            return ctx.run_one(t(f"evaluate-{where.name}"), evaluate_job,
                               (str(d), where.to_dict(), track.name, rc.n_eval, policies), d / "job.log", cost)
        return run, keys, cost

    stages = _dataset_stages(rc, track, ctx, train)
    for name, (data, overrides) in models.items():
        cfg = model_config("<dataset>", overrides)
        stages.append(Stage(t(name), dataclasses.asdict(cfg), pretrain(name, data, overrides), (t(data),),
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
