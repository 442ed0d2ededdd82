"""Does a warm-started phase optimiser pay along a trajectory? Single core.

Feeds docs/performance.md.

The per-slot optimiser (:func:`uavris.physics.phase_opt.optimize_slot_phases`) solves
every slot from scratch: one co-phasing start per active link and 2 random starts, a
noise continuation over 7 levels (1e6 ... 1 times sigma^2), 30 L-BFGS iterations each,
and a null polish. Along a trajectory the UAV moves little from one slot to the next, so
the solution of the last slot with the same active links might be a good start
(``warm=``). This script measures it on the slots of the study's own rollouts:

- the planning oracle (``PlanningOracle()``) in the first 4 unseen generated halls
  (``LayoutGenerator(devices=4, seed=0)``, ``SystemConfig(observe_devices=True)``);
- the plan of the nearest training hall (by ``layout_distance``, among the quick study's
  512 training halls), flown in each of those halls (``PlannedFlight``);
- the planning oracle in the strong track's scenarios fig2, unseen1, unseen2 of
  ``SystemConfig()``;

8 episodes each from seed 1,000,000 (the evaluation seeds), the channels, incidence
cosines, pairing, position and alive mask copied every slot by ``rollout``'s ``on_slot``
hook. Then every multi-pair slot (one active pair has a closed form) is solved, slot by
slot in the order of the episodes (each call holds the episodes' slots of one slot index,
as a rollout would call it), by the full multi-start and by warm starts: ``W`` holds, per
row, the phases of the last solution of the same set of active links in that episode, NaN
where there is none (such slots get the full method). Variants: the warm levels, the
L-BFGS iterations per level, and where ``W`` comes from: the full solution of the previous
occurrence (the best case: the warm start is as good as it gets) or the variant's own
previous solution (the real case, a chain of warm starts).

Reported per variant: slots/s against the full multi-start (the time of the optimiser
calls only, best of ``--repeats`` passes, the variants interleaved), the mean sum rate
relative to the full multi-start's over all multi-pair slots, and the median and worst-1%
per-slot loss over the warm-started slots. Target: >= 5x the slots/s and a mean within
0.1%. The script prints the machine, the command, Markdown tables and PASS/FAIL lines; it
always exits 0: it is a report, not a test.

Run from the repository root::

    .venv/bin/python benchmarks/findings/warm_start.py            # ~1 minute
    .venv/bin/python benchmarks/findings/warm_start.py --quick    # ~20 seconds: 2 episodes per rollout, 1 timing
"""

from __future__ import annotations

import os
import pathlib

# Limit numerical libraries to one thread before numpy (and its BLAS) is imported.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
for _variable in THREAD_VARIABLES:
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import platform  # noqa: E402
import shlex  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # benchmarks/, for _machine.py
from _machine import cpu_model, pin_to_one_core, table  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

import uavris  # noqa: E402
from uavris.agents.oracle import PlanningOracle  # noqa: E402
from uavris.agents.oracle.policy import PlannedFlight  # noqa: E402
from uavris.config import SystemConfig  # noqa: E402
from uavris.env.rollout import rollout  # noqa: E402
from uavris.layouts import LayoutGenerator, layout_distance, nearest_layout  # noqa: E402
from uavris.physics.phase_opt import DEFAULT_NOISE_LEVELS, optimize_slot_phases, sum_rate_and_gradient  # noqa: E402
from uavris.presets import EVAL_SEED  # noqa: E402

HALLS = 4  # the first unseen generated halls
TRAIN_HALLS = 512  # the quick study's training halls, among which the nearest is chosen
STRONG_SCENARIOS = ("fig2", "unseen1", "unseen2")
EPISODES = 8
SPEED_TARGET = 5.0
QUALITY_TARGET = 0.001


@dataclass(frozen=True)
class Variant:
    name: str
    levels: tuple[float, ...]
    iterations: int
    source: str  # "full": the previous occurrence's full solution (best case); "own": the variant's own

    @property
    def label(self) -> str:
        levels = "(1.0,)" if self.levels == (1.0,) else ("1e6 ... 1.0 (all 7)" if self.levels == DEFAULT_NOISE_LEVELS
                                                         else "(" + ", ".join(f"{x:g}" for x in self.levels) + ")")
        source = "full solution (best case)" if self.source == "full" else "its own (real case)"
        return f"{self.name}: levels {levels}, {self.iterations} it., warm from {source}"


VARIANTS = (
    Variant("A", (1.0,), 30, "full"),
    Variant("A", (1.0,), 30, "own"),
    Variant("B", (1.0,), 100, "full"),
    Variant("C", (1e2, 1e1, 1.0), 30, "full"),
    # A copy of the levels: optimize_phases tells the full method from a warm start by the
    # identity of the levels tuple (``levels is noise_levels``), so DEFAULT_NOISE_LEVELS itself
    # as warm_levels would silently solve the warm-started slots from scratch.
    Variant("D", tuple(float(x) for x in DEFAULT_NOISE_LEVELS), 30, "full"),
)


@dataclass
class Slots:
    """Every recorded slot, ``(episodes, T, ...)``, with where its episode came from."""

    channels: NDArray[np.complex128]
    cos_theta: NDArray[np.float64]
    pairing: NDArray[np.float64]
    pos: NDArray[np.float64]
    alive: NDArray[np.bool_]
    group: list[str]  # per episode

    @property
    def multi(self) -> NDArray[np.bool_]:
        return self.alive & (self.pairing.sum(axis=(-2, -1)) >= 2)


def record(policy: Any, system: SystemConfig, scenario: Any, seeds: NDArray[np.int64], name: str) -> Slots:
    frames: list[tuple[NDArray, ...]] = []

    def hook(sim: Any, obs: Any, actions: Any, alive: NDArray[np.bool_]) -> None:
        frames.append((sim.channels.copy(), sim.cos_theta.copy(), sim.pairing.copy(), sim.pos.copy(), alive.copy()))

    rollout(policy, system, scenario, seeds, on_slot=hook)
    arrays = [np.stack([f[i] for f in frames], axis=1) for i in range(5)]
    return Slots(*arrays, group=[name] * len(seeds))


def concatenate(parts: list[Slots]) -> Slots:
    t = max(p.alive.shape[1] for p in parts)

    def pad(x: NDArray) -> NDArray:
        return np.concatenate([x, np.zeros((x.shape[0], t - x.shape[1]) + x.shape[2:], x.dtype)], axis=1)

    fields = [np.concatenate([pad(getattr(p, f)) for p in parts]) for f in ("channels", "cos_theta", "pairing", "pos",
                                                                           "alive")]
    return Slots(*fields, group=[g for p in parts for g in p.group])


def record_all(episodes: int) -> tuple[Slots, list[tuple[str, str, float]]]:
    """The slots of every rollout (module docstring) and, per hall, its nearest training hall."""
    seeds = EVAL_SEED + np.arange(episodes)
    oracle = PlanningOracle()
    gen = LayoutGenerator(devices=4, seed=0)
    base = SystemConfig(observe_devices=True)
    train = gen.layouts("train", TRAIN_HALLS, base)
    parts, nearest = [], []
    for j in range(HALLS):
        hall = gen.layout("unseen", j, base)
        system, scenario = hall.resolve(base)
        print(f"recording {hall.name}: oracle, nearest hall's plan ...", file=sys.stderr, flush=True)
        parts.append(record(oracle, system, scenario, seeds, f"oracle, {hall.name}"))
        other = nearest_layout(hall, train)
        nearest.append((hall.name, other.name, layout_distance(hall, other)))
        other_system, other_scenario = other.resolve(base)
        flight = PlannedFlight(oracle.plan(other_system, other_scenario.start))
        parts.append(record(flight, system, scenario, seeds, f"plan of {other.name}, {hall.name}"))
    for name in STRONG_SCENARIOS:
        print(f"recording {name}: oracle ...", file=sys.stderr, flush=True)
        parts.append(record(oracle, SystemConfig(), name, seeds, f"oracle, {name}"))
    return concatenate(parts), nearest


def previous_of(slots: Slots, phases: NDArray[np.float64]) -> NDArray[np.float64]:
    """``W`` per slot: ``phases`` of the last multi-pair slot of the episode with the same
    active links (the same pairing matrix), NaN where there is none."""
    e_count, t_count = slots.alive.shape
    warm = np.full(phases.shape, np.nan)
    multi = slots.multi
    for e in range(e_count):
        last: dict[bytes, NDArray[np.float64]] = {}
        for t in np.flatnonzero(multi[e]):
            key = slots.pairing[e, t].tobytes()
            if key in last:
                warm[e, t] = last[key]
            last[key] = phases[e, t]
    return warm


def solve(slots: Slots, config: SystemConfig, variant: Variant | None, best_warm: NDArray[np.float64] | None
          ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Every multi-pair slot, slot index by slot index: (phases, sum rates, seconds in the
    optimiser's calls). ``variant`` None: the full multi-start."""
    e_count, t_count = slots.alive.shape
    n = slots.channels.shape[-1]
    phases, rates = np.full((e_count, t_count, n), np.nan), np.full((e_count, t_count), np.nan)
    multi = slots.multi
    last: list[dict[bytes, NDArray[np.float64]]] = [{} for _ in range(e_count)]
    seconds = 0.0
    for t in range(t_count):
        rows = np.flatnonzero(multi[:, t])
        if not rows.size:
            continue
        kwargs: dict[str, Any] = {}
        if variant is not None:
            if variant.source == "full":
                assert best_warm is not None
                warm = best_warm[rows, t]
            else:
                warm = np.array([last[e].get(slots.pairing[e, t].tobytes(), np.full(n, np.nan)) for e in rows])
            kwargs = dict(warm=warm, warm_levels=variant.levels, warm_iterations=variant.iterations)
        start = time.perf_counter()
        sol = optimize_slot_phases(config, slots.channels[rows, t], slots.cos_theta[rows, t], slots.pairing[rows, t],
                                   **kwargs)
        seconds += time.perf_counter() - start
        phases[rows, t], rates[rows, t] = sol.phases, sol.sum_rate
        for i, e in enumerate(rows):
            last[e][slots.pairing[e, t].tobytes()] = sol.phases[i]
    return phases, rates, seconds


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 episodes per rollout, one timing")
    parser.add_argument("--episodes", type=int, default=None, help="episodes per rollout (default 8)")
    parser.add_argument("--repeats", type=int, default=None, help="timed passes per variant, best kept (default 3)")
    args = parser.parse_args(argv)
    episodes = args.episodes or (2 if args.quick else EPISODES)
    repeats = args.repeats or (1 if args.quick else 3)

    pinning = pin_to_one_core()
    config = SystemConfig()
    print("# Warm-started phase optimiser along trajectories (one core)")
    print()
    print(f"- command: {shlex.join([sys.executable, *sys.argv])}")
    print(f"- cpu: {cpu_model()}; {pinning}; " + ", ".join(f"{v}={os.environ[v]}" for v in THREAD_VARIABLES))
    print(f"- platform: {platform.platform()}; python {platform.python_version()}, numpy {np.__version__}, "
          f"uavris {uavris.__version__}")
    print(f"- rollouts: the planning oracle in the first {HALLS} unseen generated halls and the nearest training "
          f"hall's plan flown there (SystemConfig(observe_devices=True)); the oracle in "
          f"{', '.join(STRONG_SCENARIOS)} (SystemConfig()); {episodes} episodes each from seed {EVAL_SEED:,}")
    print(f"- mode: {'quick' if args.quick else 'full'}; best of {repeats} timed passes per variant")
    print(flush=True)

    slots, nearest = record_all(episodes)
    for other in (SystemConfig(observe_devices=True),):  # one optimiser problem for every recorded slot
        assert (other.tx_power_w, other.noise_w, other.angle_dependent_reflection) == \
            (config.tx_power_w, config.noise_w, config.angle_dependent_reflection)
    multi = slots.multi
    optimize_slot_phases(config, slots.channels[multi][:4], slots.cos_theta[multi][:4],
                         slots.pairing[multi][:4])  # compile (or load the cache) and warm up

    print("solving the full multi-start ...", file=sys.stderr, flush=True)
    full_phi, full_rate, _ = solve(slots, config, None, None)
    best_warm = previous_of(slots, full_phi)
    has_warm = multi & np.all(np.isfinite(best_warm), axis=-1)
    timings: dict[str, float] = {"full": float("inf")}
    results: dict[str, NDArray[np.float64]] = {}
    for rep in range(repeats):
        print(f"timed pass {rep + 1} of {repeats} ...", file=sys.stderr, flush=True)
        _, _, t_full = solve(slots, config, None, None)
        timings["full"] = min(timings["full"], t_full)
        for v in VARIANTS:
            _, rate, seconds = solve(slots, config, v, best_warm)
            timings[v.label] = min(timings.get(v.label, float("inf")), seconds)
            results[v.label] = rate

    # The previous occurrence's full solution applied unchanged (no optimisation): how far the slot moved.
    reuse = np.full(full_rate.shape, np.nan)
    reuse[has_warm], _ = sum_rate_and_gradient(best_warm[has_warm], slots.channels[has_warm],
                                               slots.cos_theta[has_warm], slots.pairing[has_warm], config.tx_power_w,
                                               config.noise_w, config.angle_dependent_reflection, need_gradient=False)

    count, warm_count = int(multi.sum()), int(has_warm.sum())
    print("## Recorded slots")
    print()
    rows = [("rollout", "episodes", "slots", "multi-pair slots", "with a warm start")]
    for group in dict.fromkeys(slots.group):
        sel = np.array([g == group for g in slots.group])
        rows.append((group, f"{sel.sum()}", f"{int(slots.alive[sel].sum()):,}", f"{int(multi[sel].sum()):,}",
                     f"{int(has_warm[sel].sum()):,}"))
    rows.append(("all", f"{len(slots.group)}", f"{int(slots.alive.sum()):,}", f"{count:,}", f"{warm_count:,}"))
    print(table(rows))
    print()
    print("nearest training hall (layout distance, m): " + "; ".join(f"{a} -> {b} ({d:.2f})" for a, b, d in nearest))
    moved = np.linalg.norm(np.diff(slots.pos, axis=1), axis=-1)[slots.alive[:, 1:]]
    print(f"UAV movement between consecutive slots: median {np.median(moved):.3f} m, 90th percentile "
          f"{np.percentile(moved, 90):.3f} m")
    print()

    ref_mean = float(full_rate[multi].mean())
    print("## Warm starts against the full multi-start")
    print()
    print(f"{count:,} multi-pair slots, {warm_count:,} of them with a warm start (the others get the full method in "
          "every variant); per-slot loss = 1 - rate / full multi-start's rate, over the warm-started slots; time: the "
          "optimiser's calls only")
    print()
    rows = [("variant", "time (s)", "slots/s", "speed vs full", "mean sum rate (bps/Hz)", "vs full (all multi-pair)",
             "mean loss (warm slots)", "median loss", "worst-1% loss")]
    t_full = timings["full"]
    rows.append(("full multi-start (2 co-phasing + 2 random starts, 7 levels x 30 it.)", f"{t_full:.2f}",
                 f"{count / t_full:,.0f}", "1.00x", f"{ref_mean:.3f}", "0.000%", "", "", ""))
    verdicts = []
    for v in VARIANTS:
        rate, seconds = results[v.label], timings[v.label]
        rel = float(rate[multi].mean()) / ref_mean - 1.0
        loss = 1.0 - rate[has_warm] / full_rate[has_warm]
        speed = t_full / seconds
        rows.append((v.label, f"{seconds:.2f}", f"{count / seconds:,.0f}", f"{speed:.2f}x",
                     f"{rate[multi].mean():.3f}", f"{rel:+.3%}", f"{loss.mean():.2%}", f"{np.median(loss):.2%}",
                     f"{np.percentile(loss, 99):.1%}"))
        verdicts.append((v.label, speed, rel))
    loss = 1.0 - reuse[has_warm] / full_rate[has_warm]
    rel = float(np.where(has_warm, reuse, full_rate)[multi].mean()) / ref_mean - 1.0
    rows.append(("previous full solution reused as is (no optimisation)", "", "", "", "", f"{rel:+.3%}",
                 f"{loss.mean():.2%}", f"{np.median(loss):.2%}", f"{np.percentile(loss, 99):.1%}"))
    print(table(rows))
    print()
    for label, speed, rel in verdicts:
        ok = speed >= SPEED_TARGET and abs(rel) <= QUALITY_TARGET
        print(f"{label}: {speed:.2f}x the slots/s, mean sum rate {rel:+.3%} (target >= {SPEED_TARGET:.0f}x and "
              f"within {QUALITY_TARGET:.1%}) {'PASS' if ok else 'FAIL'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
