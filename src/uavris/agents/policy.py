"""The policy interface: observations in, actions out; and the explicit interface of the references
that see more than the observation.

Lives here: the protocols every policy of uavris follows, as the rollout loop
(:func:`uavris.env.rollout.rollout`) uses them, and :class:`Privileged`, the marker of a
reference that reads the simulator's state. Not here: any policy (baselines, experts,
the Decision Transformer and the oracle each live with their family) and loading a user's
policy by name (:mod:`uavris.experiments.tools.user_policy`).

The contract (README, "Your own controller"):

- Batched. ``policy(obs) -> actions``: ``obs`` is ``(n, obs_dim)`` float32, one row per
  running episode (``n`` can be 1 or hundreds; every row is its own episode), and the answer
  is ``(n, act_dim)`` finite numbers; values outside [-1, 1] are clipped.
- Observation: ``obs_dim`` is 158 at the defaults; its named slices are
  :func:`uavris.env.observation_layout` (``position``, ``velocity``, ``attitude_sin``,
  ``attitude_cos``, ``channel_real``, ``channel_imag``, ``pairing``, ``energy_remaining``,
  ``time_fraction``, and ``devices`` with ``SystemConfig(observe_devices=True)``); scaling:
  docs/model.md, section 15.
- Two action layouts. ``act_dim`` 22 (``phase_control="agent"``, the default): acceleration
  (3, times ``a_max``), the 16 RIS phases (-1..1 maps to 0..2 pi), yaw/pitch/roll increments
  (3, times ``attitude_step_deg``). ``act_dim`` 6 (a ``phase_control = "optimizer"``
  attribute on the policy, or ``--phase-control optimizer``): acceleration and attitude
  only; the per-slot optimiser sets the phases every slot (a 22-entry answer then has its
  phases replaced).
- :class:`Policy`: ``policy(obs) -> actions`` and nothing else (a function or an object).
- :class:`EpisodicPolicy`: a policy with a memory of its episodes (the Decision
  Transformer): ``begin(n)`` when a batch of ``n`` episodes starts (slot 0 for every row),
  ``record(actions, rewards)`` after every step (the actions as executed, clipped; the
  slot's sum rates).
- :class:`PrivilegedPolicy`: a reference that reads the simulator's state (this slot's
  channels, incidence and pairing, the pose, the scenario), e.g. the oracle; it is called
  ``policy(obs, sim)``. Everything a learned policy may use is in ``obs``.
- ``observation_dim`` (optional attribute): the observation size the policy was made for;
  evaluating it in a system that gives another size is one :class:`ConfigError` line.
- ``for_system(system)`` (optional method): the policy made to read ``system``'s
  observations, if it can (a Decision Transformer with the device-set encoder reads any
  number of devices); :func:`fit_policy` calls it before the size check.
"""

from __future__ import annotations

from typing import Callable, ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from uavris.config import SystemConfig
from uavris.env.simulator import BatchedSimulator
from uavris.errors import ConfigError


@runtime_checkable
class Policy(Protocol):
    def __call__(self, obs: NDArray[np.float32]) -> NDArray[np.float32]: ...


@runtime_checkable
class EpisodicPolicy(Protocol):
    def __call__(self, obs: NDArray[np.float32]) -> NDArray[np.float32]: ...

    def begin(self, n: int) -> None:
        """``n`` episodes start (slot 0 for every row)."""

    def record(self, actions: NDArray[np.float32], rewards: NDArray[np.float64]) -> None:
        """The actions just taken (as returned, clipped to [-1, 1]) and the slot's rewards r(t)."""


@runtime_checkable
class PrivilegedPolicy(Protocol):
    privileged: ClassVar[bool]

    def __call__(self, obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]: ...


class Privileged:
    """A function ``fn(obs, sim) -> actions`` marked as a privileged reference."""

    privileged: ClassVar[bool] = True

    def __init__(self, fn: Callable[[NDArray[np.float32], BatchedSimulator], NDArray[np.float32]]) -> None:
        self.fn = fn

    def __call__(self, obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        return self.fn(obs, sim)


class Constant:
    """The same action in every row and slot (the zero action: doing nothing)."""

    def __init__(self, action: NDArray[np.float32], phase_control: str = "agent") -> None:
        self.action = np.asarray(action, dtype=np.float32)
        self.phase_control = phase_control

    def __call__(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        return np.broadcast_to(self.action, (obs.shape[0], self.action.size)).copy()

class LevelAttitude:
    """Another policy with its attitude increments replaced by zero: the UAV keeps the attitude it
    starts with (level), whatever the policy turns. An episodic policy still reads its own
    actions in its memory (the Decision Transformer's context keeps what it chose, not what
    was executed), so this changes what happens, not what the policy thinks it did."""

    def __init__(self, policy: object) -> None:
        self.policy = policy
        for name in ("phase_control", "observation_dim"):
            if hasattr(policy, name):
                setattr(self, name, getattr(policy, name))
        self._chosen: NDArray[np.float32] | None = None

    def begin(self, n: int) -> None:
        if callable(getattr(self.policy, "begin", None)):
            self.policy.begin(n)  # type: ignore[attr-defined]

    def __call__(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        self._chosen = np.asarray(self.policy(obs), dtype=np.float32)  # type: ignore[operator]
        level = self._chosen.copy()
        level[:, -3:] = 0.0  # yaw, pitch and roll increments: the last three entries in both layouts
        return level

    def record(self, actions: NDArray[np.float32], rewards: NDArray[np.float64]) -> None:
        if callable(getattr(self.policy, "record", None)):
            self.policy.record(np.clip(self._chosen, -1.0, 1.0), rewards)  # type: ignore[attr-defined]

    def for_system(self, system: SystemConfig) -> LevelAttitude:
        """The wrapped policy in ``system`` (its own ``for_system``), still held level."""
        inner = _for_system(self.policy, system)
        return self if inner is self.policy else LevelAttitude(inner)


def check_policy_fits(policy: object, system: SystemConfig, what: str = "the policy") -> None:
    """A policy that declares the observation size it was trained on (``observation_dim``: the
    experts and the Decision Transformer) must get that size from ``system``; another number
    of devices, or device positions observed or not, is one :class:`ConfigError` line."""
    want = getattr(policy, "observation_dim", None)
    if want is not None and want != system.observation_dim:
        seen = " with device positions" if system.observe_devices else ""
        raise ConfigError(f"{what} reads observations of {want} entries, but this system ({system.num_users} devices"
                          f"{seen}) gives {system.observation_dim}: it was trained for another number of devices "
                          "or observation")


def fit_policy(policy: object, system: SystemConfig, what: str = "the policy") -> object:
    """``policy`` made to read ``system``'s observations where it can (``for_system``: a
    Decision Transformer with the device-set encoder in a hall of another number of
    devices), then checked (:func:`check_policy_fits`)."""
    policy = _for_system(policy, system)
    check_policy_fits(policy, system, what)
    return policy


def _for_system(policy: object, system: SystemConfig) -> object:
    adapt = getattr(policy, "for_system", None)
    return adapt(system) if callable(adapt) else policy
