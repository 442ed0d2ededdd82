"""Angle-dependent RIS reflection (paper eq. 5-6 as corrected in docs/model.md section 6).

Lives here: :func:`reflection_coefficient`, :func:`unit_reflection_coefficient` (the
phase-only case), :func:`preset_for_target` (its inverse), and :func:`lambda_coefficients`
with :func:`reflection_coefficient_eq5` (eq. 5-6 literally, for checking). Not here: the
vector each transmitter sees (:func:`uavris.physics.channel.effective_reflection`) and the
choice of presets (:mod:`.phase_opt`).

With eta = 120*pi, lambda1 = (2/eta)(1 - r_pre)/(1 + r_pre) and
lambda2 = 2*eta*(1 + r_pre)/(1 - r_pre), eq. (5) reduces to the Moebius map

    r(theta) = (cos(theta) - a) / (cos(theta) + a),   a = (1 - r_pre)/(1 + r_pre),

so r(0) = r_pre, |r| = 1 whenever |r_pre| = 1, r(90 deg) = -1 and |r| <= 1 whenever
|r_pre| <= 1 (Re a >= 0).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FREE_SPACE_IMPEDANCE = 120.0 * np.pi  # eta, ohm


def reflection_coefficient(r_pre: ArrayLike, cos_theta: ArrayLike) -> NDArray[np.complex128]:
    """Practical reflection coefficient r(theta) for preset ``r_pre`` (eq. 5).

    Evaluated as (c(1+r) - (1-r)) / (c(1+r) + (1-r)), the form above multiplied through
    by (1 + r_pre), so r_pre = -1 gives -1 exactly. r_pre = +1 gives +1 for c > 0; at
    grazing incidence (c = 0) it takes the limit value -1 shared by every other preset.
    ``cos_theta`` is clipped to [0, 1]: a user behind the RIS is blocked elsewhere.
    """
    r = np.asarray(r_pre, dtype=np.complex128)
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    num = c * (1.0 + r) - (1.0 - r)
    den = c * (1.0 + r) + (1.0 - r)
    # Near r_pre = 1 at grazing incidence both terms can underflow to subnormals, where a
    # plain complex division overflows; rescale both by the same power of two first.
    big = np.maximum(np.maximum(np.abs(num.real), np.abs(num.imag)), np.maximum(np.abs(den.real), np.abs(den.imag)))
    _, e = np.frexp(big)
    num = np.ldexp(num.real, -e) + 1j * np.ldexp(num.imag, -e)
    den = np.ldexp(den.real, -e) + 1j * np.ldexp(den.imag, -e)
    degenerate = den == 0  # only r_pre = 1 at c = 0
    general = np.where(degenerate, -1.0 + 0j, num / np.where(degenerate, 1.0, den))
    # For unit-modulus presets 1 - r_pre loses its real part (1 - cos(phi)) to rounding when
    # phi is tiny, which breaks |r| = 1 by up to ~1e-9; the half-angle form is exact there.
    unit = (np.abs(np.abs(r) - 1.0) <= 1e-12) & (r.imag != 0)  # r_pre = +-1 are exact above
    if np.any(unit):
        general = np.where(unit, unit_reflection_coefficient(np.angle(r), c), general)
    return general


def unit_reflection_coefficient(phase: ArrayLike, cos_theta: ArrayLike) -> NDArray[np.complex128]:
    """r(theta) for a unit-modulus preset r_pre = exp(j phase), in real arithmetic.

    With psi = phase/2, a = -j tan(psi) and r = A / conj(A) = A^2 / |A|^2 where
    A = c cos(psi) + j sin(psi): the same map as :func:`reflection_coefficient`, without
    complex division (the simulator's hot path). |r| = 1 exactly by construction.
    """
    phase = np.asarray(phase)
    # Keep float32 phases in float32 (the simulator's fast path); promote anything else.
    psi = 0.5 * (phase if phase.dtype == np.float32 else phase.astype(np.float64))
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    re = c * np.cos(psi)
    im = np.sin(psi)
    # Normalise A with hypot (no underflow for tiny c and phase) and use r = (A/|A|)^2 as
    # (2u^2 - 1, 2uv): at the degenerate point (r_pre = 1, c = 0) A = 0, u = v = 0 and the
    # same expression gives the limit value -1 exactly, with no branch.
    h = np.hypot(re, im)
    h = np.where(h > 0.0, h, 1.0)
    u = re / h  # divide, not multiply by 1/h: 1/h overflows for subnormal h
    v = im / h
    out = np.empty(u.shape, dtype=np.complex128)
    out.real = 2.0 * u * u - 1.0
    out.imag = 2.0 * u * v
    return out


def preset_for_target(r_target: ArrayLike, cos_theta: ArrayLike) -> NDArray[np.complex128]:
    """Inverse of :func:`reflection_coefficient`: the r_pre that yields ``r_target``.

    Defined for c = cos(theta) in (0, 1]; a unit-modulus target gives a unit-modulus
    preset. Used to co-phase the RIS for a chosen incidence angle.
    """
    rt = np.asarray(r_target, dtype=np.complex128)
    c = np.asarray(cos_theta, dtype=np.float64)
    a = c * (1.0 - rt) / (1.0 + rt)
    return (1.0 - a) / (1.0 + a)


def lambda_coefficients(r_pre: ArrayLike) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """lambda1, lambda2 of eq. (6), with the units typo of lambda2 corrected."""
    r = np.asarray(r_pre, dtype=np.complex128)
    eta = FREE_SPACE_IMPEDANCE
    return (2.0 / eta) * (1.0 - r) / (1.0 + r), 2.0 * eta * (1.0 + r) / (1.0 - r)


def reflection_coefficient_eq5(r_pre: ArrayLike, cos_theta: ArrayLike) -> NDArray[np.complex128]:
    """Eq. (5) evaluated literally from lambda1, lambda2 (for checking the reduced form).

    Undefined at r_pre = +-1; use :func:`reflection_coefficient` in simulations.
    """
    lam1, lam2 = lambda_coefficients(r_pre)
    c = np.asarray(cos_theta, dtype=np.float64)
    eta = FREE_SPACE_IMPEDANCE
    return -eta * lam1 / (2.0 * c + eta * lam1) + lam2 * c / (lam2 * c + 2.0 * eta)
