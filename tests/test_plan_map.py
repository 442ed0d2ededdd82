"""The rate map of ``uavris plan`` checked by its data, not its file size:
undefined exactly where the UAV may not be (inside a safety ball, outside the flight
region, computed here from the distances), drawn as computed, and consistent with the plan:
no grid pose beats the plan's target, the pose next to the target is about as good, and the
map's value there is what the simulator measures hovering there."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import keep_figures
from uavris.agents.references import reference_policy
from uavris.config import SystemConfig
from uavris.experiments.tools import plan as plan_module
from uavris.layouts import Layout

GRID_STEP = 2.0
HALL = Layout("two-pairs", ((8.0, 9.0, 1.0), (14.0, 11.0, 0.5), (30.0, 28.0, 1.2), (26.0, 32.0, 0.0)),
              (20.0, 20.0, 4.5))


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """``plan_hall`` on a hall of the test's own, with the figure's mesh kept for inspection."""
    out = tmp_path_factory.mktemp("plan") / "two-pairs"
    drawn = {}
    real_save = plan_module.save_figure

    def keep(fig, stem):
        drawn["mesh"] = fig.axes[0].collections[0]
        return real_save(fig, stem)

    plan_module.save_figure = keep
    try:
        plan, paths = plan_module.plan_hall(HALL, SystemConfig(), out, GRID_STEP, progress=False)
    finally:
        plan_module.save_figure = real_save
    hall, _ = HALL.resolve(SystemConfig())
    xs, ys, rates = plan_module.rate_map(hall, plan["target"][2], GRID_STEP)
    return hall, plan, paths, xs, ys, rates, drawn["mesh"]


@pytest.mark.slow
def test_the_map_is_undefined_exactly_where_the_uav_may_not_be(planned):
    hall, plan, _, xs, ys, rates, _ = planned
    z = plan["target"][2]
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    pose = np.stack([gx, gy, np.full_like(gx, z)], axis=-1)
    near = np.zeros(gx.shape, dtype=bool)
    for u in hall.users:
        near |= np.linalg.norm(pose - np.asarray(u), axis=-1) < hall.safety_distance
    outside = np.zeros(gx.shape, dtype=bool)
    for i in range(3):
        outside |= (pose[..., i] < hall.region_low[i]) | (pose[..., i] > hall.region_high[i])
    assert near.any() and (~near).any()  # the hall's balls reach the map's altitude: the check means something
    np.testing.assert_array_equal(np.isnan(rates), near | outside)
    assert np.all(rates[~(near | outside)] > 0)


@pytest.mark.slow
def test_the_figure_draws_the_map_and_the_files_hold_the_plan(planned):
    _, plan, paths, _, _, rates, mesh = planned
    drawn = np.ma.masked_invalid(rates.T)
    shown = mesh.get_array()
    np.testing.assert_array_equal(np.ma.getmaskarray(shown).ravel(), np.ma.getmaskarray(drawn).ravel())
    np.testing.assert_allclose(np.ma.compressed(shown), np.ma.compressed(drawn))
    assert {p.suffix for p in paths} == {".json", ".png", ".pdf"} and all(p.exists() for p in paths)
    import json

    assert json.loads(paths[0].read_text())["target"] == plan["target"]


def _simulated(hall: SystemConfig, pose) -> tuple[float, float]:
    """Hovering at ``pose`` with the optimiser's phases in the simulator, 12 episodes of fresh
    draws: the mean sum rate per slot and its standard error."""
    from uavris.env.rollout import rollout

    batch = rollout(reference_policy("hover-optimizer", hall), hall, list(pose), 7_000 + np.arange(12), record=True)
    x = np.concatenate([r[:n] for r, n in zip(batch.rewards, batch.lengths)])
    return float(x.mean()), float(x.std(ddof=1) / np.sqrt(x.size))


@pytest.mark.slow
def test_the_map_agrees_with_the_plan_and_the_simulator(planned):
    """The Monte-Carlo tolerance: the planner's R averages 2 NLoS draws (0.3 bps/Hz, as in
    test_oracle) plus three standard errors of the simulation."""
    hall, plan, _, xs, ys, rates, _ = planned
    target = plan["target"]
    # the plan's expected rate is what the simulator measures hovering at its target
    mean, se = _simulated(hall, target)
    assert abs(plan["expected_sum_rate"] - mean) < 3 * se + 0.3, (plan["expected_sum_rate"], mean, se)
    # nowhere on the map is better than the target
    assert np.nanmax(rates) <= plan["expected_sum_rate"] + 0.3
    # the map's value at the feasible grid pose nearest the target is what the simulator measures there
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    far = np.hypot(gx - target[0], gy - target[1]) + np.where(np.isnan(rates), np.inf, 0.0)
    i, j = np.unravel_index(np.argmin(far), far.shape)
    assert far[i, j] < 2 * GRID_STEP
    mean, se = _simulated(hall, (xs[i], ys[j], target[2]))
    assert abs(rates[i, j] - mean) < 3 * se + 0.3, (rates[i, j], mean, se)


def test_the_legends_hide_no_device_and_a_plan_that_stays_shows_its_start(tmp_path, monkeypatch):
    """The plan map's and the trajectory plot's legends sit below their maps (no device under
    them); a plan that stays draws the start on top of the target, both in the legend."""
    from uavris.experiments.display import plots
    from uavris.experiments.tools import plan as plan_module
    from uavris.experiments.tools import trajectory

    figures = keep_figures(monkeypatch, plan_module, trajectory, plots)
    system = SystemConfig()
    start = [15.0, 20.0, 4.5]
    plan = {"planner": "exact", "expected_sum_rate": 40.0, "layout": {"name": "stays", "start": start},
            "target": start, "travel_s": 0.0}
    xs, ys = np.linspace(0, 40, 5), np.linspace(0, 40, 5)
    plan_module.plan_figure(system, plan, xs, ys, np.full((5, 5), 30.0), tmp_path / "p")
    log = trajectory.SlotLog(np.array([7]))
    log.rows = [(7, t, 15.0 + t, 20.0, 4.5, 0.0, 0.0, 0.0, 1, 30.0, 10.0) for t in range(5)]
    trajectory.trajectory_plot(log, system, tmp_path / "t", "title")
    assert len(figures) == 2
    for fig in figures:
        ax = fig.axes[0]
        legend = ax.get_legend().get_window_extent()
        assert legend.y1 <= ax.get_window_extent().y0 + 1  # below the map
    labels = [t.get_text() for t in figures[0].axes[0].get_legend().get_texts()]
    assert "target: stay at the start" in labels and "start" in labels


def test_a_marker_on_the_rooms_edge_is_drawn_whole(tmp_path, monkeypatch):
    """A target in a corner of the room, a device and a start on its walls (the axes' limits):
    their markers are not clipped by the axes, so the star is a star, not a quarter of one."""
    figures = keep_figures(monkeypatch, plan_module)
    system = SystemConfig()
    room_x, room_y = system.room[0], system.room[1]
    plan = {"planner": "exact", "expected_sum_rate": 40.0, "layout": {"name": "corner", "start": [0.0, 20.0, 4.5]},
            "target": [room_x, room_y, 4.5], "travel_s": 9.0}
    xs, ys = np.linspace(0, room_x, 5), np.linspace(0, room_y, 5)
    plan_module.plan_figure(system, plan, xs, ys, np.full((5, 5), 30.0), tmp_path / "p")
    [fig] = figures
    markers = {c.get_label(): c for c in fig.axes[0].collections if c.get_label() in ("target", "start", "devices")}
    assert set(markers) == {"target", "start", "devices"}
    ax = fig.axes[0]
    assert tuple(markers["target"].get_offsets()[0]) == (ax.get_xlim()[1], ax.get_ylim()[1])  # in the corner
    for label, marker in markers.items():
        assert not marker.get_clip_on(), label


def test_learning_curves_show_a_rate_band_from_zero_whole_episodes_and_a_legend_off_the_curves(tmp_path,
                                                                                                monkeypatch):
    """Fig. 2's band is the seeds' t interval of the mean, its lower edge clipped at 0 (a rate is
    never negative; with two seeds the raw one reaches far below); the x axis ticks whole
    episodes only; the legend lies below the axes and their label, over no curve."""
    from uavris.experiments.display import plots

    figures = keep_figures(monkeypatch, plots)
    x = np.array([1, 2, 3])
    curves = {"ppo": (x, np.array([5.0, 10.0, 20.0]), np.array([-30.0, -5.0, 10.0]), np.array([40.0, 25.0, 30.0])),
              "sac": (x, np.array([6.0, 12.0, 18.0]), np.array([1.0, 2.0, 3.0]), np.array([9.0, 20.0, 30.0]))}
    plots.learning_curves(curves, tmp_path / "lc", "title", {"ppo": 30.0},
                          {"zero-action": ("zero action", 8.0), "oracle": ("oracle", 35.0)})
    [fig] = figures
    ax = fig.axes[0]
    bands = [c for c in ax.collections if c.get_paths()]
    assert len(bands) == 2
    for band in bands:
        assert min(v[1] for p in band.get_paths() for v in p.vertices) >= 0.0
    ticks = [t for t in ax.xaxis.get_majorticklocs() if ax.get_xlim()[0] <= t <= ax.get_xlim()[1]]
    assert ticks and all(float(t).is_integer() for t in ticks), ticks
    legend = ax.get_legend().get_window_extent()
    assert legend.y1 <= ax.xaxis.label.get_window_extent().y0 + 1 <= ax.get_window_extent().y0 + 1
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert {"PPO", "SAC", "paper's converged value"} <= set(labels)
