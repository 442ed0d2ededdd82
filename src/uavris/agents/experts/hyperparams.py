"""Hyperparameters of the DRL experts (DDPG, PPO, SAC, TD3): their values and their reasons, in one place.

Lives here: :class:`Hyperparams` (each field's default and why), what an algorithm and a preset
change from those defaults (:data:`ALGORITHM_CHANGES`, :data:`PRESET_CHANGES`, with their
reasons), the algorithms' names (:data:`ALGORITHMS`, :data:`OFF_POLICY`,
:func:`check_algorithm`), which hyperparameters each uses (:func:`hyperparams_for`) and a
preset's values (:func:`default_hyperparams`). Not here: the presets' budgets
(:mod:`uavris.presets`) and building and running the SB3 models (:mod:`.sb3`).

The paper gives no hyperparameters. The defaults below are the ``paper`` preset's for DDPG and
TD3; ``uavris train --algo ALGO --preset PRESET --help`` shows any algorithm's and preset's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Literal, get_args

from uavris.config import DictConfig
from uavris.errors import ConfigError
from uavris.presets import check_preset

Algorithm = Literal["ddpg", "ppo", "sac", "td3"]  # what --algo accepts (tyro lists and checks them)
ALGORITHMS: tuple[str, ...] = get_args(Algorithm)
OFF_POLICY: tuple[str, ...] = ("ddpg", "sac", "td3")


@dataclass(frozen=True)
class Hyperparams(DictConfig):
    """Hyperparameters of one algorithm (fields not used by an algorithm are ignored)."""

    # Each default's reason above it: the paper preset's values for DDPG and TD3.
    # 256 units: the common continuous-control size.
    net_arch: tuple[int, ...] = (256, 256)
    """hidden units per layer, actor and critic alike"""
    # DDPG's and TD3's usual.
    learning_rate: float = 1e-3
    """Adam's step size"""
    # A slot's reward depends on that slot's phases and pose, and moving pays off within 10-20 slots
    # (5-10 s at up to 5 m/s): a 20-slot effective horizon suffices and keeps Q-values small.
    gamma: float = 0.95
    """discount factor"""
    # Sum rates are 5-40 bps/Hz per slot: scaled, the critic's targets stay of order 10.
    reward_scale: float = 0.1
    """reward = reward_scale x the slot's sum rate"""
    n_envs: int = 8
    """parallel systems stepped as one vector"""
    batch_size: int = 256
    """samples per gradient step"""
    # off-policy
    buffer_size: int = 1_000_000
    """replay buffer size (transitions)"""
    learning_starts: int = 2_000
    """env steps of random actions before the first update"""
    tau: float = 0.005
    """soft-update rate of the target networks"""
    # n_envs, so one gradient step per env step: at one per 4 env steps DDPG did not improve in 16,000 steps
    # (average sum rate 2-8 bps/Hz, actions saturated at +-1); at 1:1 it climbed from 6.6 to 9.0 bps/Hz.
    gradient_steps: int = 8
    """gradient steps per vector step"""
    action_noise: float = 0.1
    """DDPG, TD3: sigma of the Gaussian exploration noise (actions in [-1, 1])"""
    policy_delay: int = 2  # TD3's own, as the next
    """TD3: critic updates per actor update"""
    target_policy_noise: float = 0.2
    """TD3: sigma of the smoothing noise on the target action"""
    ent_coef: str = "auto"
    """SAC: entropy coefficient, a number or auto (tuned automatically)"""
    # on-policy (PPO): the standard continuous-control settings
    n_steps: int = 256
    """PPO: steps per system per rollout"""
    n_epochs: int = 10
    """PPO: passes over each rollout"""
    gae_lambda: float = 0.95
    """PPO: lambda of the generalised advantage estimate"""
    clip_range: float = 0.2
    """PPO: clip of the probability ratio"""

    def __post_init__(self) -> None:
        object.__setattr__(self, "net_arch", tuple(int(x) for x in self.net_arch))
        checks = [
            ("net_arch", len(self.net_arch) >= 1 and all(x >= 1 for x in self.net_arch), "non-empty, units >= 1"),
            ("learning_rate", 0 < self.learning_rate < 1, "in (0, 1)"),
            ("gamma", 0 < self.gamma <= 1, "in (0, 1]"),
            ("reward_scale", self.reward_scale > 0, "> 0"),
            ("n_envs", self.n_envs >= 1, ">= 1"),
            ("batch_size", self.batch_size >= 1, ">= 1"),
            ("buffer_size", self.buffer_size >= self.batch_size, ">= batch_size"),
            ("learning_starts", self.learning_starts >= 0, ">= 0"),
            ("tau", 0 < self.tau <= 1, "in (0, 1]"),
            ("gradient_steps", self.gradient_steps >= 1, ">= 1"),
            ("action_noise", self.action_noise >= 0, ">= 0"),
            ("policy_delay", self.policy_delay >= 1, ">= 1"),
            ("target_policy_noise", self.target_policy_noise >= 0, ">= 0"),
            ("n_steps", self.n_steps >= 2, ">= 2"),
            ("n_epochs", self.n_epochs >= 1, ">= 1"),
            ("gae_lambda", 0 <= self.gae_lambda <= 1, "in [0, 1]"),
            ("clip_range", self.clip_range > 0, "> 0"),
        ]
        for name, ok, allowed in checks:
            if not ok:
                raise ConfigError(f"Hyperparams.{name} must be {allowed}, got {getattr(self, name)!r}")
        if not (self.ent_coef == "auto" or _is_float(self.ent_coef)):
            raise ConfigError(f"Hyperparams.ent_coef must be 'auto' or a number, got {self.ent_coef!r}")

    def replace(self, **changes: Any) -> Hyperparams:
        return dataclasses.replace(self, **changes)


_COMMON = ("net_arch", "learning_rate", "gamma", "reward_scale", "n_envs", "batch_size")
_OFF = ("buffer_size", "learning_starts", "tau", "gradient_steps")
_USED_BY = {
    "ddpg": _COMMON + _OFF + ("action_noise",),
    "td3": _COMMON + _OFF + ("action_noise", "policy_delay", "target_policy_noise"),
    "sac": _COMMON + _OFF + ("ent_coef",),
    "ppo": _COMMON + ("n_steps", "n_epochs", "gae_lambda", "clip_range"),
}


def hyperparams_for(algo: str, hp: Hyperparams) -> dict[str, Any]:
    """The hyperparameters ``algo`` actually uses, by name."""
    check_algorithm(algo)
    return {name: getattr(hp, name) for name in _USED_BY[algo]}


def _is_float(x: str) -> bool:
    try:
        float(x)
    except ValueError:
        return False
    return True


# What an algorithm changes from the defaults, in every preset.
ALGORITHM_CHANGES: dict[str, dict[str, Any]] = {
    "ddpg": {},
    "td3": {},
    "sac": dict(learning_rate=3e-4),  # SAC's usual
    "ppo": dict(learning_rate=3e-4, n_envs=16, batch_size=256),  # 16 systems x n_steps per rollout, minibatch 256
}
# What a preset changes on top, for the off-policy algorithms and for PPO (fields an algorithm does not use are
# ignored by it, and kept so that a run's config.yaml and its stage's key stay as they are).
# quick: 64 units, because a DDPG gradient step costs ~12 ms on one CPU core at 256 units and ~3 ms at 64, and the
# quick study trains 20 such runs on a laptop's two cores (docs/timings.md); a replay to match its 50,000 steps.
_QUICK = dict(net_arch=(64, 64), buffer_size=200_000, learning_starts=1_000, gradient_steps=4)
# smoke: the code paths only, in seconds.
_SMOKE = dict(net_arch=(32, 32), batch_size=32, buffer_size=10_000, learning_starts=100, n_envs=4, gradient_steps=4,
              n_steps=32, n_epochs=2)
PRESET_CHANGES: dict[str, dict[str, dict[str, Any]]] = {
    "paper": {"off_policy": {}, "ppo": {}},
    "quick": {"off_policy": dict(_QUICK, batch_size=128, n_envs=4),  # 4 systems: gradient_steps = n_envs
              "ppo": dict(_QUICK, batch_size=256, n_envs=16, n_steps=128)},
    "smoke": {"off_policy": _SMOKE, "ppo": _SMOKE},
}


def default_hyperparams(algo: str, preset: str) -> Hyperparams:
    """The hyperparameters of ``algo`` in a preset: the defaults, changed by the algorithm's
    :data:`ALGORITHM_CHANGES`, then by the preset's :data:`PRESET_CHANGES`."""
    check_algorithm(algo)
    check_preset(preset)
    kind = "ppo" if algo == "ppo" else "off_policy"
    return Hyperparams(**{**ALGORITHM_CHANGES[algo], **PRESET_CHANGES[preset][kind]})


def check_algorithm(algo: str) -> None:
    if algo not in ALGORITHMS:
        raise ConfigError(f"unknown algorithm {algo!r}; choose one of {', '.join(ALGORITHMS)}")


