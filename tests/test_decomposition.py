"""Issue 29's decomposition on a hall of the test's own: a policy that flies to the oracle's target
and stays level has no place gap and no attitude gap; one that tilts a device behind the RIS plane
loses what the planner's evaluator gives for that tilt, and is counted as blocking."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from uavris import physics as ph
from uavris.agents.evaluation import evaluate
from uavris.agents.oracle import PlanningOracle
from uavris.agents.oracle.planner import assessed_rate
from uavris.agents.oracle.policy import PlannedFlight
from uavris.config import SystemConfig
from uavris.experiments.study.report.decomposition import decomposition_section
from uavris.experiments.study.workers import _decomposition, _Whereabouts, oracle_target
from uavris.layouts import Layout, Site

HALL = Layout("mine", ((6.0, 6.0, 1.0), (16.0, 8.0, 1.2), (30.0, 28.0, 0.5), (10.0, 32.0, 0.8)), (20.0, 20.0, 4.5))
EPISODES = 4


@pytest.fixture(scope="module")
def hall():
    system, where = HALL.resolve(SystemConfig(observe_devices=True))
    plan = PlanningOracle().plan(system, where.start)
    return system, where, plan


def _flown(system, where, plan, attitude):
    rec = _Whereabouts(system, EPISODES)
    res = evaluate(PlannedFlight(dataclasses.replace(plan, attitude=np.asarray(attitude, dtype=np.float64))),
                   system, where, EPISODES, 1_000_000, on_slot=rec)
    return res, rec


def test_flying_to_the_target_level_has_no_place_and_no_attitude_gap(hall):
    system, where, plan = hall
    _, rec = _flown(system, where, plan, np.zeros(3))
    d = _decomposition(system, rec)
    target = oracle_target(Site("mine", system, where.start))
    assert np.linalg.norm(np.asarray(d["end_position"]) - plan.target) < 0.2  # it arrived (within a slot's creep)
    assert abs(target["plan_rate_level"] - d["end_rate_level"]) < 0.05 * target["plan_rate_level"] / 10
    assert d["end_rate_own"] == d["end_rate_level"] and d["behind_share"] == 0.0  # level: no device behind


def test_a_tilt_that_puts_a_device_behind_costs_what_the_evaluator_says(hall):
    system, where, plan = hall
    # find a pitch that blocks a device at the target (the far devices are 1-3 degrees below the plane)
    tilt = next(np.radians([0.0, p, 0.0]) for p in range(2, 40, 2)
                if ph.worst_elevation(np.radians([0.0, p, 0.0]), plan.target, np.asarray(system.users)) < -0.01)
    _, rec = _flown(system, where, plan, tilt)
    d = _decomposition(system, rec)
    pos = np.asarray(d["end_position"])
    own = np.radians(d["end_attitude_deg"])  # the tilt it flew with, as the episodes ended
    (want_level, want_tilted), _ = assessed_rate(system, np.stack([pos, pos]), np.stack([np.zeros(3), own]))
    assert d["end_rate_level"] == pytest.approx(want_level) and d["end_rate_own"] == pytest.approx(want_tilted)
    assert d["end_rate_level"] - d["end_rate_own"] > 1.0  # a lost device costs bps/Hz, not a rounding
    assert d["behind_share"] > 0.0
    # the report's table and claim: the tilted row blocks, the level one does not
    oracle = {"mean": 40.0, **oracle_target(Site("mine", system, where.start)), **d, "behind_share": 0.0}
    results = {"mine": {"oracle": oracle, "dt-zero-shot": {"mean": 30.0, **d}}}
    lines, [claim] = decomposition_section(results, {})
    row = next(line for line in lines if line.startswith("| zero-shot DT |"))
    gap = float(row.split("|")[3])
    assert gap == pytest.approx(d["end_rate_level"] - d["end_rate_own"], abs=0.006)
    assert "**: does not hold" in claim
