"""Expected wall clock of `uavris reproduce --preset paper`, from measured per-step costs.

The ``paper`` preset is sized like the paper (2.5 million env steps per training run, the
DT paper's 100,000 pre-training steps), far too long to time end to end. This script
measures, on one core with one torch thread, the steady-state cost of each part at the
``paper`` preset's sizes and multiplies by the work the study does:

- training: for each algorithm, the seconds per env step after ``learning_starts`` (for
  off-policy algorithms the warm-up has no gradient steps), measured over ``--steps``
  env steps of ``build_model(algo, UavRisVecEnv(...), default_hyperparams(algo, "paper"))``;
  the study trains 5 seeds of each of the four algorithms plus 10 DDPG scenario experts;
- DT pre-training: seconds per step of the ``paper`` pre-training preset (the DT paper's
  size, batch 64), taken by the pipeline's own optimiser and training step on windows cut
  from random episodes, times its 100,000 steps; fine-tuning and evaluation are not
  included (minutes, measured in the quick run).

Training runs are independent jobs, so they spread over workers (the longest-job bound
is reported too); pre-training is one sequential job. Run on an otherwise idle machine::

    .venv/bin/python benchmarks/paper_wallclock.py            # ~5 minutes
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402
from _machine import cpu_model, pin_to_one_core  # noqa: E402  (benchmarks/_machine.py)
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402

from uavris.agents.dt.model import DecisionTransformer  # noqa: E402
from uavris.agents.dt.training import TrainingWindows, make_optimizer, train_steps  # noqa: E402
from uavris.agents.dt.trajectories import Trajectory  # noqa: E402
from uavris.agents.experts import ALGORITHMS, default_hyperparams  # noqa: E402
from uavris.agents.experts.sb3 import build_model  # noqa: E402
from uavris.agents.experts.vec_env import UavRisVecEnv  # noqa: E402
from uavris.config import SystemConfig  # noqa: E402
from uavris.experiments.training.pretrain import PretrainConfig  # noqa: E402
from uavris.presets import PRETRAIN, TRAIN  # noqa: E402

SEEDS_PER_ALGO = 5
SCENARIO_EXPERTS = 10  # 8 training + 2 unseen scenarios, DDPG


class _Clock(BaseCallback):
    """Time from the first vector step past ``start`` to the last one."""

    def __init__(self, start: int) -> None:
        super().__init__()
        self.start, self.t0, self.n0 = start, None, 0

    def _on_step(self) -> bool:
        if self.t0 is None and self.num_timesteps > self.start:
            self.t0, self.n0 = time.perf_counter(), self.num_timesteps
        return True


def seconds_per_env_step(algo: str, steps: int) -> float:
    hp = default_hyperparams(algo, "paper")
    start = hp.learning_starts if algo != "ppo" else 0
    model = build_model(algo, UavRisVecEnv(hp.n_envs, SystemConfig(), "fig2", hp.reward_scale), hp, seed=0)
    clock = _Clock(start)
    model.learn(start + steps, callback=clock)
    return (time.perf_counter() - clock.t0) / (model.num_timesteps - clock.n0)


def seconds_per_pretrain_step(steps: int) -> float:
    """One pre-training step exactly as ``uavris pretrain-dt --preset paper`` takes it (the
    pipeline's own optimiser and step, windows cut from random 100-slot episodes)."""
    system = SystemConfig()
    cfg = PretrainConfig(dataset="<benchmark>", preset="paper")
    rng = np.random.default_rng(0)
    trajs = [Trajectory(rng.standard_normal((system.horizon + 1, system.observation_dim)).astype(np.float32),
                        rng.uniform(-1, 1, (system.horizon, system.action_dim)).astype(np.float32),
                        rng.uniform(0, 30, system.horizon), False, True, "fig2", i) for i in range(32)]
    windows = TrainingWindows(trajs, cfg.model.context)
    model = DecisionTransformer(cfg.model.for_data(system, system.action_dim))
    opt = make_optimizer(model, cfg.learning_rate, cfg.weight_decay)

    def train(first: int, count: int) -> None:
        train_steps(model, opt, windows, rng, first, count, cfg.batch_size, cfg.learning_rate, cfg.warmup_steps,
                    cfg.grad_clip)

    train(0, 5)  # warm-up of the allocator and kernels, not timed
    t0 = time.perf_counter()
    train(5, steps)
    return (time.perf_counter() - t0) / steps


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=4000, help="timed env steps per algorithm (default 4000)")
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2, 8, 32], help="worker counts to tabulate")
    args = p.parse_args(argv)
    pinning = pin_to_one_core()
    torch.set_num_threads(1)
    print(f"# expected wall clock of `reproduce --preset paper`\n\n- cpu: {cpu_model()}; {pinning}; torch threads 1"
          f"\n- command: {' '.join([sys.executable] + sys.argv)}\n")
    total_steps = TRAIN["paper"]["total_steps"]
    print("| part | measured cost | runs x work | core-hours |\n|---|---:|---|---:|")
    jobs_h: list[float] = []
    for algo in ALGORITHMS:
        s = seconds_per_env_step(algo, args.steps)
        runs = SEEDS_PER_ALGO + (SCENARIO_EXPERTS if algo == "ddpg" else 0)
        hours = s * total_steps / 3600
        jobs_h += [hours] * runs
        print(f"| {algo.upper()} training | {s * 1e3:.2f} ms/env step | {runs} x {total_steps:,} steps "
              f"| {runs * hours:.1f} |", flush=True)
    pre_steps = PRETRAIN["paper"]["steps"]
    s = seconds_per_pretrain_step(50)
    pre_h = s * pre_steps / 3600
    print(f"| DT pre-training | {s * 1e3:.0f} ms/step | 1 x {pre_steps:,} steps | {pre_h:.1f} |")
    train_h = sum(jobs_h)
    print(f"\ntraining: {len(jobs_h)} jobs, {train_h:.0f} core-hours; longest job {max(jobs_h):.1f} h\n")
    print("| workers | expected wall clock (h) |\n|---:|---:|")
    for w in args.workers:
        # jobs spread over workers (never faster than the longest job), then the sequential DT stages
        print(f"| {w} | {max(train_h / w, max(jobs_h)) + pre_h:.0f} |")


if __name__ == "__main__":
    main()
