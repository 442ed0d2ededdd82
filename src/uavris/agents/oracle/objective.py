"""What a plan is worth: the value of a pose, of a trip and of an episode, and where a UAV may be.

Lives here: the one objective every planner of uavris maximises (the exact planner
:func:`.planner.plan_target`, the wide search :func:`.search.exhaustive_plan`, the learned
planner :func:`uavris.agents.place.planner.learned_plan`): ``R`` of a pose
(:func:`expected_optimised_rate`, on fresh batches :func:`rate_batches` and
:func:`assessed_rate`), the trip's slots (:func:`travel_slots`, :func:`trip_slots`, with the
controller's own :func:`approach_speed`), the episode value of flying there and hovering
(:func:`episode_value`), the positions a UAV may hold (:func:`feasible`,
:func:`feasible_grid`) and the best places kept apart (:func:`top_apart`). Not here: how a
planner searches (:mod:`.planner`, :mod:`.search`, :mod:`uavris.agents.place.planner`), the
controller that flies a plan (:mod:`.policy`).

**Value of a pose.** ``R(q, zeta)`` = expected sum rate of a hovering UAV at position ``q``
and attitude ``zeta`` whose phases are re-optimised every slot
(:func:`uavris.physics.phase_opt.optimize_slot_phases`). The expectation over the pairing is
exact: every pairing the model can draw is enumerated with its probability (24 for K = 4: 12
single links and 12 pairs of links; above :data:`MAX_ENUMERATED_PAIRINGS` a stratified
sample); the expectation over the NLoS draw is a Monte-Carlo mean. The draws are the same at
every pose (common random numbers), so two poses are compared on the same channels and
pairings and the map is smooth in the pose.

**Value of a plan** (docs/model.md, "The oracle"): the expected average sum rate of the
episode if the UAV flies from rest at the start to a pose and hovers there,
``(t R_route + (T - t) R(target)) / T`` with ``t`` the slots the trip takes
(:func:`travel_slots`: the controller's own motion along a straight line) and
``R_route = min(R(start), R(target))`` for the slots in flight.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from uavris import physics as ph
from uavris.config import SystemConfig
from uavris.physics import streams
from uavris.physics.phase_opt import optimize_slot_phases
from uavris.physics.slot_memo import SlotMemo

# Above this many pairings (K = 4 has 24) the expectation samples this many (stratified by the
# number of active pairs, common random numbers) instead of enumerating them: the cost of a
# pose then grows with K only through the optimiser's cost per slot (measured in
# benchmarks/oracle_throughput.py, with the sampled value's error against 256 samples).
MAX_ENUMERATED_PAIRINGS = 24
# Every R of this process solves its slots through this memo: a pose valued again (a pattern
# search stepping back, a finalist checked, a place every row is told) costs nothing, with the
# same bits (uavris.physics.slot_memo).
SLOT_MEMO = SlotMemo()
ARRIVAL_TOLERANCE = 0.05  # m: the trip is over within this distance of the target, at rest


# ------------------------------------------------------------------------------------- R, the value of a pose
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


def expected_optimised_rate(config: SystemConfig, position: NDArray, attitude: NDArray, *, draws: int = 2,
                            seed: int = 0, **optimiser: Any) -> NDArray[np.float64]:
    """``R`` of poses ``(P, 3)``, ``(P, 3)``: expected sum rate with per-slot optimised phases, ``(P,)``.

    Exact over the pairing, ``draws`` NLoS draws (the same for every pose), see the module
    docstring; ``optimiser`` settings go to :func:`uavris.physics.phase_opt.optimize_phases`
    (its slots through :data:`SLOT_MEMO` unless ``memo`` is given; ``memo=None``: none).
    """
    optimiser.setdefault("memo", SLOT_MEMO)
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


# ------------------------------------------------------------------------------------- the trip
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

# ------------------------------------------------------------------------------------- the value of a plan
def trip_slots(config: SystemConfig, start: NDArray, positions: NDArray) -> NDArray[np.int64]:
    """The slots of the trips from rest at ``start`` to each of ``positions`` ``(..., 3)``, at most the horizon."""
    distance = np.linalg.norm(np.asarray(positions, dtype=np.float64) - np.asarray(start, dtype=np.float64), axis=-1)
    return np.minimum(travel_slots(config, distance), config.horizon)


def episode_value(horizon: int, slots: NDArray | int, r_start: NDArray | float, rates: NDArray | float
                  ) -> NDArray[np.float64]:
    """The episode average of flying ``slots`` slots to a pose worth ``rates`` from one worth
    ``r_start`` and hovering there for the rest of the ``horizon`` (module docstring)."""
    t = np.minimum(slots, horizon)
    return (t * np.minimum(r_start, rates) + (horizon - t) * np.asarray(rates)) / horizon


# ------------------------------------------------------------------------------------- where the UAV may be
def feasible(config: SystemConfig, position: NDArray) -> NDArray[np.bool_]:
    """Positions ``(..., 3)`` inside the flight region and outside every safety ball."""
    q = np.asarray(position, dtype=np.float64)
    inside = np.all((q >= np.asarray(config.region_low)) & (q <= np.asarray(config.region_high)), axis=-1)
    return inside & np.all(ph.separation(q, config.users) >= config.safety_distance, axis=-1)


def feasible_grid(config: SystemConfig, step: float, z_step: float | None = None, flat: bool = True
                  ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """A grid of spacing ``step`` across and ``z_step`` (default ``step``) in height over the
    flight region, with which of its points are :func:`feasible`: ``(M, 3)`` and ``(M,)``, or
    with ``flat=False`` ``(nx, ny, nz, 3)`` and ``(nx, ny, nz)``."""
    lo, hi = np.asarray(config.region_low), np.asarray(config.region_high)
    steps = (step, step, step if z_step is None else z_step)
    axes = [np.linspace(lo[i], hi[i], max(2, int(round((hi[i] - lo[i]) / steps[i])) + 1)) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    if flat:
        grid = grid.reshape(-1, 3)
    return grid, feasible(config, grid)


def top_apart(values: NDArray, places: NDArray, k: int, separation: float) -> list[int]:
    """Indices of the ``k`` best places by ``values``, each at least ``separation`` from the better ones."""
    chosen: list[int] = []
    for i in np.argsort(-values, kind="stable"):
        if all(np.linalg.norm(places[i] - places[j]) >= separation for j in chosen):
            chosen.append(int(i))
            if len(chosen) == k:
                break
    return chosen
