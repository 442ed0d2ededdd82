"""Short demo: the zero action, random actions and a co-phasing hover, side by side.

``uavris demo [--episodes N] [--seed S] [--scenario NAME]`` or ``python -m uavris.experiments.tools.demo``.
Lives here: the demo's choice of policies and its printout. Not here: the policies
(:mod:`uavris.agents.references`) and the rollout (:func:`uavris.agents.evaluation.evaluate`).
"""

from __future__ import annotations

from uavris.agents.evaluation import check_episodes, evaluate
from uavris.agents.references import REFERENCES, reference_policy
from uavris.config import Scenario, SystemConfig, get_scenario

DEMO_POLICIES = ("hover", "random", "hover-aligned")


def run_demo(episodes: int = 32, seed: int = 0, scenario: str | Scenario = "fig2",
             system: SystemConfig | None = None) -> dict[str, float]:
    """Print and return each demo policy's mean average sum rate over ``episodes`` seeded episodes
    of ``system`` (default: the paper's)."""
    check_episodes(episodes, seed)
    cfg = system or SystemConfig()
    where = get_scenario(scenario)
    where.validate_for(cfg)
    print(f"uavris demo: scenario {where.name} {[round(c, 2) for c in where.start]}, {episodes} episodes, "
          f"T = {cfg.horizon} slots of {cfg.slot_s} s")
    means = {}
    for name in DEMO_POLICIES:
        res = evaluate(reference_policy(name, cfg), cfg, where, episodes, seed)
        s = res.summary()
        means[name] = s["mean"]
        print(f"  {REFERENCES[name].label:42s} average sum rate {s['mean']:6.2f} bps/Hz "
              f"(95% CI {s['ci_low']:.2f}-{s['ci_high']:.2f})")
    return means

