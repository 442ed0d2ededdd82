"""The planning oracle's global stage: where the system is best, and whether it is worth the trip.

Lives here: the expected sum rate with optimised phases at a pose (:func:`expected_optimised_rate`),
the plan (:func:`plan_target`) and the travel-time model it uses. Not here: the per-slot
controller that executes the plan (:mod:`.policy`).

Method (docs/model.md, "The oracle"):

1. **Value of a pose.** ``R(q, zeta)`` = expected sum rate of a hovering UAV at position
   ``q`` and attitude ``zeta`` whose phases are re-optimised every slot
   (:func:`uavris.physics.phase_opt.optimize_slot_phases`). The expectation over the
   pairing is exact: every pairing the model can draw is enumerated with its probability
   (24 for K = 4: 12 single links and 12 pairs of links); the expectation over the NLoS
   draw is a Monte-Carlo mean over ``nlos_draws`` draws. The draws are the same at every pose
   (common random numbers), so two poses are compared on the same channels and pairings
   and the map is smooth in the pose.
2. **Screen.** The interference-free score of the lookahead
   (:func:`.lookahead.expected_sum_rate`, microseconds per pose) on a grid of spacing
   ``grid_step`` over the flight region outside the safety balls, level RIS. Its local
   maxima (26-neighbourhood) are the candidate regions; the ``candidates`` best and the
   start itself are valued with ``R``.
3. **Choice.** A candidate's value is the expected average sum rate of the episode if the
   UAV flies there and hovers: ``(t R_route + (T - t) R(target)) / T`` with ``t`` the slots
   the trip takes from rest (:func:`travel_slots`, the controller's own motion along a
   straight line) and ``R_route = min(R(start), R(target))`` for the slots in flight. The
   best value wins; the start (stay where you are) is a candidate too.
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
   draw: :func:`rate_batches`), and a move is taken only when its plan value beats staying
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

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from uavris import physics as ph
from uavris.agents.oracle.lookahead import pose_score
from uavris.config import SystemConfig
from uavris.physics import streams
from uavris.physics.phase_opt import optimize_slot_phases

# Above this many pairings (K = 4 has 24) the expectation samples this many (stratified by the
# number of active pairs, common random numbers) instead of enumerating them: the cost of a
# pose then grows with K only through the optimiser's cost per slot (measured in
# benchmarks/oracle_throughput.py, with the sampled value's error against 256 samples).
MAX_ENUMERATED_PAIRINGS = 24
ARRIVAL_TOLERANCE = 0.05  # m: the trip is over within this distance of the target, at rest


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
    check_batches: int = 8  # fresh batches the finalists are valued on (step 5), and the plan's numbers

    def __post_init__(self) -> None:
        for name in ("grid_step", "refine_step", "min_step"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"PlanSettings.{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("candidates", "nlos_draws"):
            if getattr(self, name) < 1:
                raise ValueError(f"PlanSettings.{name} must be >= 1, got {getattr(self, name)!r}")
        if self.check_batches < 2:
            raise ValueError(f"PlanSettings.check_batches must be >= 2 (a standard error), got {self.check_batches!r}")
        if self.max_refinements < 0 or self.seed < 0:
            raise ValueError("PlanSettings.max_refinements and seed must be >= 0")


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


def pairing_distribution(config: SystemConfig, seed: int = 0, limit: int = MAX_ENUMERATED_PAIRINGS
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Every pairing the model draws, with its probability: ``(C,)`` and ``(C, K, K)``.

    The model (docs/model.md section 10) draws ``m`` uniformly in ``{1, ..., m_max}`` and then a
    uniformly random set of ``m`` disjoint ordered links (a random permutation, paired in
    order). When there are more than ``limit`` sets, ``limit`` pairings are drawn from the
    model instead (counter-based, ``seed``), stratified by ``m``: an equal share of the draws
    for each ``m``, weighted ``1 / (m_max x its draws)``, so every ``m`` keeps its probability.
    """
    k, m_max = config.num_users, config.pairs_upper
    counts = [math.perm(k, 2 * m) // math.factorial(m) for m in range(1, m_max + 1)]
    if sum(counts) > limit:
        per = np.full(m_max, limit // m_max)
        per[:limit % m_max] += 1  # the remainder to the smallest m
        bits = streams.raw_bits(streams.seed_key(seed), limit * k)
        u = streams.uniforms(bits).reshape(limit, k)
        m = np.repeat(np.arange(1, m_max + 1), per)
        # u_count in the middle of m's bin of pairing_from_uniforms: exactly m pairs
        pairing = ph.pairing_from_uniforms((m - 0.5) / m_max, u, m_max)
        return 1.0 / (m_max * per[m - 1]), pairing
    probs, mats = [], []
    for m, count in zip(range(1, m_max + 1), counts):
        sets = sorted({frozenset(zip(p[0::2], p[1::2])) for p in itertools.permutations(range(k), 2 * m)}, key=sorted)
        for links in sets:
            mat = np.zeros((k, k))
            for tx, rx in links:
                mat[tx, rx] = 1.0
            mats.append(mat)
            probs.append(1.0 / (m_max * count))
    return np.array(probs), np.stack(mats)


def nlos_draws(config: SystemConfig, draws: int, seed: int) -> NDArray[np.complex128]:
    """``draws`` NLoS realisations ``(draws, K, N)`` of CN(0, 1), counter-based from ``seed``."""
    k, n = config.num_users, config.num_elements
    bits = streams.raw_bits(streams.seed_key(seed + 1), draws * k * n)
    return streams.complex_normals(bits).reshape(draws, k, n)


# The cheap estimate of R that ranks poses with PlanSettings(exact=False): one NLoS draw, and
# the optimiser from its co-phasing starts only, with a two-level continuation of 20
# iterations; the chosen pose and the start are then valued by R. Measured on the 11 named
# scenarios and 16 generated halls (benchmarks/oracle_throughput.py): 11x cheaper per new
# hall, the plan's value 0.23% below the exact plan's on average and 1.2% in the worst hall
# (a tilt of the RIS the exact search finds and this one does not, or an equally good place
# elsewhere). Above the 0.5% the references can afford, so the oracle of every report plans
# exactly; the estimate is an option for what does not need the reference.
RANK_DRAWS = 1
RANK_OPTIMISER = dict(restarts=0, noise_levels=(1e3, 1.0), iterations=20)


def expected_optimised_rate(config: SystemConfig, position: NDArray, attitude: NDArray, *, draws: int = 2,
                            seed: int = 0, **optimiser: Any) -> NDArray[np.float64]:
    """``R`` of poses ``(P, 3)``, ``(P, 3)``: expected sum rate with per-slot optimised phases, ``(P,)``.

    Exact over the pairing, ``draws`` NLoS draws (the same for every pose), see the module
    docstring; ``optimiser`` settings go to :func:`uavris.physics.phase_opt.optimize_phases`.
    """
    c = config
    pos = np.atleast_2d(np.asarray(position, dtype=np.float64))
    att = np.broadcast_to(np.asarray(attitude, dtype=np.float64), pos.shape)
    probs, pairing = pairing_distribution(c, seed)
    w = nlos_draws(c, draws, seed)
    u, v, cos_t, dist = ph.incidence(pos, np.asarray(c.users, dtype=np.float64), ph.ris_axes(att))  # (P, K)
    h = ph.rician_channels(u[:, None], v[:, None], cos_t[:, None], dist[:, None], w[None],
                           rician_factor=c.rician_factor, pathloss_exponent=c.pathloss_exponent, nx=c.nx, ny=c.ny,
                           spacing=c.element_spacing)  # (P, D, K, N)
    shape = (len(pos), draws, len(probs))
    sol = optimize_slot_phases(c, np.broadcast_to(h[:, :, None], shape + h.shape[-2:]),
                               np.broadcast_to(cos_t[:, None, None], shape + cos_t.shape[-1:]),
                               np.broadcast_to(pairing, shape + pairing.shape[-2:]), seed=seed, **optimiser)
    return np.einsum("pdc,c->p", sol.sum_rate, probs) / draws


# Seed offsets of the fresh batches of step 5: the finalists are chosen on one set and the plan's
# numbers stated on another, both independent of the planning's common random numbers.
CHECK_SEED, ASSESS_SEED = 10_000, 20_000
FINALIST_CANDIDATES = 3  # the best candidates by the planning value, unrefined, among the finalists beside the refined


def rate_batches(config: SystemConfig, position: NDArray, attitude: NDArray, batches: int, seed: int
                 ) -> NDArray[np.float64]:
    """``R`` of poses ``(P, 3)``, ``(P, 3)`` on ``batches`` independent batches of draws, ``(P, B)``:
    batch ``b`` has its own pairing sample (where the pairings are sampled; all of them where
    they are enumerated) and its own NLoS draw, from seed ``seed + 2 b`` (its two streams), the
    same for every pose. The batches' mean is ``R``; their spread is its standard error's."""
    return np.stack([expected_optimised_rate(config, position, attitude, draws=1, seed=seed + 2 * b)
                     for b in range(batches)], axis=-1)


def assessed_rate(config: SystemConfig, position: NDArray, attitude: NDArray, batches: int = 8, seed: int = 0
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``R`` of poses and its standard error, ``(P,)`` each, on the fresh draws a plan states its
    numbers with (:data:`ASSESS_SEED`): independent of every draw a plan is chosen on, so the
    value of a chosen pose is unbiased, and two poses assessed together are paired."""
    x = rate_batches(config, np.atleast_2d(position), np.atleast_2d(attitude), batches, seed + ASSESS_SEED)
    return x.mean(axis=-1), x.std(axis=-1, ddof=1) / math.sqrt(batches)


def feasible(config: SystemConfig, position: NDArray) -> NDArray[np.bool_]:
    """Positions ``(..., 3)`` inside the flight region and outside every safety ball."""
    q = np.asarray(position, dtype=np.float64)
    inside = np.all((q >= np.asarray(config.region_low)) & (q <= np.asarray(config.region_high)), axis=-1)
    return inside & np.all(ph.separation(q, config.users) >= config.safety_distance, axis=-1)


def screen(config: SystemConfig, step: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Local maxima of the interference-free score on a grid over the feasible region, best first:
    positions ``(M, 3)`` and scores ``(M,)``."""
    lo, hi = np.asarray(config.region_low), np.asarray(config.region_high)
    axes = [np.linspace(lo[i], hi[i], max(2, int(round((hi[i] - lo[i]) / step)) + 1)) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    score = np.where(feasible(config, grid), pose_score(config, grid, np.zeros(3)), -np.inf)
    peak = (score == ndimage.maximum_filter(score, size=3, mode="constant", cval=-np.inf)) & np.isfinite(score)
    order = np.argsort(-score[peak], kind="stable")
    return grid[peak][order], score[peak][order]


def approach_speed(config: SystemConfig, remaining: NDArray, speed: NDArray) -> NDArray[np.float64]:
    """Speed to have at the end of this slot so that the UAV can still stop at the target.

    With the kinematics of eq. (9) the slot covers ``(v + v') dt / 2`` and braking at
    ``a_max`` from ``v'`` then covers ``v'^2 / (2 a_max)``; ``v'`` solves
    ``v'^2 / (2 a) + (v + v') dt / 2 = remaining``, clipped to ``[0, v_max]``. ``speed`` is
    the current speed towards the target.
    """
    c = config
    a, dt = c.a_max, c.slot_s
    disc = a * a * dt * dt + 8.0 * a * np.asarray(remaining) - 4.0 * a * dt * np.asarray(speed)
    v_next = 0.5 * (-a * dt + np.sqrt(np.maximum(disc, 0.0)))
    return np.clip(v_next, 0.0, c.v_max)


def travel_slots(config: SystemConfig, distance: NDArray | float) -> NDArray[np.int64]:
    """Slots the approach controller needs to cover ``distance`` (m) in a straight line from
    rest and come to rest within ``ARRIVAL_TOLERANCE``: its own discrete motion, in 1-D."""
    c = config
    left = np.atleast_1d(np.asarray(distance, dtype=np.float64)).copy()
    speed = np.zeros_like(left)
    slots = np.zeros(left.shape, dtype=np.int64)
    for _ in range(c.horizon):
        moving = (left > ARRIVAL_TOLERANCE) | (speed > 0.5 * c.a_max * c.slot_s)
        if not moving.any():
            break
        a = np.clip((approach_speed(c, left, speed) - speed) / c.slot_s, -c.a_max, c.a_max)
        left = left - (speed * c.slot_s + 0.5 * a * c.slot_s**2)
        speed = speed + a * c.slot_s
        slots += moving
    return slots


def plan_target(config: SystemConfig, start: tuple[float, float, float], settings: PlanSettings = PlanSettings(),
                memo: dict[bytes, float] | None = None) -> Plan:
    """The plan from ``start`` (at rest, level): screen, value, choose, refine (module docstring).

    ``memo`` caches ``R`` by pose across plans of the same system and settings: the
    candidates and the refinement path do not depend on the start, so later scenarios
    mostly reuse the first one's work.
    """
    c, s = config, settings
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

    peaks, _ = screen(c, s.grid_step)
    cands = np.concatenate([start_q[None], peaks[:s.candidates]])
    r = rate(cands, level)
    t = travel_slots(c, np.linalg.norm(cands - start_q, axis=1))

    def value(r_target: NDArray | float, slots: NDArray | int) -> NDArray[np.float64]:
        slots = np.minimum(slots, c.horizon)
        return (slots * np.minimum(r[0], r_target) + (c.horizon - slots) * np.asarray(r_target)) / c.horizon

    vals = value(r, t)
    best = int(np.argmax(vals))
    q, att, r_best = cands[best].copy(), level.copy(), float(r[best])
    pos_step, att_step = s.refine_step, c.attitude_step_rad
    for _ in range(s.max_refinements):
        if pos_step < s.min_step:
            break
        nq, na, ok = pattern_neighbours(c, q, att, pos_step, att_step)
        if not ok.any():
            pos_step, att_step = pos_step / 2, att_step / 2
            continue
        nr = rate(nq[ok], na[ok])
        i = int(np.argmax(nr))
        if nr[i] > r_best + 1e-6:
            q, att, r_best = nq[ok][i], ph.wrap_angle(na[ok][i]), float(nr[i])
        else:
            pos_step, att_step = pos_step / 2, att_step / 2
    table = tuple((tuple(float(x) for x in p), float(rv), float(vv)) for p, rv, vv in zip(cands, r, vals))
    runners_up = [cands[i] for i in np.argsort(-vals, kind="stable")[:FINALIST_CANDIDATES] if i != 0]
    finalists = [(start_q, level), (q, att), *((p, level) for p in runners_up)]
    return check_finalists(c, s, start_q, finalists, valued, table)


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
    ok = feasible(c, nq)
    if c.front_margin_deg is not None:  # the attitude safety layer: no pose it would not let the UAV hold
        ok &= ph.worst_elevation(na, nq, np.asarray(c.users)) >= np.sin(np.radians(c.front_margin_deg))
    return nq, na, ok


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
    slots = np.minimum(travel_slots(c, np.linalg.norm(pos - start_q, axis=1)), c.horizon)

    def episode(x: NDArray, t: NDArray) -> NDArray[np.float64]:  # (F, B) rates, the start's first -> plan values
        t = t[:, None]
        return (t * np.minimum(x[:1], x) + (c.horizon - t) * x) / c.horizon

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
                rate_se=float(rate.std(ddof=1) / math.sqrt(b)))

