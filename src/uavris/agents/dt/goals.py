"""Goals for a goal-conditioned Decision Transformer: where it is told to go, and as what it reads it.

Lives here: :func:`goal_offsets` (the goal as the controller reads it at every slot: its
offset from the UAV in the frame of the devices' offsets) and the sources of an episode's
goal (:class:`FixedGoals`, :class:`PlannedGoals`), which a
:class:`~uavris.agents.dt.policy.DTBatchPolicy` asks at each episode's first slot. Not here:
the planners that choose a goal (:mod:`uavris.agents.oracle.planner`,
:mod:`uavris.agents.place.planner`), the model that reads it (:mod:`.model`).

Why a goal (docs/places.md): return conditioning on expert data collapses to behaviour cloning
(measured: the DT and BC tie); what is left of the gap to the oracle in a new hall is the
place, so the controller is told the place and learns to fly there (each demonstration's
own plan target is its goal), and the place is chosen by a planner.
"""

from __future__ import annotations

from typing import Any, Callable, Protocol

import numpy as np
from numpy.typing import NDArray

from uavris.config import SystemConfig
from uavris.env.simulator import device_scale, devices_seen, uav_position

GOAL_DIM = 3


def goal_offsets(observations: NDArray, goals: NDArray, config: SystemConfig) -> NDArray[np.float32]:
    """``(goal - UAV position) / device scale``, ``(..., 3)``, for observations ``(..., D)`` of
    ``config`` and goals ``(..., 3)`` (m): the goal as the UAV sees it, in the units of the
    devices' offsets in the observation (:func:`uavris.env.simulator.device_observation`)."""
    pos = uav_position(observations, config)
    return ((np.asarray(goals, dtype=np.float64) - pos) / device_scale(config)).astype(np.float32)


class GoalSource(Protocol):
    def __call__(self, config: SystemConfig, starts: NDArray, devices: NDArray) -> NDArray[np.float64]:
        """The goals ``(n, 3)`` (m) of ``n`` episodes starting at ``starts`` ``(n, 3)`` among
        ``devices`` ``(n, K, 3)`` (both as the first observation holds them)."""


class FixedGoals:
    """The same goal for every episode, or one per row (fine-tuning's places)."""

    def __init__(self, goals: NDArray | tuple[float, float, float]) -> None:
        self.goals = np.asarray(goals, dtype=np.float64)

    def __call__(self, config: SystemConfig, starts: NDArray, devices: NDArray) -> NDArray[np.float64]:
        return np.broadcast_to(self.goals, starts.shape).copy()


class PlannedGoals:
    """Each episode's goal from a planner, ``plan(config, start) -> target`` (m), made once per
    hall and start (the first observation's, rounded to a millimetre) and cached. The hall is
    the devices the observation holds (the system's own where they are those, to the
    observation's float precision)."""

    def __init__(self, plan: Callable[[SystemConfig, tuple[float, float, float]], NDArray], label: str = "") -> None:
        self.plan, self.label = plan, label
        self._cache: dict[Any, NDArray[np.float64]] = {}

    def __call__(self, config: SystemConfig, starts: NDArray, devices: NDArray) -> NDArray[np.float64]:
        out = np.empty((len(starts), 3))
        for i, (start, users) in enumerate(zip(np.round(starts, 3), np.round(devices, 3))):
            key = (start.tobytes(), users.tobytes())
            if key not in self._cache:
                own = np.allclose(users, np.asarray(config.users), atol=0.01)
                hall = config if own else config.replace(users=tuple(tuple(float(c) for c in u) for u in users))
                self._cache[key] = np.asarray(self.plan(hall, tuple(float(c) for c in start)), dtype=np.float64)
            out[i] = self._cache[key]
        return out


def first_goals(source: GoalSource, observations: NDArray, config: SystemConfig) -> NDArray[np.float64]:
    """The goals a source gives episodes whose first observations are ``observations``."""
    return source(config, uav_position(observations, config), devices_seen(observations, config))
