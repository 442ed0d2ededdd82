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
    .venv/bin/python benchmarks/findings/cost_model.py runs/quick --fit    # unit costs fitted to the run

``--now`` and ``--fit`` build the run's study with the experts' algorithm its comparison chose
(read from the comparison's ``summary.json``; ``--expert-algo`` overrides it), as the run itself
did once the comparison had ended. ``--fit``: every expected cost is a sum of unit costs times amounts of work,
so doubling one group of unit costs (the SB3 step, the simulated slot, the plans, the planner's
poses, the DT's step, the value's step) and rebuilding the study gives each stage's part of it;
the scale of each group that makes the stages' expected seconds closest to the measured ones in
relative terms (non-negative least squares, each stage weighted by 1 / its measured seconds) is
printed with the unit costs it gives.
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


# the unit costs of uavris.experiments.engine.costs, in the groups --fit scales together
GROUPS = {
    "SB3 env step": ("SB3_STEP_S",),
    "simulated slot": ("SLOT_S", "IMITATION_SLOT_S"),
    "plan of a hall": ("PLAN_S", "TEACHER_PLAN_S", "ORACLE_PLAN_S"),
    "planner's pose": ("POSE_S",),
    "DT step": ("DT_STEP_S", "DT_STEP_OVERHEAD_S", "DEVICE_ENCODER_STATE_S"),
    "value step": ("VALUE_STEP_S",),
}


def _scaled(value, factor: float):
    if isinstance(value, dict):
        return {k: _scaled(v, factor) for k, v in value.items()}
    return value * factor


def _expected_now(run: Path, expert_algo: str | None = None) -> dict[str, float]:
    """Each stage's expected seconds by this version's cost model (the run's own study, with the
    experts' algorithm the comparison chose, or ``expert_algo``)."""
    import dataclasses

    from uavris.experiments.engine.scheduling import StudyContext
    from uavris.experiments.study.finished import Study
    from uavris.experiments.study.pipeline import build_pipeline
    from uavris.experiments.study.stage_names import COMPARE

    study = Study.open(run)
    rc = study.config
    if rc.expert_algo == "auto":
        compare = study.done(COMPARE)
        chosen = [json.loads((compare / "summary.json").read_text())["expert"]] if compare is not None else []
        if expert_algo is None and len(set(chosen)) != 1:
            raise SystemExit(f"{run}: no finished comparison says which algorithm the experts are; pass --expert-algo")
        rc = dataclasses.replace(rc, expert_algo=expert_algo or chosen[0])
    stages = build_pipeline(rc, run, StudyContext(1, "local", None)).stages
    return {name: (st.progress_s if st.progress_s is not None else sum(st.costs)) for name, st in stages.items()}


def fit(run: Path, measured: dict[str, float], expert_algo: str | None) -> None:
    """Print the scale of each group of unit costs (:data:`GROUPS`) that fits ``measured`` (seconds per stage)."""
    import numpy as np
    from scipy.optimize import nnls

    from uavris.experiments.engine import costs

    names = sorted(measured)
    base = _expected_now(run, expert_algo)
    parts = []
    for group in GROUPS.values():
        kept = {name: getattr(costs, name) for name in group}
        try:
            for name, value in kept.items():
                setattr(costs, name, _scaled(value, 2.0))
            doubled = _expected_now(run, expert_algo)
        finally:
            for name, value in kept.items():
                setattr(costs, name, value)
        parts.append([doubled.get(n, 0.0) - base.get(n, 0.0) for n in names])
    a = np.array(parts).T  # (stages, groups): each group's seconds in each stage
    rest = np.array([base.get(n, 0.0) for n in names]) - a.sum(axis=1)
    y = np.array([measured[n] for n in names])
    w = 1.0 / np.maximum(y, 1.0)
    scale, _ = nnls(a * w[:, None], (y - rest) * w)
    print("\n| group of unit costs | expected core-min in this run | scale fitted |\n|---|---:|---:|")
    for (group, units), col, s in zip(GROUPS.items(), a.T, scale):
        print(f"| {group} ({', '.join(units)}) | {col.sum() / 60:.1f} | {s:.2f} |")
    print("\nunit costs they give:")
    for units, s in zip(GROUPS.values(), scale):
        for name in units:
            print(f"  {name} = {_scaled(getattr(costs, name), float(s))!r}")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="the output folder of a finished reproduce run")
    ap.add_argument("--now", action="store_true",
                    help="expected by this version's cost model, not the one the run recorded (a recalibration)")
    ap.add_argument("--fit", action="store_true", help="fit the groups of unit costs to the run's stage times")
    ap.add_argument("--expert-algo", default=None,
                    help="with --now or --fit: the experts' algorithm (default: the one the run's comparison chose)")
    args = ap.parse_args(argv)
    sched = json.loads((args.run / "schedule.json").read_text())
    now = _expected_now(args.run, args.expert_algo) if args.now else None
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
    if args.fit:
        measured: dict[str, float] = {}
        for j in sched["jobs"]:
            measured[j["stage"]] = measured.get(j["stage"], 0.0) + j["end"] - j["start"]
        fit(args.run, measured, args.expert_algo)


if __name__ == "__main__":
    main()
