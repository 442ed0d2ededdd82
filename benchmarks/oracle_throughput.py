"""Single-core cost of the phase optimiser, the planning stage and the oracle policy.

Measurements, in this one process pinned to a single CPU with BLAS/OpenMP limited to one
thread:

1. The optimiser against 0.1.0's. ``optimize_phases`` (default settings) and the frozen
   numpy optimiser of uavris 0.1.0 (read from git history by ``benchmarks/_v010.py``, its default
   settings) on the same ``--slots`` seeded slots (default 1024: default-system slots at
   random poses over the flight region, tilts up to 0.4 rad, the default pairing draw, so
   about half have two active pairs), reported separately for the two-pair slots, the
   one-pair slots (a closed form in both) and all of them. Best of ``--repeats`` timings
   each. Targets, on the two-pair slots: at least 5x 0.1.0's slots per second, mean sum
   rate within 0.5% of 0.1.0's. Today's kernels are compiled without fast-math and with
   their own Cholesky solve instead of LAPACK's, so that they give the same bits on any CPU.
2. One slot at a time: the optimiser in a Python loop over the first ``--loop-slots``
   slots (the cost a policy pays per environment step with few environments), against
   the batched call.
3. A peer for unit-modulus problems: SciPy's ``minimize(method="L-BFGS-B")`` on the same
   objective (minus :func:`uavris.physics.phase_opt.sum_rate_and_gradient`, its analytic
   gradient, the 16 phases of one slot, no bounds), from the same starts as the full
   multi-start (one co-phasing start per active link, ``co_phasing_phases``, and the 2
   random starts of ``random_starts``), best of the starts, on the first ``--peer-slots``
   two-pair slots of measurement 1 (default 128), once with SciPy's default iteration
   limit and once with at most uavris's budget (7 levels x 30 = 210 iterations per start):
   mean sum rate and slots/s beside uavris's optimiser on the same slots (SciPy timed once:
   it is some 1000x slower). SciPy solves the true problem directly; uavris adds the noise
   continuation and the null polish.
4. The planning stage: :func:`uavris.agents.oracle.plan_target` for every named scenario,
   the first from scratch and the others with the poses valued so far (as the policy
   does). Target: at most 10 s per scenario.
5. The planner's cheap ranking estimate: ``plan_target(system, start, PlanSettings(exact=False))``
   against ``PlanSettings(exact=True)`` (the reference) on the 11 named scenarios and the
   first 16 generated halls (``LayoutGenerator(devices=4, seed=0)``, training and unseen
   halls alternating), every plan from scratch (no memo): the ratio of the total planning
   time and the relative loss of the plan's value (``plan.value``, exact in both: the fast
   plan values its chosen pose exactly) against the exact plan's. Target: >= 10x and the
   worst plan within 0.5%.
6. The oracle policy: the planning oracle and the greedy oracle evaluated with
   :func:`uavris.agents.evaluation.evaluate` on ``--episodes`` episodes (default 32) of
   fig2 and unseen2, seed 1_000_000, with the zero action (``hover``) on the same
   episodes. Target: a 32-episode evaluation under 5 minutes.

It prints the machine, the command line, Markdown tables and PASS/FAIL lines. It always
exits with status 0: it is a report, not a test.

Run from the repository root::

    .venv/bin/python benchmarks/oracle_throughput.py            # ~3 minutes
    .venv/bin/python benchmarks/oracle_throughput.py --quick    # ~1.5 minutes: 256 / 32 / 32 slots, 4 halls, 8 episodes
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

import numpy as np  # noqa: E402
import scipy  # noqa: E402
from _machine import cpu_model, pin_to_one_core  # noqa: E402  (benchmarks/_machine.py)
from _v010 import optimizer_v010  # noqa: E402  (benchmarks/_v010.py)
from numpy.typing import NDArray  # noqa: E402

import uavris  # noqa: E402
from uavris.agents.evaluation import evaluate  # noqa: E402
from uavris.agents.oracle import PlanningOracle, PlanSettings, greedy_oracle_policy, plan_target  # noqa: E402
from uavris.agents.oracle.policy import forget_shared_plans  # noqa: E402
from uavris.agents.references import reference_policy  # noqa: E402
from uavris.config import SCENARIOS, SystemConfig  # noqa: E402
from uavris.env.simulator import BatchedSimulator  # noqa: E402
from uavris.layouts import LayoutGenerator  # noqa: E402
from uavris.physics.co_phasing import co_phasing_phases  # noqa: E402
from uavris.physics.phase_opt import (  # noqa: E402
    DEFAULT_ITERATIONS,
    DEFAULT_NOISE_LEVELS,
    DEFAULT_RESTARTS,
    active_links,
    optimize_slot_phases,
    random_starts,
    sum_rate_and_gradient,
)
from uavris.presets import EVAL_SEED  # noqa: E402

SEED = 0
SPEED_TARGET = 5.0
QUALITY_TARGET = 0.005
PLAN_LIMIT_S = 10.0
EVAL_LIMIT_S = 300.0
FAST_PLAN_SPEED_TARGET = 10.0
FAST_PLAN_LOSS_TARGET = 0.005
HALLS = 16  # generated halls planned exactly and cheaply (training and unseen alternating)
PEER_SLOTS = 128  # two-pair slots SciPy's L-BFGS-B solves


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


def scipy_peer(config: SystemConfig, h: NDArray, cos: NDArray, pairing: NDArray,
               maxiter: int | None = None) -> tuple[NDArray, NDArray]:
    """SciPy's L-BFGS-B on minus the sum rate of each slot, from the full multi-start's starts
    (one co-phasing start per active link and ``DEFAULT_RESTARTS`` random ones, as
    ``optimize_phases`` makes them), best of the starts: (sum rates, function evaluations per
    slot). ``maxiter``: iterations per start (None: SciPy's default, 15,000)."""
    from scipy.optimize import minimize

    k = h.shape[-2]
    tx, rx, valid = active_links(pairing, max(k // 2, 1))
    starts = np.concatenate([co_phasing_phases(h[:, None], cos[:, None], tx, rx, config.angle_dependent_reflection),
                             random_starts(h, 0, DEFAULT_RESTARTS)], axis=1)
    rates, evaluations = np.empty(len(h)), np.zeros(len(h), dtype=np.int64)
    for b in range(len(h)):
        def objective(phi: NDArray, b: int = b) -> tuple[float, NDArray]:
            rate, grad = sum_rate_and_gradient(phi, h[b], cos[b], pairing[b], config.tx_power_w, config.noise_w,
                                               config.angle_dependent_reflection)
            return -float(rate), -grad  # type: ignore[operator]

        best = -np.inf
        for i, x0 in enumerate(starts[b]):
            if i < tx.shape[1] and not valid[b, i]:
                continue  # a padding link repeats the first one's start
            res = minimize(objective, x0, jac=True, method="L-BFGS-B",
                           options={} if maxiter is None else {"maxiter": maxiter})
            best = max(best, -float(res.fun))
            evaluations[b] += res.nfev
        rates[b] = best
    return rates, evaluations


def plan_sites(halls: int) -> list[tuple[str, SystemConfig, tuple[float, float, float]]]:
    """(name, system, start) of the 11 named scenarios and the first ``halls`` generated halls."""
    config = SystemConfig()
    sites = [(name, config, tuple(scen.start)) for name, scen in SCENARIOS.items()]
    gen = LayoutGenerator(devices=4, seed=0)
    for j in range(halls):
        hall = gen.layout(("train", "unseen")[j % 2], j // 2, config)
        system, scenario = hall.resolve(config)
        sites.append((hall.name, system, tuple(scenario.start)))
    return sites


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="256 batched / 32 looped / 32 SciPy slots, 4 generated halls, 8 episodes")
    parser.add_argument("--slots", type=int, default=None, help="slots in the batched call (default 1024)")
    parser.add_argument("--loop-slots", type=int, default=None, help="slots optimised one at a time (default 128)")
    parser.add_argument("--episodes", type=int, default=None, help="evaluation episodes per scenario (default 32)")
    parser.add_argument("--peer-slots", type=int, default=None, help="two-pair slots SciPy solves (default 128)")
    parser.add_argument("--halls", type=int, default=None,
                        help="generated halls planned both ways, besides the 11 scenarios (default 16)")
    parser.add_argument("--repeats", type=int, default=3, help="timings per optimiser measurement (best is kept)")
    args = parser.parse_args(argv)
    slots = args.slots or (256 if args.quick else 1024)
    loop_slots = min(args.loop_slots or (32 if args.quick else 128), slots)
    episodes = args.episodes or (8 if args.quick else 32)
    peer_slots = args.peer_slots or (32 if args.quick else PEER_SLOTS)
    halls = args.halls if args.halls is not None else (4 if args.quick else HALLS)

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

    v010 = optimizer_v010()
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

    two = np.flatnonzero(groups["two-pair slots"])[:peer_slots]
    hs, cs, ps = h[two], cos[two], pairing[two]
    print(f"SciPy L-BFGS-B on {len(two)} two-pair slots, best of {args.repeats} ...", file=sys.stderr, flush=True)
    t_ours, ours = best_time(lambda: optimize_slot_phases(config, hs, cs, ps), args.repeats)
    start = time.perf_counter()
    for i in range(len(two)):
        optimize_slot_phases(config, hs[i], cs[i], ps[i])
    t_ours_loop = time.perf_counter() - start
    # SciPy once (it is ~1000x slower: a best of several would change nothing but the run time).
    t_scipy, (scipy_rate, nfev) = best_time(lambda: scipy_peer(config, hs, cs, ps), 1)
    budget = len(DEFAULT_NOISE_LEVELS) * DEFAULT_ITERATIONS
    t_budget, (budget_rate, budget_nfev) = best_time(lambda: scipy_peer(config, hs, cs, ps, budget), 1)

    print(f"## A peer: SciPy's L-BFGS-B on the same objective ({len(two)} two-pair slots)")
    print()
    print(f"SciPy {scipy.__version__}, `minimize(method='L-BFGS-B')` with its defaults and the analytic gradient, "
          f"from the same {ps[0].sum():.0f} co-phasing + {DEFAULT_RESTARTS} random starts as uavris's multi-start, "
          "best of the starts")
    print()
    print("| optimiser | time (s) | slots/s | speed vs SciPy | mean sum rate (bps/Hz) | "
          "objective evaluations per slot |")
    print("|---|---:|---:|---:|---:|---:|")
    print(f"| SciPy L-BFGS-B, true problem, one slot and start at a time | {t_scipy:.2f} | {len(two) / t_scipy:,.1f} | "
          f"1.0x | {scipy_rate.mean():.3f} | {nfev.mean():,.0f} |")
    print(f"| SciPy L-BFGS-B, at most {budget} iterations per start (uavris's {len(DEFAULT_NOISE_LEVELS)} levels x "
          f"{DEFAULT_ITERATIONS}) | {t_budget:.2f} | {len(two) / t_budget:,.1f} | {t_scipy / t_budget:,.1f}x | "
          f"{budget_rate.mean():.3f} | {budget_nfev.mean():,.0f} |")
    print(f"| uavris, one batched call (continuation + polish) | {t_ours:.3f} | {len(two) / t_ours:,.0f} | "
          f"{t_scipy / t_ours:,.0f}x | {ours.sum_rate.mean():.3f} | |")
    print(f"| uavris, one slot at a time | {t_ours_loop:.3f} | {len(two) / t_ours_loop:,.0f} | "
          f"{t_scipy / t_ours_loop:,.0f}x | {ours.sum_rate.mean():.3f} | |")
    print()
    gap = ours.sum_rate - scipy_rate
    print(f"uavris - SciPy (default iterations) per slot: mean {gap.mean():+.3f} bps/Hz "
          f"({ours.sum_rate.mean() / scipy_rate.mean() - 1:+.2%} of SciPy's mean); uavris better by > 0.5 bps/Hz in "
          f"{int(np.sum(gap > 0.5))} slots, worse by > 0.5 in {int(np.sum(gap < -0.5))}")
    gap = ours.sum_rate - budget_rate
    print(f"uavris - SciPy ({budget} iterations per start) per slot: mean {gap.mean():+.3f} bps/Hz "
          f"({ours.sum_rate.mean() / budget_rate.mean() - 1:+.2%}); uavris better by > 0.5 bps/Hz in "
          f"{int(np.sum(gap > 0.5))} slots, worse by > 0.5 in {int(np.sum(gap < -0.5))}")
    print(flush=True)

    print("planning every named scenario ...", file=sys.stderr, flush=True)
    forget_shared_plans()
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

    sites = plan_sites(halls)
    print("## The planner's cheap ranking estimate (PlanSettings(exact=False)) against the exact planner")
    print()
    print(f"{len(sites)} plans each way, every one from scratch (no memo); "
          "loss = 1 - fast plan value / exact plan value")
    print()
    print("| where | exact (s) | fast (s) | exact: target | fast: target | exact plan value | fast plan value | loss |")
    print("|---|---:|---:|---|---|---:|---:|---:|")
    t_exact, t_fast, losses = 0.0, 0.0, []
    for name, system, start_q in sites:
        print(f"planning {name} exactly and cheaply ...", file=sys.stderr, flush=True)
        start = time.perf_counter()
        exact = plan_target(system, start_q, PlanSettings(exact=True))
        te = time.perf_counter() - start
        start = time.perf_counter()
        fast = plan_target(system, start_q, PlanSettings(exact=False))
        tf = time.perf_counter() - start
        t_exact, t_fast = t_exact + te, t_fast + tf
        losses.append(1.0 - fast.value / exact.value)
        print(f"| {name} | {te:.2f} | {tf:.2f} | {np.round(exact.target, 2).tolist()} | "
              f"{np.round(fast.target, 2).tolist()} | {exact.value:.3f} | {fast.value:.3f} | {losses[-1]:+.2%} |",
              flush=True)
    print()
    loss_arr = np.array(losses)
    worst = int(np.argmax(loss_arr))
    speed = t_exact / t_fast
    print(f"planning time, exact / fast: {t_exact:.1f} s / {t_fast:.1f} s = {speed:.1f}x; plan value loss: mean "
          f"{loss_arr.mean():.2%}, worst {loss_arr[worst]:.2%} ({sites[worst][0]}); fast plan at or above the exact "
          f"one in {int(np.sum(loss_arr <= 0))} of {len(sites)}")
    ok = speed >= FAST_PLAN_SPEED_TARGET and loss_arr.max() <= FAST_PLAN_LOSS_TARGET
    print(f"fast planner: {speed:.1f}x, worst loss {loss_arr[worst]:.2%} (target >= {FAST_PLAN_SPEED_TARGET:.0f}x and "
          f"worst within {FAST_PLAN_LOSS_TARGET:.1%}) {'PASS' if ok else 'FAIL'}")
    print(flush=True)

    print("## Oracle policies")
    print()
    print("| scenario | policy | time (s) | ms per slot | average sum rate (bps/Hz) | 95% CI |")
    print("|---|---|---:|---:|---:|---|")
    eval_times = []
    for scenario in ("fig2", "unseen2"):
        for name, policy in (("planning oracle", PlanningOracle()), ("greedy oracle", greedy_oracle_policy()),
                             ("hover (zero action)", reference_policy("zero-action", config))):
            print(f"evaluating {name} on {episodes} {scenario} episodes ...", file=sys.stderr, flush=True)
            forget_shared_plans()  # the time includes the plan, as an evaluation's first use of the oracle does
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
