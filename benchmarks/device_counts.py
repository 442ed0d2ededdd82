"""One Decision Transformer for any number of devices: the deployment DT in unseen halls of
3 to 8 devices, trained on 4-device halls only and on halls of mixed counts.

The device-set encoder has no weight whose shape depends on the number of devices K (one
network per device and per pair, pooled; ``uavris.agents.dt.encoders``), so a model trained
on halls of K devices reads halls of any other count, and one model trains on halls of
several counts (``PretrainConfig.more_datasets``: each batch from one count). This script
measures both, on the deployment track's protocol:

1. the planning oracle's demonstrations in ``--halls`` generated training halls of each
   other count (``LayoutGenerator(devices=K)``, train split, 2 episodes each), beside the
   study's 512 four-device halls (the finished quick run's dataset, ``--run``);
2. the deployment model (the track's size and learning rate) pre-trained on all of them,
   one model per seed (``--seeds``), the quick preset's 1,500 steps;
3. in ``--unseen`` unseen halls of each count (unseen split, never trained on), the same
   seeded episodes for every policy: the run's 4-device DTs (the same seeds), the mixed-count
   DTs, hovering with optimised phases and the oracle, the DTs under the attitude safety
   layer as in the report's main rows, beside the zero action (hover, level, equal phases).

Prints per count the fraction of the oracle (mean of the seeds per hall, then mean and 95%
CI over halls) and the paired difference mixed - 4-only over halls; writes the table to
``OUT/device_counts.md``. Rerunning reuses the datasets, models and hall results it finds.

Run on an otherwise idle machine after ``make run`` (about 25 minutes on 2 cores)::

    .venv/bin/python benchmarks/device_counts.py --run runs/quick
"""

from __future__ import annotations

import argparse
import json
import os
import re
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from _machine import cpu_model, table  # noqa: E402  (benchmarks/_machine.py)

EPISODE_SEED = 1_000_000  # the study's evaluation seeds (uavris.presets.EVAL_SEED)


def base_system(devices: int):
    """The deployment track's system with a generated hall of ``devices`` devices (its users
    only set the count: every episode's hall replaces them)."""
    from uavris.config import SystemConfig
    from uavris.layouts import LayoutGenerator

    system = SystemConfig(observe_devices=True)
    return LayoutGenerator(devices=devices).layout("train", 0).resolve(system)[0]


def demonstrations_job(devices: int, halls: int, first: int, count: int, out: str) -> None:
    import pickle

    from uavris.experiments.training.demonstrations import DemonstrationConfig, demonstrate

    cfg = DemonstrationConfig(halls=halls, system=base_system(devices))
    trajectories = demonstrate(cfg, first, count)
    Path(out).write_bytes(pickle.dumps(trajectories))


def merge_job(devices: int, halls: int, parts: list[str], out: str) -> None:
    import pickle

    from uavris.experiments.training.demonstrations import DemonstrationConfig, collect_demonstrations

    cfg = DemonstrationConfig(halls=halls, system=base_system(devices))
    trajectories = [tr for p in parts for tr in pickle.loads(Path(p).read_bytes())]
    collect_demonstrations(cfg, out, trajectories=trajectories, progress=False)


def pretrain_job(config: dict, out: str) -> None:
    from uavris.experiments.training.pretrain import PretrainConfig, pretrain

    pretrain(PretrainConfig.from_dict(config), out, progress=False)


def evaluate_job(devices: int, hall: int, models: dict[str, list[str]], margin: float, episodes: int,
                 out: str) -> None:
    """Every policy in unseen hall ``hall`` of ``devices`` devices: the episodes' mean sum rates."""
    from uavris.agents.evaluation import evaluate
    from uavris.agents.references import HOVER_OPTIMIZER, ORACLE, REFERENCE_SEED, ZERO_ACTION, reference_policy
    from uavris.experiments.training.dt_runs import load_dt_policy
    from uavris.layouts import LayoutGenerator

    layout = LayoutGenerator(devices=devices).layout("unseen", hall)
    system, where = layout.resolve(base_system(devices))
    safe = system.replace(front_margin_deg=margin)
    rates = {}
    for name in (ZERO_ACTION, HOVER_OPTIMIZER, ORACLE):
        rates[name] = evaluate(reference_policy(name, system, REFERENCE_SEED), system, where, episodes,
                               EPISODE_SEED).avg_sum_rate.tolist()
    for name, paths in models.items():
        per_seed = []
        for p in paths:
            policy = load_dt_policy(p)[0]
            per_seed.append(evaluate(policy, safe, where, episodes, EPISODE_SEED).avg_sum_rate.tolist())
        rates[name] = per_seed
    Path(out).write_text(json.dumps({"hall": layout.name, "rates": rates}))


def run(jobs: list, workers: int, what: str) -> None:
    from uavris.experiments.engine.jobs import run_jobs

    failed = [r for r in run_jobs(jobs, workers) if not r.ok]
    if failed:
        raise SystemExit(f"{what}: {failed[0].name} failed: {failed[0].error}")


def finished_stage(stages: Path, name: str) -> Path:
    found = [d for d in stages.glob(f"{name}-*") if re.fullmatch(rf"{name}-[0-9a-f]{{12}}", d.name)]
    if len(found) != 1:
        raise SystemExit(f"{stages.parent}: no finished stage {name} (run make run first)")
    return found[0]


def collect(args: argparse.Namespace) -> dict[int, Path]:
    """Step 1: the other counts' demonstration datasets, built in parts of 8 halls."""
    from uavris.experiments.engine.jobs import Job

    datasets, jobs, merges = {}, [], []
    for k in args.counts:
        d = args.out / f"demonstrations-k{k}"
        datasets[k] = d / "dataset"
        if datasets[k].exists():
            continue
        d.mkdir(parents=True, exist_ok=True)
        parts = []
        for first in range(0, args.halls, 8):
            part = d / f"part-{first}.pkl"
            parts.append(str(part))
            if not part.exists():
                jobs.append(Job(f"demonstrations-k{k}-{first}", demonstrations_job,
                                (k, args.halls, first, min(8, args.halls - first), str(part)),
                                d / f"part-{first}.log", cost=float(k * k)))
        merges.append(Job(f"merge-k{k}", merge_job, (k, args.halls, parts, str(datasets[k])), d / "merge.log"))
    run(jobs, args.workers, "demonstrations")
    run(merges, args.workers, "merge")
    return datasets


def train(args: argparse.Namespace, four: Path, datasets: dict[int, Path]) -> dict[int, Path]:
    """Step 2: the mixed-count models, one per seed, the deployment track's model and schedule."""
    from uavris.experiments.engine.jobs import Job
    from uavris.experiments.study.tracks import TRACK_SPECS

    track = dict(TRACK_SPECS["deployment"].pretrain)
    mixed, jobs = {}, []
    for s in range(args.seeds):
        d = args.out / f"pretrain-mixed-s{s}"
        mixed[s] = d  # the run directory holds the model (model.json, its weights)
        cfg = {"dataset": str(four), "more_datasets": [str(datasets[k]) for k in args.counts], "preset": "quick",
               "seed": s, **track}
        if not (mixed[s] / "model.json").exists():
            jobs.append(Job(f"pretrain-mixed-s{s}", pretrain_job, (cfg, str(d)), args.out / f"pretrain-mixed-s{s}.log"))
    run(jobs, args.workers, "pre-training")
    return mixed


def evaluate_all(args: argparse.Namespace, models: dict[str, list[str]], counts: list[int]) -> dict:
    """Step 3: every count's unseen halls, one job per hall."""
    from uavris.experiments.engine.jobs import Job
    from uavris.experiments.study.tracks import SAFE_MARGIN_DEG

    jobs, files = [], {}
    for k in counts:
        for j in range(args.unseen):
            f = args.out / "halls" / f"k{k}-unseen-{j}.json"
            files[k, j] = f
            if not f.exists():
                f.parent.mkdir(parents=True, exist_ok=True)
                jobs.append(Job(f"evaluate-k{k}-{j}", evaluate_job,
                                (k, j, models, SAFE_MARGIN_DEG, args.episodes, str(f)), f.with_suffix(".log"),
                                cost=float(k * k)))
    run(jobs, args.workers, "evaluation")
    return files


def summary_row(k: int, results: list[dict]) -> tuple[str, ...]:
    """One count: each policy's fraction of the oracle over halls, and the paired difference."""
    import numpy as np

    from uavris.agents.references import HOVER_OPTIMIZER, ORACLE, ZERO_ACTION
    from uavris.stats import over_units

    fractions: dict[str, list[float]] = {ZERO_ACTION: [], "dt-4": [], "dt-mixed": [], HOVER_OPTIMIZER: []}
    for r in results:
        oracle = float(np.mean(r[ORACLE]))
        for name in (ZERO_ACTION, HOVER_OPTIMIZER):
            fractions[name].append(float(np.mean(r[name])) / oracle)
        for name in ("dt-4", "dt-mixed"):
            fractions[name].append(float(np.mean([np.mean(seed) for seed in r[name]])) / oracle)
    cells = [f"{np.mean([np.mean(r[ORACLE]) for r in results]):.2f}"]
    for values in fractions.values():
        s = over_units(values)
        cells.append(f"{s['mean']:.1%} [{s['ci_low']:.1%}, {s['ci_high']:.1%}] (worst {min(values):.1%})")
    d = over_units([m - f for m, f in zip(fractions["dt-mixed"], fractions["dt-4"])])
    cells.append(f"{100 * d['mean']:+.1f} [{100 * d['ci_low']:+.1f}, {100 * d['ci_high']:+.1f}]")
    return (str(k), *cells)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", type=Path, default=Path("runs/quick"), help="a finished quick run (make run)")
    parser.add_argument("--counts", type=int, nargs="+", default=[3, 5, 6, 8], help="other device counts")
    parser.add_argument("--halls", type=int, default=96, help="training halls per other count")
    parser.add_argument("--unseen", type=int, default=16, help="unseen halls per count")
    parser.add_argument("--episodes", type=int, default=8, help="episodes per hall and policy")
    parser.add_argument("--seeds", type=int, default=3, help="pre-training seeds")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("runs/device-counts"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    stages = args.run / "stages"
    four = finished_stage(stages, "deploy-dataset") / "dataset"
    single = [str(finished_stage(stages, "deploy-pretrain" + ("" if s == 0 else f"-s{s}")) / "model")
              for s in range(args.seeds)]
    t0 = time.perf_counter()
    datasets = collect(args)
    t_data = time.perf_counter() - t0
    mixed = train(args, four, datasets)
    t_train = time.perf_counter() - t0 - t_data
    counts = sorted({4, *args.counts})
    files = evaluate_all(args, {"dt-4": single, "dt-mixed": [str(mixed[s]) for s in range(args.seeds)]}, counts)
    t_eval = time.perf_counter() - t0 - t_data - t_train
    rows = [summary_row(k, [json.loads(files[k, j].read_text())["rates"] for j in range(args.unseen)])
            for k in counts]
    header = ("devices K", "oracle (bps/Hz)", "zero action", "DT trained on K = 4, safety layer",
              f"DT trained on K = {', '.join(map(str, counts))}, safety layer", "hovering, optimised phases",
              "mixed - 4-only (points)")
    text = (f"Fraction of the oracle in {args.unseen} unseen halls per count ({args.episodes} episodes each, mean of "
            f"{args.seeds} pre-training seeds per hall; mean [95% CI over halls] (worst hall)). Training: the quick "
            f"run's 512 four-device halls, plus {args.halls} halls of each of K = {', '.join(map(str, args.counts))} "
            f"for the mixed model. Machine: {cpu_model()}, {args.workers} workers; demonstrations {t_data / 60:.1f} "
            f"min, pre-training {t_train / 60:.1f} min, evaluation {t_eval / 60:.1f} min (this invocation).\n\n"
            + table([header, *rows]))
    (args.out / "device_counts.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
