"""How `uavris reproduce` scales with workers: 1 and 2, local process pool vs Ray.

Two measurements, each configuration in a fresh temporary folder so nothing is skipped:

1. **Training jobs**, the part of the study that scales: ``--jobs`` DDPG runs (quick-preset
   hyperparameters, ``--steps`` env steps each, seeds 0..jobs-1, scenario ``fig2``) sent
   through ``uavris.experiments.engine.jobs.run_jobs``, the dispatcher the pipeline uses for
   algorithm x seed and scenario-expert jobs. Every job is minutes long in ``quick`` and
   hours in ``paper``, so this is the ratio that predicts the big presets.
2. **End to end**, ``reproduce --preset smoke``: seconds-long jobs, so it measures the
   fixed costs (process and Ray start-up, imports, sequential DT stages) rather than
   scaling.

The evaluation scores of the training jobs are compared across configurations: the same
seeds must give the same numbers whatever the backend or worker count.

Run on an otherwise idle machine (about 10 minutes on 2 cores)::

    .venv/bin/python benchmarks/reproduce_scaling.py
    .venv/bin/python benchmarks/reproduce_scaling.py --backends local --jobs 2 --steps 2000
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from _machine import cpu_model  # noqa: E402  (benchmarks/_machine.py)


def run_training_jobs(backend: str, workers: int, jobs: int, steps: int) -> tuple[float, list[float]]:
    """(wall clock s, final evaluation means in seed order)."""
    from uavris.experiments.engine.jobs import run_jobs
    from uavris.experiments.engine.worker import Job
    from uavris.experiments.training.train_expert import TrainConfig, train_job

    with tempfile.TemporaryDirectory(prefix=f"uavris-jobs-{backend}-{workers}-") as tmp:
        out = Path(tmp)
        todo = [Job(f"ddpg-s{s}", train_job,
                    (TrainConfig(algo="ddpg", scenario="fig2", seed=s, preset="quick", total_steps=steps,
                                 eval_every=steps,
                                   checkpoint_every=steps, eval_episodes=8).to_dict(), str(out / f"s{s}")),
                    out / "logs" / f"s{s}.log") for s in range(jobs)]
        t0 = time.perf_counter()
        results = run_jobs(todo, workers, backend=backend)
        wall = time.perf_counter() - t0
        failed = [r for r in results if not r.ok]
        if failed:
            raise SystemExit(f"job {failed[0].name} failed: {failed[0].error} (log {failed[0].log})")
        by_name = {r.name: r.value["final_eval"]["mean"] for r in results}
        return wall, [by_name[f"ddpg-s{s}"] for s in range(jobs)]


def run_smoke(backend: str, workers: int) -> float:
    from uavris.experiments.study.config import ReproduceConfig
    from uavris.experiments.study.reproduce import reproduce

    with tempfile.TemporaryDirectory(prefix=f"uavris-smoke-{backend}-{workers}-") as out:
        t0 = time.perf_counter()
        reproduce(ReproduceConfig("smoke"), out, workers=workers, backend=backend, progress=False)
        return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backends", nargs="+", default=["local", "ray"], choices=["local", "ray"])
    p.add_argument("--jobs", type=int, default=4, help="training jobs per configuration (default 4)")
    p.add_argument("--steps", type=int, default=8000, help="env steps per training job (default 8000)")
    p.add_argument("--no-smoke", action="store_true", help="skip the end-to-end smoke measurement")
    args = p.parse_args(argv)
    if args.jobs < 1 or args.steps < 1:
        p.error("--jobs and --steps must be >= 1")
    print(f"# reproduce scaling: 1 vs 2 workers\n\n- cpu: {cpu_model()}, {os.cpu_count()} cores\n"
          f"- command: {' '.join([sys.executable] + sys.argv)}\n")
    print(f"## {args.jobs} DDPG training jobs of {args.steps:,} env steps (quick hyperparameters)\n")
    print("| backend | workers | wall clock (s) | final scores (bps/Hz, seeds 0..) |\n|---|---:|---:|---|")
    times: dict[tuple[str, int], float] = {}
    scores: dict[tuple[str, int], list[float]] = {}
    for backend in args.backends:
        for workers in (1, 2):
            key = (backend, workers)
            times[key], scores[key] = run_training_jobs(backend, workers, args.jobs, args.steps)
            print(f"| {backend} | {workers} | {times[key]:.0f} | {', '.join(f'{x:.3f}' for x in scores[key])} |",
                  flush=True)
    print()
    for backend in args.backends:
        print(f"- {backend}: 2 workers / 1 worker speed-up = {times[(backend, 1)] / times[(backend, 2)]:.2f}x")
    same = all(v == next(iter(scores.values())) for v in scores.values())
    print(f"- same scores in every configuration: {'yes' if same else 'NO'}")
    if args.no_smoke:
        return
    print("\n## `reproduce --preset smoke` end to end\n")
    print("| backend | workers | wall clock (s) |\n|---|---:|---:|")
    smoke: dict[tuple[str, int], float] = {}
    for backend in args.backends:
        for workers in (1, 2):
            smoke[(backend, workers)] = run_smoke(backend, workers)
            print(f"| {backend} | {workers} | {smoke[(backend, workers)]:.0f} |", flush=True)
    print()
    for backend in args.backends:
        print(f"- {backend}: 2 workers / 1 worker speed-up = {smoke[(backend, 1)] / smoke[(backend, 2)]:.2f}x")


if __name__ == "__main__":
    main()
