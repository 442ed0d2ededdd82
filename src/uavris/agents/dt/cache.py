"""The banded DT's key/value cache: three new tokens per slot at deployment.

Lives here: :class:`KVCache`, a fixed-size ring buffer of every block's keys and values.
Not here: the model that fills and reads it (:mod:`.model`).
"""

from __future__ import annotations

import numpy as np
import torch

from uavris.agents.dt.config import DTConfig


class KVCache:
    """Keys and values of each row's recent tokens, per block (banded DT), in a ring buffer.

    The ring has ``band + 2`` slots: the ``band - 1`` tokens a new slot's three tokens may
    attend to, plus room for those three, which overwrite the oldest entries in place (no
    copying of the cache per slot). Attention does not depend on the order of its keys, so
    only the mask needs each entry's position: ``position`` is the token index of each ring
    entry (all rows advance in lockstep), ``valid`` marks entries that hold a real token of
    the row's current episode (all False after :meth:`reset`), so rows may be at different
    slots of their episodes.
    """

    def __init__(self, cfg: DTConfig, batch: int, device: torch.device, dtype: torch.dtype) -> None:
        assert cfg.band is not None
        self.band = cfg.band
        size, h = cfg.band + 2, cfg.heads
        shape = (batch, h, size, cfg.width // h)
        self.keys = [torch.zeros(shape, device=device, dtype=dtype) for _ in range(cfg.depth)]
        self.values = [torch.zeros(shape, device=device, dtype=dtype) for _ in range(cfg.depth)]
        self.valid = torch.zeros(batch, size, dtype=torch.bool, device=device)
        self.position = torch.full((size,), -(10 ** 9), dtype=torch.long, device=device)
        self.next_position = 0

    def reset(self, rows: torch.Tensor | np.ndarray) -> None:
        """Forget the history of ``rows`` (they start new episodes)."""
        self.valid[torch.as_tensor(rows)] = False

    def insert(self, new_valid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Claim ring entries for ``m`` new tokens (``new_valid`` is (B, m)); returns those
        entries and the ``(B, 1, m, size)`` attention mask of the new tokens over the ring.
        Each block puts its keys and values there with :meth:`write` before attending."""
        m = new_valid.shape[1]
        new_positions = self.next_position + torch.arange(m, device=new_valid.device)
        slots = new_positions % self.valid.shape[1]
        self.position[slots] = new_positions
        self.valid[:, slots] = new_valid
        query = new_positions[:, None]
        in_band = (self.position[None, :] <= query) & (query - self.position[None, :] < self.band)
        own = self.position[None, :] == query  # an invalid new token keeps its own key (no NaN)
        self.next_position += m
        return slots, (in_band & (self.valid[:, None, :] | own)).unsqueeze(1)

    def write(self, block: int, slots: torch.Tensor, keys: torch.Tensor, values: torch.Tensor) -> None:
        self.keys[block][:, :, slots] = keys
        self.values[block][:, :, slots] = values
