"""The decomposition of the gap to the oracle (docs/study.md, section 2) on a hall of the test's
own: a policy that flies to the oracle's target and stays level has no place gap and no attitude
gap; one that tilts a device behind the RIS plane loses what hovering there tilted costs on the
simulator's own draws (a Monte-Carlo check independent of the planner's evaluator), and is
counted as blocking."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from uavris import physics as ph
from uavris.agents.evaluation import evaluate
from uavris.agents.oracle import PlanningOracle
from uavris.agents.oracle.policy import PlannedFlight
from uavris.config import SystemConfig
from uavris.env.simulator import BatchedSimulator
from uavris.experiments.study.report.decomposition import decomposition_section
from uavris.experiments.study.report.deployment import row_labels
from uavris.experiments.study.workers import _decomposition, _Whereabouts, oracle_target
from uavris.experiments.tools.targets import Row, Target
from uavris.layouts import Layout, Site
from uavris.physics.phase_opt import optimize_slot_phases

HALL = Layout("mine", ((6.0, 6.0, 1.0), (16.0, 8.0, 1.2), (30.0, 28.0, 0.5), (10.0, 32.0, 0.8)), (20.0, 20.0, 4.5))
EPISODES = 4


@pytest.fixture(scope="module")
def hall():
    system, where = HALL.resolve(SystemConfig(observe_devices=True))
    plan = PlanningOracle().plan(system, where.start)
    return system, where, plan


def _monte_carlo_rate(system, where, position, attitude, n=4096):
    """The sum rate with optimised phases of ``n`` slots hovering at a pose, on the simulator's draws."""
    sim = BatchedSimulator(system.replace(safety_distance=0.0), where, n)
    sim.seed(77 + np.arange(n))
    sim.reset()
    sim.place(position, attitude)
    return optimize_slot_phases(system, sim.channels, sim.cos_theta, sim.pairing).sum_rate


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


def test_a_tilt_that_puts_a_device_behind_costs_what_hovering_tilted_costs(hall):
    system, where, plan = hall
    # find a pitch that blocks a device at the target (the far devices are 1-3 degrees below the plane)
    tilt = next(np.radians([0.0, p, 0.0]) for p in range(2, 40, 2)
                if ph.worst_elevation(np.radians([0.0, p, 0.0]), plan.target, np.asarray(system.users)) < -0.01)
    _, rec = _flown(system, where, plan, tilt)
    d = _decomposition(system, rec)
    pos = np.asarray(d["end_position"])
    own = np.radians(d["end_attitude_deg"])  # the tilt it flew with, as the episodes ended
    # independently: hovering there with the optimiser's phases on 4,096 slots of the simulator's own draws
    # (random pairings and NLoS), level and tilted on the same draws
    level, tilted = (_monte_carlo_rate(system, where, pos, att) for att in (np.zeros(3), own))
    se = level.std(ddof=1) / np.sqrt(level.size)
    gap_se = (level - tilted).std(ddof=1) / np.sqrt(level.size)
    assert abs(d["end_rate_level"] - level.mean()) < 3 * se + 0.2
    assert abs(d["end_rate_own"] - tilted.mean()) < 3 * se + 0.2
    assert abs((d["end_rate_level"] - d["end_rate_own"]) - (level - tilted).mean()) < 3 * gap_se + 0.2
    assert d["end_rate_level"] - d["end_rate_own"] > 1.0  # a lost device costs bps/Hz, not a rounding
    assert d["behind_share"] > 0.0
    # the report's table and claim: the tilted row blocks, the level one does not
    learned = Row("dt-zero-shot", "zero-shot DT", Target.of_model(Path("model")))
    oracle = {"mean": 40.0, "label": "oracle", **Row.reference("oracle").facts(),
              **oracle_target(Site("mine", system, where.start)), **d, "behind_share": 0.0}
    results = {"mine": {"oracle": oracle, "dt-zero-shot": {"mean": 30.0, "label": "zero-shot DT", **learned.facts(),
                                                           **d}}}
    lines, [claim] = decomposition_section(results, row_labels(results))
    row = next(line for line in lines if line.startswith("| zero-shot DT |"))
    gap = float(row.split("|")[3])
    assert gap == pytest.approx(d["end_rate_level"] - d["end_rate_own"], abs=0.006)
    assert "**: does not hold" in claim
