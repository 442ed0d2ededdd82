"""Stable-Baselines3 models of the experts: construction, the policy's files, the deterministic policy.

Lives here: the SB3 class of each algorithm, :func:`build_model` with uavris's
hyperparameters; the policy's weights as safetensors and its architecture as JSON
(:func:`save_policy`, :func:`load_policy`: what every command reads, files that cannot run
code when read); :func:`load_model`, SB3's own archive (a pickle: only to resume a run uavris
sealed as its own, or where the user trusts it, :mod:`uavris.runs.seal`); and
:class:`SB3Policy`, a trained policy as an observation-only policy. Not here: the
hyperparameters (:mod:`.hyperparams`), training runs (:mod:`uavris.experiments.training.train_expert`).
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from safetensors import SafetensorError
from safetensors.torch import load, save
from stable_baselines3 import DDPG, PPO, SAC, TD3
from stable_baselines3.common.noise import NormalActionNoise

from uavris.agents.experts.hyperparams import Hyperparams, check_algorithm
from uavris.agents.experts.vec_env import expert_spaces
from uavris.agents.row_invariant import rows_apart
from uavris.config import SystemConfig
from uavris.errors import CheckpointError
from uavris.io import atomic_write_bytes, read_checkpoint_meta, write_json
from uavris.runs.seal import check_sealed

POLICY_KIND, POLICY_FORMAT_VERSION = "uavris-expert-policy", 1
# What the architecture's JSON may hold: the keyword arguments uavris's models are built with (build_model).
POLICY_KWARGS = ("net_arch", "use_sde", "n_critics", "share_features_extractor")


def algorithm_class(algo: str) -> type:
    check_algorithm(algo)

    return {"ddpg": DDPG, "ppo": PPO, "sac": SAC, "td3": TD3}[algo]


def build_model(algo: str, env: Any, hp: Hyperparams, seed: int, tensorboard_log: str | None = None,
                device: str = "cpu") -> Any:
    """A fresh SB3 model of ``algo`` on ``env`` (a VecEnv) with hyperparameters ``hp``, on ``device``."""
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


def save_policy(model: Any, algo: str, stem: Path) -> None:
    """The policy of an SB3 ``model`` as ``STEM.safetensors`` (its weights) and ``STEM.json``
    (the algorithm and the keyword arguments its network is built with), atomically."""
    kwargs = {k: v for k, v in model.policy_kwargs.items() if k in POLICY_KWARGS}
    if algo == "ppo":  # on-policy algorithms hand use_sde to the policy beside its kwargs
        kwargs["use_sde"] = bool(model.use_sde)
    tensors = {k: v.detach().cpu().contiguous().clone() for k, v in model.policy.state_dict().items()}
    atomic_write_bytes(stem.parent / f"{stem.name}.safetensors", save(tensors))
    write_json(stem.parent / f"{stem.name}.json", {"kind": POLICY_KIND, "format_version": POLICY_FORMAT_VERSION,
                                                   "algo": algo, "policy_kwargs": kwargs})


def has_policy(stem: Path) -> bool:
    return (stem.parent / f"{stem.name}.json").is_file()


def load_policy(stem: Path, config: SystemConfig, phase_control: str, device: str = "cpu") -> Any:
    """The policy network :func:`save_policy` wrote at ``stem``, for ``config`` (its spaces), in
    eval mode; nothing in the files is run. One :class:`CheckpointError` line naming what is wrong."""
    meta = read_checkpoint_meta(stem.parent, f"{stem.name}.json", POLICY_KIND, POLICY_FORMAT_VERSION,
                                "an expert's policy", "an expert's policy")
    algo, kwargs = meta.get("algo"), meta.get("policy_kwargs")
    if algo not in ("ddpg", "ppo", "sac", "td3") or not isinstance(kwargs, dict) or set(kwargs) - set(POLICY_KWARGS):
        raise CheckpointError(f"{stem}.json does not describe an expert's policy (algo {algo!r}, keyword arguments "
                              f"{sorted(kwargs) if isinstance(kwargs, dict) else kwargs!r})")
    weights = stem.parent / f"{stem.name}.safetensors"
    obs_space, act_space = expert_spaces(config, phase_control)
    try:
        policy = algorithm_class(algo).policy_aliases["MlpPolicy"](obs_space, act_space, lambda _: 0.0, **kwargs)
        policy.load_state_dict(load(weights.read_bytes()))
    except (OSError, SafetensorError, RuntimeError, TypeError, ValueError, KeyError) as e:
        raise CheckpointError(f"{weights} is missing, corrupt or of another size ({type(e).__name__})") from None
    policy.set_training_mode(False)
    return policy.to(device)


class SB3Policy:
    """A trained SB3 model or policy network (anything with SB3's ``predict`` and
    ``observation_space``) as a deterministic batch policy of the observation; a model trained
    on the motion (``phase_control="optimizer"``) acts with the optimiser's phases. Its linear
    layers act row by row (:mod:`uavris.agents.row_invariant`): each episode's actions are
    those it would get alone."""

    def __init__(self, model: Any, phase_control: str = "agent") -> None:
        self.model = model
        self.phase_control = phase_control

    @property
    def observation_dim(self) -> int:
        """Entries of the observation the model was trained on (:func:`uavris.agents.policy.check_policy_fits`)."""
        return int(self.model.observation_space.shape[0])

    def __call__(self, obs: NDArray[np.float32]) -> NDArray[np.float32]:
        with rows_apart(getattr(self.model, "policy", self.model)):
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


def load_model(path: str | Path, algo: str, env: Any = None, device: str = "cpu", trust_pickle: bool = False) -> Any:
    """An SB3 model of ``algo`` from ``path`` (a model.zip or checkpoint): SB3 unpickles it, so
    only a file sealed as uavris's own or, with ``trust_pickle``, one the user trusts."""
    path = Path(path)
    _check_model_file(path)
    check_sealed(path, trust_pickle)
    try:
        return algorithm_class(algo).load(path, env=env, device=device)
    except Exception as e:  # noqa: BLE001 - SB3 raises many types for a bad archive
        raise CheckpointError(f"checkpoint {path} could not be loaded: {type(e).__name__}: {e}") from None
