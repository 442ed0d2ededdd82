"""Gymnasium environment ``uavris/UavRisD2D-v0`` (one UAV-RIS system).

Lives here: :class:`UavRisD2DEnv`, a one-row :class:`uavris.env.simulator.BatchedSimulator`
behind Gymnasium's ``reset`` and ``step`` (spaces, reward, termination: its docstring). Not
here: the dynamics (:mod:`.simulator`), the batched environment (:mod:`.vector`) and the
registration with :func:`uavris.env.make_env` (:mod:`uavris.env`).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from uavris.config import Scenario, SystemConfig
from uavris.env.simulator import BatchedSimulator, observation_bounds, step_info

_SCALARS = {"energy_used": float, "energy_remaining": float, "slot": int, "sum_rate": float, "slot_energy": float}


def _row(info: dict[str, NDArray], i: int = 0) -> dict[str, Any]:
    """Row ``i`` of a batched ``info`` (:func:`uavris.env.simulator.step_info`), scalars as Python numbers."""
    return {k: _SCALARS[k](v[i]) if k in _SCALARS else v[i] for k, v in info.items()}


class UavRisD2DEnv(gym.Env[NDArray[np.float32], NDArray[np.float32]]):
    """UAV-mounted RIS serving randomly activated D2D pairs (paper Sec. II-IV).

    Args:
        config: the system (:class:`uavris.config.SystemConfig`); defaults to the paper's.
        scenario: a scenario name (``"fig2"``, ``"train1"``..``"train8"``, ``"unseen1"``,
            ``"unseen2"``), a :class:`Scenario`, or a start position ``[x, y, z]``.

    Action: ``Box(-1, 1, (22,), float32)`` = acceleration (x a_max), 16 RIS phases
    (mapped to [0, 2 pi]; 0 and 2 pi are the same phasor), attitude increments (x the per-slot
    bound). Out-of-range values are clipped; NaN or inf raise ``ValueError``.
    Observation: ``Box((158,), float32)``, every component of order 1, see
    :func:`uavris.env.simulator.observation_layout`.
    Reward: the sum rate r(t) of the active pairs in bps/Hz.
    The episode terminates when the propulsion energy reaches ``energy_budget_j`` and is
    truncated after ``horizon`` slots.
    """

    metadata = {"render_modes": []}

    def __init__(self, config: SystemConfig | None = None, scenario: str | Scenario = "fig2") -> None:
        self.config = config if config is not None else SystemConfig()
        self.sim = BatchedSimulator(self.config, scenario, 1)
        self.scenario = self.sim.scenario
        low, high = observation_bounds(self.config)
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.config.action_dim,), dtype=np.float32)
        self._seeded = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        if seed is not None:
            self.sim.seed(np.array([seed]))
            self.sim.reset()
        elif not self._seeded:
            # Unseeded: draw the key from Gymnasium's entropy-seeded generator.
            self.sim.seed(self.np_random.integers(0, 2**63, size=1))
            self.sim.reset()
        else:
            self.sim.reset(next_episode=True)
        self._seeded = True
        return self.sim.observe()[0], _row(step_info(self.sim, None))

    def step(self, action: NDArray):
        if not self._seeded:
            raise RuntimeError("call reset() before step()")
        reward, terminated, truncated, info = self.sim.step(np.asarray(action).reshape(1, -1))
        return (self.sim.observe()[0], float(reward[0]), bool(terminated[0]), bool(truncated[0]),
                _row(step_info(self.sim, info)))
