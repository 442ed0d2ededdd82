"""Stable-Baselines3 models of the experts: construction, loading, the deterministic policy.

Lives here: the SB3 class of each algorithm, :func:`build_model` with uavris's
hyperparameters, :func:`load_model` with a clear error for a corrupt archive, and
:class:`SB3Policy`, a trained model as an observation-only policy. Not here: the
hyperparameters (:mod:`.hyperparams`), training runs (:mod:`uavris.experiments.training.train_expert`).
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from uavris.agents.experts.hyperparams import Hyperparams, check_algorithm
from uavris.errors import CheckpointError


def algorithm_class(algo: str) -> type:
    check_algorithm(algo)
    from stable_baselines3 import DDPG, PPO, SAC, TD3

    return {"ddpg": DDPG, "ppo": PPO, "sac": SAC, "td3": TD3}[algo]


def build_model(algo: str, env: Any, hp: Hyperparams, seed: int, tensorboard_log: str | None = None,
                device: str = "cpu") -> Any:
    """A fresh SB3 model of ``algo`` on ``env`` (a VecEnv) with hyperparameters ``hp``, on ``device``."""
    from stable_baselines3.common.noise import NormalActionNoise

    cls = algorithm_class(algo)
    common: dict[str, Any] = dict(learning_rate=hp.learning_rate, gamma=hp.gamma, seed=seed, device=device,
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


class SB3Policy:
    """A trained SB3 model as a deterministic batch policy of the observation; a model trained
    on the motion (``phase_control="optimizer"``) acts with the optimiser's phases."""

    def __init__(self, model: Any, phase_control: str = "agent") -> None:
        self.model = model
        self.phase_control = phase_control

    @property
    def observation_dim(self) -> int:
        """Entries of the observation the model was trained on (:func:`uavris.agents.policy.check_policy_fits`)."""
        return int(self.model.observation_space.shape[0])

    def __call__(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        action, _ = self.model.predict(obs, deterministic=True)
        return action


def _check_model_file(path: Path) -> None:
    """SB3 models are zip archives; reject a truncated or foreign file with a clear message."""
    if not path.exists():
        raise CheckpointError(f"checkpoint {path} is missing")
    try:
        with zipfile.ZipFile(path) as z:
            names = set(z.namelist())
            bad = z.testzip()
    except (zipfile.BadZipFile, OSError) as e:
        raise CheckpointError(f"checkpoint {path} is corrupt ({e})") from None
    if bad is not None or "data" not in names:
        raise CheckpointError(f"checkpoint {path} is corrupt (not a Stable-Baselines3 model)")


def load_model(path: str | Path, algo: str, env: Any = None, device: str = "cpu") -> Any:
    """An SB3 model of ``algo`` from ``path`` (a model.zip or checkpoint)."""
    path = Path(path)
    _check_model_file(path)
    try:
        return algorithm_class(algo).load(path, env=env, device=device)
    except Exception as e:  # noqa: BLE001 - SB3 raises many types for a bad archive
        raise CheckpointError(f"checkpoint {path} could not be loaded: {type(e).__name__}: {e}") from None
