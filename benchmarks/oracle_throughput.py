"""Single-core cost of the phase optimiser, the planning stage and the oracle policy.

Measurements, in this one process pinned to a single CPU with BLAS/OpenMP limited to one
thread:

1. The optimiser against 0.1.0's. ``optimize_phases`` (default settings) and the frozen
   numpy optimiser of uavris 0.1.0 (``benchmarks/_phase_optimizer_v010.py``, its default
   settings) on the same ``--slots`` seeded slots (default 1024: default-system slots at
   random poses over the flight region, tilts up to 0.4 rad, the default pairing draw, so
   about half have two active pairs), reported separately for the two-pair slots, the
   one-pair slots (a closed form in both) and all of them. Best of ``--repeats`` timings
   each. Targets, on the two-pair slots: at least 5x 0.1.0's slots per second, mean sum
   rate within 0.5% of 0.1.0's.
2. One slot at a time: the optimiser in a Python loop over the first ``--loop-slots``
   slots (the cost a policy pays per environment step with few environments), against
   the batched call.
3. The planning stage: :func:`uavris.agents.oracle.plan_target` for every named scenario,
   the first from scratch and the others with the poses valued so far (as the policy
   does). Target: at most 10 s per scenario.
4. The oracle policy: the planning oracle and the greedy oracle evaluated with
   :func:`uavris.agents.evaluation.evaluate` on ``--episodes`` episodes (default 32) of
   fig2 and unseen2, seed 1_000_000, with the zero action (``hover``) on the same
   episodes. Target: a 32-episode evaluation under 5 minutes.

It prints the machine, the command line, Markdown tables and PASS/FAIL lines. It always
exits with status 0: it is a report, not a test.

Run from the repository root::

    .venv/bin/python benchmarks/oracle_throughput.py            # ~3 minutes
    .venv/bin/python benchmarks/oracle_throughput.py --quick    # 256 / 32 slots, 8 episodes
"""

from __future__ import annotations

import os

# Limit numerical libraries to one thread before numpy (and its BLAS) is imported.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
for _variable in THREAD_VARIABLES:
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import platform  # noqa: E402
import shlex  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import _phase_optimizer_v010 as v010  # noqa: E402  (benchmarks/_phase_optimizer_v010.py)
import numpy as np  # noqa: E402
from _machine import cpu_model, pin_to_one_core  # noqa: E402  (benchmarks/_machine.py)
from numpy.typing import NDArray  # noqa: E402

import uavris  # noqa: E402
from uavris.agents.evaluation import evaluate  # noqa: E402
from uavris.agents.oracle import PlanningOracle, greedy_oracle_policy  # noqa: E402
from uavris.agents.references import reference_policy  # noqa: E402
from uavris.config import SCENARIOS, SystemConfig  # noqa: E402
from uavris.env.simulator import BatchedSimulator  # noqa: E402
from uavris.physics.phase_opt import DEFAULT_RESTARTS, optimize_slot_phases  # noqa: E402
from uavris.presets import EVAL_SEED  # noqa: E402

SEED = 0
SPEED_TARGET = 5.0
QUALITY_TARGET = 0.005
PLAN_LIMIT_S = 10.0
EVAL_LIMIT_S = 300.0


def make_slots(config: SystemConfig, n: int, seed: int) -> tuple[NDArray, NDArray, NDArray]:
    """``n`` seeded slots at random poses: channels, cos(theta), pairing (default draw)."""
    sim = BatchedSimulator(config.replace(safety_distance=0.0), "fig2", n)  # poses anywhere in the region
    sim.seed(seed + np.arange(n))
    sim.reset()
    rng = np.random.default_rng(seed)
    sim.place(np.c_[rng.uniform(0, 40, (n, 2)), rng.uniform(config.z_min, config.z_max, n)],
              rng.uniform(-0.4, 0.4, (n, 3)))
    return sim.channels.copy(), sim.cos_theta.copy(), sim.pairing.copy()


def best_time(fn, repeats: int):
    """(best wall time over ``repeats`` calls, last result)."""
    best, out = float("inf"), None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="256 batched / 32 looped slots, 8 episodes")
    parser.add_argument("--slots", type=int, default=None, help="slots in the batched call (default 1024)")
    parser.add_argument("--loop-slots", type=int, default=None, help="slots optimised one at a time (default 128)")
    parser.add_argument("--episodes", type=int, default=None, help="evaluation episodes per scenario (default 32)")
    parser.add_argument("--repeats", type=int, default=3, help="timings per optimiser measurement (best is kept)")
    args = parser.parse_args(argv)
    slots = args.slots or (256 if args.quick else 1024)
    loop_slots = min(args.loop_slots or (32 if args.quick else 128), slots)
    episodes = args.episodes or (8 if args.quick else 32)

    pinning = pin_to_one_core()
    config = SystemConfig()
    print("# uavris phase optimiser, planning stage and oracle (one core)")
    print()
    print(f"- command: {shlex.join([sys.executable, *sys.argv])}")
    print(f"- cpu: {cpu_model()}; {pinning}; " + ", ".join(f"{v}={os.environ[v]}" for v in THREAD_VARIABLES))
    print(f"- platform: {platform.platform()}; python {platform.python_version()}, numpy {np.__version__}, "
          f"uavris {uavris.__version__}")
    print(f"- optimiser today: compiled kernel, 2 co-phasing + {DEFAULT_RESTARTS} random starts, 7 noise levels x 30 "
          "L-BFGS iterations, 10 polish steps; 0.1.0: batched numpy, 2 + 4 starts, same levels, iterations, polish")
    print(flush=True)

    h, cos, pairing = make_slots(config, slots, SEED)
    optimize_slot_phases(config, h[:8], cos[:8], pairing[:8])  # compile (or load the cache) and warm up
    v010.optimize_slot_phases(config, h[:8], cos[:8], pairing[:8])
    # One active pair has a closed form (co-phasing): cheap for both optimisers. The headline is
    # the two-pair slots, where the optimisers differ; the mixed batch is what a rollout sees.
    pairs = pairing.sum(axis=(1, 2))
    groups = {"two-pair slots": pairs >= 2, "one-pair slots (closed form)": pairs == 1,
              "all (the default pairing draw)": np.ones(slots, dtype=bool)}
    print("## Phase optimiser")
    print()
    print("| slots | count | today (s) | today slots/s | 0.1.0 (s) | 0.1.0 slots/s | speed-up | "
          "mean sum rate today / 0.1.0 (bps/Hz) |")
    print("|---|---:|---:|---:|---:|---:|---:|---|")
    results = {}
    for label, mask in groups.items():
        print(f"optimiser, {label}: {int(mask.sum())} slots, best of {args.repeats} ...", file=sys.stderr, flush=True)
        hs, cs, ps = h[mask], cos[mask], pairing[mask]
        t_new, new = best_time(lambda hs=hs, cs=cs, ps=ps: optimize_slot_phases(config, hs, cs, ps), args.repeats)
        t_old, old = best_time(lambda hs=hs, cs=cs, ps=ps: v010.optimize_slot_phases(config, hs, cs, ps),
                               args.repeats)
        results[label] = (t_old / t_new, new.sum_rate.mean() / old.sum_rate.mean() - 1.0, new, old)
        n = int(mask.sum())
        print(f"| {label} | {n} | {t_new:.2f} | {n / t_new:,.0f} | {t_old:.2f} | {n / t_old:,.0f} | "
              f"{t_old / t_new:.1f}x | {new.sum_rate.mean():.3f} / {old.sum_rate.mean():.3f} |", flush=True)
    start = time.perf_counter()
    for i in range(loop_slots):
        optimize_slot_phases(config, h[i], cos[i], pairing[i])
    t_loop = time.perf_counter() - start
    print()
    print(f"today, one slot at a time (the first {loop_slots} slots in a Python loop): {loop_slots / t_loop:,.0f} "
          "slots/s")
    speed, quality, new, old = results["two-pair slots"]
    diff = new.sum_rate - old.sum_rate
    print(f"two-pair slots, today - 0.1.0: mean {diff.mean():+.4f}, slots worse by > 0.5 bps/Hz: "
          f"{int(np.sum(diff < -0.5))}, better by > 0.5: {int(np.sum(diff > 0.5))} (non-concave: different local "
          "optima)")
    print(f"speed today / 0.1.0 on two-pair slots = {speed:.1f}x (target >= {SPEED_TARGET:.0f}x) "
          f"{'PASS' if speed >= SPEED_TARGET else 'FAIL'}")
    print(f"mean sum rate today vs 0.1.0 on two-pair slots: {quality:+.2%} (target within {QUALITY_TARGET:.1%}) "
          f"{'PASS' if abs(quality) <= QUALITY_TARGET else 'FAIL'}")
    print(flush=True)

    print("planning every named scenario ...", file=sys.stderr, flush=True)
    oracle = PlanningOracle()
    print("## Planning stage")
    print()
    print("| scenario | start | plan (s) | poses valued | target | attitude (deg) | R(target) | R(start) | "
          "trip (slots) | plan value |")
    print("|---|---|---:|---:|---|---|---:|---:|---:|---:|")
    plan_times = []
    for name, scen in SCENARIOS.items():
        start = time.perf_counter()
        plan = oracle.plan(config, scen.start)
        plan_times.append(time.perf_counter() - start)
        print(f"| {name} | {list(scen.start)} | {plan_times[-1]:.2f} | {plan.poses_valued} | "
              f"{np.round(plan.target, 2).tolist()} | {np.round(np.degrees(plan.attitude), 1).tolist()} | "
              f"{plan.rate:.2f} | {plan.start_rate:.2f} | {plan.travel_slots} | {plan.value:.2f} |")
    print()
    print(f"planning stage: first scenario {plan_times[0]:.2f} s, slowest {max(plan_times):.2f} s "
          f"(target <= {PLAN_LIMIT_S:.0f} s per scenario) {'PASS' if max(plan_times) <= PLAN_LIMIT_S else 'FAIL'}")
    print(flush=True)

    print("## Oracle policies")
    print()
    print("| scenario | policy | time (s) | ms per slot | average sum rate (bps/Hz) | 95% CI |")
    print("|---|---|---:|---:|---:|---|")
    eval_times = []
    for scenario in ("fig2", "unseen2"):
        for name, policy in (("planning oracle", PlanningOracle()), ("greedy oracle", greedy_oracle_policy()),
                             ("hover (zero action)", reference_policy("hover", config))):
            print(f"evaluating {name} on {episodes} {scenario} episodes ...", file=sys.stderr, flush=True)
            start = time.perf_counter()
            res = evaluate(policy, config, scenario, episodes, EVAL_SEED)
            wall = time.perf_counter() - start
            s = res.summary()
            if name == "planning oracle":
                eval_times.append(wall)
            print(f"| {scenario} | {name} | {wall:.1f} | {1000 * wall / res.length.sum():.2f} | {s['mean']:.2f} | "
                  f"{s['ci_low']:.2f}-{s['ci_high']:.2f} |")
    print()
    scaled = max(eval_times) * 32 / episodes
    note = "" if episodes == 32 else f" (scaled from {episodes} episodes)"
    print(f"planning oracle evaluation of 32 episodes (planning included): {scaled:.1f} s on one core{note} "
          f"(target < {EVAL_LIMIT_S:.0f} s) {'PASS' if scaled < EVAL_LIMIT_S else 'FAIL'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
