"""The bound no controller can beat (docs/model.md section 20): above every policy on every
episode, and exact in the limit it is derived for."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavris.agents.evaluation import evaluate
from uavris.agents.oracle.bound import distance_floor, episode_bounds, fewest_slots, most_power_w, slot_bounds
from uavris.agents.references import REFERENCES, reference_policy
from uavris.config import Scenario, SystemConfig
from uavris.env.rollout import rollout
from uavris.layouts import LayoutGenerator
from uavris.physics import propulsion_power

SEEDS = 1_000_000 + np.arange(6)


@pytest.mark.parametrize("devices", [3, 8])
@pytest.mark.parametrize("name", ["zero-action", "random", "hover-aligned", "hover-optimizer", "oracle"])
def test_no_reference_scores_above_the_bound_on_any_episode(name: str, devices: int) -> None:
    base = SystemConfig(horizon=40)
    system, where = LayoutGenerator(devices=devices).layout("unseen", 2, base).resolve(base)
    got = evaluate(reference_policy(name, system), system, where, len(SEEDS), int(SEEDS[0])).avg_sum_rate
    assert np.all(got <= episode_bounds(system, SEEDS)), name


def test_no_slot_of_a_random_controller_is_above_its_slots_bound() -> None:
    """Slot by slot, for a controller that wanders, tilts and sets any phases and amplitudes."""
    system = SystemConfig(horizon=30, learn_amplitudes=True)
    bounds = slot_bounds(system, SEEDS)
    batch = rollout(reference_policy("random", system), system, "fig2", SEEDS, record=True)
    assert batch.rewards is not None and np.all(batch.rewards <= bounds[:, :batch.rewards.shape[1]])


def test_the_bound_is_attained_by_one_line_of_sight_link_at_the_distance_floor() -> None:
    """Two devices 5 m apart below a UAV 3 m (the safety distance) from each: the floor of
    d_k d_i is 9 m^2 and reached; with no NLoS part (kappa huge) and an ideal surface the
    co-phasing reference earns the bound in every slot, to the floor's last millimetre."""
    height = math.sqrt(3.0 ** 2 - 2.5 ** 2) + 1e-3  # the UAV's altitude: 3.0004 m from both devices
    system = SystemConfig(users=((10.0, 10.0, 0.0), (15.0, 10.0, 0.0)), z_min=height - 1e-6, horizon=8,
                          rician_factor=1e12, angle_dependent_reflection=False)
    assert distance_floor(system)[0, 1] == pytest.approx(9.0)
    start = Scenario("above", (12.5, 10.0, height))
    batch = rollout(reference_policy("hover-aligned", system), system, start, SEEDS, record=True)
    assert batch.rewards is not None
    bounds = slot_bounds(system, SEEDS)
    closed_form = math.log2(1 + system.tx_power_w * system.num_elements ** 2 * 9.0 ** (-system.pathloss_exponent)
                            / system.noise_w)  # one co-phased link of N unit elements, no interference
    assert np.allclose(bounds, closed_form, rtol=1e-5)
    assert np.all(batch.rewards <= bounds) and np.allclose(batch.rewards, bounds, atol=2e-3)


def test_an_episode_cannot_end_before_the_energy_budget_allows() -> None:
    system = SystemConfig()
    speeds = np.linspace(0.0, system.v_max, 10_001)
    assert most_power_w(system) >= propulsion_power(speeds, **vars(system.propulsion)).max()
    shortest = min(int(evaluate(reference_policy(n, system), system, "fig2", 2, 0).length.min()) for n in REFERENCES)
    assert fewest_slots(system) <= shortest and fewest_slots(system) == 95  # hovering, the costliest, lasts 95
