"""Short demo: roll out simple policies and print their average sum rate.

``python -m uavris.demo [--episodes N] [--seed S] [--scenario NAME]``
"""

from __future__ import annotations

import argparse

import numpy as np

from uavris import physics as ph
from uavris.config import SCENARIOS, SystemConfig
from uavris.env import UavRisD2DVectorEnv


def aligned_hover_actions(env: UavRisD2DVectorEnv) -> np.ndarray:
    """Hover (zero acceleration, fixed attitude) and co-phase the RIS for the first active pair."""
    sim, c = env.sim, env.config
    n = sim.num_envs
    first = np.argmax(sim.pairing.reshape(n, -1), axis=1)  # first active link in row-major order
    k, i = first // c.num_users, first % c.num_users
    hk = sim.channels[np.arange(n), k]
    hi = sim.channels[np.arange(n), i]
    target = np.exp(-1j * np.angle(hk * hi))  # r_n that co-phases every element
    cos_k = np.clip(sim.cos_theta[np.arange(n), k], 1e-6, 1.0)[:, None]
    r_pre = ph.preset_for_target(target, cos_k) if c.angle_dependent_reflection else target
    phase = np.mod(np.angle(r_pre), 2 * np.pi)
    act = np.zeros((n, c.action_dim), dtype=np.float32)
    act[:, 3:3 + c.num_elements] = phase / np.pi - 1.0
    return act


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--episodes", type=int, default=32, help="episodes per policy (default 32)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first episode (default 0)")
    p.add_argument("--scenario", default="fig2", choices=sorted(SCENARIOS), help="start position (default fig2)")
    args = p.parse_args(argv)
    if args.episodes < 1:
        p.error("--episodes must be >= 1")
    cfg = SystemConfig()
    print(f"uavris demo: scenario {args.scenario} {SCENARIOS[args.scenario].start}, {args.episodes} episodes, "
          f"T = {cfg.horizon} slots of {cfg.slot_s} s")
    rng = np.random.default_rng(args.seed)
    policies = {
        "random actions": lambda env: rng.uniform(-1, 1, (env.num_envs, cfg.action_dim)).astype(np.float32),
        "hover, co-phased for one active pair": aligned_hover_actions,
    }
    for name, policy in policies.items():
        env = UavRisD2DVectorEnv(args.episodes, cfg, args.scenario, autoreset_mode="SameStep")
        env.reset(seed=args.seed)
        total = np.zeros(args.episodes)
        slots = np.zeros(args.episodes)
        alive = np.ones(args.episodes, dtype=bool)
        while alive.any():
            _, reward, term, trunc, _ = env.step(policy(env))
            total += np.where(alive, reward, 0.0)
            slots += alive
            alive &= ~(term | trunc)
        avg = total / slots
        print(f"  {name:40s} average sum rate {avg.mean():6.2f} bps/Hz (+- {avg.std(ddof=1) / np.sqrt(len(avg)):.2f} s.e.)")


if __name__ == "__main__":
    main()
