"""``uavris plan``: where the UAV should go in a hall, and what it is worth there.

Lives here: :func:`plan_layout` (the planning oracle's plan for a layout, or the learned
planner's, written as JSON) and :func:`rate_map` / :func:`plan_figure` (the expected sum
rate over the hall at the plan's altitude, or the learned value ``V`` there, with the
devices, their safety balls, the start and the target). Not here: the plans themselves
(:func:`uavris.agents.oracle.plan_target`, :func:`uavris.agents.place.planner.learned_plan`) and the
layouts (:mod:`uavris.layouts`).

This is what a network planner asks first about a new hall: the best hovering pose, its
expected sum rate with optimised phases, how long the trip takes from the start, and how
sharply the rate falls off around it. The map values every feasible grid point with the
planner's own expected-rate estimate (:func:`uavris.agents.oracle.expected_optimised_rate`:
exact over the pairings, common NLoS draws, optimised phases), level RIS; the target's own
value is with its refined attitude.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from uavris.agents.evaluation import evaluate
from uavris.agents.oracle import PlanSettings, expected_optimised_rate, plan_target
from uavris.agents.oracle.objective import feasible
from uavris.agents.policy import fit_policy
from uavris.config import SystemConfig
from uavris.errors import ConfigError
from uavris.experiments.display.plots import plt, save_figure
from uavris.experiments.display.progress import progress_bar
from uavris.experiments.tools.evaluate import outside_training
from uavris.experiments.tools.rows import read_controller
from uavris.experiments.tools.trajectory import SlotLog
from uavris.io import write_json
from uavris.layouts import Layout
from uavris.presets import EVAL_SEED

if TYPE_CHECKING:  # the learned value needs torch (the training extra); the exact plan does not
    from uavris.agents.place.value import PoseValue

MAP_CHUNK = 64  # poses valued per call (the progress bar's step)


def plan_layout(layout: Layout, system: SystemConfig, settings: PlanSettings | None = None,
                value: PoseValue | None = None, top_k: int = 0, deployed: bool = False) -> dict[str, Any]:
    """The plan for ``layout`` on ``system``: target pose, expected sum rate ``R`` there and at
    the start, travel time, the plan's expected episode average, and the seconds planning took.
    The planning oracle's by default; with a learned ``value``, the learned planner's: its
    numbers are ``V``'s, under their own keys (``learned_value``, ``learned_value_start``,
    ``learned_episode_value``; the ``R`` keys None: nothing was valued by ``R``), and with
    ``top_k`` > 0 its top places valued by ``R``, or with ``deployed`` the deployed place (V proposes,
    R disposes: :func:`uavris.agents.place.planner.decided_plan`) (the ``R`` keys, with ``V`` at the
    target beside)."""
    hall, scenario = layout.resolve(system)
    began = time.perf_counter()
    if value is None:
        plan, planner = plan_target(hall, scenario.start, settings or PlanSettings()), "exact"
    else:
        from uavris.agents.place.planner import PlaceSettings, decided_plan, learned_plan

        if deployed:
            plan, planner = decided_plan(value, hall, scenario.start), "deployed (V proposes, R disposes)"
        else:
            plan = learned_plan(value, hall, scenario.start, PlaceSettings(top_k=top_k))
            planner = f"learned, top {top_k} valued by R" if top_k else "learned"
    seconds = time.perf_counter() - began
    out = {"layout": layout.to_dict(), "planner": planner, "target": [float(v) for v in plan.target],
           "attitude_deg": [float(v) for v in np.degrees(plan.attitude)], "travel_slots": plan.travel_slots,
           "travel_s": plan.travel_slots * hall.slot_s, "poses_valued": plan.poses_valued, "planning_s": seconds}
    if value is not None and not top_k and not deployed:  # V alone: no R was computed, V has no sampling error
        return {**out, "expected_sum_rate": None, "expected_sum_rate_se": None, "start_sum_rate": None,
                "expected_episode_average": None, "learned_value": plan.rate, "learned_value_start": plan.start_rate,
                "learned_episode_value": plan.value}
    learned = {} if value is None else {
        "learned_value": float(_v(value, np.asarray(hall.users, dtype=np.float64), plan.target[None])[0])}
    return {**out, "expected_sum_rate": plan.rate, "expected_sum_rate_se": plan.rate_se,
            "start_sum_rate": plan.start_rate, "expected_episode_average": plan.value, **learned}


# The exact plan's time grows with the devices about as K^2.4 (one core, measured: 3.6 s at 4 devices,
# 18.5 s at 8, 51 s at 12): 16 devices take about 2 minutes, 30 would take over 10.
MAX_PLAN_DEVICES = 16


def planning_seconds(devices: int) -> float:
    """The exact plan's expected seconds on one core for a hall of ``devices`` (the fit above)."""
    return 3.6 * (devices / 4) ** 2.4


def check_devices(system: SystemConfig) -> None:
    """One :class:`ConfigError` line for a hall beyond :data:`MAX_PLAN_DEVICES` devices."""
    if system.num_users > MAX_PLAN_DEVICES:
        raise ConfigError(f"uavris plan plans halls of at most {MAX_PLAN_DEVICES} devices (about "
                          f"{planning_seconds(MAX_PLAN_DEVICES) / 60:.0f} min on one core; the time grows as K^2.4: "
                          f"{system.num_users} devices would take about "
                          f"{planning_seconds(system.num_users) / 60:.0f} min)")


MAX_MAP_POSES = 10_000  # about 3 min of one core (~19 ms a pose): a 0.4 m grid over the 40 m hall


def check_grid(system: SystemConfig, step: float) -> int:
    """The number of poses of the rate map's grid of spacing ``step`` (m); a step that is not a
    positive distance, or that makes more than :data:`MAX_MAP_POSES` poses (a mistyped 0.01
    would run for days and exhaust memory), is one :class:`ConfigError` line."""
    if not (np.isfinite(step) and step > 0):
        raise ConfigError(f"--grid-step must be a distance > 0 (m), got {step!r}")
    nx, ny = _grid_points(system, step)
    if nx * ny > MAX_MAP_POSES:
        raise ConfigError(f"--grid-step {step:g} m makes a {nx} x {ny} grid ({nx * ny:,} poses) over the "
                          f"{system.room[0]:g} x {system.room[1]:g} m floor; at most {MAX_MAP_POSES:,} "
                          f"(a step of at least {_min_step(system):.2f} m)")
    return nx * ny


def _grid_points(system: SystemConfig, step: float) -> tuple[int, int]:
    """Points of the rate map's grid along x and y: the floor's ends included, at least two."""
    return max(2, int(round(system.room[0] / step)) + 1), max(2, int(round(system.room[1] / step)) + 1)


def _min_step(system: SystemConfig) -> float:
    area = (system.room[0] + 1.0) * (system.room[1] + 1.0)
    return float(np.sqrt(area / MAX_MAP_POSES))


def rate_map(system: SystemConfig, altitude: float, step: float, progress: bool = False,
             value: PoseValue | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(x, y, R)``: the expected sum rate (level RIS, optimised phases) on a grid of spacing
    ``step`` over the floor plan at ``altitude``, or the learned ``value``'s ``V`` there (one
    call: milliseconds); NaN where the UAV may not be (a safety ball)."""
    system.check()
    check_grid(system, step)
    nx, ny = _grid_points(system, step)
    xs, ys = np.linspace(0.0, system.room[0], nx), np.linspace(0.0, system.room[1], ny)
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
    poses = np.column_stack([grid, np.full(len(grid), altitude)])
    ok = np.flatnonzero(feasible(system, poses))
    values = np.full(len(poses), np.nan)
    if value is not None:
        values[ok] = _v(value, np.asarray(system.users, dtype=np.float64), poses[ok])
        return xs, ys, values.reshape(len(xs), len(ys))
    with progress_bar(len(ok), "rate map", "pose", progress, leave=False) as bar:
        for start in range(0, len(ok), MAP_CHUNK):
            idx = ok[start:start + MAP_CHUNK]
            values[idx] = expected_optimised_rate(system, poses[idx], np.zeros(3))
            bar.update(len(idx))
    return xs, ys, values.reshape(len(xs), len(ys))


def _v(value: PoseValue, users: NDArray, poses: NDArray) -> NDArray[np.float64]:
    from uavris.agents.place.value import predict

    return predict(value, users, poses)


def plan_figure(system: SystemConfig, plan: dict[str, Any], xs: NDArray, ys: NDArray, rates: NDArray,
                stem: Path) -> list[Path]:
    """The map (``rates``: ``R``, or a learned planner's ``V``) with the devices, their safety
    balls at the map's altitude, start and target; the colour bar marks the target's value of
    the map's own quantity (``V`` at it for a learned map, ``R`` with its attitude for ``R``'s)."""
    learned = plan.get("planner", "exact") != "exact"
    marked = plan["learned_value"] if learned else plan["expected_sum_rate"]  # the map's quantity at the target
    fig, ax = plt.subplots(figsize=(4.8, 4.2))
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.85")  # grey: inside a safety ball, no place to be
    vmin, vmax = colour_limits(rates, marked)
    mesh = ax.pcolormesh(xs, ys, rates.T, shading="nearest", cmap=cmap, vmin=vmin, vmax=vmax)
    ax.grid(False)
    bar = fig.colorbar(mesh, ax=ax, label="learned value V (bps/Hz)" if learned else "expected sum rate (bps/Hz)")
    bar.ax.axhline(marked, color="#d62728", lw=1.2)  # the target's
    users = np.asarray(system.users)
    altitude = plan["target"][2]
    ring = np.linspace(0, 2 * np.pi, 90)
    for k, u in enumerate(users):
        r = np.sqrt(max(system.safety_distance ** 2 - (altitude - u[2]) ** 2, 0.0))
        if r > 0:
            ax.plot(u[0] + r * np.cos(ring), u[1] + r * np.sin(ring), color="k", lw=0.6)
        ax.annotate(f"D{k + 1}", u[:2], textcoords="offset points", xytext=(4, 4), color="k", fontsize=7)
    # The markers are not clipped at the axes: a device, a start or a target on a wall or in a
    # corner of the room (the axes' limits) is drawn whole, not cut to a quarter of itself.
    ax.scatter(users[:, 0], users[:, 1], marker="^", color="w", edgecolor="k", s=36, label="devices", zorder=3,
               clip_on=False)
    start, target = plan["layout"]["start"], plan["target"]
    stays = bool(np.allclose(start, target))
    ax.scatter(*target[:2], marker="*", color="#d62728", edgecolor="k", s=110, zorder=3,
               label="target: stay at the start" if stays else "target", clip_on=False)
    ax.scatter(*start[:2], marker="o", color="#ff7f0e", edgecolor="k", s=16 if stays else 36, label="start",
               zorder=4, clip_on=False)  # above the target: a plan that stays shows both
    ax.plot([start[0], target[0]], [start[1], target[1]], color="#d62728", lw=0.8, ls="--")
    ax.set_xlim(0, system.room[0])
    ax.set_ylim(0, system.room[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    what = "learned value V" if learned else "expected sum rate"
    stated = (f"V {plan['learned_value']:.2f}" if plan["expected_sum_rate"] is None else
              f"R {plan['expected_sum_rate']:.2f}" + (f" (V {plan['learned_value']:.2f})" if learned else ""))
    ax.set_title(f"{plan['layout']['name']}: {what} at z = {altitude:.2f} m (level RIS)\n"
                 f"target {np.round(target, 2).tolist()}: {stated} bps/Hz, "
                 f"{plan['travel_s']:.1f} s from the start", fontsize=8)
    # below the map, where it hides no device
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3, frameon=False)
    return save_figure(fig, stem)


def colour_limits(rates: NDArray, target_rate: float) -> tuple[float, float]:
    """The map's colour scale: the map's range, stretched to hold the target's rate (the map is
    drawn level, the target may carry a refined attitude worth more)."""
    finite = rates[np.isfinite(rates)]
    low, high = (float(finite.min()), float(finite.max())) if finite.size else (target_rate, target_rate)
    return min(low, target_rate), max(high, target_rate)


def controller_flight(controller: Path, layout: Layout, seed: int = EVAL_SEED) -> dict[str, Any]:
    """Where a controller directory (``uavris export``) told its place actually flies in ``layout``:
    one evaluation episode (``seed``) in its own system in that hall, as ``uavris evaluate
    CONTROLLER --layout`` runs it: its pose at the last slot, its average sum rate and, where the
    hall lies outside what it was trained in, the warning ``evaluate`` prints. The place it is
    told is a request; a weak controller may not get there."""
    row = read_controller(controller)
    hall, where = layout.resolve(row.own_system())
    evaluated = row.system(hall)
    policy = fit_policy(row.load(evaluated).policy, evaluated, row.key)
    log = SlotLog(np.array([seed]))
    rate = evaluate(policy, evaluated, where, 1, seed, on_slot=log.on_slot, on_step=log.on_step).avg_sum_rate[0]
    last = log.rows[-1]
    return {"row": row.key, "seed": seed, "end": [float(v) for v in last[2:5]],
            "end_attitude_deg": [float(v) for v in last[5:8]], "average_sum_rate": float(rate),
            "warning": outside_training(row, evaluated, Path(controller).name)}


def plan_hall(layout: Layout, system: SystemConfig, out: Path, grid_step: float, progress: bool = True,
              value: PoseValue | None = None, top_k: int = 0, controller: Path | None = None,
              deployed: bool = False) -> tuple[dict[str, Any], list[Path]]:
    """Plan, map and draw ``layout``: writes ``out.json``, ``out.png`` and ``out.pdf``; with a
    learned ``value``, its plan and its map (:func:`plan_layout`, :func:`rate_map`); with a
    ``controller`` told that place, where it flies (:func:`controller_flight`, under
    ``controller_flight``)."""
    hall, _ = layout.resolve(system)
    check_grid(hall, grid_step)
    if value is None or top_k or deployed:  # the optimiser values poses (V alone takes milliseconds at any count)
        check_devices(hall)
    plan = plan_layout(layout, system, value=value, top_k=top_k, deployed=deployed)
    if controller is not None:
        plan["controller_flight"] = controller_flight(controller, layout)
    xs, ys, rates = rate_map(hall, plan["target"][2], grid_step, progress, value)
    paths = plan_figure(hall, plan, xs, ys, rates, out)
    write_json(out.parent / f"{out.name}.json", plan)
    return plan, [out.parent / f"{out.name}.json", *paths]
