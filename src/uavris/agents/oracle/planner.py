"""The planning oracle's global stage: where the system is best, and whether it is worth the trip.

Lives here: the plan (:func:`plan_target`, :class:`Plan`, :class:`PlanSettings`), its screen
(:func:`screen`), pattern search (:func:`pattern_neighbours`) and check of the finalists on
fresh draws (:func:`check_finalists`). Not here: what a plan is worth, ``R`` of a pose and the
episode value of a trip (:mod:`.objective`); the per-slot controller that executes the plan
(:mod:`.policy`).

Method (docs/model.md, "The oracle"):

1. **Value of a pose.** ``R(q, zeta)`` (:func:`.objective.expected_optimised_rate`), on
   ``nlos_draws`` NLoS draws, the same at every pose (common random numbers).
2. **Screen.** The interference-free score of the lookahead
   (:func:`.lookahead.expected_sum_rate`, microseconds per pose) on a grid of spacing
   ``grid_step`` over the flight region outside the safety balls, level RIS. Its local
   maxima (26-neighbourhood) are the candidate regions; the ``candidates`` best and the
   start itself are valued with ``R``.
3. **Choice.** A candidate's value is the expected average sum rate of the episode if the
   UAV flies there and hovers (:func:`.objective.episode_value`). The best value wins; the
   start (stay where you are) is a candidate too.
4. **Refinement.** Pattern search on ``R`` from the chosen target: the 6 position
   neighbours at ``+-step`` per axis and the 6 attitude neighbours at ``+-attitude step``
   per angle are valued in one batch, the best improving one is taken, and the steps are
   halved when none improves, down to ``min_step``. Infeasible neighbours (outside the
   region or a safety ball) are skipped.
5. **Check on fresh draws.** Steps 3-4 take maxima of estimates made on one set of common
   random numbers, so the winner's estimate is biased upwards (the winner's curse: with 6
   devices the 24 sampled pairings favoured a corner worth 52.1 bps/Hz that measures 48.0,
   below staying at the start). The finalists (the start, the refined target and the best
   three candidates unrefined) are valued again on ``check_batches`` independent batches of fresh
   draws (each its own pairing sample, where the pairings are sampled, and its own NLoS
   draw: :func:`.objective.rate_batches`), and a move is taken only when its plan value beats staying
   by more than one standard error of the paired difference. The plan's numbers
   (``rate``, ``start_rate``, ``value``, ``rate_se``) come from a second fresh set, so the
   value stated for the chosen pose is not the maximum of anything: it is unbiased.

Cost (one core, default system, measured by ``benchmarks/oracle_throughput.py``): the
screen is milliseconds; each valued pose is ``24 x nlos_draws`` optimised slots, half of
them the closed form; a plan values ~60 poses. The plan depends only on the system, the
start and the seed, so it is made once per scenario and cached by the policy.

Energy. Moving costs less than hovering (the propulsion power falls with speed up to
``v_max``), so a trip never costs more energy than hovering for its duration: the energy
budget cannot end an episode before the UAV arrives, and the plan ignores it beyond that.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from uavris import physics as ph
from uavris.agents.oracle.lookahead import pose_score
from uavris.agents.oracle.objective import (
    ASSESS_SEED,
    CHECK_SEED,
    episode_value,
    expected_optimised_rate,
    feasible,
    feasible_grid,
    rate_batches,
    top_apart,
    trip_slots,
)
from uavris.config import SystemConfig

# The attitude safety layer's margin (SystemConfig.front_margin_deg, docs/model.md section 3) that the
# oracle plans and flies with, and the deployment track's "safe" rows fly with (docs/study.md section 2).
SAFE_MARGIN_DEG = 1.0
# What the oracle's plans and flights are, as a version: raised with every change of code that moves them.
# A study's stages whose results follow from them carry it in their keys (the strong experts, who imitate
# the oracle's flight; the demonstrations, the planner's plans flown; the learned value's labels, its screen
# and rate of poses; the evaluations, which score the oracle), so that a study made before a change is run
# again instead of read back. 1: the global stage (docs/model.md section 19); 2: every device kept 1 degree
# in front of the RIS in the plan and its flight.
ORACLE_VERSION = 2


@dataclass(frozen=True)
class PlanSettings:
    """How hard the planner looks (defaults: see the module docstring and the benchmark)."""

    grid_step: float = 1.0  # m, screening grid
    candidates: int = 6  # screened local maxima valued with the optimiser
    nlos_draws: int = 2  # NLoS draws per pairing in R
    refine_step: float = 0.5  # m, first pattern-search step
    min_step: float = 0.125  # m, the search stops below this step
    max_refinements: int = 12  # batches of neighbours valued at most
    seed: int = 0  # common random numbers of R
    exact: bool = True  # rank every pose with R itself (the reference); False: with the cheap estimate, 11x cheaper
    # the pattern search (step 4) on the cheap estimate while the candidates are still ranked with R: the
    # demonstrations' teacher (TEACHER), whose region is the exact planner's and whose refinement is cheap
    cheap_refinement: bool = False
    check_batches: int = 8  # fresh batches the finalists are valued on (step 5), and the plan's numbers
    # the global stage (step 2b): the cheap R, interference included, on a coarse grid of the whole region
    global_step: float = 4.0  # m across; 0: none (the screen alone: the demonstrations' teacher, TEACHER)
    global_z_step: float = 2.0  # m in height
    global_regions: int = 6  # its best places, a grid step apart, valued by R beside the screen's
    refine_from: int = 2  # the best candidates the pattern search starts from
    # every pose of the plan keeps each device this far (deg) in front of the RIS, as the attitude safety
    # layer would; None: only the system's own margin. A plan on the edge loses a device behind the plane
    # to the hover's drift (docs/model.md section 19); the teacher keeps None, its demonstrations unchanged
    front_margin_deg: float | None = SAFE_MARGIN_DEG

    def __post_init__(self) -> None:
        for name in ("grid_step", "refine_step", "min_step", "global_z_step"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"PlanSettings.{name} must be > 0, got {getattr(self, name)!r}")
        if not (math.isfinite(self.global_step) and self.global_step >= 0):
            raise ValueError(f"PlanSettings.global_step must be >= 0 (0: no global stage), got {self.global_step!r}")
        for name in ("candidates", "nlos_draws", "refine_from"):
            if getattr(self, name) < 1:
                raise ValueError(f"PlanSettings.{name} must be >= 1, got {getattr(self, name)!r}")
        if self.check_batches < 2:
            raise ValueError(f"PlanSettings.check_batches must be >= 2 (a standard error), got {self.check_batches!r}")
        if self.max_refinements < 0 or self.seed < 0:
            raise ValueError("PlanSettings.max_refinements and seed must be >= 0")
        m = self.front_margin_deg
        if m is not None and not (math.isfinite(m) and 0 <= m < 90):
            raise ValueError(f"PlanSettings.front_margin_deg must be None or in [0, 90) degrees, got {m!r}")


def holding(config: SystemConfig, margin_deg: float | None) -> SystemConfig:
    """``config`` with the attitude safety layer's margin at least ``margin_deg`` (its own where larger):
    the system a plan is made in, so that its every pose is one the UAV can hold."""
    if margin_deg is None or (config.front_margin_deg is not None and config.front_margin_deg >= margin_deg):
        return config
    return config.replace(front_margin_deg=margin_deg)


@dataclass(frozen=True)
class Plan:
    """Where to go from ``start``: target position and attitude, and what the planner found."""

    start: tuple[float, float, float]
    target: NDArray[np.float64]  # (3,) m
    attitude: NDArray[np.float64]  # (3,) rad, yaw, pitch, roll
    rate: float  # R(target), bps/Hz
    start_rate: float  # R(start), level
    travel_slots: int
    value: float  # expected episode average of the plan, bps/Hz
    poses_valued: int  # poses evaluated with the optimiser for this plan (the cost; memoised ones excluded)
    candidates: tuple[tuple[tuple[float, ...], float, float], ...]  # (position, R, value) of each candidate
    rate_se: float = 0.0  # standard error of ``rate`` (the fresh batches'), bps/Hz
    front_margin_deg: float | None = None  # the margin it keeps (PlanSettings.front_margin_deg), its flight too


# The cheap estimate of R that ranks poses with PlanSettings(exact=False): one NLoS draw, and
# the optimiser from its co-phasing starts only, with a two-level continuation of 20
# iterations; the chosen pose and the start are then valued by R. Measured on the 11 named
# scenarios and 16 generated halls (benchmarks/oracle_throughput.py): 11x cheaper per new
# hall, the plan's value 0.23% below the exact plan's on average and 1.2% in the worst hall
# (a tilt of the RIS the exact search finds and this one does not, or an equally good place
# elsewhere). Above the 0.5% the references can afford, so the oracle of every report plans
# exactly; the estimate is an option for what does not need the reference.
# They shape the demonstrations' teacher's refinement too (TEACHER): a change to them, or to
# FINALIST_CANDIDATES, changes plans, and goes with a new ORACLE_VERSION (every stage key of a plan).
RANK_DRAWS = 1
RANK_OPTIMISER = dict(restarts=0, noise_levels=(1e3, 1.0), iterations=20)


# The demonstrations' teacher, made in hundreds of halls, where the yardstick's cost (the oracle's, made
# once per evaluated hall) must not go: the planner without the global stage and the front margin, its
# candidates ranked with R, its pattern search on the cheap estimate and its finalists checked on 4 fresh
# batches. Against the same planner searching with R (96 training halls, one core, docs/timings.md): 4.1x
# cheaper, its plans worth 0.19% less on average and 1.26% in the worst hall.
TEACHER = PlanSettings(global_step=0.0, refine_from=1, front_margin_deg=None, cheap_refinement=True, check_batches=4)
# That planner searching with R and checking on 8 batches (the teacher before 0.4.0)
EXACT_TEACHER = PlanSettings(global_step=0.0, refine_from=1, front_margin_deg=None)

FINALIST_CANDIDATES = 3  # the best candidates by the planning value, unrefined, among the finalists beside the refined


def screen(config: SystemConfig, step: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Local maxima of the interference-free score on a grid over the feasible region, best first:
    positions ``(M, 3)`` and scores ``(M,)``."""
    grid, ok = feasible_grid(config, step, flat=False)
    score = np.where(ok, pose_score(config, grid, np.zeros(3)), -np.inf)
    peak = (score == ndimage.maximum_filter(score, size=3, mode="constant", cval=-np.inf)) & np.isfinite(score)
    order = np.argsort(-score[peak], kind="stable")
    return grid[peak][order], score[peak][order]


def plan_target(config: SystemConfig, start: tuple[float, float, float], settings: PlanSettings = PlanSettings(),
                memo: dict[bytes, float] | None = None) -> Plan:
    """The plan from ``start`` (at rest, level): screen, value, choose, refine (module docstring).

    ``memo`` caches ``R`` by pose across plans of the same system and settings: the
    candidates and the refinement path do not depend on the start, so later scenarios
    mostly reuse the first one's work.
    """
    c, s = holding(config, settings.front_margin_deg), settings
    start_q = np.asarray(start, dtype=np.float64)
    level = np.zeros(3)
    memo = {} if memo is None else memo
    valued = 0

    def valuer(exact: bool) -> Any:
        def rate(q: NDArray, att: NDArray) -> NDArray[np.float64]:
            nonlocal valued
            poses = np.concatenate([q, np.broadcast_to(att, q.shape)], axis=1)
            keys = [bytes([exact]) + p.tobytes() for p in poses]
            new = [i for i, k in enumerate(keys) if k not in memo]
            if new:
                valued += len(new)
                kw = dict(draws=s.nlos_draws) if exact else dict(draws=RANK_DRAWS, **RANK_OPTIMISER)
                values = expected_optimised_rate(c, poses[new, :3], poses[new, 3:], seed=s.seed, **kw)
                memo.update(zip((keys[i] for i in new), values.tolist()))
            return np.array([memo[k] for k in keys])
        return rate

    exact_rate = valuer(True)
    rate = exact_rate if s.exact else valuer(False)
    search = valuer(False) if s.cheap_refinement else rate

    peaks, _ = screen(c, s.grid_step)
    screened = np.concatenate([start_q[None], peaks[:s.candidates]])
    found = [np.concatenate([screened, np.zeros_like(screened)], axis=1)]  # poses (position, attitude): level
    if s.global_step > 0:
        found.append(global_poses(c, s, start_q, valuer(False)))
    poses = distinct(np.concatenate(found))  # the start first
    cands, atts = poses[:, :3], poses[:, 3:]
    r = rate(cands, atts)
    vals = episode_value(c.horizon, trip_slots(c, start_q, cands), r[0], r)
    order = np.argsort(-vals, kind="stable")
    refined = [refine(c, s, cands[i], atts[i], float(r[i] if search is rate else search(cands[i:i + 1], atts[i])[0]),
                      search) for i in order[:s.refine_from] if i != 0]
    table = tuple((tuple(float(x) for x in p), float(rv), float(vv)) for p, rv, vv in zip(cands, r, vals))
    runners_up = [(cands[i], atts[i]) for i in order[:FINALIST_CANDIDATES] if i != 0]
    finalists = [(start_q, level), *refined, *runners_up]
    return check_finalists(c, s, start_q, finalists, valued, table)


def distinct(places: NDArray) -> NDArray[np.float64]:
    """``places`` (or poses) with each one once, in their order."""
    keep = [i for i in range(len(places)) if not any(np.array_equal(places[i], places[j]) for j in range(i))]
    return places[keep]


def global_poses(c: SystemConfig, s: PlanSettings, start_q: NDArray, cheap: Any) -> NDArray[np.float64]:
    """Step 2b: the cheap ``R`` (interference and every pairing included, unlike the screen) of
    every feasible place of a coarse grid over the whole region, level and facing the devices
    (:func:`facing_attitudes`); its ``global_regions`` best poses ``(M, 6)`` (position, attitude)
    by the episode value of flying there, at least a grid step apart. The screen's
    interference-free score of a level RIS misses the places where the devices' links interfere
    least, and those where a tilt turns the surface to them (20 degrees of roll took a place of a
    6-device hall from 42.9 to 49.9 bps/Hz), which decide a hall of many devices."""
    grid, ok = feasible_grid(c, s.global_step, s.global_z_step)
    places = grid[ok]
    if not len(places):
        return np.zeros((0, 6))
    level = np.zeros(3)
    r0 = float(cheap(start_q[None], level)[0])
    facing = facing_attitudes(c, places)
    flat, turned = cheap(places, level), cheap(places, facing)
    rates = np.maximum(flat, turned)
    atts = np.where((turned > flat)[:, None], facing, 0.0)
    vals = episode_value(c.horizon, trip_slots(c, start_q, places), r0, rates)
    keep = top_apart(vals, places, s.global_regions, s.global_step - 1e-9)
    return np.concatenate([places[keep], atts[keep]], axis=1)


MAX_FACING_TILT = math.radians(20.0)


def facing_attitudes(c: SystemConfig, places: NDArray) -> NDArray[np.float64]:
    """``(M, 3)`` attitudes (yaw 0) whose RIS normal points from the devices' centroid to the UAV
    at each place, pitch and roll each at most :data:`MAX_FACING_TILT`: the surface turned
    towards the devices (eq. 10's normal ``n = (sin p cos r, -sin r, cos p cos r)`` at yaw 0).
    Level where the attitude safety layer would not let the UAV hold the tilt."""
    d = places - np.asarray(c.users, dtype=np.float64).mean(axis=0)
    n = d / np.linalg.norm(d, axis=1, keepdims=True)
    roll = np.clip(-np.arcsin(np.clip(n[:, 1], -1.0, 1.0)), -MAX_FACING_TILT, MAX_FACING_TILT)
    pitch = np.clip(np.arctan2(n[:, 0], n[:, 2]), -MAX_FACING_TILT, MAX_FACING_TILT)
    att = np.stack([np.zeros(len(places)), pitch, roll], axis=1)
    att[~held(c, places, att)] = 0.0
    return att


def turned_towards(c: SystemConfig, places: NDArray) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`facing_attitudes` at ``places`` (none: an empty ``(0, 3)``) and which of them are
    turned: the places where the surface can be turned towards the devices at all (the others
    stay level, and are valued once)."""
    facing = facing_attitudes(c, places) if len(places) else np.zeros((0, 3))
    return facing, np.any(facing != 0.0, axis=1)


def held(c: SystemConfig, places: NDArray, atts: NDArray) -> NDArray[np.bool_]:
    """Which poses the attitude safety layer lets the UAV hold: every device at least ``c.front_margin_deg``
    in front of the RIS (docs/model.md section 3); all of them where the system has no margin."""
    if c.front_margin_deg is None:
        return np.ones(len(places), dtype=bool)
    return ph.worst_elevation(atts, places, np.asarray(c.users)) >= np.sin(np.radians(c.front_margin_deg))


def refine(c: SystemConfig, s: PlanSettings, q: NDArray, att: NDArray, r_q: float, rate: Any
           ) -> tuple[NDArray, NDArray]:
    """Step 4: the pattern search on ``R`` from the pose ``(q, att)``, down to ``min_step``, at most
    ``max_refinements`` batches; each pose taken with its attitude wrapped, as the UAV holds it."""
    q, att, _ = pattern_search(c, q.copy(), np.asarray(att, dtype=np.float64).copy(), r_q, rate, s.refine_step,
                               s.min_step, tolerance=1e-6, max_batches=s.max_refinements, settle=ph.wrap_angle)
    return q, att


def pattern_search(c: SystemConfig, q: NDArray, att: NDArray, v: float, value: Any, first_step: float,
                   min_step: float, *, tolerance: float, max_batches: int | None = None,
                   settle: Any = lambda att: att) -> tuple[NDArray, NDArray, float]:
    """The pattern search of the planner (step 4) and of the wider search
    (:mod:`.search`): from the pose ``(q, att)`` worth ``v``, the neighbours of
    :func:`pattern_neighbours` valued in one batch (``value`` of positions and attitudes), the
    best taken where it improves on ``v`` by more than ``tolerance`` (``settle`` of its attitude),
    else both steps halved (the attitude's from the system's ``attitude_step_rad``), until the
    position step is below ``min_step`` or after ``max_batches`` rounds (a round with no feasible
    neighbour counts, though it values none). Returns the pose found and its value."""
    pos_step, att_step = first_step, c.attitude_step_rad
    batches = 0
    while pos_step >= min_step and (max_batches is None or batches < max_batches):
        batches += 1
        nq, na, ok = pattern_neighbours(c, q, att, pos_step, att_step)
        if not ok.any():
            pos_step, att_step = pos_step / 2, att_step / 2
            continue
        nv = value(nq[ok], na[ok])
        i = int(np.argmax(nv))
        if nv[i] > v + tolerance:
            q, att, v = nq[ok][i], settle(na[ok][i]), float(nv[i])
        else:
            pos_step, att_step = pos_step / 2, att_step / 2
    return q, att, v


def pattern_neighbours(c: SystemConfig, q: NDArray, att: NDArray, pos_step: float, att_step: float
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """The pattern search's neighbours of the pose ``(q, att)``: the 6 positions ``+-pos_step``
    per axis (attitude kept) and the 6 attitudes ``+-att_step`` per angle (position kept; none
    when ``att_step`` is 0), and which of them may be held: inside the flight region, outside
    every safety ball and, under the attitude safety layer, with every device in front."""
    eye = np.eye(3)
    nq = np.concatenate([q + pos_step * eye, q - pos_step * eye, np.repeat(q[None], 6 if att_step > 0 else 0, 0)])
    na = np.concatenate([np.repeat(att[None], 6, 0)] + ([att + att_step * eye, att - att_step * eye]
                                                      if att_step > 0 else []))
    return nq, na, feasible(c, nq) & held(c, nq, na)


def check_finalists(c: SystemConfig, s: PlanSettings, start_q: NDArray, finalists: list[tuple[NDArray, NDArray]],
                    valued: int, table: tuple) -> Plan:
    """Step 5 (module docstring): the finalists (the start first) valued on fresh batches, a move
    taken only when it beats staying by more than a standard error, the plan's numbers stated
    on a second fresh set."""
    unique: list[tuple[NDArray, NDArray]] = []
    for q, att in finalists:
        if not any(np.array_equal(q, u) and np.array_equal(att, a) for u, a in unique):
            unique.append((q, att))
    pos, att = np.stack([u for u, _ in unique]), np.stack([a for _, a in unique])
    slots = trip_slots(c, start_q, pos)

    def episode(x: NDArray, t: NDArray) -> NDArray[np.float64]:  # (F, B) rates, the start's first -> plan values
        return episode_value(c.horizon, t[:, None], x[:1], x)

    b = s.check_batches
    moves = episode(rate_batches(c, pos, att, b, s.seed + CHECK_SEED), slots)
    gain = moves - moves[:1]
    mean, se = gain.mean(axis=1), gain.std(axis=1, ddof=1) / math.sqrt(b)
    chosen = max((i for i in range(1, len(unique)) if mean[i] > se[i]), key=lambda i: mean[i], default=0)
    keep = [0, chosen] if chosen else [0]
    stated = rate_batches(c, pos[keep], att[keep], b, s.seed + ASSESS_SEED)
    rate = stated[-1]
    return Plan(start=tuple(float(x) for x in start_q), target=pos[chosen].copy(), attitude=att[chosen].copy(),
                rate=float(rate.mean()), start_rate=float(stated[0].mean()), travel_slots=int(slots[chosen]),
                value=float(episode(stated, slots[keep])[-1].mean()),
                poses_valued=valued + (len(unique) + len(keep)) * b, candidates=table,
                rate_se=float(rate.std(ddof=1) / math.sqrt(b)), front_margin_deg=s.front_margin_deg)

