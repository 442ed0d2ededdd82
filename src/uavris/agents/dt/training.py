"""Training a Decision Transformer, read top to bottom: the windows, the loss, a model for the data,
the optimiser and its schedule, the gradient steps, and the trainer state a resumed run needs.

Lives here: :class:`TrainingWindows` and :class:`MixedWindows` (the context windows of L_OFF,
eq. 16, and L_FT, eq. 19, of one set of trajectories or of sets of several device counts),
:func:`masked_action_loss` (L_OFF / L_FT), :func:`model_for_data` (a model with the state
normalisation and return scale of its training data), :func:`make_optimizer` (AdamW, weight
decay on the weight matrices only), :func:`warmup_schedule` (a linear warm-up,
``torch.optim.lr_scheduler.LambdaLR``), :func:`train_steps` (gradient steps with
gradient-norm clipping) and the trainer state (optimiser moments and random streams,
safetensors + JSON, no pickle). Not here: the model (:mod:`.model`, sized by
:class:`~.config.DTConfig`), the trajectories and their statistics (:mod:`.trajectories`),
and the runs that call this, with their directories, logs and checkpoints
(:func:`uavris.experiments.training.pretrain.pretrain`, Algorithm 1 stage 1, and
:func:`uavris.experiments.training.finetune.finetune`, stage 2).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch
from numpy.typing import NDArray
from safetensors import SafetensorError
from safetensors.torch import load, save

from uavris.agents.dt.config import DTConfig
from uavris.agents.dt.encoders import pooled_over_devices
from uavris.agents.dt.goals import goal_offsets
from uavris.agents.dt.model import DecisionTransformer
from uavris.agents.dt.trajectories import Trajectory, normalisation_from, returns_to_go
from uavris.config import SystemConfig
from uavris.errors import CheckpointError, DatasetError
from uavris.io import atomic_write_bytes, read_json, write_json


# ------------------------------------------------------------------------------ the windows
class TrainingWindows:
    """All slots of a set of trajectories, ready to be cut into context windows.

    A window is the ``context`` slots ending at a slot chosen uniformly among all slots;
    near an episode's start it is left-padded, exactly as the history a deployed DT sees
    at that slot (:mod:`uavris.agents.dt.policy`). The loss covers every real slot of it.

    With ``whole_episodes`` (the banded DT, which reads episodes from slot 0) a sample is
    instead one whole episode chosen uniformly, left-padded to the longest episode.
    """

    def __init__(self, trajectories: Sequence[Trajectory], context: int, whole_episodes: bool = False,
                 goals: Sequence[NDArray] | None = None) -> None:
        if not trajectories:
            raise DatasetError("no trajectories to train on")
        lengths = np.array([tr.length for tr in trajectories])
        self.whole_episodes = whole_episodes
        self.model_context = context
        self.context = int(lengths.max()) if whole_episodes else context
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        self.episode_end = starts + lengths - 1
        self.states = np.concatenate([tr.observations[:-1] for tr in trajectories]).astype(np.float32)
        self.actions = np.concatenate([tr.actions for tr in trajectories]).astype(np.float32)
        self.rtg = np.concatenate([returns_to_go(tr.rewards) for tr in trajectories]).astype(np.float32)
        # a goal-conditioned model's: the goal's offset from the UAV at every slot (.goals.goal_offsets)
        self.goals = None if goals is None else np.concatenate(goals).astype(np.float32)
        self.timesteps = np.concatenate([np.arange(n) for n in lengths]).astype(np.int64)
        self.episode_start = np.repeat(starts, lengths)

    @classmethod
    def for_model(cls, trajectories: Sequence[Trajectory], model_config: DTConfig,
                  system: SystemConfig | None = None) -> TrainingWindows:
        """The samples a model of this :class:`~uavris.agents.dt.config.DTConfig` trains on; a
        goal-conditioned model's hold each trajectory's own goal (its plan's target) as the UAV
        saw it at every slot, read against ``system``."""
        goals = None
        if model_config.goal:
            if system is None or any(tr.goal is None for tr in trajectories):
                raise DatasetError("a goal-conditioned DT trains on trajectories that record their goal "
                                   "(the oracle's demonstrations), with their system")
            goals = [goal_offsets(tr.observations[:-1], np.asarray(tr.goal), system) for tr in trajectories]
        return cls(trajectories, model_config.context, whole_episodes=model_config.attention == "banded",
                   goals=goals)

    @property
    def num_slots(self) -> int:
        return int(self.rtg.shape[0])

    @property
    def samples_per_epoch(self) -> int:
        """Samples of one epoch: one window per slot, or, for whole episodes, ``context``
        draws per episode, so that an epoch predicts about as many actions either way (a
        window predicts ``context`` of them, an episode all of its slots)."""
        return len(self.episode_end) * self.model_context if self.whole_episodes else self.num_slots

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, torch.Tensor]:
        """``batch_size`` windows: rtg (B, K), states (B, K, S), actions (B, K, A),
        timesteps (B, K), valid (B, K); padded entries are zero."""
        if self.whole_episodes:
            ends = self.episode_end[rng.integers(0, len(self.episode_end), batch_size)]
        else:
            ends = rng.integers(0, self.num_slots, batch_size)
        pos = ends[:, None] + np.arange(1 - self.context, 1)
        valid = pos >= self.episode_start[ends][:, None]
        idx = np.where(valid, pos, ends[:, None])
        pad = ~valid
        states, actions = self.states[idx], self.actions[idx]
        rtg, steps = self.rtg[idx], self.timesteps[idx]
        goals = None if self.goals is None else self.goals[idx]
        states[pad], actions[pad], rtg[pad], steps[pad] = 0.0, 0.0, 0.0, 0
        batch = {"returns_to_go": torch.from_numpy(rtg), "states": torch.from_numpy(states),
                 "actions": torch.from_numpy(actions), "timesteps": torch.from_numpy(steps),
                 "valid": torch.from_numpy(valid)}
        if goals is not None:
            goals[pad] = 0.0
            batch["goals"] = torch.from_numpy(goals)
        return batch


class MixedWindows:
    """The windows of several sets of trajectories whose observations differ in width (halls
    of different numbers of devices, read by one device-set encoder): each batch is drawn
    from one set, chosen with probability proportional to its slots, so every slot is as
    likely to be trained on as in one set, and a batch stacks observations of one width."""

    def __init__(self, parts: Sequence[TrainingWindows]) -> None:
        if not parts:
            raise DatasetError("no trajectories to train on")
        self.parts = list(parts)
        slots = np.array([p.num_slots for p in self.parts], dtype=np.float64)
        self._weights = slots / slots.sum()

    @property
    def num_slots(self) -> int:
        return sum(p.num_slots for p in self.parts)

    @property
    def samples_per_epoch(self) -> int:
        return sum(p.samples_per_epoch for p in self.parts)

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, torch.Tensor]:
        """``batch_size`` windows of one set (:meth:`TrainingWindows.sample`)."""
        return self.parts[int(rng.choice(len(self.parts), p=self._weights))].sample(batch_size, rng)


# ------------------------------------------------------------------------------ the loss
def masked_action_loss(pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Mean squared action error over the real slots: the paper's L_OFF (eq. 16) and L_FT
    (eq. 19), E ||A - A_hat||^2, divided by ``act_dim`` (a per-component MSE)."""
    err = (pred - target).pow(2).mean(dim=-1)
    w = valid.to(err.dtype)
    return (err * w).sum() / w.sum().clamp_min(1.0)


# ------------------------------------------------------------------------------ a model for the data
def model_for_data(cfg: DTConfig, trajectories: Sequence[Trajectory]) -> DecisionTransformer:
    """A new model of ``cfg`` (sized for its data: :meth:`~.config.DTConfig.for_data`) with the
    state normalisation and return scale of ``trajectories`` (:func:`~.trajectories.normalisation_from`),
    which travel with its weights; the device-set encoder's statistics do not depend on a
    device's index (:func:`~.encoders.pooled_over_devices`). Its weights come from torch's
    random stream (seed it first)."""
    norm = normalisation_from(trajectories)
    mean, std = norm.state_mean, norm.state_std
    if cfg.state_encoder == "devices":
        mean, std = pooled_over_devices(mean, std, cfg.devices, cfg.elements)
    return DecisionTransformer(cfg, mean, std, norm.return_scale)


# ------------------------------------------------------------------------------ the optimiser and its schedule
def make_optimizer(model: DecisionTransformer, lr: float, weight_decay: float) -> torch.optim.AdamW:
    """AdamW that decays the weight matrices only: biases, LayerNorm gains and the timestep
    table keep their scale."""
    decay = [p for n, p in model.named_parameters() if p.ndim >= 2 and not n.startswith("embed_timestep")]
    keep = [p for n, p in model.named_parameters() if not (p.ndim >= 2 and not n.startswith("embed_timestep"))]
    # foreach: one multi-tensor update for all parameters instead of a Python loop over them
    # (torch picks it by itself on CUDA only).
    return torch.optim.AdamW([{"params": decay, "weight_decay": weight_decay}, {"params": keep, "weight_decay": 0.0}],
                             lr=lr, betas=(0.9, 0.999), foreach=True)


def warmup_schedule(opt: torch.optim.Optimizer, lr: float, warmup: int, step: int) -> torch.optim.lr_scheduler.LambdaLR:
    """Linear warm-up to ``lr`` over ``warmup`` steps, then constant, positioned at ``step``
    (the rate of the next gradient step is ``lr * min(1, (step + 1) / warmup)``)."""
    for group in opt.param_groups:
        group["initial_lr"] = lr
    return torch.optim.lr_scheduler.LambdaLR(opt, lambda s: min(1.0, (s + 1) / warmup), last_epoch=step - 1)


def train_steps(model: DecisionTransformer, opt: torch.optim.Optimizer, windows: TrainingWindows | MixedWindows,
                rng: np.random.Generator, first_step: int, count: int, batch_size: int, lr: float, warmup: int,
                grad_clip: float, on_step: Callable[[int, float], None] | None = None) -> list[float]:
    """``count`` gradient steps from global step ``first_step``; returns the losses.

    ``on_step(step, loss)`` is called after each, with ``step`` counted from 1 and the
    optimiser's rate still the one the step used.
    """
    schedule = warmup_schedule(opt, lr, warmup, first_step)
    model.train()
    device = next(model.parameters()).device
    losses = []
    for i in range(count):
        batch = {k: v.to(device) for k, v in windows.sample(batch_size, rng).items()}
        pred = model(batch["returns_to_go"], batch["states"], batch["actions"], batch["timesteps"], batch["valid"],
                     goals=batch.get("goals"))
        loss = masked_action_loss(pred, batch["actions"], batch["valid"])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), grad_clip, foreach=True)
        opt.step()
        losses.append(float(loss.detach()))
        if on_step is not None:
            on_step(first_step + i + 1, losses[-1])
        schedule.step()
    model.eval()
    return losses


# ------------------------------------------------------------------------------ the trainer state
def save_trainer_state(directory: Path, opt: torch.optim.Optimizer, rng: np.random.Generator,
                       extra: dict[str, Any]) -> None:
    """Optimiser moments and the torch RNG as safetensors, the rest as JSON (no pickle)."""
    state = opt.state_dict()
    tensors = {"torch_rng": torch.get_rng_state()}
    for pid, st in state["state"].items():
        for key, value in st.items():
            tensors[f"optimizer.{pid}.{key}"] = value.detach().cpu().contiguous().clone()
    groups = [{k: (list(v) if isinstance(v, tuple) else v) for k, v in g.items()} for g in state["param_groups"]]
    atomic_write_bytes(directory / "trainer.safetensors", save(tensors))
    write_json(directory / "trainer.json", {"param_groups": groups, "numpy_rng": rng.bit_generator.state, **extra})


def load_trainer_state(directory: Path, opt: torch.optim.Optimizer, rng: np.random.Generator) -> dict[str, Any]:
    """Restore what :func:`save_trainer_state` wrote; returns its JSON (with the ``extra`` fields)."""
    path = directory / "trainer.safetensors"
    meta = read_json(directory / "trainer.json")
    try:
        tensors = load(path.read_bytes())
    except FileNotFoundError:
        raise CheckpointError(f"{path} is missing; pass --force to start over") from None
    except (SafetensorError, ValueError) as e:
        raise CheckpointError(f"{path} is corrupt ({e})") from None
    try:
        state: dict[int, dict[str, Any]] = {}
        for name, value in tensors.items():
            if name.startswith("optimizer."):
                _, pid, key = name.split(".", 2)
                state.setdefault(int(pid), {})[key] = value
        opt.load_state_dict({"state": state, "param_groups": meta["param_groups"]})
        rng.bit_generator.state = meta["numpy_rng"]
        torch.set_rng_state(tensors["torch_rng"])
    except (KeyError, ValueError, TypeError, RuntimeError) as e:
        raise CheckpointError(f"{directory} holds an unusable trainer state ({type(e).__name__}: {e})") from None
    return meta
