"""Simple reference policies, evaluated exactly like the learned ones.

Lives here: doing nothing (:func:`hover`, the zero action), random actions, hovering with
random phases, and hovering co-phased for the strongest pair (a privileged reference: it
reads the simulator's channels). Not here: the oracle (:mod:`uavris.agents.oracle`), the
registry of all references by name (:mod:`uavris.agents.references`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from uavris import physics as ph
from uavris.agents.policy import Constant, Privileged
from uavris.config import SystemConfig
from uavris.env.simulator import BatchedSimulator, phases_to_action


def hover(config: SystemConfig) -> Constant:
    """The zero action: the UAV hovers at its start, level, with all N phases equal (the
    phase action 0 maps to pi). "Doing nothing": every learned policy is read against it."""
    return Constant(np.zeros(config.action_dim, dtype=np.float32))


class RandomActions:
    """Uniform random actions in [-1, 1] (all entries, or only the phases with ``phases_only``).

    In a rollout each episode draws from a stream of its own, made from ``seed`` and the
    episode's seed (:meth:`seed_episodes`), so an episode is the same alone or in a batch;
    called outside one, the rows share one stream of ``seed``."""

    def __init__(self, config: SystemConfig, seed: int, phases_only: bool = False) -> None:
        self.config, self.phases_only, self.seed = config, phases_only, seed
        self.rng = np.random.default_rng(seed)
        self.streams: list[np.random.Generator] | None = None

    def seed_episodes(self, seeds: NDArray[np.integer]) -> None:
        self.streams = [np.random.default_rng([self.seed, int(s)]) for s in seeds]

    def _uniform(self, n: int, width: int) -> NDArray[np.float64]:
        if self.streams is None or len(self.streams) != n:
            return self.rng.uniform(-1.0, 1.0, (n, width))
        return np.stack([g.uniform(-1.0, 1.0, width) for g in self.streams])

    def __call__(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        c, n = self.config, obs.shape[0]
        if not self.phases_only:
            return self._uniform(n, c.action_dim).astype(np.float32)
        a = np.zeros((n, c.action_dim), dtype=np.float32)
        a[:, 3:3 + c.num_elements] = self._uniform(n, c.num_elements)
        return a


def random_policy(config: SystemConfig, seed: int) -> RandomActions:
    """Uniform random actions in [-1, 1]."""
    return RandomActions(config, seed)


def hover_random_phases(config: SystemConfig, seed: int) -> RandomActions:
    """Hover at the start (zero acceleration, attitude kept level) with random phases each slot."""
    return RandomActions(config, seed, phases_only=True)


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


def _hover_aligned(obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
    c = sim.config
    tx, rx = strongest_active_link(sim)
    a = np.zeros((obs.shape[0], c.action_dim), dtype=np.float32)
    a[:, 3:3 + c.num_elements] = phases_to_action(np.angle(co_phasing_presets(sim, tx, rx)))
    return a


def hover_aligned() -> Privileged:
    """Hover at the start, phases co-phased for the strongest active pair of each slot (privileged)."""
    return Privileged(_hover_aligned)
