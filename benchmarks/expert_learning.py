"""Does each track's expert beat its own baseline? Learning, measured against named references.

In one process pinned to one core, on the same seeded evaluation episodes of fig2
(``--episodes``, default 32, seed 1,000,000):

1. Paper track: PPO (the quick comparison's winner by IQM), end to end on all 22 action
   entries, quick hyperparameters, at several budgets (``--ppo-steps``), against the zero
   action (``hover``) and random actions.
2. Strong track: the imitation expert (PPO on the 6 motion entries, DAgger from the planning
   oracle, the quick preset's 6 rounds of 32 episodes), and hybrid PPO from scratch on the
   motion entries (``--hybrid-steps``), against hovering with the optimiser's phases and the
   oracle.

For every learned policy it prints its score over its baseline's (a ratio; above 1.00 means
it beats the baseline) and whether the 95% CIs separate. It always exits with status 0.

    .venv/bin/python benchmarks/expert_learning.py       # ~6 minutes
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import platform  # noqa: E402
import shlex  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from _machine import cpu_model, pin_to_one_core  # noqa: E402  (benchmarks/_machine.py)

import uavris  # noqa: E402
from uavris.agents.evaluation import evaluate  # noqa: E402
from uavris.agents.experts.imitation import ImitationConfig  # noqa: E402
from uavris.agents.references import reference_policy  # noqa: E402
from uavris.config import SystemConfig  # noqa: E402
from uavris.experiments.training.train_expert import TrainConfig, train  # noqa: E402
from uavris.io import read_json  # noqa: E402
from uavris.presets import EVAL_SEED  # noqa: E402


def verdict(s: dict, base: dict) -> str:
    ratio = s["mean"] / base["mean"]
    sep = "above" if s["ci_low"] > base["ci_high"] else "below" if s["ci_high"] < base["ci_low"] else "CIs overlap"
    return f"{ratio:.2f}x ({sep})"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--ppo-steps", type=int, nargs="+", default=[50_000, 200_000, 500_000])
    parser.add_argument("--hybrid-steps", type=int, default=150_000)
    args = parser.parse_args(argv)
    pinning = pin_to_one_core()
    config = SystemConfig()
    print("# uavris experts against their baselines (fig2, one core)")
    print()
    print(f"- command: {shlex.join([sys.executable, *sys.argv])}")
    print(f"- cpu: {cpu_model()}; {pinning}; python {platform.python_version()}, uavris {uavris.__version__}")
    print(f"- evaluation: {args.episodes} seeded episodes from seed {EVAL_SEED}, the same for every policy")
    print(flush=True)
    refs = {name: evaluate(reference_policy(name), config, "fig2", args.episodes, EVAL_SEED).summary()
            for name in ("zero-action", "random", "hover-optimizer", "oracle")}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        def run(name: str, cfg, baseline: str) -> None:
            print(f"training {name} ...", file=sys.stderr, flush=True)
            start = time.perf_counter()
            train(cfg, Path(tmp) / name, progress=False)
            wall = time.perf_counter() - start
            s = read_json(Path(tmp) / name / "done.json")["final_eval"]
            rows.append((name, wall, s, baseline))

        for steps in args.ppo_steps:
            run(f"paper track: PPO, {steps:,} env steps", TrainConfig(algo="ppo", scenario="fig2", seed=0,
                                                                      preset="quick", total_steps=steps,
                                                                         eval_episodes=args.episodes), "zero-action")
        run("strong track: imitation of the oracle (6 rounds x 32 episodes)",
            TrainConfig(algo="ppo", scenario="fig2", seed=0, preset="quick", total_steps=0, eval_episodes=args.episodes,
                          phase_control="optimizer", imitation=ImitationConfig()), "hover-optimizer")
        run(f"strong track alternative: hybrid PPO from scratch, {args.hybrid_steps:,} env steps",
            TrainConfig(algo="ppo", scenario="fig2", seed=0, preset="quick", total_steps=args.hybrid_steps,
                        eval_episodes=args.episodes,
                          phase_control="optimizer"), "hover-optimizer")
    print("| policy | training (s) | average sum rate | 95% CI | vs its baseline | vs random | fraction of oracle |")
    print("|---|---:|---:|---|---|---|---:|")
    for name, wall, s, baseline in rows:
        print(f"| {name} | {wall:.0f} | {s['mean']:.2f} | {s['ci_low']:.2f}-{s['ci_high']:.2f} | "
              f"{baseline}: {verdict(s, refs[baseline])} | {verdict(s, refs['random'])} | "
              f"{s['mean'] / refs['oracle']['mean']:.0%} |")
    for name, s in refs.items():
        print(f"| reference: {name} | - | {s['mean']:.2f} | {s['ci_low']:.2f}-{s['ci_high']:.2f} | | | "
              f"{s['mean'] / refs['oracle']['mean']:.0%} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
