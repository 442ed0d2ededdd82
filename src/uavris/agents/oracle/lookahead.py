"""The oracle's local motion choice: a one-step lookahead on the expected sum rate.

Lives here: the interference-free expected-rate score of a pose (also the planner's
screening map), the move grid and :func:`choose_moves`. Not here: the phase optimiser
(:mod:`uavris.physics.phase_opt`) and the global plan (:mod:`.planner`).

The lookahead scores a grid of candidate moves for the next slot:

- accelerations ``a_max * limit_norm(g)`` for ``g`` in ``{-1, 0, 1}^3`` (27 moves,
  diagonals scaled back to ``a_max``), made feasible exactly as the simulator does
  (:func:`uavris.physics.feasible_acceleration`, :func:`~uavris.physics.kinematic_step`
  with the walls and the safety separation);
- attitude increments: none, or one step of ``+-attitude_step`` on one of yaw, pitch,
  roll (7 moves); ``27 x 7 = 189`` candidate next poses per environment.

Each candidate is scored by the *expected* sum rate at its next pose, averaged with the
poses of a braking continuation ("Overshoot" below), and the best is taken (ties: the
first, i.e. no attitude change).

Score (expected next-slot sum rate). At the candidate pose the LoS part of every
channel is known (geometry); the NLoS part ``w ~ CN(0, I)`` of slot ``t+1`` and the
pairing ``P(t+1)`` are not. The next slot's phases will be re-optimised on the realised
channels, so the score credits each link with what the optimiser can get for it: the
co-phased gain, whose mean power with LoS-co-phased presets is

    E|c_ki|^2 = d_k^-alpha d_i^-alpha (mu^4 N^2 + N (2 mu^2 s^2 + s^4)),
    mu^2 = kappa/(kappa+1), s^2 = 1/(kappa+1)   (zero when k or i is behind the RIS),

and interference is taken as nulled. Then ``E[sum rate] = sum_{k != i} Pr[k -> i active]
log2(1 + P E|c_ki|^2 / sigma^2)``; by the symmetry of the pairing model every ordered
link is active with the same probability ``E[m] / (K(K-1))``, ``E[m] = (1 + m_max)/2``.
Why interference-free: with ``N = 16`` elements and at most two pairs, the optimiser
nulls the cross links at little cost. On 256 random two-pair slots across the flight
region the optimised sum rate had correlation 0.99 with the sum of the two lone-pair
optimal rates (long optimiser runs), median shortfall 1.6 bps/Hz; scoring every candidate
with the full multi-pair optimiser would cost ~10^4 optimisations per slot. Consequence:
with unit-modulus presets the co-phased gain does not depend on the RIS attitude (every
phase is reachable at any incidence ``c > 0``), so the attitude only matters through
back-side blocking and multi-pair interference geometry; the score sees the former, and
the lookahead keeps the attitude unless a change is strictly better.

Overshoot. The grid's one-slot effect on the position is small (``a dt^2 / 2`` = 0.25 m)
beside the drift ``v dt`` (up to 2.5 m), so a score of the next pose alone steers by
position without regard to speed, and the UAV overshoots its target and circles it.
From the fig2 start it wandered for ~45 slots before settling (40.3 bps/Hz against 41.6
with the braking continuation; both measured before the optimiser's null polish and the
safety separation existed). The score therefore averages the expected rate over the next
pose and the poses of a braking continuation: after the candidate move the UAV brakes at
``a_max`` (never reversing), attitude held, for ``braking_slots`` slots (default: the slots
needed to stop from ``v_max``, 5). A candidate is then good when it moves towards good
poses *and* can stop there. Still a one-step decision: only the first move is applied.
"""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray

from uavris import physics as ph
from uavris.config import SystemConfig


def candidate_moves(config: SystemConfig) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The move grid: accelerations ``(27, 3)`` in m/s^2 and attitude increments ``(7, 3)`` in rad.

    The zero acceleration and the zero attitude increment come first (tie-breaking).
    """
    grid = np.array(sorted(itertools.product((-1.0, 0.0, 1.0), repeat=3), key=lambda g: (np.abs(g).sum(), g)))
    accel = ph.limit_norm(grid * config.a_max, config.a_max)
    step = config.attitude_step_rad
    att = np.zeros((7, 3))
    for axis in range(3):
        att[1 + 2 * axis, axis] = step
        att[2 + 2 * axis, axis] = -step
    return accel, att


def default_braking_slots(config: SystemConfig) -> int:
    """Slots needed to stop from ``v_max`` at ``a_max`` (5 at the defaults)."""
    return int(np.ceil(config.v_max / (config.a_max * config.slot_s) - 1e-9))


def link_activity(config: SystemConfig) -> float:
    """Probability that a given ordered link k -> i is active in a slot (pairing model)."""
    k, m_max = config.num_users, config.pairs_upper
    return 0.5 * (1 + m_max) / (k * (k - 1))


def expected_sum_rate(config: SystemConfig, dist: NDArray[np.float64],
                      cos_theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """Expected next-slot sum rate at a pose (interference nulled, links co-phased), ``(...)``.

    ``dist`` and ``cos_theta`` are ``(..., K)`` from :func:`uavris.physics.incidence`.
    """
    kappa, n = config.rician_factor, config.num_elements
    mu2, s2 = kappa / (kappa + 1.0), 1.0 / (kappa + 1.0)
    array_gain = mu2 * mu2 * n * n + n * (2.0 * mu2 * s2 + s2 * s2)
    amp2 = np.where(cos_theta > 0.0, np.maximum(dist, 1e-12) ** (-config.pathloss_exponent), 0.0)
    snr = (config.tx_power_w * array_gain / config.noise_w) * amp2[..., :, None] * amp2[..., None, :]
    rates = np.log2(1.0 + snr)
    rates = rates * (1.0 - np.eye(config.num_users))  # no link k -> k
    return link_activity(config) * rates.sum(axis=(-2, -1))


def pose_score(config: SystemConfig, position: NDArray[np.float64], attitude: NDArray[np.float64]
               ) -> NDArray[np.float64]:
    """:func:`expected_sum_rate` of poses ``(..., 3)``, ``(..., 3)``."""
    _, _, cos_t, dist = ph.incidence(position, np.asarray(config.users, dtype=np.float64), ph.ris_axes(attitude))
    return expected_sum_rate(config, dist, cos_t)


def move(config: SystemConfig, pos: NDArray, vel: NDArray, accel: NDArray) -> tuple[NDArray, NDArray]:
    """One slot of the simulator's kinematics (feasible acceleration, walls, safety separation)."""
    c = config
    a = ph.feasible_acceleration(vel, accel, c.slot_s, c.v_max, c.a_max)
    return ph.kinematic_step(pos, vel, a, c.slot_s, c.region_low, c.region_high, c.users, c.safety_distance)


def choose_moves(config: SystemConfig, pos: NDArray, vel: NDArray, att: NDArray, braking_slots: int | None = None,
                 turn: bool = True) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """One-step lookahead for a batch of UAV states ``pos``, ``vel``, ``att`` ``(n, 3)``.

    ``turn=False`` keeps the attitude (only the 27 accelerations are scored).
    Returns (acceleration command ``(n, 3)`` m/s^2, attitude increment ``(n, 3)`` rad,
    score of the chosen move ``(n,)`` bps/Hz).
    """
    c = config
    if braking_slots is None:
        braking_slots = default_braking_slots(c)
    acc, datt = candidate_moves(c)
    if not turn:
        datt = datt[:1]
    n_g = len(datt)
    users = np.asarray(c.users, dtype=np.float64)
    q1, v1 = move(c, pos[:, None, :], vel[:, None, :], acc[None])  # (n, A, 3)
    att1 = ph.accumulate_attitude(att[:, None, :], datt[None])  # (n, G, 3)
    axes = ph.ris_axes(att1)[:, None]  # (n, 1, G, 3, 3)
    _, _, cos_t, dist = ph.incidence(q1[:, :, None, :], users, axes)  # (n, A, G, K)
    score = expected_sum_rate(c, dist, cos_t)  # (n, A, G)
    if braking_slots > 0:
        # Stopping continuation: after the candidate move, brake at up to a_max (never
        # reversing) with the attitude held; average the expected rate along the way.
        q, v = q1, v1
        for _ in range(braking_slots):
            speed = np.linalg.norm(v, axis=-1, keepdims=True)
            brake = -v / np.maximum(speed, 1e-12) * np.minimum(c.a_max, speed / c.slot_s)
            q, v = move(c, q, v, brake)
            _, _, cos_b, dist_b = ph.incidence(q[:, :, None, :], users, axes)
            score = score + expected_sum_rate(c, dist_b, cos_b)
        score = score / (1 + braking_slots)
    flat = np.argmax(score.reshape(len(pos), -1), axis=1)  # first maximum: no-op moves win ties
    ia, ig = np.divmod(flat, n_g)
    return acc[ia], datt[ig], score.reshape(len(pos), -1)[np.arange(len(pos)), flat]
