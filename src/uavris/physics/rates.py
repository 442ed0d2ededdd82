"""SINR, pair rates and the sum rate (paper eq. 7-8, corrected with |.|^2 in docs/model.md section 8).

Lives here: :func:`pair_sinr`, :func:`pair_rates` and :func:`sum_rate` (the reward). Not
here: the cascaded gains they take (:mod:`.channel`) and the phases that maximise them
(:mod:`.phase_opt`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def pair_sinr(gains: ArrayLike, pairing: ArrayLike, tx_power_w: float, noise_w: float) -> NDArray[np.float64]:
    """SINR of every active link k -> i, zero elsewhere. Shape ``(..., K, K)``.

    SINR_{k,i} = P|c_{k,i}|^2 / (sum_{j active tx, j != k} P|c_{j,i}|^2 + sigma^2).
    ``pairing[..., k, i] = 1`` when k transmits to i.
    """
    g2 = np.abs(np.asarray(gains)) ** 2
    p = np.asarray(pairing, dtype=np.float64)
    active_tx = p.sum(axis=-1)  # (..., K): 1 where k transmits
    # Power reaching receiver i from all active transmitters.
    total = tx_power_w * np.einsum("...j,...ji->...i", active_tx, g2)
    signal = tx_power_w * g2
    interference = total[..., None, :] - signal
    interference = np.maximum(interference, 0.0)  # guard tiny negative round-off
    return p * signal / (interference + noise_w)


def pair_rates(gains: ArrayLike, pairing: ArrayLike, tx_power_w: float, noise_w: float) -> NDArray[np.float64]:
    """Achievable rate log2(1 + SINR) of each active pair, bps/Hz, ``(..., K, K)``."""
    return np.log2(1.0 + pair_sinr(gains, pairing, tx_power_w, noise_w))


def sum_rate(gains: ArrayLike, pairing: ArrayLike, tx_power_w: float, noise_w: float) -> NDArray[np.float64]:
    """Reward r(t): sum of the active pairs' rates, bps/Hz (paper Sec. IV-A)."""
    return pair_rates(gains, pairing, tx_power_w, noise_w).sum(axis=(-2, -1))
