"""How far the progress bar's ETA of a finished `uavris reproduce` run was from the truth.

Feeds docs/timings.md.

``reproduce`` records, once a minute, the ETA its bar showed (the replay of what is left,
:mod:`uavris.experiments.engine.forecast`) and tqdm's own rate-based ETA (the work left over the
rate so far) in ``OUT/schedule.json``; the run's true end is its last job's. This prints,
per sample after ``--after`` minutes, both ETAs against the truth, and the worst factor of
each (max of ETA/truth and truth/ETA): ours against tqdm's, measured in the same run.

    .venv/bin/python benchmarks/findings/progress_eta.py runs/quick
    .venv/bin/python benchmarks/findings/progress_eta.py runs/quick --replay   # this code's forecast too

``--replay`` computes, at each sample, the ETA this code's forecast would have shown from what
the schedule says had ended and was running then (the study's pipeline rebuilt from its
``study.yaml``; a stage's jobs known once its dependencies had ended): a change to the forecast
is judged on a recorded run without running it again.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path


def factor(eta: float | None, truth: float) -> float:
    if eta is None or eta <= 0 or truth <= 0:
        return math.inf
    return max(eta / truth, truth / eta)


def replayed_eta(run: Path, sched: dict, t: float) -> float:
    """The ETA this code's forecast gives at ``t`` seconds into the recorded run ``run``."""
    import uavris  # noqa: F401 - first: the float path (uavris.float_paths)
    from uavris.experiments.engine.forecast import Speeds, eta_seconds
    from uavris.experiments.study.finished import Study

    pipeline = Study.open(run).pipeline
    workers = sched["workers"]
    jobs = sched["jobs"]
    stage_end: dict[str, float] = {}
    for j in jobs:
        stage_end[j["stage"]] = max(stage_end.get(j["stage"], 0.0), j["end"])
    ended = {name for name, end in stage_end.items() if end <= t}
    speeds = Speeds()
    for j in sorted((j for j in jobs if j["end"] <= t), key=lambda j: j["end"]):
        speeds.add(j["stage"], j["cost"], j["end"] - j["start"])
    running = [(j["stage"], j["cost"], t - j["start"]) for j in jobs if j["start"] <= t < j["end"]]
    stages = {}
    for name, st in pipeline.stages.items():
        if name in ended or name not in stage_end:
            continue
        if all(d in ended for d in st.deps):  # open: its own jobs are known
            costs = tuple(j["cost"] for j in jobs if j["stage"] == name and j["start"] > t)
        else:
            costs = st.costs if st.progress_s is None or not sum(st.costs) else tuple(
                c * st.progress_s / sum(st.costs) for c in st.costs)
        stages[name] = (st.deps, costs)
    return eta_seconds(stages, pipeline.downstream(workers), workers, ended, running, speeds)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="the output folder of a finished reproduce run")
    ap.add_argument("--after", type=float, default=5.0, help="minutes of the run not judged (default 5)")
    ap.add_argument("--replay", action="store_true", help="also this code's forecast at each sample (module doc)")
    args = ap.parse_args(argv)
    sched = json.loads((args.run / "schedule.json").read_text())
    if not sched.get("eta"):
        raise SystemExit(f"{args.run / 'schedule.json'} has no ETA samples (a run older than the ETA record)")
    end = max(j["end"] for j in sched["jobs"])
    worst = {"ours": 1.0, "tqdm": 1.0, "replayed": 1.0}
    print(f"run {args.run}: {end / 60:.1f} min of jobs, {sched['workers']} worker(s)")
    print("| min | true min left | our ETA | factor | tqdm's ETA | factor |" + (" this code's ETA | factor |"
          if args.replay else "") + "\n|---:|---:|---:|---:|---:|---:|" + ("---:|---:|" if args.replay else ""))
    for sample in sched["eta"]:
        t, truth = sample["t"], end - sample["t"]
        if t < args.after * 60 or truth <= 0:
            continue
        ours, rate = factor(sample["eta"], truth), factor(sample["rate_eta"], truth)
        worst["ours"], worst["tqdm"] = max(worst["ours"], ours), max(worst["tqdm"], rate)
        shown = "-" if sample["rate_eta"] is None else f"{sample['rate_eta'] / 60:.1f}"
        extra = ""
        if args.replay:
            again = replayed_eta(args.run, sched, t)
            worst["replayed"] = max(worst["replayed"], factor(again, truth))
            extra = f" {again / 60:.1f} | {factor(again, truth):.2f} |"
        print(f"| {t / 60:.0f} | {truth / 60:.1f} | {sample['eta'] / 60:.1f} | {ours:.2f} | {shown} | {rate:.2f} |"
              + extra)
    print(f"\nworst factor after {args.after:g} min: ours {worst['ours']:.2f}, tqdm's rate {worst['tqdm']:.2f} "
          f"(ratio tqdm/ours {worst['tqdm'] / worst['ours']:.2f})"
          + (f"; this code's forecast replayed {worst['replayed']:.2f}" if args.replay else ""))


if __name__ == "__main__":
    main()
