"""uavris 0.2's Decision Transformer training step, frozen as the baseline of ``dt_throughput.py``.

What changed since (``uavris.agents.dt.encoders``, ``uavris.agents.dt.trainer``): the
device-set encoder's pair network applied its first layer to every concatenated pair
``[f_k, f_j]`` (K^2 rows) where it now applies the two halves once per device; its mean
over the devices sorted the values with ``torch.sort`` (forward and backward) where it now
sorts without a gradient by a min/max network; AdamW and the gradient clipping looped over
the parameters in Python where they now use torch's multi-tensor (foreach) kernels. Same
parameters, same function: a model's weights load into either.
"""

from __future__ import annotations

import types
from typing import Any

import numpy as np
import torch

from uavris.agents.dt.encoders import DeviceSetEncoder
from uavris.agents.dt.model import DecisionTransformer, masked_action_loss
from uavris.agents.dt.trainer import warmup_schedule
from uavris.agents.dt.trajectories import TrainingWindows


def _pool_v020(x: torch.Tensor, k: int) -> torch.Tensor:
    return torch.cat([x.max(dim=-2).values, x.sort(dim=-2).values.sum(dim=-2) / k], dim=-1)


def _device_forward_v020(self: DeviceSetEncoder, raw: torch.Tensor, normalised: torch.Tensor) -> torch.Tensor:
    f = self.device_features(raw, normalised)
    k = self.k
    pairs = torch.cat([f.unsqueeze(-2).expand(*f.shape[:-2], k, k, f.shape[-1]),
                       f.unsqueeze(-3).expand(*f.shape[:-2], k, k, f.shape[-1])], dim=-1)
    relations = _pool_v020(self.pair_net(pairs), k)
    per_device = self.device_net(torch.cat([f, relations], dim=-1))
    uav = normalised[..., self.uav_index.to(normalised.device)]
    return self.combine(torch.cat([_pool_v020(per_device, k), uav], dim=-1))


def as_v020(model: DecisionTransformer) -> DecisionTransformer:
    """``model`` with 0.2's device-set encoder forward (a flat encoder is unchanged)."""
    if isinstance(model.embed_state, DeviceSetEncoder):
        model.embed_state.forward = types.MethodType(_device_forward_v020, model.embed_state)  # type: ignore[method-assign]
    return model


def make_optimizer_v020(model: DecisionTransformer, lr: float, weight_decay: float) -> torch.optim.AdamW:
    decay = [p for n, p in model.named_parameters() if p.ndim >= 2 and not n.startswith("embed_timestep")]
    keep = [p for n, p in model.named_parameters() if not (p.ndim >= 2 and not n.startswith("embed_timestep"))]
    return torch.optim.AdamW([{"params": decay, "weight_decay": weight_decay}, {"params": keep, "weight_decay": 0.0}],
                             lr=lr, betas=(0.9, 0.999), foreach=False)


def train_steps_v020(model: DecisionTransformer, opt: torch.optim.Optimizer, windows: TrainingWindows,
                     rng: np.random.Generator, first_step: int, count: int, batch_size: int, lr: float, warmup: int,
                     grad_clip: float) -> list[float]:
    schedule = warmup_schedule(opt, lr, warmup, first_step)
    model.train()
    losses: list[float] = []
    for _ in range(count):
        batch: dict[str, Any] = windows.sample(batch_size, rng)
        pred = model(batch["returns_to_go"], batch["states"], batch["actions"], batch["timesteps"], batch["valid"])
        loss = masked_action_loss(pred, batch["actions"], batch["valid"])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), grad_clip, foreach=False)
        opt.step()
        losses.append(float(loss.detach()))
        schedule.step()
    model.eval()
    return losses
