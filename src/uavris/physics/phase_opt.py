"""Per-slot RIS phase optimiser: the phases that maximise one slot's sum rate.

Lives here: :func:`optimize_phases` and :func:`optimize_slot_phases` (the entry point of the
oracles and of the ``"optimizer"`` phase control), :class:`PhaseSolution`,
:func:`sum_rate_and_gradient`, :func:`random_starts` and the kernel's compile notice
(:class:`CompileNotice`, :func:`compile_optimiser`). Not here: the one-pair closed form
(:mod:`uavris.physics.co_phasing`; its functions importable from here too), the compiled
multi-pair stages (:mod:`uavris.physics.phase_kernel`) and the phase control (:mod:`uavris.env.wrappers`).

Problem (docs/model.md sections 6-8). Given this slot's channels ``h`` ``(..., K, N)``,
incidence cosines ``cos_theta`` ``(..., K)`` and pairing ``P`` ``(..., K, K)``, choose
unit-modulus presets ``r_pre_n = exp(j phi_n)`` to maximise

    R(phi) = sum_{P[k,i]=1} log2(1 + P|c_ki|^2 / (sum_{j active tx, j != k} P|c_ji|^2 + sigma^2)),
    c_ji   = sum_n h_j[n] r_n(theta_j) h_i[n],

where ``r_n(theta_j) = unit_reflection_coefficient(phi_n, cos(theta_j))``: every
transmitter sees the preset through the angle-dependent map at its own angle. In phase
form that map is ``r_n(theta_j) = exp(j g(phi_n, c_j))`` with

    g(phi, c) = 2 arg(c cos(phi/2) + j sin(phi/2)),   dg/dphi = c / (c^2 cos^2(phi/2) + sin^2(phi/2)),

a strictly increasing bijection of the circle for ``c > 0`` (``c = 0`` gives ``-1``).

Method
------
*One active pair k -> i*: co-phasing every element, an exact closed form
(:mod:`uavris.physics.co_phasing`): ``SNR = P (sum_n |h_k[n]| |h_i[n]|)^2 / sigma^2``.

*Several active pairs* (no closed form; non-concave, with one basin per "which pair is
served" and narrow ridges where the cross links are nulled). Three stages, run for every
slot and start by the compiled kernel :mod:`uavris.physics.phase_kernel`:

1. Starts. The co-phasing solution of each active pair (so the result is never worse
   than the best single-pair co-phasing, which is what ``hover_aligned`` plays) plus
   ``restarts`` uniform random phase vectors (default 2). The basins differ by up to
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
   L-BFGS details (``phase_kernel._lbfgs``): memory 8 per start, a pair stored only when its
   curvature is positive, normalised gradient steps of 0.3 rad when there is no usable
   pair, every step capped at pi/2 rad per element. Step-size rule: try the full
   quasi-Newton step; if ``R`` does not increase, halve it (backtracking spread over
   iterations), so the iterates are monotone for each level. ``iterations`` = 30 per
   level (210 in all).
3. Null polish (``phase_kernel._polish``, 10 steps). Newton-Raphson on the cross links
   ``c_ji = 0`` with least-norm steps, kept only where the true sum rate rises. At high
   SNR the ridge ascent leaves interference well above the noise, and this is where
   quasi-Newton is weakest and Newton-Raphson on the nulls strongest.

The best of all final points and all starts, by the true sum rate, is returned.

Gradient, analytic (no autograd). With ``T_i = sum_{j active} P|c_ji|^2 + sigma^2``
(received power at ``i``) and ``I_i = T_i - P|c_{k(i),i}|^2``,

    dR/d|c_ji|^2 = W_ji = (P / ln 2) (1/T_i - [j != k(i)] / I_i)     (active j, active receiver i)
    dR/dphi_n    = -2 sum_j g'(phi_n, c_j) Im( h_j[n] r_n(theta_j) sum_i W_ji conj(c_ji) h_i[n] ),

``O(K^2 N)`` per evaluation, the same cost as the objective. Inside the iterations the
objective is evaluated on the active links only (``phase_kernel.link_rate``: ``L``
transmitters and their ``L`` receivers, ``L = floor(K/2)``), since users that neither
transmit nor receive do not enter the sum rate; for ``K = 4`` that halves the work.

Why these settings (measured with a batched numpy form of this solver on two seeded sets of
two-pair slots of the default system: A = 256 slots at random poses over the whole flight
region with random tilts up to 0.4 rad, B = 128 slots at the pose where a greedy planner
hovered, [19.95, 8, 2], SNRs 1e10-1e12; mean optimised sum rate in bps/Hz; rows marked *
with a gradient-ascent solver before it; "default" is the batched form's settings):

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
buy little. The multi-pair stages run compiled (numba), one slot and one start at a time,
each start with its own L-BFGS memory (the batched form shared one buffer between a slot's
starts), and with 2 random starts (the table: 2 and 4 alike): on the 1,024 seeded slots of
``benchmarks/oracle_throughput.py`` (random poses, the default pairing draw) the mean sum
rate is within 0.1% of the batched form's at about 5x its slots per second on one core
(the benchmark measures both in one run).

Batching: every leading axis of the inputs is a slot axis. Slots with one active pair take
the closed form (numpy, whole batch); slots without active pair get zero phases and rate
0; the others go to the kernel. Random starts are counter-based hashes of the seed and
the slot's channels (:func:`random_starts`), and the kernel solves every slot on its own,
so a slot's result is deterministic and the same whatever batch it is solved in.

Only the unit-modulus phase-only RIS (the default action) is optimised. For a single
pair unit amplitude is optimal (|r_n| <= 1 and the triangle inequality); for several
pairs a smaller amplitude could in principle trade signal for interference, which this
optimiser does not explore.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uavris import physics as ph
from uavris.config import SystemConfig
from uavris.physics import streams
from uavris.physics.co_phasing import co_phasing_phases, single_pair_snr, target_phases_to_presets  # noqa: F401
from uavris.physics.phase_kernel import solve_slots
from uavris.physics.slot_memo import SlotMemo

# The first compile of the kernel on one core (measured, docs/timings.md: 13 s on the AMD EPYC of family 26,
# 24 s on one of family 25 with the other core busy); numba caches it beside the module (or in
# NUMBA_CACHE_DIR) and every later process loads it in well under a second.
COMPILE_S = "10-25"


class CompileNotice(UserWarning):
    """The phase optimiser's kernel is being compiled: once, then numba's cache serves every process."""


def kernel_ready() -> bool:
    """Whether the optimiser's compiled kernel is at hand: compiled in this process, or in numba's cache."""
    if solve_slots.signatures:
        return True
    cache = getattr(getattr(solve_slots, "_cache", None), "cache_path", None)
    return cache is not None and any(Path(cache).glob("phase_kernel.solve_slots-*.nbi"))


def announce_compile() -> None:
    """One notice (:class:`CompileNotice`, shown once) before the first use compiles the kernel: a
    first run that waits for it says why."""
    if not kernel_ready():
        warnings.warn(f"compiling the phase optimiser, once: {COMPILE_S} s (later runs load it from numba's "
                      "cache)", CompileNotice, stacklevel=3)


def compile_optimiser() -> None:
    """Compile (or load) the kernel now, on one slot of two active pairs: what ``make`` does once after
    installing, so that no run or test waits for it. Without :class:`CompileNotice`: the caller has
    said what it is doing (make's install step prints its line)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CompileNotice)
        _one_slot()


def _one_slot() -> None:
    c = SystemConfig()
    rng = np.random.default_rng(0)
    h = (rng.standard_normal((1, c.num_users, c.num_elements))
         + 1j * rng.standard_normal((1, c.num_users, c.num_elements)))
    pairing = np.zeros((1, c.num_users, c.num_users))
    pairing[0, 0, 1] = pairing[0, 2, 3] = 1.0
    optimize_slot_phases(c, h, np.ones((1, c.num_users)), pairing)


TWO_PI = 2.0 * np.pi
LN2 = np.log(2.0)

DEFAULT_ITERATIONS = 30  # L-BFGS iterations per continuation level
DEFAULT_RESTARTS = 2  # random starts, besides one co-phasing start per active pair
DEFAULT_NOISE_LEVELS = (1e6, 1e5, 1e4, 1e3, 1e2, 1e1, 1.0)  # continuation: multiples of sigma^2
DEFAULT_MEMORY = 8  # L-BFGS pairs kept
DEFAULT_POLISH_STEPS = 10  # Newton-Raphson nulling steps after the continuation
DEFAULT_WARM_ITERATIONS = 30  # L-BFGS iterations per level from a warm start
DEFAULT_WARM_LEVELS = (1.0,)  # the continuation from a warm start
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
                    seed: int = 0, warm: ArrayLike | None = None,
                    warm_iterations: int = DEFAULT_WARM_ITERATIONS,
                    warm_levels: tuple[float, ...] = DEFAULT_WARM_LEVELS,
                    memo: SlotMemo | None = None) -> PhaseSolution:
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
        warm: ``(..., N)`` phases to start from instead (a nearby slot's solution), NaN
            where a slot has none. A multi-pair slot with a warm start is solved from it
            alone, over ``warm_levels`` with ``warm_iterations`` L-BFGS iterations each and
            the polish; the co-phasing starts are valued beside it, so the result is never
            below the best single-pair co-phasing. Other slots: the full method. An option,
            not a default: on the study's own rollouts even the previous slot's full solution
            as the warm start loses 1.8-4.6% of the sum rate (the NLoS draw of every slot
            moves the nulls), measured by ``benchmarks/findings/warm_start.py``.
        warm_iterations: L-BFGS iterations per level of a warm start.
        warm_levels: the continuation of a warm start (multiples of ``sigma^2``; default the
            true problem only).

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
    if multi.size:
        announce_compile()
        # Reduced problem on the active links only (padding links get zero channels).
        pad = valid[multi][..., None]
        h_tx = np.take_along_axis(h[multi], tx[multi][..., None], axis=1) * pad  # (M, L, N)
        h_rx = np.take_along_axis(h[multi], rx[multi][..., None], axis=1) * pad
        cos_tx = np.ascontiguousarray(np.take_along_axis(cos[multi], tx[multi], axis=1))
        part = [np.ascontiguousarray(x) for x in (h_tx.real, h_tx.imag, h_rx.real, h_rx.imag)]
        has_warm = np.zeros(multi.size, dtype=bool)
        if warm is not None:
            w = np.broadcast_to(np.asarray(warm, dtype=np.float64), lead + (n,)).reshape(-1, n)[multi]
            has_warm = np.all(np.isfinite(w), axis=1)
        out_phi = np.empty((multi.size, n))
        out_rate = np.empty(multi.size)
        for warm_path, levels, its in ((False, noise_levels, iterations), (True, warm_levels, warm_iterations)):
            sel = np.flatnonzero(has_warm == warm_path)
            if not sel.size:
                continue
            if not warm_path:  # the full method: co-phasing and random starts, all optimised
                phi0 = np.concatenate([starts[multi[sel]], random_starts(h[multi[sel]], seed, restarts)], axis=1)
                n_opt = phi0.shape[1]
            else:  # the warm start optimised, the co-phasing starts valued beside it
                phi0, n_opt = np.concatenate([w[sel][:, None], starts[multi[sel]]], axis=1), 1
            sub_phi, sub_rate = np.empty((sel.size, n)), np.empty(sel.size)
            solve = solve_slots if memo is None else memo.solve
            solve(*(x[sel] for x in part), cos_tx[sel], np.ascontiguousarray(phi0), n_opt, float(tx_power_w),
                  float(noise_w), np.asarray(levels, dtype=np.float64), its, memory, polish_steps,
                  bool(angle_dependent), INITIAL_STEP, MAX_STEP, MIN_STEP, sub_phi, sub_rate)
            out_phi[sel], out_rate[sel] = sub_phi, sub_rate
        phases[multi] = out_phi
        rate[multi] = out_rate
    return PhaseSolution(ph.wrap_angle(phases).reshape(lead + (n,)), rate.reshape(lead))


def random_starts(channels: NDArray[np.complex128], seed: int, count: int) -> NDArray[np.float64]:
    """``count`` uniform phase vectors in [0, 2 pi) per slot, ``(B, count, N)`` for channels ``(B, K, N)``.

    Counter-based (:mod:`uavris.physics.streams`): the key of a slot hashes the seed with the
    bits of the slot's own channels, so a slot gets the same starts whatever batch it is
    in, and the kernel then solves it on its own.
    """
    b, _, n = channels.shape
    words = np.ascontiguousarray(channels).view(np.uint64).reshape(b, -1)
    with np.errstate(over="ignore"):
        position = np.arange(1, words.shape[1] + 1, dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)
        mixed = streams.mix64(words + position)
        keys = streams.mix64(np.bitwise_xor.reduce(mixed, axis=1) ^ streams.seed_key(seed))
    u = streams.uniforms(streams.raw_bits(keys, count * n))
    return TWO_PI * u.reshape(b, count, n)


def optimize_slot_phases(config: SystemConfig, channels: ArrayLike, cos_theta: ArrayLike, pairing: ArrayLike,
                         **kwargs: object) -> PhaseSolution:
    """:func:`optimize_phases` with ``P``, ``sigma^2`` and the reflection model taken from ``config``."""
    return optimize_phases(channels, cos_theta, pairing, config.tx_power_w, config.noise_w,
                           angle_dependent=config.angle_dependent_reflection, **kwargs)  # type: ignore[arg-type]
