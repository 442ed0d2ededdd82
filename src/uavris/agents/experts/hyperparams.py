"""Hyperparameters of the DRL experts (DDPG, PPO, SAC, TD3), validated, with their reasons.

Lives here: :class:`Hyperparams`, the algorithms' names (:data:`ALGORITHMS`,
:data:`OFF_POLICY`, :func:`check_algorithm`), which hyperparameters each uses
(:func:`hyperparams_for`) and a preset's defaults (:func:`default_hyperparams`). Not here:
the per-preset values (tables in :mod:`uavris.presets`) and building and running the SB3
models (:mod:`.sb3`).

The paper gives no hyperparameters. Ours, with their reasons:

- Networks: two hidden layers (``net_arch``) for actor and critic; 256 units in ``paper``
  (the common continuous-control size), 64 in ``quick`` because a DDPG gradient step costs
  ~12 ms on one CPU core at 256 units and ~3 ms at 64, and the quick study trains 20 such
  runs on a laptop's two cores (its time: docs/timings.md).
- ``gamma`` = 0.95: a slot's reward depends on that slot's phases and pose; moving pays off
  within ~10-20 slots (5-10 s at up to 5 m/s), so a 20-slot effective horizon suffices and
  keeps Q-values small.
- ``reward_scale`` = 0.1: sum rates are 5-40 bps/Hz per slot; scaled rewards keep critic
  targets of order 10.
- Off-policy: ``n_envs`` parallel systems (8 paper, 4 quick/smoke), one update every
  vector step with ``gradient_steps`` = ``n_envs``: one gradient step per env step. We
  measured that at one gradient step per 4 env steps DDPG did not improve in 16,000 steps
  (average sum rate 2-8 bps/Hz, actions saturated at +-1), while at 1:1 it climbed from
  6.6 to 9.0 bps/Hz over the same steps. Replay 1e6 (paper) or 2e5 (quick); batch
  256/128; learning rate 1e-3 (DDPG, TD3) and 3e-4 (SAC, its usual); exploration:
  Gaussian noise sigma = 0.1 on DDPG/TD3 actions, SAC's automatic entropy.
- PPO (``paper`` and ``quick``): 16 parallel systems x 256 steps per rollout (128 in
  ``quick``), 10 epochs of minibatch 256, lr 3e-4, GAE 0.95, clip 0.2: the standard
  continuous-control settings.

The values are :class:`Hyperparams`' defaults overlaid by :data:`uavris.presets.ALGO_HYPERPARAMS`
(per algorithm) and :data:`uavris.presets.HYPERPARAMS` (per preset: ``smoke`` is far smaller);
``uavris train --algo ALGO --preset PRESET --help`` shows them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Literal, get_args

from uavris.config import DictConfig
from uavris.errors import ConfigError
from uavris.presets import ALGO_HYPERPARAMS, HYPERPARAMS, check_preset

Algorithm = Literal["ddpg", "ppo", "sac", "td3"]  # what --algo accepts (tyro lists and checks them)
ALGORITHMS: tuple[str, ...] = get_args(Algorithm)
OFF_POLICY: tuple[str, ...] = ("ddpg", "sac", "td3")


@dataclass(frozen=True)
class Hyperparams(DictConfig):
    """Hyperparameters of one algorithm (fields not used by an algorithm are ignored)."""

    net_arch: tuple[int, ...] = (256, 256)
    learning_rate: float = 1e-3
    gamma: float = 0.95
    reward_scale: float = 0.1
    n_envs: int = 8
    batch_size: int = 256
    # off-policy
    buffer_size: int = 1_000_000
    learning_starts: int = 2_000
    tau: float = 0.005
    gradient_steps: int = 8
    action_noise: float = 0.1  # DDPG/TD3 Gaussian exploration sigma (actions in [-1, 1])
    policy_delay: int = 2  # TD3
    target_policy_noise: float = 0.2  # TD3
    ent_coef: str = "auto"  # SAC
    # on-policy (PPO)
    n_steps: int = 256
    n_epochs: int = 10
    gae_lambda: float = 0.95
    clip_range: float = 0.2

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


def default_hyperparams(algo: str, preset: str) -> Hyperparams:
    """The documented defaults of ``algo`` for a preset (:data:`uavris.presets.HYPERPARAMS`)."""
    check_algorithm(algo)
    check_preset(preset)
    kind = "ppo" if algo == "ppo" else "off_policy"
    return Hyperparams(**{**ALGO_HYPERPARAMS[algo], **HYPERPARAMS[preset][kind]})


def check_algorithm(algo: str) -> None:
    if algo not in ALGORITHMS:
        raise ConfigError(f"unknown algorithm {algo!r}; choose one of {', '.join(ALGORITHMS)}")


