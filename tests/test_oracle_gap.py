"""The planners' objective and the search that measures the oracle's gap: the episode value of a
trip worked by hand, and the search finding a known optimum of a made-up R."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from uavris.agents.oracle.objective import episode_value, trip_slots
from uavris.agents.oracle.search import SearchSettings, exhaustive_plan
from uavris.config import SystemConfig


def test_the_search_finds_a_known_optimum():
    # A made-up R with one peak at a known pose, and the start on it: the objective's maximum is there
    # (moving only loses rate), and the search must find it within its last step.
    cfg = SystemConfig()
    best_q, best_a = np.array([20.3, 17.6, 5.2]), np.radians([13.0, -7.0, 4.0])

    def valuer(q, att):
        return 50.0 - np.sum((q - best_q) ** 2, axis=-1) - 100.0 * np.sum((att - best_a) ** 2, axis=-1)

    found = exhaustive_plan(cfg, tuple(best_q), SearchSettings(grid_step=4.0, top=4, refine=2), valuer)
    assert np.linalg.norm(found.target - best_q) < 0.07
    off = (found.attitude - best_a + np.pi) % (2 * np.pi) - np.pi  # attitudes are wrapped angles
    assert np.degrees(np.abs(off)).max() < 0.7
    assert found.value == pytest.approx(50.0, abs=0.01)


def test_the_episode_value_of_a_trip_worked_by_hand():
    # 100 slots: 10 in flight at the lower of the two poses' rates, 90 hovering at the target's
    assert episode_value(100, 10, 10.0, 40.0) == pytest.approx(37.0)
    assert episode_value(100, 10, 40.0, 10.0) == pytest.approx(10.0)  # a worse target: 10 all along
    assert episode_value(100, 0, 10.0, 40.0) == 40.0  # no trip
    assert episode_value(100, 250, 10.0, 40.0) == pytest.approx(10.0)  # a trip longer than the episode
    got = episode_value(100, np.array([[0], [50]]), np.array([20.0, 20.0]), np.array([[20.0, 20.0], [30.0, 10.0]]))
    assert got.tolist() == [[20.0, 20.0], [25.0, 10.0]]  # (50 x 20 + 50 x 30) / 100; batches broadcast
    cfg = SystemConfig()
    far = trip_slots(cfg, np.zeros(3), np.array([[0.0, 0.0, 0.0], [1e4, 0.0, 0.0]]))
    assert far.tolist() == [0, cfg.horizon]  # no trip; a trip beyond reach takes the whole episode


def test_the_search_allows_only_the_poses_the_oracle_may_plan():
    # A made-up R whose peak tilts the RIS 60 degrees: from 5 m up some of the paper's devices are then
    # behind the plane. Without a margin the search finds the peak; with the oracle's 1-degree margin
    # every pose it returns keeps each device that far in front (the elevation from the geometry).
    from uavris import physics as ph

    best_q, best_a = np.array([20.0, 17.0, 5.0]), np.radians([0.0, 60.0, 0.0])

    def valuer(q, att):
        return 50.0 - np.sum((q - best_q) ** 2, axis=-1) - 10.0 * np.sum((att - best_a) ** 2, axis=-1)

    settings = SearchSettings(grid_step=4.0, top=4, refine=2, attitudes_deg=(-60.0, -30.0, 0.0, 30.0, 60.0))
    free = exhaustive_plan(SystemConfig(), tuple(best_q), settings, valuer)
    users = np.asarray(SystemConfig().users)
    assert ph.worst_elevation(free.attitude, free.target, users) < 0  # the peak blocks a device
    kept = exhaustive_plan(SystemConfig(front_margin_deg=1.0), tuple(best_q), settings, valuer)
    rot = ph.rotation_matrix(*kept.attitude)
    d = kept.target - users  # eq. (11): from each device to the RIS, against its normal
    assert (d @ rot[:, 2] / np.linalg.norm(d, axis=1)).min() >= np.sin(np.radians(1.0)) - 1e-12
    assert kept.value < free.value


def test_seeded_with_the_oracles_poses_the_search_never_returns_less_than_them():
    """A made-up R with a narrow tilted peak between the grids' points (the grids and their attitude
    grid miss it): without seeds the search returns less than that pose is worth; seeded with it (as
    the oracle's plan's pose, :func:`plan_seeds`) it returns at least its value: a superset."""
    from uavris.agents.oracle.planner import Plan
    from uavris.agents.oracle.search import plan_seeds

    cfg = SystemConfig()
    peak_q, peak_a = np.array([21.3, 15.7, 3.3]), np.radians([7.0, 14.0, -9.0])

    def valuer(q, att):
        off = np.sum((q - peak_q) ** 2, axis=-1) + 50.0 * np.sum((att - peak_a) ** 2, axis=-1)
        return 30.0 + 20.0 * np.exp(-off / 0.05)  # a narrow peak on a flat 30

    settings = SearchSettings(grid_step=4.0, top=4, refine=2, fine_places=2)
    start = (5.0, 5.0, 4.5)
    alone = exhaustive_plan(cfg, start, settings, valuer)
    plan = Plan(start=start, target=peak_q, attitude=peak_a, rate=50.0, start_rate=30.0, travel_slots=0, value=0.0,
                poses_valued=0, candidates=(((10.0, 10.0, 3.0), 30.0, 30.0),))
    seeded = exhaustive_plan(cfg, start, settings, valuer, seeds=plan_seeds(plan))
    at_peak = float(episode_value(cfg.horizon, trip_slots(cfg, np.array(start), peak_q[None]), 30.0,
                                  valuer(peak_q[None], peak_a[None]))[0])
    assert alone.value < at_peak - 5.0  # the grids alone miss it
    assert seeded.value >= at_peak - 1e-9
    # a seed 0.2 m off the peak is refined from, not only valued: the pattern search climbs to the peak
    off_q = peak_q + np.array([0.2, 0.0, 0.0])
    near = exhaustive_plan(cfg, start, settings, valuer, seeds=[(off_q, peak_a)])
    at_seed = float(episode_value(cfg.horizon, trip_slots(cfg, np.array(start), off_q[None]), 30.0,
                                  valuer(off_q[None], peak_a[None]))[0])
    assert at_seed < at_peak - 5.0 and near.value > at_peak - 0.5
    # each distinct seed is searched from once: the start twice over costs what it costs once
    twice = exhaustive_plan(cfg, start, settings, valuer, seeds=[(peak_q, peak_a), (np.array(start), np.zeros(3)),
                                                                (np.array(start), np.zeros(3))])
    once = exhaustive_plan(cfg, start, settings, valuer, seeds=[(peak_q, peak_a), (np.array(start), np.zeros(3))])
    assert twice.poses_valued == once.poses_valued and twice.value == once.value


def test_the_fine_grid_reaches_as_far_as_the_learned_planners():
    """The default fine grid values every place of its 0.5 m grid up to 2 m each way (the learned
    planner's reach) from the best place: a made-up R peaked on a place of the coarse grid, the
    search's other stages kept to one pose, and the positions it values level recorded."""
    import dataclasses

    from uavris.agents.oracle.objective import feasible
    from uavris.agents.place.planner import PlaceSettings

    reach = max(2.0, PlaceSettings().grid_step)  # the learned planner's fine grid reaches its coarse step
    assert SearchSettings().fine_reach >= reach
    cfg, place = SystemConfig(), np.array([24.0, 28.0, 5.0])  # on the 2 m x 2 m x 1 m grid, 4 m from any device
    seen: set[tuple[float, ...]] = set()

    def valuer(q, att):
        seen.update(tuple(np.round(x, 6)) for x in q[np.all(att == 0.0, axis=1)])
        return 50.0 - np.sum((q - place) ** 2, axis=-1)

    settings = dataclasses.replace(SearchSettings(), fine_places=1, top=1, refine=1)
    exhaustive_plan(cfg, tuple(place), settings, valuer)
    ticks = np.arange(-reach, reach + 1e-9, SearchSettings().fine_step)
    rim = np.array([o for o in itertools.product(ticks, repeat=3) if np.abs(o).max() > reach - 1e-9])
    rim = place + rim[np.any(np.abs(rim) % 1.0 != 0.0, axis=1)]  # off the coarse grid: the fine grid's alone
    assert len(rim) and feasible(cfg, rim).all()
    assert all(tuple(np.round(x, 6)) in seen for x in rim)


def test_the_oracle_gap_page_is_stamped_and_states_each_halls_numbers(tmp_path):
    from uavris.experiments.study.oracle_gap import write_page
    from uavris.experiments.study.stamp import read_stamp, stale

    hall = {"devices": 6, "split": "unseen", "oracle": 44.0, "search": 44.5, "stay": 30.0, "teacher": 42.0,
            "search_minus_oracle": 0.5, "search_minus_oracle_se": 0.2, "oracle_s": 10.0, "teacher_s": 1.0,
            "search_s": 200.0}
    done = {f"layout-unseen-{j}-k6": {**hall, "oracle": 44.0 - j} for j in range(3)}
    text = write_page(done, tmp_path / "oracle-gap.md", tmp_path / "runs", "python -m x").read_text()
    stamp = read_stamp(text)
    assert stamp.page == "oracle-gap" and stale(stamp) == [] and stamp.extra["halls"] == list(done)
    assert "| layout-unseen-2-k6 | 6 | 42.00 | 44.50 |" in text and "| 6 devices | 3 | 96.6% [" in text
