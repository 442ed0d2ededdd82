"""Hybrid control: the RL agent steers the UAV, the per-slot optimiser sets the phases.

The agent's action shrinks to the 6 motion entries (acceleration and attitude
increments, the first and last three of the full action); every slot the RIS phases are
those of :func:`uavris.agents.phase_optimizer.optimize_slot_phases` for the slot's
channels, incidence angles and pairing, all of which the agent observes in S_t.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from uavris.agents.baselines import BatchPolicy, phases_to_action
from uavris.agents.phase_optimizer import optimize_slot_phases
from uavris.config import ConfigError, SystemConfig
from uavris.env.simulator import BatchedSimulator

PHASE_CONTROLS: tuple[str, ...] = ("agent", "optimizer")
MOTION_DIM = 6


def check_phase_control(mode: str) -> None:
    if mode not in PHASE_CONTROLS:
        raise ConfigError(f"unknown phase control {mode!r}; choose one of {', '.join(PHASE_CONTROLS)}")


def action_dim_for(config: SystemConfig, phase_control: str) -> int:
    """Entries of the learner's action: all of them, or the 6 motion entries under the optimiser."""
    check_phase_control(phase_control)
    return MOTION_DIM if phase_control == "optimizer" else config.action_dim


def motion_of(action: NDArray) -> NDArray[np.float32]:
    """The 6 motion entries (acceleration, attitude increments) of full actions ``(n, action_dim)``."""
    a = np.asarray(action)
    return np.concatenate([a[..., :3], a[..., -3:]], axis=-1).astype(np.float32)


def optimised_phase_actions(sim: BatchedSimulator) -> NDArray[np.float32]:
    """The phase part of the action ``(n, N)`` in [-1, 1] that realises the optimiser's phases."""
    sol = optimize_slot_phases(sim.config, sim.channels, sim.cos_theta, sim.pairing)
    return phases_to_action(sol.phases).astype(np.float32)


def full_action(sim: BatchedSimulator, motion: NDArray) -> NDArray[np.float32]:
    """Full actions ``(n, action_dim)`` from motion actions ``(n, 6)`` plus optimised phases."""
    c: SystemConfig = sim.config
    m = np.asarray(motion, dtype=np.float32).reshape(sim.num_envs, -1)
    if m.shape[1] != MOTION_DIM:
        raise ValueError(f"motion actions must have {MOTION_DIM} entries (acceleration, attitude), got {m.shape[1]}")
    if c.learn_amplitudes:
        raise ConfigError("phase control 'optimizer' sets unit-amplitude phases; use learn_amplitudes=False")
    out = np.zeros((sim.num_envs, c.action_dim), dtype=np.float32)
    out[:, :3] = m[:, :3]
    out[:, -3:] = m[:, 3:]
    out[:, 3:3 + c.num_elements] = optimised_phase_actions(sim)
    return out


def with_optimised_phases(policy: BatchPolicy) -> BatchPolicy:
    """Wrap a policy so the optimiser sets the phases: a 6-entry (motion) policy is expanded,
    a full-action policy keeps its motion and loses its own phases."""

    def act(obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        a = np.asarray(policy(obs, sim))
        return full_action(sim, a if a.shape[-1] == MOTION_DIM else motion_of(a))

    return act
