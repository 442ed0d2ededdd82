"""The learned planner against the exact planner: the value lost and the time per hall, same run.

Feeds docs/places.md.

Measurements, in this one process pinned to a single CPU with BLAS/OpenMP and torch limited
to one thread, on ``--halls`` unseen halls (default 8) of ``LayoutGenerator(devices=K)`` for
each ``K`` of ``--devices`` (default 4 and 8), from each hall's start:

- the exact planner, :func:`uavris.agents.oracle.plan_target` (what ``uavris plan`` runs and
  the oracle flies to), every plan from scratch;
- the learned planner, :func:`uavris.agents.place.planner.learned_plan` with a learned value
  ``V`` (``--value``: a study's ``stages/deploy-value-KEY/value`` folder, seed 0's): amortised (V's
  argmax alone, no ``R`` computed) and semi-amortised (its top ``--top-k`` places and the
  start valued by ``R``, default 3);
- the deployed place, :func:`uavris.agents.place.planner.decided_plan`: V proposes, R disposes.

Value: the episode value of each plan (flying from the start to its target and hovering there
with its attitude: ``R`` of the start and of the target on the fresh draws plans state their
numbers with, :func:`~uavris.agents.oracle.objective.assessed_rate`, every pose of a hall on the
same draws, and the travel-time rule), as a fraction of the exact plan's: mean with its
Student-t 95% CI over halls, and the worst hall. Time: wall seconds per hall, and the exact
planner's time over each planner's in the same run. Targets (issue 67): the deployed place
>= 99% of the exact plan's value, its decision <= 10% of its time.

Run: ``python benchmarks/findings/place_planner.py --value runs/quick/stages/deploy-value-[0-9a-f]*/value``.
"""

from __future__ import annotations

import os
import pathlib
import sys

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
for _variable in THREAD_VARIABLES:
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

# isort: off
import uavris  # noqa: E402, F401 - first: it pins the float path before numpy loads (uavris.float_paths)
# isort: on
import numpy as np  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # benchmarks/, for _machine.py
from _machine import cpu_model, pin_to_one_core, table  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--value", required=True, help="a learned value (stages/deploy-value-KEY/value)")
    parser.add_argument("--devices", type=int, nargs="+", default=[4, 8], help="device counts (default: 4 8)")
    parser.add_argument("--halls", type=int, default=8, help="unseen halls per device count (default: 8)")
    parser.add_argument("--top-k", type=int, default=3, help="places the semi-amortised planner values by R")
    args = parser.parse_args(argv)
    pinning = pin_to_one_core()
    import torch

    torch.set_num_threads(1)
    from uavris.agents.oracle import plan_target
    from uavris.agents.oracle.objective import assessed_rate, episode_value, trip_slots
    from uavris.agents.place.checkpoint import load_value
    from uavris.agents.place.planner import PlaceSettings, decided_plan, learned_plan
    from uavris.config import SystemConfig
    from uavris.layouts import LayoutGenerator
    from uavris.stats import t_interval

    value, _ = load_value(args.value)
    print(f"# learned planner against the exact planner\n- cpu: {cpu_model()}; {pinning}; torch threads 1\n"
          f"- value: {args.value}; {args.halls} unseen halls per device count; semi-amortised top {args.top_k}\n")
    rows = [("devices", "planner", "plan value / exact plan's, mean [95% CI]", "worst hall", "s per hall",
             "exact's time / this")]
    planners = {"learned (V's argmax)": lambda s, q: learned_plan(value, s, q),
                f"semi-amortised (top {args.top_k} by R)": lambda s, q: learned_plan(value, s, q,
                                                                                    PlaceSettings(top_k=args.top_k)),
                "deployed (V proposes, R disposes)": lambda s, q: decided_plan(value, s, q)}
    for k in args.devices:
        gen = LayoutGenerator(devices=k)
        share = {name: [] for name in planners}
        seconds = {"exact": 0.0, **{name: 0.0 for name in planners}}
        for j in range(args.halls):
            system, where = gen.layout("unseen", j).resolve(SystemConfig(observe_devices=True))
            began = time.perf_counter()
            exact = plan_target(system, where.start)
            seconds["exact"] += time.perf_counter() - began
            targets, attitudes = [exact.target], [exact.attitude]
            for name, decide in planners.items():
                began = time.perf_counter()
                plan = decide(system, where.start)
                seconds[name] += time.perf_counter() - began
                targets.append(plan.target)
                attitudes.append(plan.attitude)
            start = np.asarray(where.start, dtype=np.float64)
            rates, _ = assessed_rate(system, np.stack([start, *targets]), np.stack([np.zeros(3), *attitudes]))
            plans = episode_value(system.horizon, trip_slots(system, start, np.stack(targets)), rates[0], rates[1:])
            for i, name in enumerate(planners, start=1):
                share[name].append(plans[i] / plans[0])
        rows.append((str(k), "exact (uavris plan)", "100.0%", "100.0%", f"{seconds['exact'] / args.halls:.3f}", "1.0x"))
        for name in planners:
            low, high = t_interval(share[name])
            rows.append((str(k), name, f"{np.mean(share[name]):.1%} [{low:.1%}, {high:.1%}]",
                         f"{np.min(share[name]):.1%}",
                         f"{seconds[name] / args.halls:.3f}", f"{seconds['exact'] / max(seconds[name], 1e-9):.1f}x"))
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
