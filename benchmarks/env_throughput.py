"""Single-core throughput of the ``uavris/UavRisD2D-v1`` environments, in env-steps/s.

Five configurations are measured, all in this one process pinned to a single CPU with
BLAS/OpenMP limited to one thread:

1. the single environment, ``gymnasium.make("uavris/UavRisD2D-v1")``;
2. ``gymnasium.vector.SyncVectorEnv`` of 64 single environments;
3. ``gymnasium.vector.SyncVectorEnv`` of 1024 single environments;
4. the natively batched ``uavris.env.UavRisD2DVectorEnv`` with 64 environments;
5. the natively batched ``uavris.env.UavRisD2DVectorEnv`` with 1024 environments.

One *env-step* is one environment advancing one slot, so a vector step of N
environments counts N env-steps. Every configuration is driven by pre-generated, seeded
float32 actions uniform in [-1, 1], stepped through a warm-up, then timed over a fixed
number of steps (best of ``--repeats`` consecutive timings). Episodes end as they would
in training: the vector environments auto-reset themselves (Gymnasium's default
next-step mode), and the single environment is reset whenever it reports
``terminated`` or ``truncated``; those resets are inside the timed loop.

The baselines (1-3) run before any batched environment is built, because the batched
simulator tunes glibc's allocator for the whole process when it is constructed.

The script prints the machine, the command line, a Markdown table and two PASS/FAIL
lines against the targets (batched@1024 at least 10x SyncVectorEnv@1024, and at least
200,000 env-steps/s). It always exits with status 0: it is a report, not a test.

Run from the repository root::

    .venv/bin/python benchmarks/env_throughput.py              # ~1-2 minutes
    .venv/bin/python benchmarks/env_throughput.py --quick      # ~15 seconds
    .venv/bin/python benchmarks/env_throughput.py --repeats 5  # best of 5 timings
"""

from __future__ import annotations

import os

# Limit numerical libraries to one thread. This has to happen before numpy (and the
# BLAS it loads) is imported anywhere in the process, hence before the imports below.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
for _variable in THREAD_VARIABLES:
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import gc  # noqa: E402
import platform  # noqa: E402
import shlex  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from enum import Enum  # noqa: E402
from typing import Any  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
from _machine import cpu_model, pin_to_one_core  # noqa: E402  (benchmarks/_machine.py)
from numpy.typing import NDArray  # noqa: E402

import uavris  # noqa: E402  (registers the environment id)

SEED = 0
ACTION_POOL_BATCHES = 256  # pre-generated action batches, cycled through when stepping
RATIO_TARGET = 10.0
THROUGHPUT_TARGET = 200_000.0


class Kind(Enum):
    SINGLE = "single env (gymnasium.make)"
    SYNC = "SyncVectorEnv"
    BATCHED = "batched UavRisD2DVectorEnv"


@dataclass(frozen=True)
class Case:
    """One configuration and how many (vector) steps to time in each mode."""

    kind: Kind
    num_envs: int
    full_steps: int
    quick_steps: int

    @property
    def name(self) -> str:
        return f"{self.kind.value} @ {self.num_envs}" if self.kind is not Kind.SINGLE else self.kind.value

    def timed_steps(self, quick: bool) -> int:
        return self.quick_steps if quick else self.full_steps


@dataclass(frozen=True)
class Result:
    case: Case
    env_steps_per_s: float
    timings_s: list[float]
    timed_env_steps: int


# Steps are chosen so one timing takes roughly 2-7 s in a full run (about 20 s per
# repeat) and under 4 s with --quick, on a core doing ~3k single-env steps/s.
# Baselines come first; see the module docstring.
CASES: tuple[Case, ...] = (
    Case(Kind.SINGLE, 1, full_steps=12_000, quick_steps=5_000),
    Case(Kind.SYNC, 64, full_steps=200, quick_steps=100),
    Case(Kind.SYNC, 1024, full_steps=16, quick_steps=8),
    Case(Kind.BATCHED, 64, full_steps=3_000, quick_steps=1_000),
    Case(Kind.BATCHED, 1024, full_steps=800, quick_steps=300),
)


def make_env(case: Case) -> Any:
    """Build the environment of one configuration."""
    if case.kind is Kind.SINGLE:
        return gym.make(uavris.ENV_ID)
    if case.kind is Kind.SYNC:
        return gym.vector.SyncVectorEnv([lambda: gym.make(uavris.ENV_ID)] * case.num_envs)
    return gym.make_vec(uavris.ENV_ID, num_envs=case.num_envs, vectorization_mode="vector_entry_point")


def make_actions(case: Case, action_dim: int, num_batches: int, seed: int) -> NDArray[np.float32]:
    """Seeded uniform actions in [-1, 1], shape (batches, action_dim) or (batches, N, action_dim)."""
    shape = (num_batches, action_dim) if case.kind is Kind.SINGLE else (num_batches, case.num_envs, action_dim)
    return np.random.default_rng(seed).uniform(-1.0, 1.0, size=shape).astype(np.float32)


def stepper(env: Any, case: Case, actions: NDArray[np.float32]) -> Callable[[int], None]:
    """A function running ``n`` (vector) steps of ``env``, continuing from previous calls."""
    pool = len(actions)
    counter = 0

    def run_single(n: int) -> None:
        nonlocal counter
        for i in range(counter, counter + n):
            _, _, terminated, truncated, _ = env.step(actions[i % pool])
            if terminated or truncated:
                env.reset()
        counter += n

    def run_vector(n: int) -> None:
        nonlocal counter
        for i in range(counter, counter + n):
            env.step(actions[i % pool])
        counter += n

    return run_single if case.kind is Kind.SINGLE else run_vector


def measure(case: Case, quick: bool, repeats: int, seed: int) -> Result:
    """Warm up, then time ``repeats`` windows of the case's step count; keep the best."""
    steps = case.timed_steps(quick)
    warmup = max(2, steps // 10)
    env = make_env(case)
    action_dim = uavris.SystemConfig().action_dim
    actions = make_actions(case, action_dim, min(steps + warmup, ACTION_POOL_BATCHES), seed)
    env.reset(seed=seed)
    run = stepper(env, case, actions)
    run(warmup)
    timings: list[float] = []
    for _ in range(repeats):
        gc.collect()
        start = time.perf_counter()
        run(steps)
        timings.append(time.perf_counter() - start)
    env.close()
    env_steps = steps * case.num_envs
    return Result(case, env_steps / min(timings), timings, env_steps)


def format_rate(rate: float) -> str:
    return f"{rate:,.0f}"


def report(results: list[Result], repeats: int) -> None:
    """Print the Markdown table and the two target checks."""
    sync_rate = {r.case.num_envs: r.env_steps_per_s for r in results if r.case.kind is Kind.SYNC}
    rows = [("configuration", "num_envs", "env-steps/s", "vs SyncVectorEnv at same num_envs")]
    for r in results:
        baseline = sync_rate.get(r.case.num_envs)
        relative = "n/a" if r.case.kind is Kind.SINGLE or baseline is None else f"{r.env_steps_per_s / baseline:.1f}x"
        rows.append((r.case.kind.value, str(r.case.num_envs), format_rate(r.env_steps_per_s), relative))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    right = (False, True, True, True)

    def line(cells: tuple[str, ...]) -> str:
        padded = (c.rjust(w) if r else c.ljust(w) for c, w, r in zip(cells, widths, right))
        return "| " + " | ".join(padded) + " |"

    print(line(rows[0]))
    print("|" + "|".join(("-" * (w + 1) + ":") if r else ("-" * (w + 2)) for w, r in zip(widths, right)) + "|")
    for row in rows[1:]:
        print(line(row))
    print()
    print(f"Best of {repeats} timing(s) per configuration; timed env-steps per timing: "
          + ", ".join(f"{r.case.name}: {r.timed_env_steps:,}" for r in results) + ".")
    print()

    batched = next(r for r in results if r.case.kind is Kind.BATCHED and r.case.num_envs == 1024)
    ratio = batched.env_steps_per_s / sync_rate[1024]
    print(f"batched@1024 / SyncVectorEnv@1024 = {ratio:.1f}x (target >= {RATIO_TARGET:.0f}x) "
          f"{'PASS' if ratio >= RATIO_TARGET else 'FAIL'}")
    print(f"batched@1024 = {format_rate(batched.env_steps_per_s)} env-steps/s "
          f"(target >= {format_rate(THROUGHPUT_TARGET)}) "
          f"{'PASS' if batched.env_steps_per_s >= THROUGHPUT_TARGET else 'FAIL'}")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer steps and one timing (~15 s)")
    parser.add_argument("--repeats", type=int, default=None,
                        help="timings per configuration, the best is kept (default: 3, or 1 with --quick)")
    parser.add_argument("--seed", type=int, default=SEED, help="seed of the actions and environment resets")
    args = parser.parse_args(argv)
    if args.repeats is None:
        args.repeats = 1 if args.quick else 3
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    pinning = pin_to_one_core()
    threads = ", ".join(f"{v}={os.environ[v]}" for v in THREAD_VARIABLES)

    print("# uavris environment throughput (one core)")
    print()
    print(f"- command: {shlex.join([sys.executable, *sys.argv])}")
    print(f"- cpu: {cpu_model()} (platform.processor: {platform.processor() or 'n/a'}); {pinning}; {threads}")
    print(f"- platform: {platform.platform()}")
    print(f"- python {platform.python_version()}, numpy {np.__version__}, gymnasium {gym.__version__}, "
          f"uavris {uavris.__version__}")
    print(f"- mode: {'quick' if args.quick else 'full'}, repeats: {args.repeats}, seed: {args.seed}")
    print(flush=True)

    results: list[Result] = []
    for index, case in enumerate(CASES):
        print(f"measuring {case.name} ...", end=" ", file=sys.stderr, flush=True)
        result = measure(case, args.quick, args.repeats, args.seed + index)
        timings = ", ".join(f"{t:.2f}" for t in result.timings_s)
        print(f"{format_rate(result.env_steps_per_s)} env-steps/s (timings {timings} s)", file=sys.stderr, flush=True)
        results.append(result)
    report(results, args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
