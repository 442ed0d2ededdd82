"""The learned planner: where to go in a hall, from the argmax of the learned value ``V`` (docs/places.md).

Lives here: :class:`PlaceSettings` and :func:`learned_plan`: ``V`` over a grid of the flight
region outside the safety balls, the exact planner's travel-time rule (a place's value is
the episode average ``(t min(V(start), V(q)) + (T - t) V(q)) / T``, ``t`` the trip's slots)
and "stay" always a candidate; its semi-amortised form (``top_k`` > 0): the ``top_k`` best
places by that value, apart from each other, and the start, valued by ``R`` and chosen as the
exact planner chooses its finalists (a move only when it beats staying by more than a
standard error, the plan's numbers on fresh draws). Not here: ``V`` (:mod:`.value`), the
exact planner (:func:`uavris.agents.oracle.planner.plan_target`), whose :class:`Plan` this
returns too, so the same flight controller flies either.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from uavris.agents.oracle.objective import (
    episode_value,
    expected_optimised_rate,
    feasible,
    feasible_grid,
    top_apart,
    travel_slots,
    trip_slots,
)
from uavris.agents.oracle.planner import (
    RANK_DRAWS,
    RANK_OPTIMISER,
    SAFE_MARGIN_DEG,
    Plan,
    PlanSettings,
    check_finalists,
    holding,
    pattern_search,
    turned_towards,
)
from uavris.agents.oracle.policy import fly_to, motion_entries
from uavris.agents.place.value import PoseValue, predict
from uavris.config import SystemConfig
from uavris.env.simulator import BatchedSimulator
from uavris.physics import wrap_angle


@dataclass(frozen=True)
class PlaceSettings:
    """How the learned planner looks."""

    grid_step: float = 2.0  # m, the coarse grid V is read on
    fine_step: float = 0.5  # m, the finer grid V is read on around the coarse grid's best places
    fine_places: int = 8  # the coarse grid's best places (apart by ``separation``) refined on the finer grid
    top_k: int = 0  # 0: V alone (amortised); 1-5: the top places by V valued by R (semi-amortised)
    separation: float = 3.0  # m: the top places are at least this far apart (distinct places, not one peak)
    check_batches: int = 8  # fresh batches R values the finalists on (semi-amortised)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.grid_step) and self.grid_step > 0):
            raise ValueError(f"PlaceSettings.grid_step must be > 0, got {self.grid_step!r}")
        if not 0 <= self.top_k <= 5:
            raise ValueError(f"PlaceSettings.top_k must be in [0, 5], got {self.top_k!r}")


def place_grid(config: SystemConfig, step: float) -> NDArray[np.float64]:
    """The feasible positions ``(M, 3)`` of a grid of spacing ``step`` over the flight region
    (inside it, outside every safety ball): the places the learned planner reads."""
    grid, ok = feasible_grid(config, step)
    return grid[ok]


def place_values(model: PoseValue, config: SystemConfig, start: NDArray, places: NDArray, tilt: bool = False
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """The episode value of flying to each of ``places`` and hovering there, by ``V`` and the
    travel-time rule, with the attitude it is valued at (level; with ``tilt`` the better of
    level and turned towards the devices where the UAV can hold it,
    :func:`~uavris.agents.oracle.planner.turned_towards`), and ``V`` at the start (the value of staying)."""
    users = np.asarray(config.users, dtype=np.float64)
    v = predict(model, users, places)
    att = np.zeros_like(places)
    if tilt and len(places):
        facing, turned = turned_towards(config, places)
        vt = v.copy()
        vt[turned] = predict(model, users, places[turned], facing[turned])
        att = np.where((vt > v)[:, None], facing, 0.0)
        v = np.maximum(v, vt)
    v0 = float(predict(model, users, np.asarray(start, dtype=np.float64)[None])[0])
    return episode_value(config.horizon, trip_slots(config, start, places), v0, v), att, v0


def ranked_poses(model: PoseValue, config: SystemConfig, start: NDArray, settings: PlaceSettings = PlaceSettings(),
                 tilt: bool = False) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], float]:
    """Every place the learned planner reads (the coarse grid, and the finer grid around its
    best places) with the attitude and episode value ``V`` gives it (:func:`place_values`),
    best first, and ``V`` at the start."""
    start_q = np.asarray(start, dtype=np.float64)
    coarse = place_grid(config, settings.grid_step)
    values, atts, v0 = place_values(model, config, start_q, coarse, tilt)
    # the finer grid around the coarse grid's best places (V is smooth: its argmax lies near them)
    step, reach = settings.fine_step, settings.grid_step
    offsets = np.stack(np.meshgrid(*[np.arange(-reach, reach + 1e-9, step)] * 3, indexing="ij"), -1).reshape(-1, 3)
    near = np.concatenate([coarse[i] + offsets for i in top_apart(values, coarse, settings.fine_places,
                                                                   settings.separation)])
    near = near[feasible(config, near)]
    fine, fine_atts, _ = place_values(model, config, start_q, near, tilt)
    places, atts, values = (np.concatenate(x) for x in ((coarse, near), (atts, fine_atts), (values, fine)))
    order = np.argsort(-values, kind="stable")
    return places[order], atts[order], values[order], v0


def ranked_places(model: PoseValue, config: SystemConfig, start: NDArray, settings: PlaceSettings = PlaceSettings()
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """:func:`ranked_poses` level: the places with their episode value by ``V``, best first, and ``V`` at the start."""
    places, _, values, v0 = ranked_poses(model, config, start, settings)
    return places, values, v0


def learned_plan(model: PoseValue, config: SystemConfig, start: tuple[float, float, float],
                 settings: PlaceSettings = PlaceSettings()) -> Plan:
    """Where to go from ``start`` in ``config``'s hall (module docstring), level. With
    ``top_k`` 0 the plan's rate and value are ``V``'s (no ``R`` is computed: milliseconds);
    with ``top_k`` > 0 they are ``R``'s on fresh draws, as the exact planner's."""
    config.check()  # a hall judged whole before any place is valued in it
    start_q = np.asarray(start, dtype=np.float64)
    places, values, v0 = ranked_places(model, config, start_q, settings)
    level = np.zeros(3)
    if settings.top_k:
        best = top_apart(values, places, settings.top_k, settings.separation)
        checks = PlanSettings(check_batches=settings.check_batches, front_margin_deg=None)  # level places: none to keep
        table = tuple((tuple(float(x) for x in places[i]), float("nan"), float(values[i])) for i in best)
        finalists = [(start_q, level), *((places[i], level) for i in best)]
        return check_finalists(config, checks, start_q, finalists, 0, table)
    moves = values[0] > v0
    target = places[0] if moves else start_q
    slots = int(travel_slots(config, np.linalg.norm(target - start_q))[0]) if moves else 0
    rate = float(predict(model, np.asarray(config.users, dtype=np.float64), target[None])[0])
    value = float(values[0]) if moves else v0
    return Plan(start=tuple(float(x) for x in start_q), target=target.copy(), attitude=level, rate=rate,
                start_rate=v0, travel_slots=slots, value=value, poses_valued=0,
                candidates=((tuple(float(x) for x in target), rate, value),))


def places_to_try(model: PoseValue, config: SystemConfig, start: tuple[float, float, float], count: int,
                  settings: PlaceSettings = PlaceSettings()) -> NDArray[np.float64]:
    """The start and the ``count`` best places by ``V`` (apart by ``settings.separation``),
    ``(count + 1, 3)``: what fine-tuning that tries places flies to (one place per episode)."""
    start_q = np.asarray(start, dtype=np.float64)
    places, values, _ = ranked_places(model, config, start_q, settings)
    return np.concatenate([start_q[None], places[top_apart(values, places, count, settings.separation)]])


class LearnedPlanner:
    """The learned planner's plan flown by the planning oracle's controller
    (:func:`uavris.agents.oracle.policy.fly_to`) with the optimiser's phases: what the learned
    place is worth, apart from any learned controller. Privileged like the oracle (it reads
    the simulator's pose, velocity and hall); plans are made once per hall and start."""

    privileged: ClassVar[bool] = True
    phase_control: ClassVar[str] = "optimizer"

    def __init__(self, model: PoseValue, settings: PlaceSettings = PlaceSettings(), deployed: bool = False) -> None:
        self.model, self.settings, self.deployed = model, settings, deployed
        self.plans: dict[tuple, Plan] = {}

    def plan(self, config: SystemConfig, start: tuple[float, float, float]) -> Plan:
        """The plan from ``start``: the learned planner's, or with ``deployed`` the deployed place
        (:func:`decided_plan`); made once per hall and start."""
        key = (config, tuple(start))
        if key not in self.plans:
            self.plans[key] = (decided_plan(self.model, config, start) if self.deployed
                               else learned_plan(self.model, config, start, self.settings))
        return self.plans[key]

    def target(self, config: SystemConfig, start: tuple[float, float, float]) -> NDArray[np.float64]:
        """Where the plan goes (a goal source's planner: :class:`uavris.agents.dt.goals.PlannedGoals`)."""
        return self.plan(config, start).target

    def __call__(self, obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        return motion_entries(sim.config, *fly_to(sim, self.plan(sim.config, sim.scenario.start)))


# The grids V is read on for the deployed place: coarser than the learned planner's (each place is valued
# level and tilted), its proposals valued by the cheap R anyway (measured: docs/places.md)
DEPLOYED_GRIDS = PlaceSettings(grid_step=3.0, fine_step=1.5, fine_places=6)


@dataclass(frozen=True)
class DecideSettings:
    """How the deployed place is decided: ``V`` proposes, ``R`` disposes (:func:`decided_plan`)."""

    proposals: int = 16  # V's best places (apart by ``separation``) valued by the cheap R, level and tilted
    separation: float = 2.0  # m between proposals
    refine_from: int = 1  # the best poses by the cheap R refined by a pattern search on it
    max_refinements: int = 6  # batches of that pattern search
    refine_step: float = 0.5  # m, its first step
    runners_up: int = 1  # the next best poses by the cheap R among the finalists, unrefined
    check_batches: int = 4  # fresh batches of R the finalists (and staying) are valued on
    front_margin_deg: float | None = SAFE_MARGIN_DEG  # the oracle's: every device this far in front of the RIS


def decided_plan(model: PoseValue, config: SystemConfig, start: tuple[float, float, float],
                 settings: DecideSettings = DecideSettings(), place: PlaceSettings = DEPLOYED_GRIDS) -> Plan:
    """The deployed place (docs/places.md): ``V``'s best ``proposals`` places (its grids, each
    place valued level and turned, :func:`ranked_poses`), each level and turned towards the
    devices where the UAV can hold it
    (the oracle's global stage's tilt, :func:`~uavris.agents.oracle.planner.facing_attitudes`),
    with the start, valued by the planner's cheap ``R`` and the travel-time rule; the best refined
    by a short pattern search in position and attitude on the cheap ``R``; the refined, the
    runners-up and staying valued by ``R`` on fresh batches and chosen as the oracle chooses
    (a move only when it beats staying by more than a standard error,
    :func:`~uavris.agents.oracle.planner.check_finalists`), every pose keeping the oracle's
    front margin."""
    s = settings
    c = holding(config, s.front_margin_deg)
    start_q = np.asarray(start, dtype=np.float64)
    level = np.zeros(3)
    places, _, values, _ = ranked_poses(model, c, start_q, place, tilt=True)
    chosen = places[top_apart(values, places, s.proposals, s.separation)]
    memo: dict[bytes, float] = {}

    def cheap(q: NDArray, att: NDArray) -> NDArray[np.float64]:
        poses = np.concatenate([np.atleast_2d(q), np.broadcast_to(att, np.atleast_2d(q).shape)], axis=1)
        keys = [p.tobytes() for p in poses]
        new = [i for i, k in enumerate(keys) if k not in memo]
        if new:
            r = expected_optimised_rate(c, poses[new, :3], poses[new, 3:], draws=RANK_DRAWS, seed=0, **RANK_OPTIMISER)
            memo.update(zip((keys[i] for i in new), r.tolist()))
        return np.array([memo[k] for k in keys])

    facing, tilted = turned_towards(c, chosen)
    pos = np.concatenate([start_q[None], chosen, chosen[tilted]])
    att = np.concatenate([level[None], np.zeros_like(chosen), facing[tilted]])
    r = cheap(pos, att)
    vals = episode_value(c.horizon, trip_slots(c, start_q, pos), r[0], r)
    order = [int(i) for i in np.argsort(-vals, kind="stable") if i != 0]

    def episode(q: NDArray, a: NDArray) -> NDArray[np.float64]:
        return episode_value(c.horizon, trip_slots(c, start_q, np.atleast_2d(q)), r[0], cheap(q, a))

    refined = []
    for i in order[:s.refine_from]:
        q, a, _ = pattern_search(c, pos[i].copy(), att[i].copy(), float(vals[i]), episode, s.refine_step,
                                 PlanSettings().min_step, tolerance=1e-6, max_batches=s.max_refinements,
                                 settle=wrap_angle)
        refined.append((q, a))
    finalists = [(start_q, level), *refined, *((pos[i], att[i]) for i in order[s.refine_from:
                                                                                  s.refine_from + s.runners_up])]
    table = tuple((tuple(float(x) for x in p), float(rv), float(vv)) for p, rv, vv in zip(pos, r, vals))
    checks = PlanSettings(check_batches=s.check_batches, front_margin_deg=s.front_margin_deg)
    return check_finalists(c, checks, start_q, finalists, len(memo), table)
