"""Compiled core of the per-slot phase optimiser: the multi-pair method, one slot at a time.

Lives here: the objective and its analytic gradient on the active links, monotone
L-BFGS ascent, the Newton-Raphson null polish and the per-slot driver, compiled with
numba. Not here: the method's description and reasons, the starts and the closed form
for one pair (:mod:`uavris.physics.phase_opt`, which calls :func:`solve_slots`).

Why compiled: a slot's problem is tiny (L = 2 links, N = 16 phases); batched numpy spent
most of its time in array overheads and could not stop a start that had converged or
keep a proper L-BFGS memory per start. Here every slot and start is solved on its own,
so a slot's result does not depend on the batch it is in.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

LN2 = math.log(2.0)
# No fast-math: every operation is IEEE, in the order written, so that the kernels give the
# same bits whatever CPU numba compiles them for (vector widths, FMA contraction and
# reassociated sums would otherwise differ between, say, an AVX-512 Xeon and an AMD EPYC:
# docs/study.md, section 3). Elementwise loops still vectorise; only the sums do not.
FAST = False
# The helpers are inlined into their caller by numba itself (inline="always"), so that the
# caller's machine code is the same whether this process compiles it or loads it from
# numba's cache. Left to LLVM, they were inlined (and fast-math reassociated across them)
# only when compiling, while a cached load linked them separately: the same slot got other
# bits in a process that had compiled the kernels (docs/study.md, section 3).


@njit(cache=True, fastmath=FAST, inline="always")
def _reflect(phi, cos_tx, angle_dependent, rr, ri, sl):  # pragma: no cover - compiled
    """r_n(theta_j) (real, imaginary) and g'(phi_n, c_j) into ``rr, ri, sl`` ``(L, N)``.

    With t = tan(phi/2) and c = cos(theta): r = (c + j t)^2 / (c^2 + t^2) and
    g' = c (1 + t^2) / (c^2 + t^2) (docs/model.md section 6); at c = 0, phi = 0 the tiny
    guard gives the grazing value r = -1.
    """
    n_links, n_el = rr.shape
    for n in range(n_el):
        if angle_dependent:
            t = math.tan(0.5 * phi[n])
            t2 = t * t
            for j in range(n_links):
                c = min(max(cos_tx[j], 0.0), 1.0)
                c2 = c * c
                inv = 1.0 / (c2 + t2 + 1e-300)
                rr[j, n] = 2.0 * c2 * inv - 1.0
                ri[j, n] = 2.0 * c * t * inv
                sl[j, n] = c * (1.0 + t2) * inv
        else:
            cr, si = math.cos(phi[n]), math.sin(phi[n])
            for j in range(n_links):
                rr[j, n] = cr
                ri[j, n] = si
                sl[j, n] = 1.0


@njit(cache=True, fastmath=FAST, inline="always")
def link_rate(phi, txr, txi, rxr, rxi, cos_tx, power, noise, angle_dependent, need_grad, grad,
              rr, ri, sl, hrr, hri, cr, ci):  # pragma: no cover - compiled
    """Sum rate of the links ``l: tx l -> rx l`` at phases ``phi`` ``(N,)``; its gradient into ``grad``.

    ``txr, txi, rxr, rxi`` ``(L, N)``: real and imaginary parts of the transmitters' and
    receivers' channels; the remaining arrays are workspace. Same objective and gradient
    as :func:`uavris.physics.phase_opt.sum_rate_and_gradient` restricted to the links.
    """
    n_links, n_el = txr.shape
    _reflect(phi, cos_tx, angle_dependent, rr, ri, sl)
    for j in range(n_links):
        for n in range(n_el):
            hrr[j, n] = txr[j, n] * rr[j, n] - txi[j, n] * ri[j, n]
            hri[j, n] = txr[j, n] * ri[j, n] + txi[j, n] * rr[j, n]
    for j in range(n_links):
        for i in range(n_links):
            sr = 0.0
            si = 0.0
            for n in range(n_el):
                sr += hrr[j, n] * rxr[i, n] - hri[j, n] * rxi[i, n]
                si += hrr[j, n] * rxi[i, n] + hri[j, n] * rxr[i, n]
            cr[j, i] = sr
            ci[j, i] = si
    rate = 0.0
    if need_grad:
        for n in range(n_el):
            grad[n] = 0.0
    for i in range(n_links):
        signal = power * (cr[i, i] * cr[i, i] + ci[i, i] * ci[i, i])
        interf = noise
        for j in range(n_links):
            if j != i:
                interf += power * (cr[j, i] * cr[j, i] + ci[j, i] * ci[j, i])
        total = interf + signal
        rate += math.log2(total) - math.log2(interf)
        if need_grad:
            for j in range(n_links):
                # W_ji = dR/d|c_ji|^2; its term of dR/dphi_n is -2 g' Im(hr_j[n] W conj(c_ji) h_i[n]).
                w = (power / LN2) * (1.0 / total - (1.0 / interf if j != i else 0.0))
                a = w * cr[j, i]
                b = w * ci[j, i]
                for n in range(n_el):
                    br = a * rxr[i, n] + b * rxi[i, n]
                    bi = a * rxi[i, n] - b * rxr[i, n]
                    grad[n] -= 2.0 * sl[j, n] * (hrr[j, n] * bi + hri[j, n] * br)
    return rate


@njit(cache=True, fastmath=FAST, inline="always")
def _lbfgs(phi, txr, txi, rxr, rxi, cos_tx, power, noise, angle_dependent, iterations, memory,
           initial_step, max_step, min_step, ws):  # pragma: no cover - compiled
    """Monotone L-BFGS ascent from ``phi`` (updated in place); rules of the numpy docstring."""
    rr, ri, sl, hrr, hri, cr, ci = ws
    n_el = phi.shape[0]
    g = np.empty(n_el)
    g_new = np.empty(n_el)
    trial = np.empty(n_el)
    d = np.zeros(n_el)
    q = np.empty(n_el)
    s_mem = np.zeros((memory, n_el))
    y_mem = np.zeros((memory, n_el))
    rho = np.zeros(memory)
    alpha = np.zeros(memory)
    count, head, gamma, t = 0, 0, 0.0, 1.0
    need_dir = True
    f = link_rate(phi, txr, txi, rxr, rxi, cos_tx, power, noise, angle_dependent, True, g, rr, ri, sl, hrr, hri,
                  cr, ci)
    for _ in range(iterations):
        if need_dir:
            for n in range(n_el):
                q[n] = g[n]
            for k in range(count):  # newest first
                idx = (head - 1 - k) % memory
                a = 0.0
                for n in range(n_el):
                    a += s_mem[idx, n] * q[n]
                alpha[idx] = rho[idx] * a
                for n in range(n_el):
                    q[n] -= alpha[idx] * y_mem[idx, n]
            ascent = 0.0
            for n in range(n_el):
                q[n] *= gamma
            for k in range(count - 1, -1, -1):
                idx = (head - 1 - k) % memory
                b = 0.0
                for n in range(n_el):
                    b += y_mem[idx, n] * q[n]
                b = alpha[idx] - rho[idx] * b
                for n in range(n_el):
                    q[n] += b * s_mem[idx, n]
            for n in range(n_el):
                ascent += q[n] * g[n]
            if count == 0 or ascent <= 0.0:
                gmax = 1e-300
                for n in range(n_el):
                    gmax = max(gmax, abs(g[n]))
                for n in range(n_el):
                    d[n] = g[n] * (initial_step / gmax)
                count = 0  # the memory no longer describes the surface: start over
            else:
                for n in range(n_el):
                    d[n] = q[n]
            dmax = 1e-300
            for n in range(n_el):
                dmax = max(dmax, abs(d[n]))
            if dmax > max_step:
                for n in range(n_el):
                    d[n] *= max_step / dmax
            t = 1.0
        for n in range(n_el):
            trial[n] = phi[n] + t * d[n]
        f_new = link_rate(trial, txr, txi, rxr, rxi, cos_tx, power, noise, angle_dependent, True, g_new, rr, ri,
                          sl, hrr, hri, cr, ci)
        ok = f_new > f
        if ok:
            sy, yy, ss = 0.0, 0.0, 0.0
            for n in range(n_el):
                y = g[n] - g_new[n]  # change of the gradient of -R
                s = t * d[n]
                sy += s * y
                yy += y * y
                ss += s * s
            if sy > 1e-10 * math.sqrt(ss * yy):
                for n in range(n_el):
                    s_mem[head, n] = t * d[n]
                    y_mem[head, n] = g[n] - g_new[n]
                rho[head] = 1.0 / sy
                gamma = sy / yy
                head = (head + 1) % memory
                count = min(count + 1, memory)
            for n in range(n_el):
                phi[n] = trial[n]
                g[n] = g_new[n]
            f = f_new
            need_dir = True
        else:
            dmax = 0.0
            for n in range(n_el):
                dmax = max(dmax, abs(d[n]))
            need_dir = t * dmax < min_step
            t *= 0.5
    return f


@njit(cache=True, fastmath=FAST, inline="always")
def _cholesky_solve(a, b):  # pragma: no cover - compiled
    """``a^-1 b`` for a symmetric positive definite ``a`` (overwritten by its Cholesky factor),
    written out rather than LAPACK's, whose kernels depend on the CPU: a non-positive pivot
    (a degenerate system) gives NaN, which the caller treats as a failed step."""
    n = a.shape[0]
    for j in range(n):
        d = a[j, j]
        for k in range(j):
            d -= a[j, k] * a[j, k]
        d = math.sqrt(d) if d > 0.0 else math.nan
        a[j, j] = d
        for i in range(j + 1, n):
            s = a[i, j]
            for k in range(j):
                s -= a[i, k] * a[j, k]
            a[i, j] = s / d
    y = np.empty(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= a[i, k] * y[k]
        y[i] = s / a[i, i]
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= a[k, i] * y[k]
        y[i] = s / a[i, i]
    return y


@njit(cache=True, fastmath=FAST, inline="always")
def _polish(phi, txr, txi, rxr, rxi, cos_tx, power, noise, angle_dependent, steps, ws):  # pragma: no cover
    """Newton-Raphson least-norm steps towards nulls of the cross links; the best iterate by the
    true rate is returned (``phi`` itself when no step raises the rate)."""
    rr, ri, sl, hrr, hri, cr, ci = ws
    n_links, n_el = txr.shape
    rows = 2 * n_links * (n_links - 1)
    dummy = np.empty(n_el)
    best = phi.copy()
    best_rate = link_rate(phi, txr, txi, rxr, rxi, cos_tx, power, noise, angle_dependent, False, dummy, rr, ri, sl,
                          hrr, hri, cr, ci)
    cur = phi.copy()
    jac = np.zeros((rows, n_el))
    val = np.zeros(rows)
    gram = np.empty((rows, rows))
    for _ in range(steps):
        _reflect(cur, cos_tx, angle_dependent, rr, ri, sl)
        row = 0
        for j in range(n_links):
            for i in range(n_links):
                if i == j:
                    continue
                sr, si = 0.0, 0.0
                for n in range(n_el):
                    hr_r = txr[j, n] * rr[j, n] - txi[j, n] * ri[j, n]
                    hr_i = txr[j, n] * ri[j, n] + txi[j, n] * rr[j, n]
                    pr = hr_r * rxr[i, n] - hr_i * rxi[i, n]
                    pi = hr_r * rxi[i, n] + hr_i * rxr[i, n]
                    sr += pr
                    si += pi
                    jac[row, n] = -sl[j, n] * pi  # d c_ji / d phi_n = j g' hr_j[n] h_i[n]
                    jac[row + 1, n] = sl[j, n] * pr
                val[row] = sr
                val[row + 1] = si
                row += 2
        for r in range(rows):
            for r2 in range(r, rows):
                acc = 0.0
                for n in range(n_el):
                    acc += jac[r, n] * jac[r2, n]
                gram[r, r2] = acc
                gram[r2, r] = acc
        reg = 1e-300
        for r in range(rows):
            reg += 1e-12 * gram[r, r]
        for r in range(rows):
            gram[r, r] += reg
        y = _cholesky_solve(gram, val)
        finite = True
        for n in range(n_el):
            acc = 0.0
            for r in range(rows):
                acc += jac[r, n] * y[r]
            cur[n] -= acc
            finite = finite and math.isfinite(cur[n])
        if not finite:  # degenerate solve: restart from the best point
            cur[:] = best
        rate = link_rate(cur, txr, txi, rxr, rxi, cos_tx, power, noise, angle_dependent, False, dummy, rr, ri, sl,
                         hrr, hri, cr, ci)
        if rate > best_rate:
            best_rate = rate
            best[:] = cur
    return best


@njit(cache=True, fastmath=FAST)
def solve_slots(txr, txi, rxr, rxi, cos_tx, phi0, n_opt, power, noise, levels, iterations, memory, polish_steps,
                angle_dependent, initial_step, max_step, min_step, out_phi, out_rate):  # pragma: no cover
    """Every slot ``m``: from each of the first ``n_opt`` starts ``phi0[m, s]``, continuation over
    ``levels`` (multiples of ``noise``) with L-BFGS, then the null polish; the best of the
    final points and of all the starts (the others are only valued) by the true sum rate goes
    to ``out_phi[m]``, ``out_rate[m]`` (first best wins)."""
    n_slots, n_starts, n_el = phi0.shape
    n_links = txr.shape[1]
    dummy = np.empty(n_el)
    for m in range(n_slots):
        ws = (np.empty((n_links, n_el)), np.empty((n_links, n_el)), np.empty((n_links, n_el)),
              np.empty((n_links, n_el)), np.empty((n_links, n_el)), np.empty((n_links, n_links)),
              np.empty((n_links, n_links)))
        a, b, c, e, f, g, h = txr[m], txi[m], rxr[m], rxi[m], cos_tx[m], power, noise
        best_rate = -np.inf
        for s in range(min(n_opt, n_starts)):
            phi = phi0[m, s].copy()
            for level in levels:
                _lbfgs(phi, a, b, c, e, f, g, h * level, angle_dependent, iterations, memory, initial_step, max_step,
                       min_step, ws)
            phi = _polish(phi, a, b, c, e, f, g, h, angle_dependent, polish_steps, ws)
            rate = link_rate(phi, a, b, c, e, f, g, h, angle_dependent, False, dummy, ws[0], ws[1], ws[2], ws[3],
                             ws[4], ws[5], ws[6])
            if rate > best_rate:
                best_rate = rate
                out_phi[m] = phi
        for s in range(n_starts):
            rate = link_rate(phi0[m, s], a, b, c, e, f, g, h, angle_dependent, False, dummy, ws[0], ws[1], ws[2],
                             ws[3], ws[4], ws[5], ws[6])
            if rate > best_rate:
                best_rate = rate
                out_phi[m] = phi0[m, s]
        out_rate[m] = best_rate
