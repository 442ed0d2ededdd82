"""Optimised phases: the learner (or any policy) moves the UAV, the per-slot optimiser sets the phases.

Lives here: the phase controls (``"agent"``: the policy sets every action entry;
``"optimizer"``: the policy sets the 6 motion entries, acceleration and attitude
increments, and :func:`uavris.physics.phase_opt.optimize_slot_phases` the RIS phases
of every slot from its channels, incidence angles and pairing, all of which the agent
observes in S_t) and :func:`optimised_action`, which turns a policy's action into the
one executed. The SB3 adapter (:mod:`uavris.agents.experts.vec_env`) and the rollout
loop (:mod:`uavris.env.rollout`) apply it. Not here: the optimiser's numerics.
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np
from numpy.typing import NDArray

from uavris.config import SystemConfig
from uavris.env.simulator import BatchedSimulator, phases_to_action
from uavris.errors import ActionError, ConfigError
from uavris.physics.phase_opt import optimize_slot_phases

PhaseControl = Literal["agent", "optimizer"]  # who sets the RIS phases (--phase-control)
PHASE_CONTROLS: tuple[str, ...] = get_args(PhaseControl)
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


class PhaseControlled:
    """What an environment executes under a phase control: the action as given (``"agent"``),
    or its 6 motion entries with the optimiser's phases (``"optimizer"``, the hybrid controller),
    checked for its shape and finiteness first, as the simulator checks a full action."""

    def __init__(self, config: SystemConfig, phase_control: str) -> None:
        check_phase_control(phase_control)
        self.phase_control = phase_control
        self.action_dim = action_dim_for(config, phase_control)

    def executed(self, sim: BatchedSimulator, actions: NDArray) -> NDArray:
        if self.phase_control == "agent":
            return actions
        a = np.asarray(actions, dtype=np.float32)
        if a.shape != (sim.num_envs, MOTION_DIM):
            raise ActionError(f"the hybrid controller takes {MOTION_DIM} motion entries per environment "
                              f"(acceleration, attitude increments), got shape {a.shape[1:]}")
        if not np.all(np.isfinite(a)):
            raise ActionError("actions must be finite numbers in [-1, 1]; got NaN or inf")
        return optimised_action(sim, np.clip(a, -1.0, 1.0))


def optimised_action(sim: BatchedSimulator, action: NDArray) -> NDArray[np.float32]:
    """Full actions ``(n, action_dim)``: the motion of ``action`` (6 motion entries, or a full
    action whose own phases are dropped) with the optimiser's phases for the current slot."""
    c: SystemConfig = sim.config
    a = np.asarray(action, dtype=np.float32).reshape(sim.num_envs, -1)
    if a.shape[1] not in (MOTION_DIM, c.action_dim):
        raise ConfigError(f"actions must have {MOTION_DIM} (motion) or {c.action_dim} entries, got {a.shape[1]}")
    if c.learn_amplitudes:
        raise ConfigError("phase control 'optimizer' sets unit-amplitude phases; use learn_amplitudes=False")
    motion = a if a.shape[1] == MOTION_DIM else motion_of(a)
    sol = optimize_slot_phases(c, sim.channels, sim.cos_theta, sim.pairing)
    out = np.zeros((sim.num_envs, c.action_dim), dtype=np.float32)
    out[:, :3] = motion[:, :3]
    out[:, -3:] = motion[:, 3:]
    out[:, 3:3 + c.num_elements] = phases_to_action(sol.phases).astype(np.float32)
    return out
