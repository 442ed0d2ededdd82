"""Stable-Baselines3 ``VecEnv`` over the batched simulator.

Lives here: :class:`UavRisVecEnv`, with the learner's ``reward_scale`` and the
``phase_control`` of :mod:`uavris.env.wrappers`. Not here: the dynamics
(:class:`uavris.env.simulator.BatchedSimulator`) and Gymnasium's vector environment
(:mod:`uavris.env.vector`).

One numpy call per quantity serves all parallel environments, where SB3's
``DummyVecEnv`` would loop over Python environments. Semantics are DummyVecEnv's:
same-step auto-reset with the last observation in ``info["terminal_observation"]``,
``info["TimeLimit.truncated"]``, and ``seed(s)`` seeding environment i with ``s + i``
at the next ``reset()``; so the two agree observation for observation.
"""

from __future__ import annotations

from typing import Any, Sequence

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

from uavris.config import Scenario, SystemConfig
from uavris.env.simulator import BatchedSimulator, observation_bounds
from uavris.env.wrappers import action_dim_for, check_phase_control, optimised_action


def expert_spaces(config: SystemConfig, phase_control: str) -> tuple[gym.spaces.Box, gym.spaces.Box]:
    """The observation and action spaces an expert of ``config`` acts in."""
    low, high = observation_bounds(config)
    return (gym.spaces.Box(low, high, dtype=np.float32),
            gym.spaces.Box(-1.0, 1.0, (action_dim_for(config, phase_control),), dtype=np.float32))


class UavRisVecEnv(VecEnv):
    """``num_envs`` UAV-RIS systems as an SB3 VecEnv.

    Args:
        num_envs: number of parallel environments.
        config: the system; defaults to the paper's.
        scenario: scenario name, :class:`Scenario` or start position.
        reward_scale: multiplies the reward handed to the learner (the sum rate in bps/Hz
            times this). Episode statistics in ``info["episode"]`` stay in bps/Hz.
        phase_control: ``"agent"`` (the learner sets all 22 action entries) or
            ``"optimizer"`` (hybrid: the learner sets the 6 motion entries and the per-slot
            phase optimiser the RIS phases, :mod:`uavris.env.wrappers`).
    """

    def __init__(self, num_envs: int, config: SystemConfig | None = None, scenario: str | Scenario = "fig2",
                 reward_scale: float = 1.0, phase_control: str = "agent") -> None:
        check_phase_control(phase_control)
        self.config = config if config is not None else SystemConfig()
        self.sim = BatchedSimulator(self.config, scenario, num_envs)
        self.phase_control = phase_control
        super().__init__(num_envs, *expert_spaces(self.config, phase_control))
        self.reward_scale = float(reward_scale)
        self._actions: np.ndarray | None = None
        self._seeded = False
        self._ep_return = np.zeros(num_envs)
        self._ep_len = np.zeros(num_envs, dtype=np.int64)

    # ------------------------------------------------------------------ VecEnv API
    def reset(self) -> np.ndarray:
        seeds = self._seeds
        if all(s is None for s in seeds):
            if self._seeded:
                self.sim.reset(next_episode=True)
            else:
                self.sim.seed(np.random.SeedSequence().generate_state(self.num_envs, dtype=np.uint64) >> np.uint64(1))
                self.sim.reset()
        else:
            rows = np.array([i for i, s in enumerate(seeds) if s is not None])
            others = np.array([i for i, s in enumerate(seeds) if s is None], dtype=np.intp)
            self.sim.seed(np.array([seeds[i] for i in rows]), rows)
            self.sim.reset(rows)
            if others.size:
                self.sim.reset(others, next_episode=self._seeded)
        self._seeded = True
        self._reset_seeds()
        self._reset_options()
        self._ep_return[:] = 0.0
        self._ep_len[:] = 0
        return self.sim.observe()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        if not self._seeded:
            raise RuntimeError("call reset() before step()")
        actions = self._actions.reshape(self.num_envs, -1)
        if self.phase_control == "optimizer":
            actions = optimised_action(self.sim, actions)
        reward, terminated, truncated, _ = self.sim.step(actions)
        done = terminated | truncated
        self._ep_return += reward
        self._ep_len += 1
        obs = self.sim.observe()
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        ended = np.flatnonzero(done)
        if ended.size:
            for i in ended:
                infos[i]["terminal_observation"] = obs[i].copy()
                infos[i]["TimeLimit.truncated"] = bool(truncated[i])
                infos[i]["episode"] = {"r": float(self._ep_return[i]), "l": int(self._ep_len[i]),
                                       "avg_sum_rate": float(self._ep_return[i] / self._ep_len[i])}
            self.sim.reset(ended, next_episode=True)
            self._ep_return[ended] = 0.0
            self._ep_len[ended] = 0
            obs[ended] = self.sim.observe()[ended]
        return obs, (reward * self.reward_scale).astype(np.float32), done, infos

    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        value = getattr(self, attr_name, None) if attr_name != "render_mode" else None
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        raise NotImplementedError(f"UavRisVecEnv has no per-environment method {method_name!r}")

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    # ------------------------------------------------------------------ checkpointing
    _STATE_FIELDS = ("sim", "_seeded", "_seeds", "_options", "_ep_return", "_ep_len")

    def get_state(self) -> dict[str, Any]:
        """Everything that evolves while stepping (the systems mid-episode, pending seeds,
        episode statistics), for an exact resume; :meth:`set_state` puts it back."""
        return {name: getattr(self, name) for name in self._STATE_FIELDS}

    def set_state(self, state: dict[str, Any]) -> None:
        if set(state) != set(self._STATE_FIELDS):
            raise ValueError(f"UavRisVecEnv state must hold {sorted(self._STATE_FIELDS)}, got {sorted(state)}")
        for name, value in state.items():
            setattr(self, name, value)

    def _get_indices(self, indices: VecEnvIndices) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return indices
