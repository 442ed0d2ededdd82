"""A learned policy's action for one episode, whatever else runs in its batch.

Lives here: :class:`Linear` (``nn.Linear`` whose product at deployment is taken row by row),
:func:`attention` (scaled dot-product attention, the same way), and :func:`rows_apart`, which
lets a network built from ``nn.Linear`` (an SB3 policy) act with the same layers. Not here: the
networks (:mod:`uavris.agents.dt.model`, :mod:`uavris.agents.experts.sb3`).

Why: evaluation episode k must score the same alone, among 4 or among 256 (``uavris evaluate
--episodes 1`` and a sweep's batch agree on the same seed). One matrix product over all the rows of
a batch lets the BLAS kernel depend on how many rows there are and where a row sits among them
(a vector kernel for one row, blocks of rows for many, another order of the sums), which moves
a float32 action by one ulp; a closed loop of 100 slots turns that into another episode
(measured on a goal-conditioned DT: 35.84 bps/Hz alone against 35.49 as the first of 4). At
deployment (no gradient: ``torch.inference_mode`` or ``no_grad``) every episode (an entry of
the first axis) is therefore multiplied on its own, one product per episode, and
attention is computed per row and head by products and a softmax of fixed shapes. Training,
which needs gradients, keeps the fused kernels; the two paths agree to rounding.
"""

from __future__ import annotations

import contextlib
import math
from typing import Iterator

import torch
import torch.nn.functional as F
from torch import nn


def linear(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None = None) -> torch.Tensor:
    """``F.linear``; without gradients, each entry of ``x``'s first axis (an episode of the
    batch) multiplied on its own, from memory of its own: the same product, of the same shape at
    the same alignment, whatever else is in the batch."""
    if torch.is_grad_enabled() or x.dim() < 2:
        return F.linear(x, weight, bias)
    return torch.stack([F.linear(part.clone(), weight, bias) for part in x])


class Linear(nn.Linear):
    """``nn.Linear`` (the same parameters and state dict) whose deployment is row-invariant (:func:`linear`)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return linear(x, self.weight, self.bias)


def attention(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, mask: torch.Tensor | None = None,
              dropout_p: float = 0.0) -> torch.Tensor:
    """``F.scaled_dot_product_attention`` over ``(B, heads, tokens, d)`` with a boolean ``mask``
    (True: attend); without gradients, by batched products (one small product per episode and
    head, the fused kernel's blocking across episodes avoided) and a softmax per row."""
    if torch.is_grad_enabled():
        return F.scaled_dot_product_attention(q, k, v, attn_mask=mask, dropout_p=dropout_p)
    scores = torch.matmul(q, k.transpose(-2, -1)) / math.sqrt(q.shape[-1])
    if mask is not None:
        scores = scores.masked_fill(~mask, float("-inf"))
    return torch.matmul(torch.softmax(scores, dim=-1), v)


@contextlib.contextmanager
def rows_apart(module: nn.Module) -> Iterator[nn.Module]:
    """``module`` (a network built from ``nn.Linear``: an SB3 policy) acting with every
    ``nn.Linear`` in it as a :class:`Linear` for the block, then as it was: the network trains
    with its own kernels between two evaluations."""
    plain = [m for m in module.modules() if type(m) is nn.Linear]
    for m in plain:
        m.__class__ = Linear  # the same object, parameters and hooks; only its forward differs
    try:
        yield module
    finally:
        for m in plain:
            m.__class__ = nn.Linear
