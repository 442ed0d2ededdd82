"""The one lockstep rollout loop: a batch policy on one seeded episode per row.

Lives here: :func:`rollout`, which serves evaluation, the collection of trajectories, the
DT's rollouts, imitation and the report's figures. Not here: what a policy is
(:mod:`uavris.agents.policy` documents the contract this loop relies on) and the
statistics of the results.

Episode j is the one a single environment produces after ``reset(seed=seeds[j])``, so
every policy rolled out on the same seeds sees the same channel and pairing draws. All
rows advance together; a row whose episode has ended keeps stepping (the simulator has
no per-row pause) but nothing it does is counted or recorded.

The contract (duck-typed, so that this layer needs nothing from the agents):

- ``policy(obs) -> actions`` for ``obs`` ``(n, obs_dim)``; a policy with a true
  ``privileged`` attribute is called ``policy(obs, sim)`` instead and may read the
  simulator's state (the references that see more than the observation: the oracle,
  co-phasing);
- a policy with ``begin(n)`` is told that ``n`` episodes start, one with ``seed_episodes(seeds)``
  the seed of each row's episode (a policy's own randomness drawn per episode, so that an
  episode is the same alone or among others), and one with
  ``record(actions, rewards)`` receives its own actions and the slot's rewards after every
  step (the Decision Transformer's return-to-go);
- ``phase_control="optimizer"`` (or a policy's own ``phase_control`` attribute) executes
  the policy's motion with the optimiser's phases (:mod:`uavris.env.wrappers`).

Actions are cast to float32 and clipped to [-1, 1] before the step (what the simulator
does anyway), and recorded as executed: the 6 motion entries under the optimiser.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from uavris.config import Scenario, SystemConfig
from uavris.env.simulator import BatchedSimulator
from uavris.env.wrappers import action_dim_for, check_phase_control, motion_of, optimised_action

SlotHook = Callable[[BatchedSimulator, NDArray[np.float32], NDArray[np.float32], NDArray[np.bool_]], None]
StepHook = Callable[[BatchedSimulator, NDArray[np.float64], NDArray[np.bool_]], None]


@dataclass(frozen=True)
class RolloutBatch:
    """What a rollout produced, one row per episode (arrays of recorded episodes are padded)."""

    seeds: NDArray[np.int64]
    returns: NDArray[np.float64]  # sum of r(t) over the episode's slots
    lengths: NDArray[np.int64]
    energy_used: NDArray[np.float64]
    terminated: NDArray[np.bool_]  # energy budget exhausted (else truncated at the horizon)
    observations: NDArray[np.float32] | None = None  # (n, T + 1, obs_dim) when recorded
    actions: NDArray[np.float32] | None = None  # (n, T, act_dim) as executed
    rewards: NDArray[np.float64] | None = None  # (n, T)


def policy_phase_control(policy: Any, phase_control: str | None = None) -> str:
    """The phase control a rollout uses: ``phase_control`` if given, else the policy's own."""
    mode = phase_control or getattr(policy, "phase_control", "agent")
    check_phase_control(mode)
    return mode


def rollout(policy: Any, config: SystemConfig, scenario: str | Scenario, seeds: Sequence[int] | NDArray[np.integer],
            *, phase_control: str | None = None, record: bool = False, on_slot: SlotHook | None = None,
            on_step: StepHook | None = None) -> RolloutBatch:
    """Roll ``policy`` out on one episode per seed, all in one batched simulator.

    ``on_slot(sim, obs, executed_actions, alive)`` is called before every step, with the
    simulator in the state the actions were chosen in; ``on_step(sim, reward, alive)`` after
    it, with the slot's reward and the rows it counts for.
    """
    seeds = np.asarray(seeds, dtype=np.int64)
    mode = policy_phase_control(policy, phase_control)
    n, horizon = len(seeds), config.horizon
    sim = BatchedSimulator(config, scenario, n)
    sim.seed(seeds)
    sim.reset()
    privileged = bool(getattr(policy, "privileged", False))
    if hasattr(policy, "begin"):
        policy.begin(n)
    if hasattr(policy, "seed_episodes"):
        policy.seed_episodes(seeds)
    returns, energy = np.zeros(n), np.zeros(n)
    lengths = np.zeros(n, dtype=np.int64)
    terminated = np.zeros(n, dtype=bool)
    alive = np.ones(n, dtype=bool)
    if record:
        obs_buf = np.zeros((n, horizon + 1, config.observation_dim), dtype=np.float32)
        act_buf = np.zeros((n, horizon, action_dim_for(config, mode)), dtype=np.float32)
        rew_buf = np.zeros((n, horizon))
    obs = sim.observe()
    t = 0
    while alive.any():
        action = np.clip(np.asarray(policy(obs, sim) if privileged else policy(obs), dtype=np.float32), -1.0, 1.0)
        executed = optimised_action(sim, action) if mode == "optimizer" else action
        if on_slot is not None:
            on_slot(sim, obs, executed, alive)
        if record:
            obs_buf[alive, t] = obs[alive]
            act_buf[alive, t] = (motion_of(executed) if mode == "optimizer" else executed)[alive]
        reward, term, trunc, _ = sim.step(executed)
        if on_step is not None:
            on_step(sim, reward, alive)
        if hasattr(policy, "record"):
            policy.record(action, reward)
        returns += np.where(alive, reward, 0.0)
        lengths += alive
        energy = np.where(alive, sim.energy, energy)
        obs = sim.observe()
        ended = alive & (term | trunc)
        terminated |= ended & term
        if record:
            rew_buf[alive, t] = reward[alive]
            obs_buf[ended, t + 1] = obs[ended]
        alive &= ~ended
        t += 1
    if not record:
        return RolloutBatch(seeds, returns, lengths, energy, terminated)
    return RolloutBatch(seeds, returns, lengths, energy, terminated, obs_buf, act_buf, rew_buf)
