"""Rician UPA channels and cascaded RIS gains (paper eq. 1-4, docs/model.md sections 4, 5 and 7).

Lives here: :func:`array_response`, :func:`rician_channels`, :func:`effective_reflection`,
:func:`effective_reflection_from_phases` and :func:`cascaded_gains`. Not here: the reflection
model (:mod:`.reflection`), the incidence angles (:mod:`.geometry`), the NLoS draws
(:mod:`.streams`, drawn by :mod:`uavris.env.simulator`) and the rates (:mod:`.rates`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uavris.physics.reflection import reflection_coefficient, unit_reflection_coefficient


def array_response(u: ArrayLike, v: ArrayLike, nx: int, ny: int, spacing: float = 0.5) -> NDArray[np.complex128]:
    """UPA response g = a_y(v) kron a_x(u) (paper eq. 2-3). Shape ``(..., nx*ny)``.

    a_x[i] = exp(-j 2 pi s i u), a_y[m] = exp(-j 2 pi s m v); element index m*nx + i.
    """
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    ax = _geometric_phasors(-2.0 * np.pi * spacing * u, nx)
    ay = _geometric_phasors(-2.0 * np.pi * spacing * v, ny)
    return (ay[..., :, None] * ax[..., None, :]).reshape(u.shape + (nx * ny,))


def _geometric_phasors(step: NDArray[np.float64], count: int) -> NDArray[np.complex128]:
    """[1, z, z^2, ...] with z = exp(j*step): one sin/cos per entry of ``step`` instead of ``count``."""
    z = np.empty(step.shape, dtype=np.complex128)
    z.real, z.imag = np.cos(step), np.sin(step)
    out = np.empty(step.shape + (count,), dtype=np.complex128)
    out[..., 0] = 1.0
    for i in range(1, count):
        out[..., i] = out[..., i - 1] * z
    return out


def rician_channels(
    u: ArrayLike,
    v: ArrayLike,
    cos_theta: ArrayLike,
    dist: ArrayLike,
    nlos: ArrayLike,
    *,
    rician_factor: float,
    pathloss_exponent: float,
    nx: int,
    ny: int,
    spacing: float = 0.5,
) -> NDArray[np.complex128]:
    """User-RIS channels h_k (paper eq. 1), one reciprocal vector per user.

    h_k = dist^(-alpha/2) (sqrt(kappa/(kappa+1)) g_k + sqrt(1/(kappa+1)) w_k), with
    ``nlos`` = w_k ~ CN(0, I) of shape ``(..., K, N)``. Users behind the RIS plane
    (cos(theta) <= 0) are blocked: their channel is zero (docs/model.md section 3).
    """
    kappa = float(rician_factor)
    g = array_response(u, v, nx, ny, spacing)
    w = np.asarray(nlos, dtype=np.complex128)
    amp = np.asarray(dist, dtype=np.float64) ** (-0.5 * pathloss_exponent)
    amp = np.where(np.asarray(cos_theta) > 0.0, amp, 0.0)[..., None]
    shape = np.broadcast_shapes(g.shape, w.shape)
    # Real-by-complex products on float views: numpy would otherwise promote the real
    # factor to complex and do full complex multiplications.
    g = np.ascontiguousarray(np.broadcast_to(g, shape)).view(np.float64)
    w = np.ascontiguousarray(np.broadcast_to(w, shape)).view(np.float64)
    h = g * (np.sqrt(kappa / (kappa + 1.0)) * amp)
    h += w * (np.sqrt(1.0 / (kappa + 1.0)) * amp)
    return h.view(np.complex128)


def effective_reflection(
    r_pre: ArrayLike, cos_theta: ArrayLike, angle_dependent: bool = True
) -> NDArray[np.complex128]:
    """Reflection vector seen by each transmitter: ``(..., K, N)`` from r_pre ``(..., N)``
    and cos(theta_k) ``(..., K)`` (each transmitter sees its own incidence angle)."""
    r_pre = np.asarray(r_pre, dtype=np.complex128)
    if not angle_dependent:
        return np.broadcast_to(r_pre[..., None, :], np.shape(cos_theta) + r_pre.shape[-1:])
    return reflection_coefficient(r_pre[..., None, :], np.asarray(cos_theta)[..., :, None])


def cascaded_gains(channels: ArrayLike, reflection: ArrayLike) -> NDArray[np.complex128]:
    """c[k, i] = sum_n h_k[n] r_n(theta_k) h_i[n], link k -> i via the RIS (docs/model.md section 7).

    Args:
        channels: h, ``(..., K, N)``.
        reflection: per-transmitter reflection ``(..., K, N)`` from :func:`effective_reflection`.
    Returns:
        ``(..., K, K)``, row = transmitter, column = receiver.
    """
    h = np.asarray(channels, dtype=np.complex128)
    r = np.asarray(reflection, dtype=np.complex128)
    return np.matmul(h * r, np.swapaxes(h, -1, -2))


def effective_reflection_from_phases(
    phase: ArrayLike, cos_theta: ArrayLike, angle_dependent: bool = True
) -> NDArray[np.complex128]:
    """As :func:`effective_reflection` for unit-amplitude presets r_pre = exp(j phase)."""
    phase = np.asarray(phase, dtype=np.float64)
    shape = np.shape(cos_theta) + phase.shape[-1:]
    if not angle_dependent:
        return np.broadcast_to(np.exp(1j * phase)[..., None, :], shape)
    return unit_reflection_coefficient(phase[..., None, :], np.asarray(cos_theta)[..., :, None])
