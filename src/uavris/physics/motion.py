"""UAV kinematics (paper eq. 9) and propulsion energy (Zeng, Xu, Zhang, IEEE TWC 2019)."""

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
    """Rotary-wing propulsion power P(V) in W (MODEL.md; P(0) = 168.49 W).

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


def feasible_acceleration(velocity: ArrayLike, accel: ArrayLike, dt: float, v_max: float, a_max: float) -> NDArray[np.float64]:
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
    position: ArrayLike, velocity: ArrayLike, accel: ArrayLike, dt: float, low: ArrayLike, high: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """q(t+1) = q + v dt + a dt^2/2 and v(t+1) = v + a dt (paper eq. 9), then projection of q
    onto the flight region [low, high] with the velocity component into a wall zeroed.

    ``accel`` must already be feasible (see :func:`feasible_acceleration`).
    """
    q = np.asarray(position, dtype=np.float64)
    v = np.asarray(velocity, dtype=np.float64)
    a = np.asarray(accel, dtype=np.float64)
    q_new = q + v * dt + 0.5 * a * dt * dt
    v_new = v + a * dt
    lo, hi = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    below, above = q_new < lo, q_new > hi
    q_new = np.clip(q_new, lo, hi)
    v_new = np.where((below & (v_new < 0)) | (above & (v_new > 0)), 0.0, v_new)
    return q_new, v_new


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
