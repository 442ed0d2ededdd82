"""How far the progress bar's ETA of a finished `uavris reproduce` run was from the truth.

Feeds docs/timings.md.

``reproduce`` records, once a minute, the ETA its bar showed (the replay of what is left,
:mod:`uavris.experiments.engine.forecast`) and tqdm's own rate-based ETA (the work left over the
rate so far) in ``OUT/schedule.json``; the run's true end is its last job's. This prints,
per sample after ``--after`` minutes, both ETAs against the truth, and the worst factor of
each (max of ETA/truth and truth/ETA): ours against tqdm's, measured in the same run.

    .venv/bin/python benchmarks/findings/progress_eta.py runs/quick
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


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="the output folder of a finished reproduce run")
    ap.add_argument("--after", type=float, default=5.0, help="minutes of the run not judged (default 5)")
    args = ap.parse_args(argv)
    sched = json.loads((args.run / "schedule.json").read_text())
    if not sched.get("eta"):
        raise SystemExit(f"{args.run / 'schedule.json'} has no ETA samples (a run older than the ETA record)")
    end = max(j["end"] for j in sched["jobs"])
    worst = {"ours": 1.0, "tqdm": 1.0}
    print(f"run {args.run}: {end / 60:.1f} min of jobs, {sched['workers']} worker(s)")
    print("| min | true min left | our ETA | factor | tqdm's ETA | factor |\n|---:|---:|---:|---:|---:|---:|")
    for sample in sched["eta"]:
        t, truth = sample["t"], end - sample["t"]
        if t < args.after * 60 or truth <= 0:
            continue
        ours, rate = factor(sample["eta"], truth), factor(sample["rate_eta"], truth)
        worst["ours"], worst["tqdm"] = max(worst["ours"], ours), max(worst["tqdm"], rate)
        shown = "-" if sample["rate_eta"] is None else f"{sample['rate_eta'] / 60:.1f}"
        print(f"| {t / 60:.0f} | {truth / 60:.1f} | {sample['eta'] / 60:.1f} | {ours:.2f} | {shown} | {rate:.2f} |")
    print(f"\nworst factor after {args.after:g} min: ours {worst['ours']:.2f}, tqdm's rate {worst['tqdm']:.2f} "
          f"(ratio tqdm/ours {worst['tqdm'] / worst['ours']:.2f})")


if __name__ == "__main__":
    main()
