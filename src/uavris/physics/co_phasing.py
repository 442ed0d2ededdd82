"""The one-pair closed form of the phase optimiser: co-phasing a lone link.

Lives here: :func:`co_phasing_phases` (the presets that co-phase every element for one link
``tx -> rx``), :func:`single_pair_snr` (that link's optimal SNR) and
:func:`target_phases_to_presets` (the presets whose practical coefficient has a given phase: the
inverse reflection model with its one singular target handled). Not here: the optimiser of
several pairs, which starts from these phases (:mod:`uavris.physics.phase_opt`, its method in
that module's docstring), the reflection model itself (:mod:`uavris.physics.reflection`).

One active pair ``k -> i`` (docs/model.md sections 6-8). By the triangle inequality
``|c_ki| <= sum_n |h_k[n]| |h_i[n]|`` for ``|r_n| = 1``, with equality when every element is
co-phased, ``r_n(theta_k) = exp(-j arg(h_k[n] h_i[n]))``. The preset achieving it is found by
inverting the reflection model with :func:`uavris.physics.preset_for_target`, so the optimum is
exact: ``SNR = P (sum_n |h_k[n]| |h_i[n]|)^2 / sigma^2``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from uavris import physics as ph


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
