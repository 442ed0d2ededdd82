"""The Decision Transformer of the paper's Sec. IV (after Chen et al., NeurIPS 2021).

A trajectory (paper eq. 14) is read as a sequence of tokens, three per slot t:
return-to-go R_hat_t (eq. 15), state S_t (the environment's observation vector) and
action A_t, in that order. Each kind has its own linear embedding; a learned timestep
embedding (the slot index t within the episode) is added to all three, as in the DT
paper. A causal pre-LayerNorm transformer (PyTorch's ``scaled_dot_product_attention``)
reads them, and a tanh head predicts A_t from the output at the state token S_t, which
has seen R_hat_<=t, S_<=t and A_<t only.

Context: the model sees the last ``context`` slots. Shorter histories (the start of an
episode) are left-padded; ``valid`` marks the real slots, and padded slots are masked out
as attention keys, so they never change the prediction of a real slot.

Two exact savings, both invisible in the outputs:

- the action token of the last slot of a window is dropped, because no state token of the
  window comes after it (at deployment it does not exist yet);
- the last block computes its queries only at the state tokens that are read out (all of
  them in training, only the last one at deployment), since the other outputs of the last
  block are never used.

Normalisation travels with the weights: ``state_mean``, ``state_std`` and ``return_scale``
are buffers (saved in the safetensors file) computed from the training dataset; the model
takes raw observations and raw returns-to-go (bps/Hz summed over slots).

Checkpoint format: a directory with ``model.safetensors`` (every parameter and buffer, no
pickle) and ``model.json`` (``kind``, ``format_version``, the :class:`DTConfig` and
caller-supplied metadata), both written atomically.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from uavris.atomic import atomic_write_bytes

from uavris.config import ConfigError

MODEL_KIND = "uavris-decision-transformer"
MODEL_FORMAT_VERSION = 1
WEIGHTS_FILE = "model.safetensors"
META_FILE = "model.json"


class CheckpointError(ValueError):
    """A DT checkpoint directory that is missing, corrupt or does not fit the model."""


@dataclass(frozen=True)
class DTConfig:
    """Size of a Decision Transformer. Defaults are the DT paper's (context 20, width 128,
    3 layers, 1 head, dropout 0.1, MLP 4x width with ReLU)."""

    state_dim: int
    act_dim: int
    context: int = 20  # slots per window (3 tokens each)
    width: int = 128
    depth: int = 3
    heads: int = 1
    dropout: float = 0.1
    max_timestep: int = 100  # size of the timestep embedding; later slots reuse the last entry
    mlp_ratio: int = 4

    def __post_init__(self) -> None:
        for name in ("state_dim", "act_dim", "context", "width", "depth", "heads", "max_timestep", "mlp_ratio"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ConfigError(f"DTConfig.{name} must be an integer >= 1, got {v!r}")
        if self.width % self.heads:
            raise ConfigError(f"DTConfig.width ({self.width}) must be a multiple of heads ({self.heads})")
        if not (isinstance(self.dropout, (int, float)) and 0.0 <= self.dropout < 1.0):
            raise ConfigError(f"DTConfig.dropout must be in [0, 1), got {self.dropout!r}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> DTConfig:
        known = {f.name for f in dataclasses.fields(cls)}
        if not isinstance(d, dict) or set(d) - known:
            raise ConfigError(f"DTConfig fields must be among {sorted(known)}, got {d!r}")
        try:
            return cls(**d)
        except TypeError as e:
            raise ConfigError(f"bad DTConfig: {e}") from None


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
        self.query = nn.Linear(w, w)
        self.key_value = nn.Linear(w, 2 * w)
        self.proj = nn.Linear(w, w)
        self.norm2 = nn.LayerNorm(w)
        self.mlp = nn.Sequential(nn.Linear(w, cfg.mlp_ratio * w), nn.ReLU(), nn.Linear(cfg.mlp_ratio * w, w))
        self.drop = nn.Dropout(cfg.dropout)

    def forward(self, x: torch.Tensor, mask: torch.Tensor, query_index: torch.Tensor | None = None) -> torch.Tensor:
        b, n, w = x.shape
        h = self.heads
        y = self.norm1(x)
        k, v = self.key_value(y).view(b, n, 2, h, w // h).permute(2, 0, 3, 1, 4)
        if query_index is not None:
            x, y, mask = x[:, query_index], y[:, query_index], mask[:, :, query_index]
        q = self.query(y).view(b, -1, h, w // h).transpose(1, 2)
        att = F.scaled_dot_product_attention(q, k, v, attn_mask=mask,
                                             dropout_p=self.dropout if self.training else 0.0)
        x = x + self.drop(self.proj(att.transpose(1, 2).reshape(b, -1, w)))
        return x + self.drop(self.mlp(self.norm2(x)))


class DecisionTransformer(nn.Module):
    """Predicts A_t from (R_hat, S, A) histories; see the module docstring."""

    def __init__(self, cfg: DTConfig, state_mean: np.ndarray | None = None, state_std: np.ndarray | None = None,
                 return_scale: float = 1.0) -> None:
        super().__init__()
        self.cfg = cfg
        w = cfg.width
        self.embed_return = nn.Linear(1, w)
        self.embed_state = nn.Linear(cfg.state_dim, w)
        self.embed_action = nn.Linear(cfg.act_dim, w)
        self.embed_timestep = nn.Embedding(cfg.max_timestep, w)
        self.embed_norm = nn.LayerNorm(w)
        self.embed_drop = nn.Dropout(cfg.dropout)
        self.blocks = nn.ModuleList(_Block(cfg) for _ in range(cfg.depth))
        self.final_norm = nn.LayerNorm(w)
        self.action_head = nn.Linear(w, cfg.act_dim)
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
                timesteps: torch.Tensor, valid: torch.Tensor | None = None, last_only: bool = False) -> torch.Tensor:
        """Predicted actions.

        Args:
            returns_to_go: ``(B, L)`` raw R_hat_t.
            states: ``(B, L, state_dim)`` raw observations.
            actions: ``(B, L, act_dim)``; the last slot's action is never read.
            timesteps: ``(B, L)`` slot index within the episode (long).
            valid: ``(B, L)`` bool, False at (left) padding; None means all real.
            last_only: predict only the last slot's action.
        Returns:
            ``(B, L, act_dim)`` in (-1, 1), or ``(B, act_dim)`` with ``last_only``.
        """
        b, length = returns_to_go.shape
        t = timesteps.clamp(0, self.cfg.max_timestep - 1)
        time_emb = self.embed_timestep(t)
        r = self.embed_return((returns_to_go / self.return_scale).unsqueeze(-1)) + time_emb
        s = self.embed_state((states - self.state_mean) / self.state_std) + time_emb
        a = self.embed_action(actions) + time_emb
        n = 3 * length - 1  # the last slot's action token is dropped (nothing reads it)
        x = torch.stack((r, s, a), dim=2).reshape(b, 3 * length, -1)[:, :n]
        x = self.embed_drop(self.embed_norm(x))
        mask = attention_mask(valid, length, b, x.device)
        readout = torch.arange(1, n, 3, device=x.device)  # state tokens
        if last_only:
            readout = readout[-1:]
        for block in self.blocks[:-1]:
            x = block(x, mask)
        x = self.blocks[-1](x, mask, readout)
        out = torch.tanh(self.action_head(self.final_norm(x)))
        return out[:, -1] if last_only else out

    @property
    def normalisation(self) -> dict[str, Any]:
        return {"state_mean": self.state_mean.tolist(), "state_std": self.state_std.tolist(),
                "return_scale": float(self.return_scale)}


def attention_mask(valid: torch.Tensor | None, length: int, batch: int, device: torch.device) -> torch.Tensor:
    """Boolean ``(B, 1, n, n)`` mask over the ``n = 3 L - 1`` tokens: True where a query may
    attend. Causal, and padded keys are hidden; a padded query keeps its own key so its row
    is never empty (an all-masked row would give NaN, and its output is never read)."""
    n = 3 * length - 1
    causal = torch.ones(n, n, dtype=torch.bool, device=device).tril()
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


def masked_action_loss(pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Mean squared action error over the real slots: the paper's L_OFF (eq. 16) and L_FT
    (eq. 19), E ||A - A_hat||^2, divided by ``act_dim`` (a per-component MSE)."""
    err = (pred - target).pow(2).mean(dim=-1)
    w = valid.to(err.dtype)
    return (err * w).sum() / w.sum().clamp_min(1.0)


# ------------------------------------------------------------------------------ checkpoints
def save_dt(model: DecisionTransformer, directory: str | Path, metadata: dict[str, Any] | None = None) -> Path:
    """Write ``model.safetensors`` then ``model.json`` into ``directory``; returns it.

    The JSON goes last, so a directory whose ``model.json`` exists has matching weights.
    """
    from safetensors.torch import save

    directory = Path(directory)
    tensors = {k: v.detach().contiguous().clone() for k, v in model.state_dict().items()}
    atomic_write_bytes(directory / WEIGHTS_FILE, save(tensors))
    meta = {"kind": MODEL_KIND, "format_version": MODEL_FORMAT_VERSION, "config": model.cfg.to_dict(),
            **(metadata or {})}
    atomic_write_bytes(directory / META_FILE, (json.dumps(meta, indent=2) + "\n").encode("utf-8"))
    return directory


def read_dt_metadata(directory: str | Path) -> dict[str, Any]:
    """The ``model.json`` of a DT checkpoint directory, checked for kind and version."""
    path = Path(directory) / META_FILE
    if not path.exists():
        raise CheckpointError(f"{directory} is not a DT checkpoint (no {META_FILE})")
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CheckpointError(f"{path} is corrupt ({e})") from None
    if not isinstance(meta, dict) or meta.get("kind") != MODEL_KIND:
        raise CheckpointError(f"{path} does not describe a uavris Decision Transformer")
    if meta.get("format_version") != MODEL_FORMAT_VERSION:
        raise CheckpointError(f"{path} has format version {meta.get('format_version')!r}; "
                              f"this uavris reads version {MODEL_FORMAT_VERSION}")
    return meta


def load_dt(directory: str | Path) -> tuple[DecisionTransformer, dict[str, Any]]:
    """Rebuild the model of a checkpoint directory (in eval mode) and return its metadata."""
    from safetensors import SafetensorError
    from safetensors.torch import load

    directory = Path(directory)
    meta = read_dt_metadata(directory)
    try:
        cfg = DTConfig.from_dict(meta.get("config"))
    except ConfigError as e:
        raise CheckpointError(f"{directory / META_FILE} has a bad model config: {e}") from None
    weights = directory / WEIGHTS_FILE
    if not weights.exists():
        raise CheckpointError(f"{weights} is missing")
    try:
        tensors = load(weights.read_bytes())
    except (SafetensorError, ValueError, OSError) as e:
        raise CheckpointError(f"{weights} is corrupt ({e})") from None
    model = DecisionTransformer(cfg)
    expected = model.state_dict()
    missing = sorted(set(expected) - set(tensors))
    extra = sorted(set(tensors) - set(expected))
    if missing or extra:
        raise CheckpointError(f"{weights} does not match its config (missing {missing[:3]}, unexpected {extra[:3]})")
    for name, t in tensors.items():
        if t.shape != expected[name].shape:
            raise CheckpointError(f"{weights}: {name} has shape {tuple(t.shape)}, "
                                  f"the config needs {tuple(expected[name].shape)}")
        if not torch.isfinite(t).all():
            raise CheckpointError(f"{weights}: {name} contains NaN or inf")
    model.load_state_dict(tensors)
    if float(model.return_scale) <= 0 or bool((model.state_std <= 0).any()):
        raise CheckpointError(f"{weights} has invalid normalisation (non-positive scale)")
    model.eval()
    return model, meta
