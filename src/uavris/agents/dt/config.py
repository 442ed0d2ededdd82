"""The size and layout of a Decision Transformer: :class:`DTConfig`.

Lives here: :class:`DTConfig` and the attention layouts (:data:`ATTENTION_LAYOUTS`). Not
here: the model built from it (:mod:`.model`), its key/value cache (:mod:`.cache`), the
state encoders it names (:mod:`.encoders`) and the run that trains it
(:class:`uavris.experiments.training.pretrain.PretrainConfig`, whose ``model`` it is).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Annotated, Literal, get_args

from tyro.conf import Suppress

from uavris.agents.dt.encoders import STATE_ENCODERS, StateEncoder, device_layout
from uavris.config import DictConfig, SystemConfig
from uavris.errors import ConfigError

Attention = Literal["window", "banded"]  # the DT's attention layout (--model.attention)
ATTENTION_LAYOUTS: tuple[str, ...] = get_args(Attention)


@dataclass(frozen=True)
class DTConfig(DictConfig):
    """Size of a Decision Transformer. Defaults are the DT paper's (context 20, width 128,
    3 layers, 1 head, dropout 0.1, MLP 4x width with ReLU). The sizes of the data
    (``state_dim``, ``act_dim``, ``max_timestep``, ``devices``, ``elements``) are the dataset's:
    0 in a model a run is asked to train (:class:`~uavris.experiments.training.pretrain.PretrainConfig`),
    set when the dataset is read (:meth:`for_data`)."""

    # The data's sizes: not flags of the command line (tyro.conf.Suppress), the dataset gives them.
    state_dim: Annotated[int, Suppress] = 0  # observation entries (0: not known until a dataset gives them)
    act_dim: Annotated[int, Suppress] = 0  # action entries (likewise)
    context: int = 20  # slots per window (3 tokens each)
    width: int = 128  # embedding width
    depth: int = 3  # transformer blocks
    heads: int = 1  # attention heads (width a multiple of them)
    dropout: float = 0.1  # dropout rate in training
    max_timestep: Annotated[int, Suppress] = 100  # size of the timestep embedding (the data's horizon)
    mlp_ratio: int = 4  # the blocks' MLP width over the embedding width
    attention: Attention = "window"  # "window" (DT paper) or "banded" (cached deployment); see the module docstring
    condition_on_return: bool = True  # False: R_hat is replaced by 0, so the model is behaviour cloning
    state_encoder: StateEncoder = "flat"  # "flat" (DT paper) or "devices" (a hall as a set of devices, .encoders)
    devices: Annotated[int, Suppress] = 0  # the system's devices K (the device encoder's; 0 for flat)
    elements: Annotated[int, Suppress] = 0  # the system's RIS elements N (the device encoder's; 0 for flat)
    ris_frame: bool = False  # the device encoder also reads each device's elevation above the RIS plane
    goal: bool = False  # the controller is told where to go: the goal's offset from the UAV joins each state token

    def __post_init__(self) -> None:
        for name in ("state_dim", "act_dim", "context", "width", "depth", "heads", "max_timestep", "mlp_ratio"):
            v = getattr(self, name)
            low = 0 if name in ("state_dim", "act_dim") else 1
            if not isinstance(v, int) or isinstance(v, bool) or v < low:
                raise ConfigError(f"DTConfig.{name} must be an integer >= {low}, got {v!r}")
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
        if self.state_encoder == "devices" and self.state_dim:
            device_layout(self.state_dim, self.devices, self.elements)

    @property
    def sized(self) -> bool:
        """Whether the data's sizes are set (a model can be built)."""
        return self.state_dim > 0 and self.act_dim > 0

    def for_data(self, system: SystemConfig, act_dim: int) -> DTConfig:
        """This model for data of ``system`` with ``act_dim`` action entries: its observation's
        entries, its horizon, and for the device-set encoder its devices and RIS elements
        (which need the devices observed)."""
        if self.state_encoder == "devices" and not system.observe_devices:
            raise ConfigError("the state encoder 'devices' needs a dataset whose observations hold the devices "
                              "(SystemConfig.observe_devices, the deployment track's)")
        sized = dict(devices=system.num_users, elements=system.num_elements) if self.state_encoder == "devices" else {}
        return replace(self, state_dim=system.observation_dim, act_dim=act_dim, max_timestep=system.horizon, **sized)

    @property
    def band(self) -> int | None:
        """Keys a token attends to (itself included) in the banded layout; None for window."""
        return 3 * self.context - 1 if self.attention == "banded" else None
