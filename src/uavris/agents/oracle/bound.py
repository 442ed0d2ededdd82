"""A bound no controller can beat: the largest average sum rate any policy could earn in an episode.

Lives here: :func:`slot_bounds` (each slot's bound from that slot's draws), :func:`episode_bounds`
(an episode's) and the two quantities they rest on, :func:`distance_floor` and
:func:`fewest_slots`. Not here: the oracle, whose plan is measured against it
(:mod:`.planner`), and the draws themselves (:func:`uavris.env.simulator.slot_draws`).

Derivation (docs/model.md, "The bound"). In slot ``t`` the NLoS draws ``w_k`` and the pairing
``P(t)`` do not depend on the actions (counter-based streams, section 16), so they are the same
for every controller. For an active link ``k -> i``:

- dropping the interference only raises the SINR (eq. 8): ``SINR <= P |c_ki|^2 / sigma^2``;
- ``|c_ki| = |sum_n h_k[n] r_n h_i[n]| <= sum_n |h_k[n]| |h_i[n]|``, since ``|r_n| <= 1`` for
  every preset, angle and learned amplitude (a passive surface, section 6);
- ``|h_k[n]| <= d_k^(-alpha/2) A_k[n]`` with ``A_k[n] = sqrt(kappa/(kappa+1)) + sqrt(1/(kappa+1))
  |w_k[n]|`` (eq. 1: ``|g_k[n]| = 1``; a blocked device's channel is 0, below the bound);
- the UAV is in the flight region and at least ``safety_distance`` from every device, so
  ``d_k >= m_k``, the larger of the two; and ``d_k + d_i >= D_ki``, the devices' distance. On
  that set ``d_k d_i`` is smallest with one distance at its floor:
  ``d_k d_i >= min(m_k max(m_i, D - m_k), m_i max(m_k, D - m_i))`` (:func:`distance_floor`).

So ``R_ki(t) <= log2(1 + P (sum_n A_k[n] A_i[n])^2 / (sigma^2 floor_ki^alpha))`` and the slot's
bound ``b(t)`` is the sum over its active links: every link at its own best pose, co-phased, at
full amplitude, without interference. An episode lasts ``T'`` slots, ``T`` unless the energy
budget ends it first, which takes at least :func:`fewest_slots` (the propulsion power is at most
its three terms' largest values on ``[0, v_max]``); its average is then at most the largest mean
of ``b`` over the first ``T'`` slots, ``T'`` from that least to ``T``.

It is loose (each link has a pose of its own, next to one of its devices, and no interference),
and exact in the limit it is built from: one link, a pure line of sight, an ideal surface, the
UAV where the floor is reached (tested). A plan's fraction of it says how much room any
controller could have left, never how good the plan is; the oracle is the yardstick.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from uavris.config import SystemConfig
from uavris.env.simulator import slot_draws
from uavris.physics import streams


def distance_floor(config: SystemConfig) -> NDArray[np.float64]:
    """``(K, K)``: a lower bound on ``d_k d_i``, the product of the UAV's distances to devices
    ``k`` and ``i``, over every pose the UAV may hold (derivation in the module docstring)."""
    users = np.asarray(config.users, dtype=np.float64)
    low, high = np.asarray(config.region_low), np.asarray(config.region_high)
    outside = np.linalg.norm(users - np.clip(users, low, high), axis=1)  # each device to the flight region
    m = np.maximum(outside, config.safety_distance)
    d = np.linalg.norm(users[:, None] - users[None], axis=-1)
    mk, mi = m[:, None], m[None, :]
    return np.minimum(mk * np.maximum(mi, d - mk), mi * np.maximum(mk, d - mi))


def most_power_w(config: SystemConfig) -> float:
    """An upper bound on the propulsion power at any speed the UAV may fly (docs/model.md
    section 13): each of its three terms at its largest on ``[0, v_max]``."""
    p, v = config.propulsion, config.v_max
    return (p.blade_profile_w * (1.0 + 3.0 * v * v / p.tip_speed ** 2) + p.induced_w
            + 0.5 * p.fuselage_drag_ratio * p.air_density * p.rotor_solidity * p.rotor_disc_area * v ** 3)


def fewest_slots(config: SystemConfig) -> int:
    """The fewest slots an episode can last: the energy budget cannot be spent sooner."""
    spent_at_most = config.slot_s * most_power_w(config)
    return min(config.horizon, max(1, math.ceil(config.energy_budget_j / spent_at_most)))


def slot_bounds(config: SystemConfig, seeds: NDArray[np.integer]) -> NDArray[np.float64]:
    """``(n, T)``: the bound ``b(t)`` on the sum rate of every slot of the episodes of ``seeds``
    (``reset(seed=s)``, episode 0), whatever the controller does."""
    c = config
    seeds = np.asarray(seeds, dtype=np.int64)
    key = streams.seed_key(seeds)
    kappa = c.rician_factor
    scale = (c.tx_power_w / c.noise_w) * distance_floor(c) ** (-c.pathloss_exponent)  # (K, K)
    out = np.zeros((len(seeds), c.horizon))
    for t in range(c.horizon):
        nlos, pairing = slot_draws(c, streams.slot_key(key, np.zeros_like(key), np.full(len(seeds), t, np.int64)))
        amp = math.sqrt(kappa / (kappa + 1.0)) + math.sqrt(1.0 / (kappa + 1.0)) * np.abs(nlos)  # (n, K, N)
        coherent = np.einsum("bkn,bin->bki", amp, amp)  # sum_n A_k[n] A_i[n]
        out[:, t] = (pairing * np.log2(1.0 + scale * coherent ** 2)).sum(axis=(-2, -1))
    return out


def episode_bounds(config: SystemConfig, seeds: NDArray[np.integer]) -> NDArray[np.float64]:
    """``(n,)``: the largest average sum rate any controller can earn in each episode of ``seeds``
    (the largest mean of :func:`slot_bounds` over the first ``T'`` slots, ``T'`` from
    :func:`fewest_slots` to ``T``)."""
    config.check()
    b = slot_bounds(config, seeds)
    lengths = np.arange(1, config.horizon + 1)
    means = np.cumsum(b, axis=1) / lengths
    return means[:, fewest_slots(config) - 1:].max(axis=1)
