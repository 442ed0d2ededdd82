"""Where a `uavris reproduce` run's CPU time goes: its job families, and inside each what computes.

Feeds docs/timings.md.

Reads a py-spy profile of the whole run in raw (collapsed) form, recorded from its start by
``py-spy record --pid PID --subprocesses --rate 5 --nonblocking --format raw -o PROFILE``. Each
sample is put in the job family whose worker function it ran under (SB3 training, evaluation,
the demonstrations, DT and behaviour-cloning pre-training, fine-tuning, ...) and, inside it, in
what it computes, by the first of these its stack holds: the planner (``R`` of poses, whose
optimised slots are most of it), the per-slot phase optimiser of the episodes, SB3's gradient
update and its rollouts, the DT's training step, the simulator, torch elsewhere, and the rest
(Python around them). Prints core-minutes (samples over the rate) per family and part.

    python benchmarks/findings/profile_families.py PROFILE --rate 5
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

# the worker function a job runs, and its family (the first that a sample's stack holds)
FAMILIES = (("train_job", "SB3 training (comparison, experts)"), ("evaluate_job", "evaluation stages"),
            ("demonstrations_job", "demonstrations (oracle's plans and episodes)"),
            ("pretrain_job", "DT and BC pre-training"), ("finetune_job", "fine-tuning"),
            ("value_labels_job", "learned value: labels"), ("value_fit_job", "learned value: fit"),
            ("dataset_job", "expert datasets (paper, strong)"))
# what a sample computes, by the first of these its stack holds anywhere (so a torch kernel under SB3's
# update is the update's, one under the DT's training step the step's)
PARTS = (("agents/oracle/planner", "planner (R of poses)"), ("agents/oracle/objective", "planner (R of poses)"),
         ("agents/oracle/search", "planner (R of poses)"), ("agents/place/labels", "planner (R of poses)"),
         ("physics/phase_opt", "phase optimiser (episodes' slots)"),
         (".train (stable_baselines3/", "SB3 gradient update"),
         ("collect_rollouts (stable_baselines3/", "SB3 rollouts"),
         ("agents/dt/training", "DT/BC training step"), ("env/simulator", "simulator"), ("uavris/physics", "simulator"),
         ("torch/", "torch elsewhere (policies' forward passes)"))


def classify(stack: list[str]) -> tuple[str, str]:
    """The sample's job family and what it computes (see :data:`FAMILIES`, :data:`PARTS`)."""
    family = next((name for fn, name in FAMILIES if any(f.startswith(fn + " ") for f in stack)), "scheduler, other")
    part = next((name for pattern, name in PARTS if any(pattern in f for f in stack)), "Python around them")
    return family, part


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("profile", type=Path, help="py-spy's raw output (--format raw)")
    ap.add_argument("--rate", type=float, default=5.0, help="samples per second it was recorded at (default 5)")
    args = ap.parse_args(argv)
    table: dict[str, dict[str, float]] = defaultdict(lambda: defaultdict(float))
    for line in args.profile.read_text().splitlines():
        stack, _, count = line.rpartition(" ")
        if not stack:
            continue
        family, part = classify(stack.split(";"))
        table[family][part] += int(count)
    total = sum(sum(p.values()) for p in table.values())
    minutes = 60 * args.rate
    print(f"{args.profile}: {total:,.0f} samples, {total / minutes:.1f} core-minutes at {args.rate:g} Hz\n")
    print("| family | core-min | share | where it goes (core-min) |\n|---|---:|---:|---|")
    for family, parts in sorted(table.items(), key=lambda kv: -sum(kv[1].values())):
        n = sum(parts.values())
        inside = ", ".join(f"{p} {v / minutes:.1f}" for p, v in sorted(parts.items(), key=lambda kv: -kv[1])
                           if v / minutes >= 0.05)
        print(f"| {family} | {n / minutes:.1f} | {n / total:.1%} | {inside} |")


if __name__ == "__main__":
    main()
