"""Simple reference policies, evaluated exactly like the learned ones.

A policy here is a callable ``policy(obs, sim) -> actions`` on a batch: ``obs`` is
``(n, obs_dim)`` and ``sim`` the :class:`~uavris.env.simulator.BatchedSimulator` whose state
the observation describes (baselines that co-phase the RIS read the channels from it;
everything they read is also in the observation).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from uavris import physics as ph
from uavris.env.simulator import BatchedSimulator

BatchPolicy = Callable[[NDArray[np.float32], BatchedSimulator], NDArray[np.float32]]


def phases_to_action(phase: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverse of the action's phase map [-1, 1] -> [0, 2 pi)."""
    return np.mod(phase, 2 * np.pi) / np.pi - 1.0


def hover() -> BatchPolicy:
    """The zero action: the UAV hovers at its start, level, with all N phases equal (the
    phase action 0 maps to pi). "Doing nothing": every learned policy is read against it."""

    def act(obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        return np.zeros((obs.shape[0], sim.config.action_dim), dtype=np.float32)

    return act


def random_policy(seed: int) -> BatchPolicy:
    """Uniform random actions in [-1, 1]."""
    rng = np.random.default_rng(seed)

    def act(obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        return rng.uniform(-1.0, 1.0, (obs.shape[0], sim.config.action_dim)).astype(np.float32)

    return act


def hover_random_phases(seed: int) -> BatchPolicy:
    """Hover at the start (zero acceleration, attitude kept level) with random phases each slot."""
    rng = np.random.default_rng(seed)

    def act(obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        c = sim.config
        a = np.zeros((obs.shape[0], c.action_dim), dtype=np.float32)
        a[:, 3:3 + c.num_elements] = rng.uniform(-1.0, 1.0, (obs.shape[0], c.num_elements))
        return a

    return act


def co_phasing_presets(sim: BatchedSimulator, tx: NDArray[np.intp], rx: NDArray[np.intp]) -> NDArray[np.complex128]:
    """Unit-modulus presets r_pre that co-phase every element for the link tx -> rx (per env).

    The practical coefficient r_n(theta_tx) must equal exp(-j arg(h_tx[n] h_rx[n])); the
    preset is found by inverting the angle-dependent reflection model.
    """
    rows = np.arange(sim.num_envs)
    h_tx, h_rx = sim.channels[rows, tx], sim.channels[rows, rx]
    target = np.exp(-1j * np.angle(h_tx * h_rx))
    if not sim.config.angle_dependent_reflection:
        return target
    cos_tx = np.clip(sim.cos_theta[rows, tx], 1e-6, 1.0)[:, None]
    return ph.preset_for_target(target, cos_tx)


def strongest_active_link(sim: BatchedSimulator) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Per env, the active link with the largest co-phased gain sum_n |h_tx[n]| |h_rx[n]|."""
    amp = np.abs(sim.channels)  # (n, K, N)
    coherent = np.einsum("bkn,bin->bki", amp, amp)
    score = np.where(sim.pairing > 0, coherent, -1.0).reshape(sim.num_envs, -1)
    best = np.argmax(score, axis=1)
    k = sim.config.num_users
    return best // k, best % k


def hover_aligned() -> BatchPolicy:
    """Hover at the start, phases co-phased for the strongest active pair of each slot."""

    def act(obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        c = sim.config
        tx, rx = strongest_active_link(sim)
        a = np.zeros((obs.shape[0], c.action_dim), dtype=np.float32)
        a[:, 3:3 + c.num_elements] = phases_to_action(np.angle(co_phasing_presets(sim, tx, rx)))
        return a

    return act


BASELINES: dict[str, Callable[[int], BatchPolicy]] = {
    "hover": lambda seed: hover(),
    "random": random_policy,
    "hover-random-phases": hover_random_phases,
    "hover-aligned": lambda seed: hover_aligned(),
}
