"""The Decision Transformer of the paper's Sec. IV (after Chen et al., NeurIPS 2021).

A trajectory (paper eq. 14) is read as a sequence of tokens, three per slot t:
return-to-go R_hat_t (eq. 15), state S_t (the environment's observation vector) and
action A_t, in that order. Each kind has its own embedding (the state's: :mod:`.encoders`,
one linear map as in the DT paper, or a set encoder over the devices); a learned timestep
embedding (the slot index t within the episode) is added to all three, as in the DT
paper. A causal pre-LayerNorm transformer (PyTorch's ``scaled_dot_product_attention``)
reads them, and a tanh head predicts A_t from the output at the state token S_t, which
has seen R_hat_<=t, S_<=t and A_<t only.

Context: the model sees the last ``context`` slots. Shorter histories (the start of an
episode) are left-padded; ``valid`` marks the real slots, and padded slots are masked out
as attention keys, so they never change the prediction of a real slot.

Two attention layouts (``DTConfig.attention``):

- ``"window"`` (default; the DT paper's): at every slot the model re-reads a fresh window
  of the last ``context`` slots, so tokens that slide out of the window change every
  representation computed from them and nothing can be reused from the previous slot.
- ``"banded"`` (opt-in, a sliding-window / banded attention): the model reads the whole
  episode from slot 0, and every token attends to itself and the ``3 context - 2`` tokens
  before it, in every block. A token's keys and values then never change once computed,
  so deployment keeps them in a cache (:class:`KVCache`) and each slot costs three new
  tokens instead of ``3 context - 1``: exact, not an approximation. The first token of a
  slot sees the same ``3 context - 1`` tokens as the window layout at its first layer, but
  deeper blocks reach further back (``depth`` bands). The model is trained on whole
  episodes (:class:`uavris.agents.dt.training.TrainingWindows` with ``whole_episodes``).
  For histories of at most ``context`` slots both layouts compute the same function.

Two exact savings, both invisible in the outputs:

- the action token of the last slot of a window is dropped, because no state token of the
  window comes after it (at deployment it does not exist yet);
- the last block computes its queries only at the state tokens that are read out (all of
  them in training, only the last one at deployment), since the other outputs of the last
  block are never used.

Normalisation travels with the weights: ``state_mean``, ``state_std`` and ``return_scale``
are buffers (saved in the safetensors file) computed from the training dataset; the model
takes raw observations and raw returns-to-go (bps/Hz summed over slots).

Behaviour cloning (``DTConfig.condition_on_return=False``): the same model with every
R_hat replaced by 0, trained and deployed alike. It has the DT's parameters, compute and
data, so the difference between the two is what return conditioning does (Chen et al.
compare the DT with behaviour cloning the same way, on the same data).

Lives here: the model (:class:`DecisionTransformer`) and the attention masks
(:func:`attention_mask`). Not here: its configuration (:class:`~.config.DTConfig`, in
:mod:`.config`), its state encoders (:mod:`.encoders`), the key/value cache of the banded
layout (:mod:`.cache`), checkpoints (:mod:`.checkpoint`), training: the windows, the loss and
the steps (:mod:`.training`), and deployment (:mod:`.policy`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import torch
from torch import nn

from uavris.agents.dt.cache import KVCache
from uavris.agents.dt.config import DTConfig
from uavris.agents.dt.encoders import devices_of_width, make_state_encoder, stats_for_devices
from uavris.agents.dt.goals import GOAL_DIM
from uavris.agents.row_invariant import Linear, attention
from uavris.env.simulator import observation_slices
from uavris.errors import ConfigError


class _Block(nn.Module):
    """Pre-LayerNorm transformer block: x + Attn(LN(x)), then x + MLP(LN(x))."""

    def __init__(self, cfg: DTConfig) -> None:
        super().__init__()
        w = cfg.width
        self.heads = cfg.heads
        self.dropout = cfg.dropout
        self.norm1 = nn.LayerNorm(w)
        # Separate query and key/value projections, so the last block can project queries
        # for the read-out tokens only.
        self.query = Linear(w, w)
        self.key_value = Linear(w, 2 * w)
        self.proj = Linear(w, w)
        self.norm2 = nn.LayerNorm(w)
        self.mlp = nn.Sequential(Linear(w, cfg.mlp_ratio * w), nn.ReLU(), Linear(cfg.mlp_ratio * w, w))
        self.drop = nn.Dropout(cfg.dropout)

    def forward(self, x: torch.Tensor, mask: torch.Tensor, query_index: torch.Tensor | None = None) -> torch.Tensor:
        b, n, w = x.shape
        y = self.norm1(x)
        k, v = self.key_value(y).view(b, n, 2, self.heads, w // self.heads).permute(2, 0, 3, 1, 4)
        return self._attend(x, y, k, v, mask, query_index)

    def forward_cached(self, x: torch.Tensor, mask: torch.Tensor, cache: KVCache, index: int, slots: torch.Tensor,
                       query_index: torch.Tensor | None = None) -> torch.Tensor:
        """As :meth:`forward` for new tokens ``x``, whose keys and values go into ring
        entries ``slots`` of block ``index`` of ``cache``; they attend over the whole ring."""
        b, n, w = x.shape
        y = self.norm1(x)
        k, v = self.key_value(y).view(b, n, 2, self.heads, w // self.heads).permute(2, 0, 3, 1, 4)
        cache.write(index, slots, k, v)
        return self._attend(x, y, cache.keys[index], cache.values[index], mask, query_index)

    def _attend(self, x: torch.Tensor, y: torch.Tensor, k: torch.Tensor, v: torch.Tensor, mask: torch.Tensor,
                query_index: torch.Tensor | None) -> torch.Tensor:
        b, _, w = x.shape
        if query_index is not None:
            x, y, mask = x[:, query_index], y[:, query_index], mask[:, :, query_index]
        q = self.query(y).view(b, -1, self.heads, w // self.heads).transpose(1, 2)
        att = attention(q, k, v, mask, self.dropout if self.training else 0.0)
        x = x + self.drop(self.proj(att.transpose(1, 2).reshape(b, -1, w)))
        return x + self.drop(self.mlp(self.norm2(x)))


class DecisionTransformer(nn.Module):
    """Predicts A_t from (R_hat, S, A) histories; see the module docstring."""

    def __init__(self, cfg: DTConfig, state_mean: np.ndarray | None = None, state_std: np.ndarray | None = None,
                 return_scale: float = 1.0) -> None:
        super().__init__()
        if not cfg.sized:
            raise ConfigError("a DT is built for data of known sizes: DTConfig.for_data(system, act_dim) sets them")
        self.cfg = cfg
        w = cfg.width
        self.embed_return = Linear(1, w)
        self.embed_state = make_state_encoder(cfg.state_encoder, cfg.state_dim, w, cfg.devices, cfg.elements,
                                              cfg.ris_frame)
        self.embed_action = Linear(cfg.act_dim, w)
        self.embed_timestep = nn.Embedding(cfg.max_timestep, w)
        self.embed_norm = nn.LayerNorm(w)
        self.embed_drop = nn.Dropout(cfg.dropout)
        self.blocks = nn.ModuleList(_Block(cfg) for _ in range(cfg.depth))
        self.final_norm = nn.LayerNorm(w)
        self.action_head = Linear(w, cfg.act_dim)
        # A goal-conditioned controller reads where it is told to go, added to each state token
        # (created last, so that a model without a goal draws the same initial weights as before).
        self.embed_goal = Linear(GOAL_DIM, w) if cfg.goal else None
        mean = np.zeros(cfg.state_dim) if state_mean is None else np.asarray(state_mean, dtype=np.float64)
        std = np.ones(cfg.state_dim) if state_std is None else np.asarray(state_std, dtype=np.float64)
        if mean.shape != (cfg.state_dim,) or std.shape != (cfg.state_dim,) or np.any(std <= 0):
            raise ConfigError(f"state normalisation must be {cfg.state_dim} means and positive stds")
        if not (math.isfinite(return_scale) and return_scale > 0):
            raise ConfigError(f"return_scale must be a finite number > 0, got {return_scale!r}")
        self.register_buffer("state_mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("state_std", torch.as_tensor(std, dtype=torch.float32))
        self.register_buffer("return_scale", torch.tensor(float(return_scale), dtype=torch.float32))
        self.apply(_init_weights)

    def forward(self, returns_to_go: torch.Tensor, states: torch.Tensor, actions: torch.Tensor,
                timesteps: torch.Tensor, valid: torch.Tensor | None = None, last_only: bool = False,
                goals: torch.Tensor | None = None) -> torch.Tensor:
        """Predicted actions.

        Args:
            returns_to_go: ``(B, L)`` raw R_hat_t.
            states: ``(B, L, state_dim)`` raw observations.
            actions: ``(B, L, act_dim)``; the last slot's action is never read.
            timesteps: ``(B, L)`` slot index within the episode (long).
            valid: ``(B, L)`` bool, False at (left) padding; None means all real.
            last_only: predict only the last slot's action.
            goals: ``(B, L, 3)`` the goal's offset from the UAV at each slot (a goal-conditioned
                model's, :func:`uavris.agents.dt.goals.goal_offsets`; None for any other).
        Returns:
            ``(B, L, act_dim)`` in (-1, 1), or ``(B, act_dim)`` with ``last_only``.
        """
        b, length = returns_to_go.shape
        r, s, a = self._embed(returns_to_go, states, actions, timesteps, goals=goals)
        n = 3 * length - 1  # the last slot's action token is dropped (nothing reads it)
        x = torch.stack((r, s, a), dim=2).reshape(b, 3 * length, -1)[:, :n]
        x = self.embed_drop(self.embed_norm(x))
        mask = attention_mask(valid, length, b, x.device, self.cfg.band)
        readout = torch.arange(1, n, 3, device=x.device)  # state tokens
        if last_only:
            readout = readout[-1:]
        for block in self.blocks[:-1]:
            x = block(x, mask)
        x = self.blocks[-1](x, mask, readout)
        out = torch.tanh(self.action_head(self.final_norm(x)))
        return out[:, -1] if last_only else out

    def _embed(self, returns_to_go: torch.Tensor, states: torch.Tensor, actions: torch.Tensor,
               timesteps: torch.Tensor, action_timesteps: torch.Tensor | None = None,
               goals: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Token embeddings of R_hat, S and A (before the embedding LayerNorm), each with the
        timestep embedding of its slot added (``action_timesteps`` for A, if given), and the
        goal's embedding added to S for a goal-conditioned model."""
        top = self.cfg.max_timestep - 1
        time_emb = self.embed_timestep(timesteps.clamp(0, top))
        if not self.cfg.condition_on_return:
            # Behaviour cloning with the DT's own architecture and budget: the return token stays
            # (same parameters, same compute) but carries no information.
            returns_to_go = torch.zeros_like(returns_to_go)
        act_time = time_emb if action_timesteps is None else self.embed_timestep(action_timesteps.clamp(0, top))
        r = self.embed_return((returns_to_go / self.return_scale).unsqueeze(-1)) + time_emb
        mean, std = self.state_statistics(states.shape[-1])
        s = self.embed_state(states, (states - mean) / std) + time_emb
        if self.embed_goal is not None:
            if goals is None:
                raise ValueError("this DT is goal-conditioned: it needs the goal's offset at every slot (goals=)")
            s = s + self.embed_goal(goals)
        return r, s, self.embed_action(actions) + act_time

    def new_cache(self, batch: int) -> KVCache:
        """An empty key/value cache for ``batch`` episodes (banded layout only)."""
        if self.cfg.band is None:
            raise ValueError("only a DT with attention='banded' can act from a key/value cache")
        p = next(self.parameters())
        return KVCache(self.cfg, batch, p.device, p.dtype)

    def step(self, cache: KVCache, returns_to_go: torch.Tensor, states: torch.Tensor, prev_actions: torch.Tensor,
             timesteps: torch.Tensor, goals: torch.Tensor | None = None) -> torch.Tensor:
        """Predict A_t of every row from the cache plus three new tokens, and add them to it.

        The new tokens are A_{t-1}, R_hat_t and S_t (their order in the sequence). Equal to
        ``forward(..., last_only=True)`` on the whole episode so far (banded layout), at the
        cost of three tokens.

        Args:
            cache: the rows' cache (:meth:`new_cache`); updated in place.
            returns_to_go: ``(B,)`` raw R_hat_t.
            states: ``(B, state_dim)`` raw S_t.
            prev_actions: ``(B, act_dim)`` A_{t-1}; ignored where t = 0 (an episode's first slot has none).
            timesteps: ``(B,)`` t (long), the slot within each row's episode.
            goals: ``(B, 3)`` the goal's offset from the UAV (a goal-conditioned model's).
        Returns:
            ``(B, act_dim)`` in (-1, 1).
        """
        if self.training:
            raise RuntimeError("DecisionTransformer.step is for deployment: call model.eval() first")
        r, s, a = self._embed(returns_to_go[:, None], states[:, None], prev_actions[:, None], timesteps[:, None],
                              (timesteps - 1)[:, None], None if goals is None else goals[:, None])
        x = self.embed_norm(torch.cat((a, r, s), dim=1))
        real = torch.ones_like(timesteps, dtype=torch.bool)
        new_valid = torch.stack((timesteps > 0, real, real), dim=1)
        slots, mask = cache.insert(new_valid)
        readout = torch.tensor([2], device=x.device)  # S_t
        for i, block in enumerate(self.blocks):
            last = i == len(self.blocks) - 1
            x = block.forward_cached(x, mask, cache, i, slots, readout if last else None)
        return torch.tanh(self.action_head(self.final_norm(x)))[:, -1]

    def state_statistics(self, width: int) -> tuple[torch.Tensor, torch.Tensor]:
        """The state's mean and std for observations of ``width`` entries: the model's own,
        or, for the device encoder, laid out for the count whose observation has that width
        (:func:`~.encoders.stats_for_devices`), so one model trains on halls of mixed counts."""
        if width == self.cfg.state_dim:
            return self.state_mean, self.state_std
        if self.cfg.state_encoder != "devices":
            raise ConfigError(f"this DT reads {self.cfg.state_dim} observation entries, got {width}")
        to = devices_of_width(width, self.cfg.elements)  # a few hundred entries: not worth a cache to keep in sync
        mean, std = stats_for_devices(self.state_mean.double().cpu().numpy(), self.state_std.double().cpu().numpy(),
                                      self.cfg.devices, self.cfg.elements, to)
        where = self.state_mean.device
        return (torch.as_tensor(mean, dtype=torch.float32, device=where),
                torch.as_tensor(std, dtype=torch.float32, device=where))

    def for_devices(self, devices: int) -> DecisionTransformer:
        """This model reading observations of ``devices`` devices: the same weights (the
        device-set encoder has none whose shape depends on the count, :mod:`.encoders`), the
        state statistics laid out for the new count (:func:`~.encoders.stats_for_devices`).
        Only a model with the device encoder can; ``self`` where the count is its own."""
        cfg = self.cfg
        if devices == cfg.devices:
            return self
        if cfg.state_encoder != "devices":
            raise ConfigError(f"this DT reads {cfg.state_dim} observation entries (state encoder "
                              f"{cfg.state_encoder!r}); "
                              "only a DT with the device-set encoder (--model.state-encoder devices) reads another "
                              "number of devices")
        if not isinstance(devices, int) or devices < 2:
            raise ConfigError(f"a hall has at least 2 devices, got {devices!r}")
        state_dim = observation_slices(devices, cfg.elements, True)["devices"].stop
        mean, std = self.state_statistics(state_dim)
        other = DecisionTransformer(replace(cfg, state_dim=state_dim, devices=devices), mean.cpu().numpy(),
                                    std.cpu().numpy(), float(self.return_scale))
        weights = {k: v for k, v in self.state_dict().items() if k not in ("state_mean", "state_std")}
        missing, unexpected = other.load_state_dict(weights, strict=False)
        assert set(missing) == {"state_mean", "state_std"} and not unexpected, (missing, unexpected)
        other.train(self.training)
        return other.to(self.return_scale.device)

    @property
    def normalisation(self) -> dict[str, Any]:
        return {"state_mean": self.state_mean.tolist(), "state_std": self.state_std.tolist(),
                "return_scale": float(self.return_scale)}


def attention_mask(valid: torch.Tensor | None, length: int, batch: int, device: torch.device,
                   band: int | None = None) -> torch.Tensor:
    """Boolean ``(B, 1, n, n)`` mask over the ``n = 3 L - 1`` tokens: True where a query may
    attend. Causal (and, with ``band``, only the ``band`` latest keys), and padded keys are
    hidden; a padded query keeps its own key so its row is never empty (an all-masked row
    would give NaN, and its output is never read)."""
    n = 3 * length - 1
    causal = torch.ones(n, n, dtype=torch.bool, device=device).tril()
    if band is not None:
        causal = causal & ~torch.ones(n, n, dtype=torch.bool, device=device).tril(-band)
    if valid is None:
        return causal.expand(batch, 1, n, n)
    keys = valid.bool().repeat_interleave(3, dim=1)[:, :n]
    eye = torch.eye(n, dtype=torch.bool, device=device)
    return (causal & (keys[:, None, :] | eye)).unsqueeze(1)


def _init_weights(module: nn.Module) -> None:
    # GPT-2 initialisation, as in the DT paper's implementation.
    if isinstance(module, (nn.Linear, nn.Embedding)):
        nn.init.normal_(module.weight, mean=0.0, std=0.02)
        if isinstance(module, nn.Linear) and module.bias is not None:
            nn.init.zeros_(module.bias)
    elif isinstance(module, nn.LayerNorm):
        nn.init.ones_(module.weight)
        nn.init.zeros_(module.bias)
