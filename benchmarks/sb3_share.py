"""Where an SB3 expert's training time goes: the environment or the learner.

For each algorithm of the comparison at the quick preset (its networks, batch, ``n_envs`` and
one gradient step per environment step), on one core: the seconds per environment step of
``model.learn`` against the seconds per environment step of the same batched environment
(:class:`uavris.agents.experts.vec_env.UavRisVecEnv`) stepped alone with random actions, and
what larger ``n_envs`` would change (the same gradient steps per environment step, more
environments per vector step). Prints a Markdown table; always exits 0.

Run: ``.venv/bin/python benchmarks/sb3_share.py`` (about 2 minutes).
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import shlex  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402
from _machine import cpu_model, pin_to_one_core, table  # noqa: E402  (benchmarks/_machine.py)

from uavris.agents.experts.sb3 import build_model  # noqa: E402
from uavris.agents.experts.vec_env import UavRisVecEnv  # noqa: E402
from uavris.experiments.training.train_expert import TrainConfig  # noqa: E402


def env_alone(cfg: TrainConfig, steps: int) -> float:
    """Seconds per environment step of the batched environment with random actions."""
    env = UavRisVecEnv(cfg.hyperparams.n_envs, cfg.system, cfg.resolved_scenario, cfg.hyperparams.reward_scale,
                       cfg.phase_control)
    env.seed(0)
    env.reset()
    rng = np.random.default_rng(0)
    n = cfg.hyperparams.n_envs
    t = time.perf_counter()
    for _ in range(steps // n):
        env.step(rng.uniform(-1, 1, (n, env.action_space.shape[0])).astype(np.float32))
    return (time.perf_counter() - t) / (steps // n * n)


def learner(cfg: TrainConfig, steps: int) -> float:
    """Seconds per environment step of SB3's learn() on that environment (after its warm-up)."""
    env = UavRisVecEnv(cfg.hyperparams.n_envs, cfg.system, cfg.resolved_scenario, cfg.hyperparams.reward_scale,
                       cfg.phase_control)
    env.seed(0)
    model = build_model(cfg.algo, env, cfg.hyperparams, 0, None, "cpu")
    model.learn(cfg.hyperparams.learning_starts + 2 * cfg.hyperparams.n_envs)  # past learning_starts
    t = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    return (time.perf_counter() - t) / steps


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000, help="environment steps timed per case")
    args = parser.parse_args(argv)
    pinning = pin_to_one_core()
    torch.set_num_threads(1)
    print("# Where an SB3 expert's training time goes (one core, quick preset)\n")
    print(f"- command: {shlex.join([sys.executable, *sys.argv])}")
    print(f"- machine: {cpu_model()}; {pinning}\n")
    rows = [("algorithm", "n_envs", "learn, ms per env step", "env alone, ms per env step", "env's share")]
    for algo in ("ddpg", "td3", "sac", "ppo"):
        base = TrainConfig(algo=algo, preset="quick")
        for n_envs in ((base.hyperparams.n_envs, 4 * base.hyperparams.n_envs) if algo != "ppo" else
                       (base.hyperparams.n_envs,)):
            hp = replace(base.hyperparams, n_envs=n_envs, gradient_steps=n_envs if algo != "ppo" else
                         base.hyperparams.gradient_steps)
            cfg = replace(base, hyperparams=hp)
            steps = args.steps * (10 if algo == "ppo" else 1)
            learn_s, env_s = learner(cfg, steps), env_alone(cfg, steps)
            rows.append((algo, str(n_envs), f"{1e3 * learn_s:.3f}", f"{1e3 * env_s:.3f}", f"{env_s / learn_s:.1%}"))
    print(table(rows))
    print("\nThe off-policy learners take one gradient step per environment step (docs/experts.md); a larger n_envs "
          "keeps that ratio, so it changes the time per step only by the batching of the environment.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
