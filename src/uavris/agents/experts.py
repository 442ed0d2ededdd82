"""DRL experts: DDPG, PPO, SAC and TD3 from Stable-Baselines3 on the batched env.

The paper gives no hyperparameters. Ours, with their reasons:

- Networks: two hidden layers (``net_arch``) for actor and critic; 256 units in ``paper``
  (the common continuous-control size), 64 in ``quick`` because a DDPG gradient step costs
  ~12 ms on one CPU core at 256 units and ~3 ms at 64, and the quick study (20 runs) must
  fit 30 minutes on two cores.
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
- PPO: 16 parallel systems x 256 steps per rollout, 10 epochs of minibatch 256, lr 3e-4,
  GAE 0.95, clip 0.2: the standard continuous-control settings.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from uavris.config import ConfigError

ALGORITHMS: tuple[str, ...] = ("ddpg", "ppo", "sac", "td3")
OFF_POLICY: tuple[str, ...] = ("ddpg", "sac", "td3")


@dataclass(frozen=True)
class Hyperparams:
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
    """The documented defaults of ``algo`` for a preset (``smoke``, ``quick`` or ``paper``)."""
    check_algorithm(algo)
    hp = Hyperparams()
    if algo == "sac":
        hp = hp.replace(learning_rate=3e-4)
    if algo == "ppo":
        hp = hp.replace(learning_rate=3e-4, n_envs=16, batch_size=256)
    if preset == "paper":
        return hp
    if preset == "quick":
        return hp.replace(net_arch=(64, 64), batch_size=128 if algo != "ppo" else 256, buffer_size=200_000,
                          learning_starts=1_000, n_envs=4 if algo != "ppo" else 16, gradient_steps=4,
                          n_steps=128 if algo == "ppo" else hp.n_steps)
    if preset == "smoke":
        return hp.replace(net_arch=(32, 32), batch_size=32, buffer_size=10_000, learning_starts=100,
                          n_envs=4, gradient_steps=4, n_steps=32, n_epochs=2)
    raise ConfigError(f"unknown preset {preset!r}; choose one of smoke, quick, paper")


def check_algorithm(algo: str) -> None:
    if algo not in ALGORITHMS:
        raise ConfigError(f"unknown algorithm {algo!r}; choose one of {', '.join(ALGORITHMS)}")


def algorithm_class(algo: str) -> type:
    check_algorithm(algo)
    from stable_baselines3 import DDPG, PPO, SAC, TD3

    return {"ddpg": DDPG, "ppo": PPO, "sac": SAC, "td3": TD3}[algo]


def build_model(algo: str, env: Any, hp: Hyperparams, seed: int, tensorboard_log: str | None = None) -> Any:
    """A fresh SB3 model of ``algo`` on ``env`` (a VecEnv) with hyperparameters ``hp``."""
    from stable_baselines3.common.noise import NormalActionNoise

    cls = algorithm_class(algo)
    common: dict[str, Any] = dict(learning_rate=hp.learning_rate, gamma=hp.gamma, seed=seed, device="cpu",
                                  verbose=0, tensorboard_log=tensorboard_log,
                                  policy_kwargs=dict(net_arch=list(hp.net_arch)))
    if algo == "ppo":
        return cls("MlpPolicy", env, n_steps=hp.n_steps, batch_size=hp.batch_size, n_epochs=hp.n_epochs,
                   gae_lambda=hp.gae_lambda, clip_range=hp.clip_range, **common)
    off = dict(buffer_size=hp.buffer_size, learning_starts=hp.learning_starts, batch_size=hp.batch_size,
               tau=hp.tau, train_freq=1, gradient_steps=hp.gradient_steps, **common)
    dim = env.action_space.shape[0]
    if algo == "sac":
        ent = hp.ent_coef if hp.ent_coef == "auto" else float(hp.ent_coef)
        return cls("MlpPolicy", env, ent_coef=ent, **off)
    noise = NormalActionNoise(np.zeros(dim), hp.action_noise * np.ones(dim)) if hp.action_noise > 0 else None
    if algo == "td3":
        return cls("MlpPolicy", env, action_noise=noise, policy_delay=hp.policy_delay,
                   target_policy_noise=hp.target_policy_noise, **off)
    return cls("MlpPolicy", env, action_noise=noise, **off)


def sb3_batch_policy(model: Any):
    """Wrap an SB3 model as a deterministic batch policy ``(obs, sim) -> actions``."""

    def act(obs: np.ndarray, sim: Any) -> np.ndarray:
        action, _ = model.predict(obs, deterministic=True)
        return action

    return act
