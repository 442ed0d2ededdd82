"""UAV kinematics (paper eq. 9) and propulsion energy (Zeng, Xu, Zhang, IEEE TWC 2019).

Lives here: :func:`kinematic_step`, :func:`feasible_acceleration`, :func:`limit_norm`,
:func:`separation`, :func:`propulsion_power` and :func:`slot_energy`. Not here: the attitude
(:mod:`.geometry`), the action's scaling (:func:`uavris.env.simulator.decode_action`) and
the energy budget that ends an episode (:class:`uavris.env.simulator.BatchedSimulator`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

# 8-point Gauss-Legendre nodes/weights on [0, 1]: exact for polynomials of degree 15; the
# power along a constant-acceleration slot is smooth, so this is accurate to ~1e-9 relative.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
GL_NODES = 0.5 * (_GL_X + 1.0)
GL_WEIGHTS = 0.5 * _GL_W


def propulsion_power(
    speed: ArrayLike,
    blade_profile_w: float = 79.86,
    induced_w: float = 88.63,
    tip_speed: float = 120.0,
    hover_induced_velocity: float = 4.03,
    fuselage_drag_ratio: float = 0.6,
    air_density: float = 1.225,
    rotor_solidity: float = 0.05,
    rotor_disc_area: float = 0.503,
) -> NDArray[np.float64]:
    """Rotary-wing propulsion power P(V) in W (docs/model.md section 13; P(0) = 168.49 W).

    P(V) = P0 (1 + 3V^2/U^2) + Pi (sqrt(1 + V^4/(4 v0^4)) - V^2/(2 v0^2))^(1/2)
           + 0.5 d0 rho s A V^3.
    Keyword names match :class:`uavris.config.PropulsionParams`.
    """
    V = np.asarray(speed, dtype=np.float64)
    v2 = V * V
    v0sq = hover_induced_velocity**2
    blade = blade_profile_w * (1.0 + 3.0 * v2 / tip_speed**2)
    induced = induced_w * np.sqrt(np.sqrt(1.0 + v2 * v2 / (4.0 * v0sq * v0sq)) - v2 / (2.0 * v0sq))
    parasite = 0.5 * fuselage_drag_ratio * air_density * rotor_solidity * rotor_disc_area * V * v2
    return blade + induced + parasite


def limit_norm(vec: ArrayLike, bound: float) -> NDArray[np.float64]:
    """Scale vectors ``(..., 3)`` whose norm exceeds ``bound`` back onto the ball (not per axis)."""
    x = np.asarray(vec, dtype=np.float64)
    n = np.sqrt(np.sum(x * x, axis=-1, keepdims=True))
    return x * np.minimum(1.0, bound / np.maximum(n, 1e-300))


def feasible_acceleration(velocity: ArrayLike, accel: ArrayLike, dt: float, v_max: float,
                          a_max: float) -> NDArray[np.float64]:
    """Acceleration actually applied in a slot, honouring |a| <= a_max and |v| <= v_max.

    The commanded acceleration is first limited to a_max; if the end-of-slot velocity
    would exceed v_max it is projected radially onto the speed ball and the acceleration
    recomputed from it. Projection onto a ball is non-expansive, so the result still has
    |a| <= a_max, and |v + a tau| <= v_max for all tau in [0, dt] (convexity).
    """
    v = np.asarray(velocity, dtype=np.float64)
    a = limit_norm(accel, a_max)
    v_end = limit_norm(v + a * dt, v_max)
    return (v_end - v) / dt


def kinematic_step(
    position: ArrayLike,
    velocity: ArrayLike,
    accel: ArrayLike,
    dt: float,
    low: ArrayLike,
    high: ArrayLike,
    keep_out: ArrayLike | None = None,
    clearance: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """q(t+1) = q + v dt + a dt^2/2 and v(t+1) = v + a dt (paper eq. 9), then the flight
    constraints: q is projected onto the flight region [low, high] (13a) and out of the
    ball of radius ``clearance`` around every point of ``keep_out`` ``(K, 3)`` (the safety
    separation from the devices, docs/model.md section 12), and the velocity component
    into a wall or a ball is removed.

    ``accel`` must already be feasible (see :func:`feasible_acceleration`). Removing a
    velocity component never raises |v|, so |v| <= v_max still holds. In the rare case
    where the projections cannot satisfy walls and balls together (a ball pressed against
    a wall), the UAV stays at ``position`` and stops: the start of the slot was feasible.
    """
    q = np.asarray(position, dtype=np.float64)
    v = np.asarray(velocity, dtype=np.float64)
    a = np.asarray(accel, dtype=np.float64)
    lo, hi = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    q_new, v_new = _project_onto_box(q + v * dt + 0.5 * a * dt * dt, v + a * dt, lo, hi)
    if keep_out is None or clearance <= 0.0:
        return q_new, v_new
    centres = np.asarray(keep_out, dtype=np.float64)
    if not np.any(separation(q_new, centres) < clearance):  # the usual case: no ball touched
        return q_new, v_new
    for centre in centres:  # K is small; balls are handled one after the other
        d = q_new - centre
        dist = np.sqrt(np.sum(d * d, axis=-1, keepdims=True))
        inside = dist < clearance
        # At the centre itself the direction is undefined: leave upwards (z_min lies above every device).
        normal = np.where(dist > 0.0, d / np.maximum(dist, 1e-300), np.array([0.0, 0.0, 1.0]))
        q_new = np.where(inside, centre + clearance * normal, q_new)
        inward = np.minimum(np.sum(v_new * normal, axis=-1, keepdims=True), 0.0)
        v_new = np.where(inside, v_new - inward * normal, v_new)
    q_new, v_new = _project_onto_box(q_new, v_new, lo, hi)
    stuck = np.any(separation(q_new, centres) < clearance * (1.0 - 1e-12), axis=-1, keepdims=True)
    if np.any(stuck):
        q_new = np.where(stuck, np.broadcast_to(q, q_new.shape), q_new)
        v_new = np.where(stuck, 0.0, v_new)
    return q_new, v_new


def _project_onto_box(q: NDArray[np.float64], v: NDArray[np.float64], lo: NDArray[np.float64],
                      hi: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Clip q to [lo, hi] and zero the velocity components pointing out through a wall."""
    below, above = q < lo, q > hi
    v = np.where((below & (v < 0)) | (above & (v > 0)), 0.0, v)
    return np.clip(q, lo, hi), v


def separation(position: ArrayLike, points: ArrayLike) -> NDArray[np.float64]:
    """Distances ``(..., K)`` from positions ``(..., 3)`` to ``K`` points ``(K, 3)``."""
    d = np.asarray(position, dtype=np.float64)[..., None, :] - np.asarray(points, dtype=np.float64)
    return np.sqrt(np.sum(d * d, axis=-1))


def slot_energy(velocity: ArrayLike, accel: ArrayLike, dt: float, **power_params: float) -> NDArray[np.float64]:
    """Propulsion energy of one slot, J: integral of P(|v + a tau|) for tau in [0, dt].

    Gauss-Legendre quadrature along the constant-acceleration speed profile.
    """
    v = np.asarray(velocity, dtype=np.float64)
    a = np.asarray(accel, dtype=np.float64)
    tau = GL_NODES * dt  # (Q,)
    vel = v[..., None, :] + a[..., None, :] * tau[:, None]  # (..., Q, 3)
    speed = np.sqrt(np.sum(vel * vel, axis=-1))
    return dt * np.sum(GL_WEIGHTS * propulsion_power(speed, **power_params), axis=-1)
