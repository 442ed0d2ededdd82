"""Natively batched ``gymnasium.vector.VectorEnv`` of the UAV-RIS system.

Same dynamics as :class:`uavris.env.single.UavRisD2DEnv` on arrays of shape
``(num_envs, ...)``, with one numpy call per quantity per step. ``reset(seed=s)`` seeds
environment i with ``s + i`` (Gymnasium's convention), so environment i reproduces a
single environment reset with seed ``s + i`` and driven with the same actions, across
auto-resets too.

Lives here: :class:`UavRisD2DVectorEnv`. Not here: the dynamics (:mod:`.simulator`), the
Stable-Baselines3 ``VecEnv`` over the same simulator (:mod:`uavris.agents.experts.vec_env`)
and :func:`uavris.env.make_vector_env` (:mod:`uavris.env`).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from uavris.config import Scenario, SystemConfig
from uavris.env.simulator import BatchedSimulator, SlotInfo, observation_bounds, step_info
from uavris.env.wrappers import PhaseControl, PhaseControlled


class UavRisD2DVectorEnv(VectorEnv):
    """``num_envs`` UAV-RIS systems stepped together.

    Args:
        num_envs: number of environments.
        config, scenario, phase_control: as for :class:`uavris.env.single.UavRisD2DEnv`.
        autoreset_mode: ``"NextStep"`` (Gymnasium's default: the step after an episode
            ends returns the reset observation with reward 0) or ``"SameStep"`` (the
            reset happens in the ending step; the last observation is in
            ``info["final_obs"]``).
    """

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, config: SystemConfig | None = None, scenario: str | Scenario = "fig2",
                 autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
                 phase_control: PhaseControl = "agent") -> None:
        self.config = config if config is not None else SystemConfig()
        self.sim = BatchedSimulator(self.config, scenario, num_envs)
        self.scenario = self.sim.scenario
        self.controls = PhaseControlled(self.config, phase_control)
        self.num_envs = num_envs
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        if self.autoreset_mode == AutoresetMode.DISABLED:
            raise ValueError("autoreset_mode must be NextStep or SameStep")
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        low, high = observation_bounds(self.config)
        self.single_observation_space = gym.spaces.Box(low, high, dtype=np.float32)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (self.controls.action_dim,), dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._needs_reset = np.zeros(num_envs, dtype=bool)
        self._seeded = False

    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        n = self.num_envs
        if seed is None and self._seeded:
            self.sim.reset(next_episode=True)
        else:
            if seed is None:
                seeds = self.np_random.integers(0, 2**63, size=n)
            elif isinstance(seed, (int, np.integer)):
                seeds = int(seed) + np.arange(n)
            else:
                if len(seed) != n:
                    raise ValueError(f"expected {n} seeds, got {len(seed)}")
                seeds = np.asarray(seed)
            self.sim.seed(seeds)
            self.sim.reset()
        self._seeded = True
        self._needs_reset[:] = False
        return self.sim.observe(), self._info(None)

    def step(self, actions: NDArray):
        if not self._seeded:
            raise RuntimeError("call reset() before step()")
        sim = self.sim
        pending = np.flatnonzero(self._needs_reset)
        executed = self.controls.executed(sim, np.asarray(actions).reshape(self.num_envs, -1))
        reward, terminated, truncated, slot = sim.step(executed)
        infos: dict[str, Any] = {}
        if pending.size:
            # Next-step autoreset: these environments ignore this action and start anew.
            sim.reset(pending, next_episode=True)
            reward[pending] = 0.0
            terminated[pending] = False
            truncated[pending] = False
        done = terminated | truncated
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            ended = np.flatnonzero(done)
            if ended.size:
                final = sim.observe()
                mask = done.copy()
                infos["final_obs"] = np.where(mask[:, None], final, 0.0)
                infos["_final_obs"] = mask
                sim.reset(ended, next_episode=True)
        else:
            self._needs_reset = done
        infos.update(self._info(slot))
        return sim.observe(), reward, terminated, truncated, infos

    def _info(self, slot: SlotInfo | None) -> dict[str, Any]:
        out: dict[str, Any] = step_info(self.sim, slot)
        mask = np.ones(self.num_envs, dtype=bool)
        for key in list(out):
            out["_" + key] = mask
        return out
