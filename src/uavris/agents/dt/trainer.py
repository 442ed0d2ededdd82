"""Training a Decision Transformer: the optimiser, the learning-rate schedule, the training step.

Lives here: :func:`make_optimizer` (AdamW, weight decay on the weight matrices only),
:func:`train_steps` (gradient steps of the masked action MSE, L_OFF of eq. 16 and L_FT of
eq. 19, with a linear warm-up, ``torch.optim.lr_scheduler.LambdaLR``, and gradient-norm
clipping) and the trainer state a resumed run needs (optimiser moments and random
streams, safetensors + JSON, no pickle). Not here: the runs that use them, their
directories and logs (:mod:`uavris.experiments.training.pretrain`, :mod:`uavris.experiments.training.finetune`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from uavris.agents.dt.model import DecisionTransformer, masked_action_loss
from uavris.agents.dt.trajectories import MixedWindows, TrainingWindows
from uavris.errors import CheckpointError
from uavris.io import atomic_write_bytes, read_json, write_json


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
        pred = model(batch["returns_to_go"], batch["states"], batch["actions"], batch["timesteps"], batch["valid"])
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


def save_trainer_state(directory: Path, opt: torch.optim.Optimizer, rng: np.random.Generator,
                       extra: dict[str, Any]) -> None:
    """Optimiser moments and the torch RNG as safetensors, the rest as JSON (no pickle)."""
    from safetensors.torch import save

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
    from safetensors import SafetensorError
    from safetensors.torch import load

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
