"""How far the oracle is from the best a much wider search finds: its optimality gap, per hall.

Feeds docs/results/oracle-gap.md.

In this one process pinned to a single CPU, on ``--halls`` unseen halls (default 8) of
``LayoutGenerator(devices=K)`` for each ``K`` of ``--devices`` (default 4), from each hall's
start (the deployment track's unseen halls, ``layout-unseen-J``):

- the oracle's plan, :func:`uavris.agents.oracle.plan_target` (what the oracle flies to);
- the search, :func:`uavris.agents.oracle.search.exhaustive_plan`: every feasible position of
  a 2 m x 2 m x 1 m grid, the 5^3 attitudes of +-20 deg at the 12 best, a pattern search from
  the 3 best, on draws that are not the planner's;
- both, and staying at the start, valued by :func:`~uavris.agents.oracle.search.plan_gap`
  on the same 8 fresh batches of draws (the planner's objective: the episode average of
  flying there and hovering).

Printed per hall: the three values, the search minus the oracle (its standard error over the
batches), and the oracle as a fraction of the best found; then the mean gap over halls with
its Student-t 95% CI (the hall the unit). The ratio this benchmark states: the oracle's value
over the search's, and the search's time over the planner's.

Run: ``python benchmarks/findings/oracle_gap.py`` (about 2-3 min per 4-device hall on one core).
"""

from __future__ import annotations

import os
import pathlib
import sys

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # benchmarks/, for _machine.py
from _machine import cpu_model, pin_to_one_core, table  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--devices", type=int, nargs="+", default=[4], help="device counts (default: 4)")
    parser.add_argument("--halls", type=int, default=8, help="unseen halls per device count (default: 8)")
    args = parser.parse_args(argv)
    pinning = pin_to_one_core()
    from uavris.agents.oracle import plan_target
    from uavris.agents.oracle.search import SearchSettings, exhaustive_plan, plan_gap
    from uavris.config import SystemConfig
    from uavris.layouts import LayoutGenerator
    from uavris.stats import over_units

    s = SearchSettings()
    print(f"# the oracle's optimality gap\n- cpu: {cpu_model()}; {pinning}\n- search: {s}\n"
          f"- {args.halls} unseen halls per device count; values in bps/Hz (episode average of the plan)\n",
          flush=True)
    rows = [("hall", "oracle", "search", "stay", "search - oracle (SE)", "oracle / search", "poses searched",
             "search s / planner s")]
    for k in args.devices:
        gen = LayoutGenerator(devices=k)
        fractions, gaps = [], []
        for j in range(args.halls):
            layout = gen.layout("unseen", j)
            system, where = layout.resolve(SystemConfig(observe_devices=True))
            began = time.perf_counter()
            plan = plan_target(system, where.start)
            planner_s = time.perf_counter() - began
            began = time.perf_counter()
            found = exhaustive_plan(system, where.start, s)
            search_s = time.perf_counter() - began
            g = plan_gap(system, where.start, plan, found)
            fractions.append(g.oracle_value / g.search_value)
            gaps.append(g.difference)
            rows.append((f"{layout.name} ({k} devices)", f"{g.oracle_value:.2f}", f"{g.search_value:.2f}",
                         f"{g.stay_value:.2f}", f"{g.difference:+.2f} ({g.difference_se:.2f})",
                         f"{g.oracle_value / g.search_value:.1%}", f"{found.poses_valued:,}",
                         f"{search_s / planner_s:.0f}x"))
            print(table(rows), flush=True)
        gap, frac = over_units(gaps), over_units(fractions)
        print(f"\n{k} devices, {len(gaps)} halls: search minus oracle {gap['mean']:+.2f} bps/Hz, 95% CI "
              f"[{gap['ci_low']:+.2f}, {gap['ci_high']:+.2f}]; the oracle at {frac['mean']:.1%} of the best found "
              f"[{frac['ci_low']:.1%}, {frac['ci_high']:.1%}]\n", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
