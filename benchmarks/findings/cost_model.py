"""How far the cost model was from a finished `uavris reproduce` run's job times, stage family by family.

Feeds docs/timings.md.

(And the unit costs of :mod:`uavris.experiments.engine.costs`, recalibrated from it.)

``reproduce`` records every job's expected cost (seconds of one core, the cost model's) and its
start and end in ``OUT/schedule.json``. This prints, per stage family (a stage's name without
its track prefix, hall, seed or data-curve suffix: ``experts-train``, ``deploy-evaluate``, ...),
the jobs, the expected and the measured core-minutes and their ratio, the measured share of the
whole, and the worst family's factor (max of measured/expected and expected/measured).

    .venv/bin/python benchmarks/findings/cost_model.py runs/quick          # the model the run used
    .venv/bin/python benchmarks/findings/cost_model.py runs/quick --now    # this version's model
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

# what makes a stage one of many of its family: a hall's or a scenario's name, a seed, a curve point
_SUFFIX = re.compile(r"-(layout-(train|unseen|other)-\d+(-k\d+)?|unseen\d|fig\d|train\d+|s\d+|n\d+)$")


def family(stage: str) -> str:
    """``deploy-evaluate-layout-unseen-3-k6`` -> ``deploy-evaluate``; ``strong-finetune-unseen1`` ->
    ``strong-finetune``; ``deploy-goal-s2`` -> ``deploy-goal``."""
    name = stage
    while True:
        shorter = _SUFFIX.sub("", name)
        if shorter == name:
            return name
        name = shorter


def _expected_now(run: Path) -> dict[str, float]:
    """Each stage's expected seconds by this version's cost model (the run's own study, opened)."""
    from uavris.experiments.study.finished import Study

    stages = Study.open(run).pipeline.stages
    return {name: (st.progress_s if st.progress_s is not None else sum(st.costs)) for name, st in stages.items()}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="the output folder of a finished reproduce run")
    ap.add_argument("--now", action="store_true",
                    help="expected by this version's cost model, not the one the run recorded (a recalibration)")
    args = ap.parse_args(argv)
    sched = json.loads((args.run / "schedule.json").read_text())
    now = _expected_now(args.run) if args.now else None
    fams: dict[str, dict[str, float]] = {}
    for j in sched["jobs"]:
        f = fams.setdefault(family(j["stage"]), {"jobs": 0, "expected": 0.0, "measured": 0.0})
        f["jobs"] += 1
        f["measured"] += j["end"] - j["start"]
        if now is None:
            f["expected"] += j["cost"]
    if now is not None:
        for stage in {j["stage"] for j in sched["jobs"]}:
            fams[family(stage)]["expected"] += now.get(stage, 0.0)
    total = sum(f["measured"] for f in fams.values())
    wall = max(j["end"] for j in sched["jobs"]) - min(j["start"] for j in sched["jobs"])
    print(f"run {args.run}: {len(sched['jobs'])} jobs, {total / 60:.1f} core-minutes, {wall / 60:.1f} min of wall "
          f"clock on {sched['workers']} worker(s)\n")
    print("| stage family | jobs | expected (core-min) | measured (core-min) | measured / expected | share |")
    print("|---|---:|---:|---:|---:|---:|")
    worst = (1.0, "")
    for name, f in sorted(fams.items(), key=lambda kv: -kv[1]["measured"]):
        ratio = f["measured"] / f["expected"] if f["expected"] > 0 else float("inf")
        factor = max(ratio, 1 / ratio) if ratio > 0 else float("inf")
        worst = max(worst, (factor, name))
        print(f"| {name} | {f['jobs']:.0f} | {f['expected'] / 60:.1f} | {f['measured'] / 60:.1f} | {ratio:.2f} | "
              f"{f['measured'] / total:.1%} |")
    expected = sum(f["expected"] for f in fams.values())
    print(f"| all | {len(sched['jobs'])} | {expected / 60:.1f} | {total / 60:.1f} | {total / expected:.2f} | 100% |")
    print(f"\nworst family: {worst[1]}, off by {worst[0]:.2f}x")


if __name__ == "__main__":
    main()
