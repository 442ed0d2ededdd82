"""Oracle references: optimised phases every slot, and motion planned over the whole room.

:func:`oracle_policy` (the planning oracle) is the reference of every report;
:func:`greedy_oracle_policy` is the one-step-lookahead oracle of earlier releases, kept for
comparison. Modules: :mod:`.lookahead` (the local move choice and its expected-rate score),
:mod:`.objective` (what a plan is worth: R of a pose, the episode value of a trip), :mod:`.planner` (the
global plan), :mod:`.search` (a wider search of the same objective, to measure the plan's gap),
:mod:`.policy` (the batch policies).

Lives here: the re-exports of those modules (:class:`PlanningOracle`, :func:`plan_target`,
:class:`Plan`, :class:`PlanSettings`, :func:`choose_moves`, ...). Not here: the per-slot
phase optimiser both oracles call (:mod:`uavris.physics.phase_opt`) and the references by
name (:mod:`uavris.agents.references`).
"""

from uavris.agents.oracle.lookahead import (
    candidate_moves,
    choose_moves,
    default_braking_slots,
    expected_sum_rate,
    link_activity,
)
from uavris.agents.oracle.objective import expected_optimised_rate
from uavris.agents.oracle.planner import Plan, PlanSettings, plan_target
from uavris.agents.oracle.policy import PlanningOracle, greedy_oracle_policy, oracle_policy

__all__ = ["Plan", "PlanSettings", "PlanningOracle", "candidate_moves", "choose_moves", "default_braking_slots",
           "expected_optimised_rate", "expected_sum_rate", "greedy_oracle_policy", "link_activity", "oracle_policy",
           "plan_target"]
