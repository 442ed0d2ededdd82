"""How good the oracle's plan is: a much wider search of the same objective, to measure its gap.

Lives here: :func:`exhaustive_plan` (the best pose a dense search finds for a start) and
:func:`plan_gap` (the oracle's plan against it, both valued on the same fresh draws). Not
here: the oracle's own planner (:mod:`.planner`), whose objective this searches.

The objective is the planner's (:mod:`.objective`, docs/model.md, "The oracle"): the
expected episode average of flying from rest at ``start`` to a pose and hovering there
(:func:`.objective.episode_value`), with ``R`` the expected sum rate with optimised phases at
the pose (:func:`.objective.expected_optimised_rate`). The search:

1. every feasible position of a grid (``grid_step`` across, ``z_step`` in height), level;
2. around its ``fine_places`` best (at least ``grid_step`` apart), every feasible position of a
   finer grid (``fine_step``, within ``fine_reach`` of the place), level: as wide as the learned
   planner's finer grid (2 m each way, by 0.5 m), which found places above the oracle's;
3. at the ``top`` best so far (at least ``grid_step`` apart), every attitude of a grid of
   yaw, pitch and roll (``attitudes_deg`` each) that the UAV can hold (under the system's
   front margin: :func:`.planner.held`);
4. a pattern search in position and attitude from each of the ``refine`` best and from every
   distinct pose of ``seeds`` (the oracle's plan and candidates, :func:`plan_seeds`), down to
   ``min_step``, the planner's own (:func:`.planner.pattern_search`, its neighbours: the
   attitude safety layer's limit included where the system has one).

Seeded with the oracle's own poses, the search is a superset of the oracle's: on its own
objective it never returns a pose worth less than any of them (any the UAV may hold in the
searched system, as all of the oracle's are in its own), so a gap it measures is a gap
of the oracle's search and not the wider search's blind spot (without them the oracle beat it
by 1-2 bps/Hz in two halls of 6 devices, where the oracle's tilted finalist lay between its
grids).

To measure the oracle, search the system it plans in (:func:`.planner.holding` with its
settings' margin): the same poses are allowed to both. Its draws are not the planner's
(``seed``), so the oracle is not judged on its own common random numbers; :func:`plan_gap`
then values both poses and staying on ``batches`` fresh batches with a many-restart
optimiser, and gives their paired difference.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from uavris import physics as ph
from uavris.agents.oracle import objective
from uavris.agents.oracle.planner import Plan, distinct, held, pattern_search
from uavris.config import SystemConfig

Valuer = Callable[[NDArray[np.float64], NDArray[np.float64]], NDArray[np.float64]]  # R of (P, 3) positions, attitudes


@dataclass(frozen=True)
class SearchSettings:
    grid_step: float = 2.0  # m, across the hall
    z_step: float = 1.0  # m, in height
    fine_step: float = 0.5  # m, the finer grid around the best places
    fine_reach: float = 2.0  # m, each way from such a place (the learned planner's reach)
    fine_places: int = 8  # the places the finer grid surrounds
    top: int = 12  # positions whose attitudes are searched
    attitudes_deg: tuple[float, ...] = (-20.0, -10.0, 0.0, 10.0, 20.0)  # each of yaw, pitch, roll
    refine: int = 6  # poses the pattern search starts from
    refine_step: float = 1.0  # m, first pattern-search step (the attitude's: attitude_step_deg)
    min_step: float = 0.0625  # m, the pattern search stops below this step
    draws: int = 2  # NLoS draws per pairing in R
    seed: int = 7  # R's common random numbers: not the planner's


@dataclass(frozen=True)
class Found:
    target: NDArray[np.float64]
    attitude: NDArray[np.float64]
    value: float  # the objective on the search's draws
    poses_valued: int


def plan_seeds(plan: Plan) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """The poses of a plan the search starts from too: its target with its attitude, and each
    candidate it valued, level (the table holds positions, not the tilt a candidate of the global
    stage was valued at: :func:`.planner.global_poses`)."""
    return [(np.asarray(plan.target, dtype=np.float64), np.asarray(plan.attitude, dtype=np.float64)),
            *((np.asarray(p, dtype=np.float64), np.zeros(3)) for p, _, _ in plan.candidates)]


def seed_poses(seeds: Sequence[tuple[NDArray, NDArray]]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The positions and attitudes ``(S, 3)`` of ``seeds``, each distinct pose once, in their order:
    a plan that stays has the start as its target and as its first candidate, and one pattern
    search from a pose finds what two would."""
    poses = distinct(np.array([np.concatenate([np.ravel(q), np.ravel(a)]) for q, a in seeds], dtype=np.float64))
    return poses[:, :3], poses[:, 3:]


def exhaustive_plan(config: SystemConfig, start: tuple[float, float, float],
                    settings: SearchSettings = SearchSettings(), valuer: Valuer | None = None,
                    seeds: Sequence[tuple[NDArray, NDArray]] = ()) -> Found:
    """The best pose for ``start`` that the search of the module docstring finds (``valuer``: R
    of poses; default the optimiser's expected rate on the search's draws), started from the
    poses of ``seeds`` too (position, attitude: the oracle's, :func:`plan_seeds`), each that
    the UAV may hold."""
    s, c = settings, config
    count = 0

    def default(q: NDArray, att: NDArray) -> NDArray[np.float64]:
        return objective.expected_optimised_rate(c, q, att, draws=s.draws, seed=s.seed)

    rate_of = valuer or default

    def value(q: NDArray, att: NDArray) -> NDArray[np.float64]:
        nonlocal count
        count += len(q)
        trip = objective.trip_slots(c, start_q, np.atleast_2d(q))
        return objective.episode_value(c.horizon, trip, r_start, rate_of(q, att))

    start_q = np.asarray(start, dtype=np.float64)
    level = np.zeros(3)
    r_start = float(rate_of(start_q[None], level[None])[0])
    places, ok = objective.feasible_grid(c, s.grid_step, s.z_step)
    grid = np.concatenate([start_q[None], places[ok]])
    v = value(grid, np.zeros_like(grid))
    ticks = np.arange(-s.fine_reach, s.fine_reach + 1e-9, s.fine_step)
    offsets = np.stack(np.meshgrid(ticks, ticks, ticks, indexing="ij"), -1).reshape(-1, 3)
    near = np.concatenate([grid[i] + offsets for i in objective.top_apart(v, grid, s.fine_places, s.grid_step - 1e-9)])
    near = near[objective.feasible(c, near)]
    grid, v = np.concatenate([grid, near]), np.concatenate([v, value(near, np.zeros_like(near))])
    chosen = objective.top_apart(v, grid, s.top, s.grid_step - 1e-9)  # the best, at least a grid step apart
    angles = np.radians(np.array(list(itertools.product(s.attitudes_deg, repeat=3))))
    poses = [(grid[i], a) for i in chosen for a in angles]
    q_all = np.array([p for p, _ in poses])
    a_all = np.array([a for _, a in poses])
    keep = held(c, q_all, a_all)  # under the system's margin, only the poses the UAV can hold (as the plan's)
    q_all, a_all = q_all[keep], a_all[keep]
    va = value(q_all, a_all)
    order = [int(i) for i in np.argsort(-va, kind="stable")[:s.refine]]
    if len(seeds):
        sq, sa = seed_poses(seeds)
        ok = objective.feasible(c, sq) & held(c, sq, sa)
        q_all, a_all = np.concatenate([q_all, sq[ok]]), np.concatenate([a_all, sa[ok]])
        va = np.concatenate([va, value(sq[ok], sa[ok])])
        order += list(range(len(va) - int(ok.sum()), len(va)))
    best = max(((q_all[i], a_all[i], float(va[i])) for i in order), key=lambda x: x[2])
    for i in order:
        q, att, vb = pattern_search(c, q_all[i].copy(), a_all[i].copy(), float(va[i]), value, s.refine_step,
                                    s.min_step, tolerance=1e-9)
        if vb > best[2]:
            best = (q, att, vb)
    return Found(np.asarray(best[0]), ph.wrap_angle(np.asarray(best[1])), best[2], count)


@dataclass(frozen=True)
class Gap:
    """The oracle's plan against the search's pose, valued on the same fresh draws (bps/Hz)."""

    oracle_value: float
    search_value: float
    stay_value: float
    difference: float  # search minus oracle, per batch mean
    difference_se: float


def plan_gap(config: SystemConfig, start: tuple[float, float, float], plan: Plan, found: Found, batches: int = 8,
             seed: int = 0) -> Gap:
    """The episode values of the oracle's plan, the search's pose and staying, each on the same
    ``batches`` batches of fresh draws (:data:`.objective.ASSESS_SEED` + 5,000: neither the plan's
    draws nor the search's), and the paired difference search minus oracle with its standard error."""
    start_q = np.asarray(start, dtype=np.float64)
    q = np.stack([start_q, plan.target, found.target])
    att = np.stack([np.zeros(3), plan.attitude, found.attitude])
    r = objective.rate_batches(config, q, att, batches, seed + objective.ASSESS_SEED + 5_000)  # (3, B)
    v = objective.episode_value(config.horizon, objective.trip_slots(config, start_q, q)[:, None], r[0], r)
    d = v[2] - v[1]
    return Gap(float(v[1].mean()), float(v[2].mean()), float(v[0].mean()), float(d.mean()),
               float(d.std(ddof=1) / math.sqrt(batches)))
