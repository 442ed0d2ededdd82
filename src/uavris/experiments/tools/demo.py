"""Short demo: the zero action, random actions and a co-phasing hover, side by side.

``uavris demo [--episodes N] [--seed S] [--scenario NAME] [--layout L] [--system.FIELD V]``.
Lives here: the demo's choice of policies and its printout. Not here: the policies
(:mod:`uavris.agents.references`) and the rollout (:func:`uavris.agents.evaluation.evaluate`).
"""

from __future__ import annotations

import math

from uavris.agents.evaluation import check_episodes, evaluate
from uavris.agents.references import REFERENCES, reference_policy
from uavris.config import SCENARIOS, Scenario, SystemConfig, get_scenario
from uavris.experiments.display.tables import counted, rate_interval
from uavris.experiments.tools.evaluate import hall_name
from uavris.physics import propulsion_power

DEMO_POLICIES = ("zero-action", "random", "hover-aligned")


def horizon_text(cfg: SystemConfig) -> str:
    """How long an episode lasts: T slots, or until the energy budget is spent, with the slot in
    which hovering (the least power a UAV that stays aloft draws, P(0)) spends it."""
    text = f"T = {cfg.horizon} slots of {cfg.slot_s:g} s"
    per_slot = float(propulsion_power(0.0, **cfg.propulsion.to_dict())) * cfg.slot_s
    hover_slots = math.ceil(cfg.energy_budget_j / per_slot)  # the episode ends once the energy used reaches the budget
    if hover_slots >= cfg.horizon:
        return text
    return f"{text}, or until the {cfg.energy_budget_j:,.0f} J energy budget is spent (hovering: slot {hover_slots})"


def where_text(cfg: SystemConfig, where: Scenario) -> str:
    """Where the demo flies, as its first line names it: a scenario of the paper's (a start in
    the paper's hall, or in devices of ``--system.users``), or a hall of its own (``--layout``)
    by the layout's name, as a hall: the paper has no scenario of that name."""
    if SCENARIOS.get(where.name) == where:
        hall = hall_name(cfg, None, where.name)
        return f"scenario {where.name}" + ("" if hall == "the paper's hall" else f" in {hall}")
    return hall_name(cfg, where.name, where.name)


def run_demo(episodes: int = 32, seed: int = 0, scenario: str | Scenario = "fig2",
             system: SystemConfig | None = None) -> dict[str, float]:
    """Print and return each demo policy's mean average sum rate over ``episodes`` seeded episodes
    of ``system`` (default: the paper's)."""
    check_episodes(episodes, seed, "--")  # the command's flags
    cfg = system or SystemConfig()
    where = get_scenario(scenario)
    where.validate_for(cfg)
    print(f"uavris demo: {where_text(cfg, where)} {[round(c, 2) for c in where.start]}, "
          f"{counted(episodes, 'episode')}, {horizon_text(cfg)}")
    means = {}
    for name in DEMO_POLICIES:
        res = evaluate(reference_policy(name, cfg), cfg, where, episodes, seed)
        s = res.summary()
        means[name] = s["mean"]
        print(f"  {REFERENCES[name].label:42s} average sum rate {s['mean']:6.2f} bps/Hz "
              f"(95% CI {rate_interval(s['ci_low'], s['ci_high'])})")
    return means

