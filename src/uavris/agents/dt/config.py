"""The size and layout of a Decision Transformer: :class:`DTConfig`.

Lives here: :class:`DTConfig` and the attention layouts (:data:`ATTENTION_LAYOUTS`). Not
here: the model built from it (:mod:`.model`), its key/value cache (:mod:`.cache`) and the
state encoders it names (:mod:`.encoders`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

from uavris.agents.dt.encoders import STATE_ENCODERS, StateEncoder, device_layout
from uavris.config import DictConfig
from uavris.errors import ConfigError

Attention = Literal["window", "banded"]  # the DT's attention layout (--attention)
ATTENTION_LAYOUTS: tuple[str, ...] = get_args(Attention)


@dataclass(frozen=True)
class DTConfig(DictConfig):
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
    attention: Attention = "window"  # "window" (DT paper) or "banded" (cached deployment); see the module docstring
    condition_on_return: bool = True  # False: R_hat is replaced by 0, so the model is behaviour cloning
    state_encoder: StateEncoder = "flat"  # "flat" (DT paper) or "devices" (a hall as a set of devices, .encoders)
    devices: int = 0  # the system's devices K (the device encoder's; 0 for flat)
    elements: int = 0  # the system's RIS elements N (the device encoder's; 0 for flat)
    ris_frame: bool = False  # the device encoder also reads each device's elevation above the RIS plane

    def __post_init__(self) -> None:
        for name in ("state_dim", "act_dim", "context", "width", "depth", "heads", "max_timestep", "mlp_ratio"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ConfigError(f"DTConfig.{name} must be an integer >= 1, got {v!r}")
        if self.width % self.heads:
            raise ConfigError(f"DTConfig.width ({self.width}) must be a multiple of heads ({self.heads})")
        if not (isinstance(self.dropout, (int, float)) and 0.0 <= self.dropout < 1.0):
            raise ConfigError(f"DTConfig.dropout must be in [0, 1), got {self.dropout!r}")
        if self.attention not in ATTENTION_LAYOUTS:
            raise ConfigError(f"DTConfig.attention must be one of {ATTENTION_LAYOUTS}, got {self.attention!r}")
        if not isinstance(self.condition_on_return, bool):
            raise ConfigError(f"DTConfig.condition_on_return must be true or false, got {self.condition_on_return!r}")
        if self.state_encoder not in STATE_ENCODERS:
            raise ConfigError(f"DTConfig.state_encoder must be one of {STATE_ENCODERS}, got {self.state_encoder!r}")
        if self.ris_frame and self.state_encoder != "devices":
            raise ConfigError("DTConfig.ris_frame needs state_encoder 'devices' (it is a feature of each device)")
        if self.state_encoder == "devices":
            device_layout(self.state_dim, self.devices, self.elements)

    @property
    def band(self) -> int | None:
        """Keys a token attends to (itself included) in the banded layout; None for window."""
        return 3 * self.context - 1 if self.attention == "banded" else None
