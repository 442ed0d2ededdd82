"""Single-core throughput of the per-slot phase optimiser and cost of the oracle policy.

Three measurements, in this one process pinned to a single CPU with BLAS/OpenMP limited
to one thread:

1. Batched optimisation: ``optimize_phases`` on ``--slots`` slots (default 1024) in one
   call. The slots are seeded default-system slots at random poses over the flight
   region (tilts up to 0.4 rad) with the default pairing draw (one or two active pairs,
   half each on average); one-pair slots take the closed form, two-pair slots the
   iterative method.
2. One slot at a time: the same optimiser called in a Python loop over the first
   ``--loop-slots`` of those slots (default 128: the loop is slow). The results are
   compared with the batched ones (same per-slot random starts; equal up to rounding
   paths).
   Target: batched at least 10x the loop's slots per second.
3. The oracle policy evaluated with ``uavris.agents.evaluation.evaluate`` on 32 episodes
   of ``fig2`` (the quick preset's evaluation size), seed 1_000_000, and the
   ``hover_aligned`` and ``random`` baselines on the same episodes for reference.
   Target: under 5 minutes on one core.

It prints the machine, the command line, a Markdown table and PASS/FAIL lines. It always
exits with status 0: it is a report, not a test.

Run from the repository root::

    .venv/bin/python benchmarks/oracle_throughput.py            # ~1-2 minutes
    .venv/bin/python benchmarks/oracle_throughput.py --quick    # 256 / 32 slots, 8 episodes
"""

from __future__ import annotations

import os

# Limit numerical libraries to one thread before numpy (and its BLAS) is imported.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
for _variable in THREAD_VARIABLES:
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import platform  # noqa: E402
import shlex  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

import uavris  # noqa: E402
from uavris.agents.baselines import hover_aligned, random_policy  # noqa: E402
from uavris.agents.evaluation import evaluate  # noqa: E402
from uavris.agents.oracle import oracle_policy  # noqa: E402
from uavris.agents.phase_optimizer import optimize_slot_phases  # noqa: E402
from uavris.config import SystemConfig  # noqa: E402
from uavris.env.simulator import BatchedSimulator  # noqa: E402
from _machine import cpu_model, pin_to_one_core  # noqa: E402  (benchmarks/_machine.py)

SEED = 0
EVAL_SEED = 1_000_000
RATIO_TARGET = 10.0
EVAL_LIMIT_S = 300.0


def make_slots(config: SystemConfig, n: int, seed: int) -> tuple[NDArray, NDArray, NDArray]:
    """``n`` seeded slots at random poses: channels, cos(theta), pairing (default draw)."""
    sim = BatchedSimulator(config, "fig2", n)
    sim.seed(seed + np.arange(n))
    sim.reset()
    rng = np.random.default_rng(seed)
    sim.pos = np.c_[rng.uniform(0, 40, (n, 2)), rng.uniform(config.z_min, config.z_max, n)]
    sim.att = rng.uniform(-0.4, 0.4, (n, 3))
    sim._draw_slot(slice(None))
    return sim.channels.copy(), sim.cos_theta.copy(), sim.pairing.copy()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="256 batched / 32 looped slots, 8 episodes")
    parser.add_argument("--slots", type=int, default=None, help="slots in the batched call (default 1024)")
    parser.add_argument("--loop-slots", type=int, default=None, help="slots optimised one at a time (default 128)")
    parser.add_argument("--episodes", type=int, default=None, help="fig2 evaluation episodes (default 32)")
    args = parser.parse_args(argv)
    slots = args.slots or (256 if args.quick else 1024)
    loop_slots = min(args.loop_slots or (32 if args.quick else 128), slots)
    episodes = args.episodes or (8 if args.quick else 32)

    pinning = pin_to_one_core()
    config = SystemConfig()
    print("# uavris phase optimiser and oracle throughput (one core)")
    print()
    print(f"- command: {shlex.join([sys.executable, *sys.argv])}")
    print(f"- cpu: {cpu_model()}; {pinning}; " + ", ".join(f"{v}={os.environ[v]}" for v in THREAD_VARIABLES))
    print(f"- platform: {platform.platform()}; python {platform.python_version()}, numpy {np.__version__}, "
          f"uavris {uavris.__version__}")
    print(f"- optimiser: default settings (2 co-phasing + 4 random starts, 7 noise levels x 30 L-BFGS "
          f"iterations, 10 polish steps); slots seeded {SEED}")
    print(flush=True)

    h, cos, pairing = make_slots(config, slots, SEED)
    two_pair = int(np.sum(pairing.sum(axis=(1, 2)) >= 2))

    print(f"batched call over {slots} slots ...", file=sys.stderr, flush=True)
    optimize_slot_phases(config, h[:8], cos[:8], pairing[:8])  # warm-up
    start = time.perf_counter()
    batched = optimize_slot_phases(config, h, cos, pairing)
    t_batched = time.perf_counter() - start

    print(f"loop over {loop_slots} slots ...", file=sys.stderr, flush=True)
    looped_rate = np.empty(loop_slots)
    looped_phases = np.empty((loop_slots, config.num_elements))
    start = time.perf_counter()
    for i in range(loop_slots):
        sol = optimize_slot_phases(config, h[i], cos[i], pairing[i])
        looped_rate[i], looped_phases[i] = sol.sum_rate, sol.phases
    t_loop = time.perf_counter() - start
    diff = looped_rate - batched.sum_rate[:loop_slots]
    same = int(np.sum(np.all(looped_phases == batched.phases[:loop_slots], axis=1) & (diff == 0)))
    loop_two_pair = int(np.sum(pairing[:loop_slots].sum(axis=(1, 2)) >= 2))

    print(f"evaluating the oracle on {episodes} fig2 episodes ...", file=sys.stderr, flush=True)
    start = time.perf_counter()
    oracle = evaluate(oracle_policy(), config, "fig2", episodes, EVAL_SEED).summary()
    t_eval = time.perf_counter() - start
    base = {name: evaluate(policy, config, "fig2", episodes, EVAL_SEED).summary()
            for name, policy in (("hover_aligned", hover_aligned()), ("random", random_policy(0)))}

    rate_batched = slots / t_batched
    rate_loop = loop_slots / t_loop
    ratio = rate_batched / rate_loop
    print("| measurement | setting | time (s) | slots/s or result |")
    print("|---|---|---:|---:|")
    print(f"| optimiser, batched | {slots} slots in one call ({two_pair} with two pairs) | {t_batched:.2f} | "
          f"{rate_batched:,.0f} slots/s |")
    print(f"| optimiser, one slot at a time | {loop_slots} slots in a loop ({loop_two_pair} with two pairs) | "
          f"{t_loop:.2f} | {rate_loop:,.1f} slots/s |")
    print(f"| oracle evaluation | {episodes} episodes of fig2, seed {EVAL_SEED} | {t_eval:.1f} | "
          f"{oracle['mean']:.2f} bps/Hz (95% CI {oracle['ci_low']:.2f}-{oracle['ci_high']:.2f}) |")
    for name, s in base.items():
        print(f"| {name} (reference) | same episodes | - | {s['mean']:.2f} bps/Hz "
              f"(95% CI {s['ci_low']:.2f}-{s['ci_high']:.2f}) |")
    print()
    lengths = ", ".join(f"{name} {s['mean_length']:.1f}" for name, s in [("oracle", oracle), *base.items()])
    print(f"mean episode length (slots): {lengths}; mean energy: oracle {oracle['mean_energy_j']:.0f} J")
    print(f"looped vs batched results: {same} of {loop_slots} slots bit-identical; sum-rate difference "
          f"mean {diff.mean():+.4f}, max |.| {np.abs(diff).max():.4f} bps/Hz (same random starts; numpy can round "
          "a batch of one differently, and the non-concave ascent may amplify it)")
    print(f"batched / one-at-a-time = {ratio:.1f}x (target >= {RATIO_TARGET:.0f}x) "
          f"{'PASS' if ratio >= RATIO_TARGET else 'FAIL'}")
    scaled = t_eval * 32 / episodes
    note = "" if episodes == 32 else f" (scaled from {episodes} episodes: {scaled:.1f} s)"
    print(f"oracle evaluation of 32 fig2 episodes: {scaled:.1f} s on one core{note} "
          f"(target < {EVAL_LIMIT_S:.0f} s) {'PASS' if scaled < EVAL_LIMIT_S else 'FAIL'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
