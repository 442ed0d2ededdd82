"""Frozen reference: the numpy phase optimiser of uavris 0.1.0 (before the compiled kernel).

Kept only so that ``benchmarks/oracle_throughput.py`` can measure today's optimiser against
it in the same run, on the same slots. The library's optimiser is
:mod:`uavris.physics.phase_opt`; do not import this file from the package.

Original module docstring follows.

Per-slot RIS phase optimiser: the phases that maximise one slot's sum rate.

Problem (MODEL.md). Given this slot's channels ``h`` ``(..., K, N)``, incidence cosines
``cos_theta`` ``(..., K)`` and pairing ``P`` ``(..., K, K)``, choose unit-modulus presets
``r_pre_n = exp(j phi_n)`` to maximise

    R(phi) = sum_{P[k,i]=1} log2(1 + P|c_ki|^2 / (sum_{j active tx, j != k} P|c_ji|^2 + sigma^2)),
    c_ji   = sum_n h_j[n] r_n(theta_j) h_i[n],

where ``r_n(theta_j) = unit_reflection_coefficient(phi_n, cos(theta_j))``: every
transmitter sees the preset through the angle-dependent map at its own angle. In phase
form that map is ``r_n(theta_j) = exp(j g(phi_n, c_j))`` with

    g(phi, c) = 2 arg(c cos(phi/2) + j sin(phi/2)),   dg/dphi = c / (c^2 cos^2(phi/2) + sin^2(phi/2)),

a strictly increasing bijection of the circle for ``c > 0`` (``c = 0`` gives ``-1``).

Method
------
*One active pair k -> i* (closed form). By the triangle inequality
``|c_ki| <= sum_n |h_k[n]| |h_i[n]|`` for ``|r_n| = 1``, with equality when every element is
co-phased, ``r_n(theta_k) = exp(-j arg(h_k[n] h_i[n]))``. The preset achieving it is
found by inverting the reflection model with :func:`uavris.physics.preset_for_target`, so
the optimum is exact: ``SNR = P (sum_n |h_k[n]| |h_i[n]|)^2 / sigma^2``.

*Several active pairs* (no closed form; non-concave, with one basin per "which pair is
served" and narrow ridges where the cross links are nulled). Three stages, all batched:

1. Starts. The co-phasing solution of each active pair (so the result is never worse
   than the best single-pair co-phasing, which is what ``hover_aligned`` plays) plus
   ``restarts`` uniform random phase vectors (default 4). The basins differ by up to
   ~20 bps/Hz (one pair served vs both), and which start reaches the best one varies
   from slot to slot: in a long reference run (26 starts x 1,500 iterations) the best
   result came from a co-phasing start in 56% of slots, from another start otherwise.
2. Noise continuation + L-BFGS. Quasi-Newton ascent on the phases ``phi`` in R^N: the
   unit-modulus constraint is built into the parameterisation, so the phase gradient is
   the Riemannian gradient on the torus of unit-modulus presets and no projection is
   needed. It is run on a sequence of problems whose noise is ``sigma^2`` times
   ``noise_levels`` = (1e6, 1e5, ..., 1): at a large noise the rate is nearly the sum of
   the SNRs, a smooth problem whose maximiser serves both pairs; each smaller noise
   makes interference matter more, and the iterate follows the ridge towards the nulls.
   Solving the true problem directly progresses slowly (table below; plain normalised
   gradient ascent was slower still). A likely reason: along the way into a null,
   ``-log(I + sigma^2)`` is convex while ``I >> sigma^2``, so curvature pairs are
   rejected and the quasi-Newton model is poor exactly where the gains are.
   L-BFGS details (:func:`_lbfgs_ascent`): memory 8, a pair stored only when its
   curvature is positive, normalised gradient steps of 0.3 rad when there is no usable
   pair, every step capped at pi/2 rad per element. Step-size rule: try the full
   quasi-Newton step; if ``R`` does not increase, halve it (backtracking spread over
   iterations), so the iterates are monotone for each level. ``iterations`` = 30 per
   level (210 in all).
3. Null polish (:func:`_null_polish`, 10 steps). Newton-Raphson on the cross links
   ``c_ji = 0`` with least-norm steps, kept only where the true sum rate rises. At high
   SNR the ridge ascent leaves interference well above the noise, and this is where
   quasi-Newton is weakest and Newton-Raphson on the nulls strongest.

The best of all final points and all starts, by the true sum rate, is returned.

Gradient, analytic (no autograd). With ``T_i = sum_{j active} P|c_ji|^2 + sigma^2``
(received power at ``i``) and ``I_i = T_i - P|c_{k(i),i}|^2``,

    dR/d|c_ji|^2 = W_ji = (P / ln 2) (1/T_i - [j != k(i)] / I_i)     (active j, active receiver i)
    dR/dphi_n    = -2 sum_j g'(phi_n, c_j) Im( h_j[n] r_n(theta_j) sum_i W_ji conj(c_ji) h_i[n] ),

``O(K^2 N)`` per evaluation, the same cost as the objective. Inside the iterations the
objective is evaluated on the active links only (:func:`_link_rate_and_gradient`: ``L``
transmitters and their ``L`` receivers, ``L = floor(K/2)``), since users that neither
transmit nor receive do not enter the sum rate; for ``K = 4`` that halves the work.

Why these settings (measured while writing this module; two seeded sets of two-pair
slots of the default system: A = 256 slots at random poses over the whole flight region
with random tilts up to 0.4 rad, B = 128 slots at the pose where the oracle hovers,
[19.95, 8, 2], SNRs 1e10-1e12; mean optimised sum rate in bps/Hz; rows marked * were
measured with an earlier version of this code, the others with this one):

| method | A | B |
|---|---|---|
| best co-phasing start only | 7.4 | - |
| best of 1,000 random phase vectors | 10.6 | - |
| * normalised gradient ascent with adaptive steps, 100 iterations, 2 + 4 starts | 19.9 | - |
| * L-BFGS, 26 starts x 1,500 iterations at the true noise (long reference) | 29.6 | - |
| L-BFGS at the true noise only, 210 iterations, no polish | 25.9 | 44.9 |
| L-BFGS at the true noise only, 210 iterations, polish | 28.7 | 60.1 |
| default without the polish | 29.3 | 52.6 |
| 2 + 32 starts, 7 levels x 100 iterations, no polish (16x the work) | 29.5 | 61.5 |
| **default** (2 + 4 starts, 7 levels x 30 iterations, polish 10) | **29.7** | **60.6** |
| default with 2 random starts (0.5x the work) | 29.7 | 60.5 |
| default with 8 random starts (1.7x the work) | 29.7 | 60.7 |
| default with 4 levels (1e6, 1e4, 1e2, 1) (0.6x the work) | 29.6 | 60.6 |
| interference-free bound (sum of the two lone-pair optima) | 31.6 | 64.0 |

The continuation and the polish each matter; starts and iterations beyond the default
buy little. ``benchmarks/oracle_throughput.py`` measures the cost: about 3 ms per
two-pair slot in a batch of 1,024 slots on one core, about 40 ms one slot at a time.

Batching: every leading axis of the inputs is a slot axis; the work is whole-array numpy
on ``(slots, starts, L, N)`` arrays, looping only over levels and iterations (the L-BFGS
memory is one circular buffer shared by all starts). Slots with one active pair take
the closed form and skip the iterations; slots without active pair get zero phases and
rate 0. With 64 or more multi-pair slots the optimiser applies the project's
glibc allocator tuning (:mod:`uavris.env._malloc`, as the batched simulator does for 64+
environments): its ~MB temporaries otherwise pay fresh page faults on every
allocation, which more than doubled the time of an objective evaluation in our
measurement. Random starts are counter-based hashes of the seed and the slot's
channels (:func:`random_starts`), so every slot's result is deterministic and, up to
floating-point rounding that depends on the batch shape, independent of the batch it is
solved in.

Only the unit-modulus phase-only RIS (the default action) is optimised. For a single
pair unit amplitude is optimal (|r_n| <= 1 and the triangle inequality); for several
pairs a smaller amplitude could in principle trade signal for interference, which this
optimiser does not explore.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uavris import physics as ph
from uavris.config import SystemConfig
from uavris.env._malloc import tune_allocator
from uavris.physics import streams

TWO_PI = 2.0 * np.pi
LN2 = np.log(2.0)

DEFAULT_ITERATIONS = 30  # L-BFGS iterations per continuation level
DEFAULT_RESTARTS = 4  # random starts, besides one co-phasing start per active pair
DEFAULT_NOISE_LEVELS = (1e6, 1e5, 1e4, 1e3, 1e2, 1e1, 1.0)  # continuation: multiples of sigma^2
DEFAULT_MEMORY = 8  # L-BFGS pairs kept
DEFAULT_POLISH_STEPS = 10  # Newton-Raphson nulling steps after the continuation
INITIAL_STEP = 0.3  # rad, largest element change of a (normalised) gradient step
MAX_STEP = 0.5 * np.pi  # rad, cap on any element's change in one step
MIN_STEP = 1e-9  # rad, a backtracked step this small triggers a fresh direction


@dataclass(frozen=True)
class PhaseSolution:
    """Optimised phases ``(..., N)`` in [0, 2 pi) and the sum rate they achieve ``(...)``, bps/Hz."""

    phases: NDArray[np.float64]
    sum_rate: NDArray[np.float64]


# ----------------------------------------------------------------------------- reflection in phase form
def _reflection_and_slope(phases: NDArray[np.float64], cos_theta: NDArray[np.float64],
                          angle_dependent: bool) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """r_n(theta_j) and g'(phi_n, c_j) for phases ``(..., N)`` and cosines ``(..., K)``: ``(..., K, N)``.

    Same map as :func:`uavris.physics.unit_reflection_coefficient` (A^2/|A|^2 with
    A = c cos(phi/2) + j sin(phi/2)), evaluated once for the value and its slope.
    """
    if not angle_dependent:
        lead = np.broadcast_shapes(phases.shape[:-1], cos_theta.shape[:-1])
        shape = lead + cos_theta.shape[-1:] + phases.shape[-1:]
        r = np.broadcast_to(np.exp(1j * phases)[..., None, :], shape)
        return r, np.ones(shape)
    # A = c cos(psi) + j sin(psi), psi = phi/2, scaled by 1/cos(psi) or 1/sin(psi) whichever
    # is larger: A ~ a + j b with (a, b) = (c, tan psi) for |tan psi| <= 1, (c cot psi, 1)
    # otherwise. r and g' are scale-free, and numpy's float64 tan is ~20x faster than its
    # cos and sin (this is the optimiser's hottest function).
    t = np.tan(0.5 * phases)[..., None, :]  # (..., 1, N)
    small = np.abs(t) <= 1.0
    m = np.where(small, t, 1.0 / np.where(small, 1.0, t))  # tan or cot, |m| <= 1
    c = np.clip(cos_theta, 0.0, 1.0)[..., :, None]  # (..., K, 1)
    a = c * np.where(small, 1.0, m)  # (..., K, N)
    b = np.where(small, m, 1.0)
    a2 = a * a
    inv = 1.0 / (a2 + b * b + 1e-300)  # 1/|A|^2 after scaling
    r = np.empty(inv.shape, dtype=np.complex128)
    r.real = 2.0 * a2 * inv - 1.0  # Re A^2/|A|^2; exactly -1 at the degenerate point c = 0, phi = 0
    r.imag = 2.0 * a * b * inv  # Im A^2/|A|^2
    return r, (c * (1.0 + m * m)) * inv  # g' = c / (c^2 cos^2 psi + sin^2 psi)


def target_phases_to_presets(target_phase: ArrayLike, cos_theta: ArrayLike,
                             angle_dependent: bool = True) -> NDArray[np.float64]:
    """Preset phases in [0, 2 pi) whose practical coefficient at ``cos_theta`` has phase ``target_phase``.

    Uses :func:`uavris.physics.preset_for_target` (the inverse reflection model). Its one
    singular target, ``-1`` (where ``1 + r_target = 0``), is reached by the preset ``-1``
    itself, which is substituted. ``cos_theta`` is floored at ``1e-6``: at grazing
    incidence every preset gives ``-1`` and the channel is blocked anyway.
    """
    tp = np.asarray(target_phase, dtype=np.float64)
    if not angle_dependent:
        return ph.wrap_angle(tp)
    target = np.exp(1j * tp)
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 1e-6, 1.0)
    singular = np.abs(1.0 + target) < 1e-12
    with np.errstate(divide="ignore", invalid="ignore"):
        r_pre = ph.preset_for_target(np.where(singular, 1.0, target), c)
    r_pre = np.where(singular, -1.0 + 0j, r_pre)
    return ph.wrap_angle(np.angle(r_pre))


def co_phasing_phases(channels: ArrayLike, cos_theta: ArrayLike, tx: ArrayLike, rx: ArrayLike,
                      angle_dependent: bool = True) -> NDArray[np.float64]:
    """Preset phases ``(..., N)`` that co-phase every element for the link ``tx -> rx``.

    ``channels`` ``(..., K, N)``, ``cos_theta`` ``(..., K)``, ``tx``/``rx`` integer arrays
    broadcastable to the leading shape ``(...)``. The practical coefficient at the
    transmitter's angle becomes ``exp(-j arg(h_tx[n] h_rx[n]))``.
    """
    h = np.asarray(channels)
    cos = np.asarray(cos_theta, dtype=np.float64)
    tx, rx = np.asarray(tx, dtype=np.intp), np.asarray(rx, dtype=np.intp)
    lead = np.broadcast_shapes(h.shape[:-2], cos.shape[:-1], tx.shape, rx.shape)
    h = np.broadcast_to(h, lead + h.shape[-2:])
    cos = np.broadcast_to(cos, lead + cos.shape[-1:])
    tx, rx = np.broadcast_to(tx, lead), np.broadcast_to(rx, lead)
    h_tx = np.take_along_axis(h, tx[..., None, None], axis=-2)[..., 0, :]
    h_rx = np.take_along_axis(h, rx[..., None, None], axis=-2)[..., 0, :]
    c_tx = np.take_along_axis(cos, tx[..., None], axis=-1)
    return target_phases_to_presets(-np.angle(h_tx * h_rx), c_tx, angle_dependent)


def single_pair_snr(channels: ArrayLike, tx: ArrayLike, rx: ArrayLike, tx_power_w: float,
                    noise_w: float) -> NDArray[np.float64]:
    """Closed-form optimal SNR of a lone link: ``P (sum_n |h_tx[n]| |h_rx[n]|)^2 / sigma^2``."""
    h = np.abs(np.asarray(channels))
    tx, rx = np.asarray(tx, dtype=np.intp), np.asarray(rx, dtype=np.intp)
    lead = np.broadcast_shapes(h.shape[:-2], tx.shape, rx.shape)
    h = np.broadcast_to(h, lead + h.shape[-2:])
    tx, rx = np.broadcast_to(tx, lead), np.broadcast_to(rx, lead)
    a_tx = np.take_along_axis(h, tx[..., None, None], axis=-2)[..., 0, :]
    a_rx = np.take_along_axis(h, rx[..., None, None], axis=-2)[..., 0, :]
    return tx_power_w * np.sum(a_tx * a_rx, axis=-1) ** 2 / noise_w


# ----------------------------------------------------------------------------- objective and gradient
def sum_rate_and_gradient(phases: ArrayLike, channels: ArrayLike, cos_theta: ArrayLike, pairing: ArrayLike,
                          tx_power_w: float, noise_w: float | ArrayLike, angle_dependent: bool = True,
                          need_gradient: bool = True
                          ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """Sum rate ``(...)`` and its gradient w.r.t. the preset phases ``(..., N)``.

    All inputs broadcast over leading axes: ``phases`` ``(..., N)``, ``channels``
    ``(..., K, N)``, ``cos_theta`` ``(..., K)``, ``pairing`` ``(..., K, K)``. The rate equals
    ``physics.sum_rate(cascaded_gains(h, effective_reflection_from_phases(phi, cos)), P, ...)``.
    ``noise_w`` may be an array over the leading axes (the continuation uses a scalar).
    """
    phi = np.asarray(phases, dtype=np.float64)
    h = np.asarray(channels, dtype=np.complex128)
    cos = np.asarray(cos_theta, dtype=np.float64)
    p = np.asarray(pairing, dtype=np.float64)
    noise_w = np.asarray(noise_w, dtype=np.float64)[..., None]  # per-slot noise allowed, (...)
    r, slope = _reflection_and_slope(phi, cos, angle_dependent)
    hr = h * r  # (..., K, N): transmitter j's signal after reflection
    c = np.matmul(hr, np.swapaxes(h, -1, -2))  # (..., K, K), row = tx
    g2 = c.real * c.real + c.imag * c.imag
    active_tx = p.sum(axis=-1)  # (..., K)
    active_rx = p.sum(axis=-2)
    signal = tx_power_w * np.sum(p * g2, axis=-2)  # P|c_{k(i), i}|^2 per receiver
    # Interference summed directly (not T_i - signal, which cancels at SINRs of ~1e8).
    interf = tx_power_w * np.einsum("...j,...ji->...i", active_tx, (1.0 - p) * g2) + noise_w  # I_i + sigma^2
    total = interf + signal  # T_i
    rate = np.sum(active_rx * (np.log2(total) - np.log2(interf)), axis=-1)
    if not need_gradient:
        return rate, None
    # W_ji = dR / d|c_ji|^2 for active tx j and active receiver i.
    w = (tx_power_w / LN2) * active_tx[..., :, None] * active_rx[..., None, :] * (
        1.0 / total[..., None, :] - (1.0 - p) / interf[..., None, :])
    b = np.matmul(w * np.conj(c), h)  # (..., K, N): sum_i W_ji conj(c_ji) h_i[n]
    q = hr * b
    grad = -2.0 * np.sum(slope * q.imag, axis=-2)
    return rate, grad


def _link_rate_and_gradient(phases: NDArray[np.float64], tx_channels: NDArray[np.complex128],
                            rx_channels: NDArray[np.complex128], tx_cos: NDArray[np.float64], tx_power_w: float,
                            noise_w: float, angle_dependent: bool, need_gradient: bool = True
                            ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """:func:`sum_rate_and_gradient` restricted to the active links, link ``l``: tx ``l`` -> rx ``l``.

    ``tx_channels``, ``rx_channels`` ``(..., L, N)`` are the channels of the ``L`` active
    transmitters and of their receivers, ``tx_cos`` ``(..., L)`` the transmitters' cosines.
    Users that neither transmit nor receive do not enter the sum rate, so this is the same
    objective at ``(L/K)`` to ``(L/K)^2`` of the cost (half for K = 4, L = 2). A link with zero
    channels contributes nothing (used to pad slots with fewer than ``L`` links).
    """
    r, slope = _reflection_and_slope(phases, tx_cos, angle_dependent)
    hr = tx_channels * r  # (..., L, N)
    c = np.matmul(hr, np.swapaxes(rx_channels, -1, -2))  # (..., L, L): c[j, i] = gain of tx j at rx i
    g2 = c.real * c.real + c.imag * c.imag
    off = 1.0 - np.eye(g2.shape[-1])
    signal = tx_power_w * np.diagonal(g2, axis1=-2, axis2=-1)
    interf = tx_power_w * np.sum(off * g2, axis=-2) + noise_w  # I_i + sigma^2, summed directly
    total = interf + signal
    rate = np.sum(np.log2(total) - np.log2(interf), axis=-1)
    if not need_gradient:
        return rate, None
    w = (tx_power_w / LN2) * (1.0 / total[..., None, :] - off / interf[..., None, :])
    b = np.matmul(w * np.conj(c), rx_channels)  # (..., L, N): sum_i W_ji conj(c_ji) h_i[n]
    q = hr * b
    return rate, -2.0 * np.sum(slope * q.imag, axis=-2)


# ----------------------------------------------------------------------------- optimiser
def active_links(pairing: NDArray[np.float64],
                 max_links: int) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
    """Up to ``max_links`` active links per slot: (tx, rx, valid), each ``(..., max_links)``.

    Invalid entries (fewer active links) repeat the first active link (or link 0 -> 0).
    """
    k = pairing.shape[-1]
    flat = pairing.reshape(pairing.shape[:-2] + (k * k,))
    order = np.argsort(-flat, axis=-1, kind="stable")[..., :max_links]
    valid = np.take_along_axis(flat, order, axis=-1) > 0
    order = np.where(valid, order, order[..., :1])
    return order // k, order % k, valid


def optimize_phases(channels: ArrayLike, cos_theta: ArrayLike, pairing: ArrayLike, tx_power_w: float, noise_w: float,
                    *, angle_dependent: bool = True, iterations: int = DEFAULT_ITERATIONS,
                    restarts: int = DEFAULT_RESTARTS, noise_levels: tuple[float, ...] = DEFAULT_NOISE_LEVELS,
                    memory: int = DEFAULT_MEMORY, polish_steps: int = DEFAULT_POLISH_STEPS,
                    seed: int = 0) -> PhaseSolution:
    """Sum-rate-maximising unit-modulus phases for every slot of a batch (method: module docstring).

    Args:
        channels: ``h`` ``(..., K, N)`` (this slot's realised channels).
        cos_theta: ``(..., K)`` incidence cosines (each transmitter's own angle).
        pairing: ``(..., K, K)``, ``pairing[..., k, i] = 1`` when ``k`` transmits to ``i``.
        tx_power_w, noise_w: ``P`` and ``sigma^2`` in W.
        angle_dependent: ``False`` for the ideal RIS ``r = r_pre``.
        iterations: L-BFGS iterations per continuation level (slots with several pairs).
        restarts: random starts per slot, in addition to one co-phasing start per active pair.
        noise_levels: continuation schedule, multiples of ``sigma^2`` solved in turn; the
            last should be 1 (the true problem).
        memory: L-BFGS memory (pairs of steps and gradient changes kept).
        polish_steps: Newton-Raphson nulling steps after the continuation (0: none).
        seed: non-negative integer seed of the random starts (see :func:`random_starts`).

    Returns:
        :class:`PhaseSolution` with ``phases`` ``(..., N)`` in [0, 2 pi) and ``sum_rate`` ``(...)``.
    """
    if iterations < 0 or restarts < 0 or memory < 1:
        raise ValueError(f"need iterations >= 0, restarts >= 0, memory >= 1; got {iterations}, {restarts}, {memory}")
    if not noise_levels or any(not np.isfinite(x) or x <= 0 for x in noise_levels):
        raise ValueError(f"noise_levels must be a non-empty tuple of positive numbers, got {noise_levels!r}")
    h = np.asarray(channels, dtype=np.complex128)
    lead, (k, n) = h.shape[:-2], h.shape[-2:]
    cos = np.broadcast_to(np.asarray(cos_theta, dtype=np.float64), lead + (k,)).reshape(-1, k)
    p = np.broadcast_to(np.asarray(pairing, dtype=np.float64), lead + (k, k)).reshape(-1, k, k)
    h = h.reshape(-1, k, n)

    tx, rx, valid = active_links(p, max(k // 2, 1))  # (B, L)
    starts = co_phasing_phases(h[:, None], cos[:, None], tx, rx, angle_dependent)  # (B, L, N)
    npairs = p.sum(axis=(-2, -1))

    # Every slot: the first link's co-phasing (the closed form when it is the only link).
    phases = starts[:, 0].copy()
    phases[npairs == 0] = 0.0
    rate, _ = sum_rate_and_gradient(phases, h, cos, p, tx_power_w, noise_w, angle_dependent, need_gradient=False)

    multi = np.flatnonzero(npairs >= 2)
    if multi.size >= 64:
        tune_allocator()  # as the batched simulator does: keeps ~MB temporaries in the heap
    if multi.size:
        # Reduced problem on the active links only (padding links get zero channels).
        pad = valid[multi][..., None]
        h_tx = np.take_along_axis(h[multi], tx[multi][..., None], axis=1) * pad  # (M, L, N)
        h_rx = np.take_along_axis(h[multi], rx[multi][..., None], axis=1) * pad
        cos_tx = np.take_along_axis(cos[multi], tx[multi], axis=1)
        sub = (h_tx[:, None], h_rx[:, None], cos_tx[:, None])
        random = random_starts(h[multi], seed, restarts)
        phi0 = np.concatenate([starts[multi], random], axis=1)  # (M, S, N)
        phi = phi0
        for level in noise_levels:
            phi = _lbfgs_ascent(phi, sub, tx_power_w, noise_w * float(level), angle_dependent, iterations, memory)
        phi = _null_polish(phi, sub, tx_power_w, noise_w, angle_dependent, polish_steps)
        # Final ranking at the true noise, the starts included: never worse than co-phasing.
        cand = np.concatenate([phi, phi0], axis=1)
        cand_rate, _ = _link_rate_and_gradient(cand, *sub, tx_power_w, noise_w, angle_dependent, need_gradient=False)
        pick = np.argmax(cand_rate, axis=1)
        phases[multi] = np.take_along_axis(cand, pick[:, None, None], axis=1)[:, 0]
        rate[multi] = np.take_along_axis(cand_rate, pick[:, None], axis=1)[:, 0]
    return PhaseSolution(ph.wrap_angle(phases).reshape(lead + (n,)), rate.reshape(lead))


def random_starts(channels: NDArray[np.complex128], seed: int, count: int) -> NDArray[np.float64]:
    """``count`` uniform phase vectors in [0, 2 pi) per slot, ``(B, count, N)`` for channels ``(B, K, N)``.

    Counter-based (:mod:`uavris.physics.streams`): the key of a slot hashes the seed with the
    bits of the slot's own channels, so a slot gets the same starts whatever batch it is
    in. Results then agree between batch shapes up to floating point: numpy's kernels
    for a batch of one can round differently, and on a non-concave surface a last-bit
    difference occasionally sends an iterate to another local maximum (1 slot in 128 in
    ``benchmarks/oracle_throughput.py``).
    """
    b, _, n = channels.shape
    words = np.ascontiguousarray(channels).view(np.uint64).reshape(b, -1)
    with np.errstate(over="ignore"):
        position = np.arange(1, words.shape[1] + 1, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)
        mixed = streams.mix64(words + position)
        keys = streams.mix64(np.bitwise_xor.reduce(mixed, axis=1) ^ streams.seed_key(seed))
    u = streams.uniforms(streams.raw_bits(keys, count * n))
    return TWO_PI * u.reshape(b, count, n)


def _null_polish(phi: NDArray[np.float64], sub: tuple[NDArray, NDArray, NDArray], tx_power_w: float,
                 noise_w: float, angle_dependent: bool, steps: int) -> NDArray[np.float64]:
    """Newton-Raphson steps towards exact nulls of the cross links, kept only where they raise ``R``.

    The cross links ``c_ji`` (active transmitter ``j``, active receiver ``i`` not its
    partner) are linearised in the phases, ``c(phi + delta) ~ c + J delta``, and the
    least-norm correction ``delta = -J^T (J J^T)^-1 c`` (real and imaginary parts stacked)
    is applied. Least-norm steps barely move the wanted links, so where interference is
    still above the noise each step removes most of it (quadratic convergence near a
    null). The best iterate by the true sum rate is returned per start.
    """
    h_tx, h_rx, cos_tx = sub
    lead, links = phi.shape[:-1], h_tx.shape[-2]
    mask = (1.0 - np.eye(links)).reshape(-1)  # the cross links c_ji, j != i
    rows = links * links
    best = phi
    best_rate, _ = _link_rate_and_gradient(phi, h_tx, h_rx, cos_tx, tx_power_w, noise_w, angle_dependent, False)
    eye = np.eye(2 * rows)
    for _ in range(steps):
        r, slope = _reflection_and_slope(phi, cos_tx, angle_dependent)
        hr = h_tx * r
        c = np.matmul(hr, np.swapaxes(h_rx, -1, -2)).reshape(lead + (rows,)) * mask
        jac = (1j * hr * slope)[..., :, None, :] * h_rx[..., None, :, :]  # dc_ji/dphi_n, (M, S, L, L, N)
        jac = jac.reshape(lead + (rows, phi.shape[-1])) * mask[..., None]
        jr = np.concatenate([jac.real, jac.imag], axis=-2)  # (M, S, 2 L^2, N)
        cr = np.concatenate([c.real, c.imag], axis=-1)
        gram = np.matmul(jr, np.swapaxes(jr, -1, -2))
        reg = 1e-12 * np.trace(gram, axis1=-2, axis2=-1)[..., None, None] + 1e-300
        y = np.linalg.solve(gram + reg * eye, cr[..., None])
        phi = phi - np.matmul(np.swapaxes(jr, -1, -2), y)[..., 0]
        phi = np.where(np.all(np.isfinite(phi), axis=-1, keepdims=True), phi, best)  # degenerate solve: restart
        rate, _ = _link_rate_and_gradient(phi, h_tx, h_rx, cos_tx, tx_power_w, noise_w, angle_dependent, False)
        better = rate > best_rate
        best = np.where(better[..., None], phi, best)
        best_rate = np.where(better, rate, best_rate)
    return best


def _dot(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.einsum("...n,...n->...", a, b)


def _lbfgs_ascent(phi: NDArray[np.float64], sub: tuple[NDArray, NDArray, NDArray], tx_power_w: float,
                  noise_w: float, angle_dependent: bool, iterations: int, memory: int) -> NDArray[np.float64]:
    """Monotone L-BFGS ascent on the phases from every start in ``phi`` ``(M, S, N)``, batched.

    Direction: the two-loop recursion on the last ``memory`` accepted (step, gradient
    change) pairs, with the usual ``s.y / y.y`` initial scaling; a pair is stored only
    when it has positive curvature ``s.y > 0`` (for the minimisation of ``-R``). When no
    pair is stored or the direction is not an ascent direction, a normalised gradient
    step of ``INITIAL_STEP`` rad replaces it (and the memory is cleared). Every step is
    capped at ``MAX_STEP`` rad per element. Step rule: try the full step; if ``R`` does
    not increase, halve it and try again next iteration (backtracking spread over
    iterations, so each iteration costs one evaluation for every start).
    """
    f, g = _link_rate_and_gradient(phi, *sub, tx_power_w, noise_w, angle_dependent)
    shape, n = f.shape, phi.shape[-1]
    # Circular memory shared by all starts (one write position), so no per-start indexing:
    # a start that stores no pair in an iteration gets a null pair (s = y = 0, rho = 0),
    # which the two-loop recursion ignores.
    s_mem = np.zeros((memory,) + shape + (n,))
    y_mem = np.zeros((memory,) + shape + (n,))
    rho = np.zeros((memory,) + shape)
    alpha = np.empty((memory,) + shape)
    head = 0  # next write position; newest pair at head - 1
    gamma = np.zeros(shape)  # s.y / y.y of each start's newest stored pair
    have = np.zeros(shape, dtype=bool)
    t = np.ones(shape)
    d = np.zeros_like(phi)
    need_dir = np.ones(shape, dtype=bool)
    for _ in range(iterations):
        if need_dir.any():
            order = [(head - 1 - i) % memory for i in range(memory)]  # newest first
            q = g.copy()  # ascent: minimise -R, whose gradient is -g; the recursion is linear
            for i in order:
                alpha[i] = rho[i] * _dot(s_mem[i], q)
                q -= alpha[i][..., None] * y_mem[i]
            r = gamma[..., None] * q
            for i in reversed(order):
                r += (alpha[i] - rho[i] * _dot(y_mem[i], r))[..., None] * s_mem[i]
            bad = ~have | (_dot(r, g) <= 0.0)
            gmax = np.maximum(np.max(np.abs(g), axis=-1), 1e-300)
            new_d = np.where(bad[..., None], g * (INITIAL_STEP / gmax)[..., None], r)
            new_d *= np.minimum(1.0, MAX_STEP / np.maximum(np.max(np.abs(new_d), axis=-1), 1e-300))[..., None]
            d = np.where(need_dir[..., None], new_d, d)
            t = np.where(need_dir, 1.0, t)
            reset = need_dir & bad & have
            if reset.any():
                s_mem[:, reset] = 0.0
                y_mem[:, reset] = 0.0
                rho[:, reset] = 0.0
                have &= ~reset
        step = t[..., None] * d
        trial = phi + step
        f_new, g_new = _link_rate_and_gradient(trial, *sub, tx_power_w, noise_w, angle_dependent)
        ok = f_new > f
        y = g - g_new
        sy = _dot(step, y)
        yy = _dot(y, y)
        store = ok & (sy > 1e-10 * np.sqrt(_dot(step, step) * yy))
        if store.any():
            s_mem[head] = np.where(store[..., None], step, 0.0)
            y_mem[head] = np.where(store[..., None], y, 0.0)
            rho[head] = np.where(store, 1.0 / np.where(store, sy, 1.0), 0.0)
            gamma = np.where(store, sy / np.maximum(yy, 1e-300), gamma)
            have |= store
            head = (head + 1) % memory
        phi = np.where(ok[..., None], trial, phi)
        g = np.where(ok[..., None], g_new, g)
        f = np.where(ok, f_new, f)
        step_size = t * np.max(np.abs(d), axis=-1)
        # New direction after a success, or when backtracking has shrunk the step to nothing.
        need_dir = ok | (step_size < MIN_STEP)
        t = np.where(ok, 1.0, 0.5 * t)
    return phi


def optimize_slot_phases(config: SystemConfig, channels: ArrayLike, cos_theta: ArrayLike, pairing: ArrayLike,
                         **kwargs: object) -> PhaseSolution:
    """:func:`optimize_phases` with ``P``, ``sigma^2`` and the reflection model taken from ``config``."""
    return optimize_phases(channels, cos_theta, pairing, config.tx_power_w, config.noise_w,
                           angle_dependent=config.angle_dependent_reflection, **kwargs)  # type: ignore[arg-type]
