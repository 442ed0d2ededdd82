"""How the Decision Transformer turns an observation into its state token.

Lives here: the two state encoders (:class:`FlatEncoder`, :class:`DeviceSetEncoder`), the
choice between them (:data:`StateEncoder`, :func:`make_state_encoder`) and the state
normalisation the device encoder needs (:func:`pooled_over_devices`, laid out for another
number of devices by :func:`stats_for_devices`). Not here: the model
that reads the tokens (:mod:`.model`), the observation itself
(:mod:`uavris.env.simulator`, docs/model.md section 15 and docs/study.md section 2).

- ``"flat"`` (the DT paper's): one linear map of the whole normalised observation. It has
  no notion that a hall is a set of devices: list a layout's devices in another order and
  the same hall gives another state, and other actions.
- ``"devices"`` (deployments, ``SystemConfig.observe_devices``): a hall is a set of devices.
  Each device ``k`` gets one feature vector from what the observation holds about it (its
  offset from the UAV, its channel row ``h_k`` of eq. (1), its role in the slot's pairing
  P(t) and its partner's offset and channel), one network shared by every device maps it,
  and a symmetric pooling (the element-wise maximum and mean over the devices) reads the
  set; the UAV's own features (position, velocity, attitude, energy, time) join after the
  pooling. Listing the devices in another order changes no bit of the token: the features
  are per device, the partner's are selected by the 0/1 pairing matrix (a sum of one value
  and exact zeros), and the mean is taken over values sorted per feature, so that the
  order of the additions does not depend on the order of the devices. (Permutation-
  invariant set encoders after Zaheer et al., "Deep Sets", NeurIPS 2017; graph networks
  for radio resource management read a wireless layout the same way.)

Normalisation: the flat encoder standardises every entry by its own mean and std over the
dataset. For the device encoder these statistics must not depend on the device's index,
or the order would come back through them: :func:`pooled_over_devices` replaces them by
statistics pooled over the devices (per RIS element, per axis, over the whole pairing).

Any number of devices: no weight of the device encoder has the number of devices K in its
shape (the networks are per device and per pair, the pooling is a maximum and a mean), and
pooled statistics are the same for every device. A model trained on halls of K devices
therefore reads halls of K' devices with the same weights (:meth:`DecisionTransformer.for_devices
<uavris.agents.dt.model.DecisionTransformer.for_devices>`): zero-shot across the count, which
docs/halls.md measures.
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from uavris.agents.row_invariant import Linear, linear
from uavris.env.simulator import observation_slices
from uavris.errors import ConfigError

StateEncoder = Literal["flat", "devices"]  # the DT's state encoder (--model.state-encoder)
STATE_ENCODERS: tuple[str, ...] = get_args(StateEncoder)
UAV_SLICES = ("position", "velocity", "attitude_sin", "attitude_cos", "energy_remaining", "time_fraction")
PER_DEVICE_SLICES = ("channel_real", "channel_imag", "devices")
RIS_FRAME_SCALE = 10.0  # the elevation feature's scale: a device 3 degrees in front reads 0.52, at the plane 0


def device_layout(state_dim: int, devices: int, elements: int) -> dict[str, slice]:
    """The observation slices of a deployment observation with ``devices`` devices and
    ``elements`` RIS elements, checked against ``state_dim``."""
    if devices < 2 or elements < 1:
        raise ConfigError(f"the device encoder needs the system's devices (>= 2) and RIS elements (>= 1), "
                          f"got {devices} and {elements}")
    lay = observation_slices(devices, elements, True)
    if lay["devices"].stop != state_dim:
        raise ConfigError(f"the device encoder reads observations with the devices' positions "
                          f"(SystemConfig.observe_devices): {lay['devices'].stop} entries for {devices} devices, "
                          f"got state_dim {state_dim}")
    return lay


def devices_of_width(width: int, elements: int) -> int:
    """The number of devices whose deployment observation (devices observed, ``elements`` RIS
    elements) has ``width`` entries; one :class:`ConfigError` line where none has."""
    k = 2
    while observation_slices(k, elements, True)["devices"].stop < width:
        k += 1
    if observation_slices(k, elements, True)["devices"].stop != width:
        raise ConfigError(f"an observation of {width} entries is no hall's with {elements} RIS elements and the "
                          "devices observed")
    return k


def _uav_index(lay: dict[str, slice]) -> torch.Tensor:
    return torch.cat([torch.arange(lay[s].start, lay[s].stop) for s in UAV_SLICES])


class FlatEncoder(Linear):
    """One linear map of the whole normalised observation (the DT paper's state embedding)."""

    def forward(self, raw: torch.Tensor, normalised: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        return linear(normalised, self.weight, self.bias)


def _sorted_sum(x: torch.Tensor) -> torch.Tensor:
    """The sum over axis -2 of ``x``'s values sorted per feature (an odd-even transposition
    network of ``torch.minimum``/``torch.maximum``, exact), without a gradient: the same bits
    whatever the order of the slices."""
    with torch.no_grad():
        v = list(x.unbind(dim=-2))
        for rnd in range(len(v)):
            for i in range(rnd % 2, len(v) - 1, 2):
                v[i], v[i + 1] = torch.minimum(v[i], v[i + 1]), torch.maximum(v[i], v[i + 1])
        total = v[0]
        for item in v[1:]:
            total = total + item
    return total


def _pool(x: torch.Tensor, k: int) -> torch.Tensor:
    """Maximum and mean over axis -2 (the devices), concatenated, for ``x >= 0`` (ReLU
    outputs). The mean's value is the sum of the values sorted per feature, so it does not
    depend on the order of the devices to the last bit; its gradient is the plain sum's
    (a sum's gradient does not depend on the order of its terms): ``s + (t - s)`` is ``t``
    exactly, since two sums of the same non-negative terms are within a factor of two of
    each other and their difference is then exact (Sterbenz)."""
    plain = x.sum(dim=-2)
    total = plain + (_sorted_sum(x) - plain).detach()
    return torch.cat([x.amax(dim=-2), total / k], dim=-1)


class DeviceSetEncoder(nn.Module):
    """The permutation-invariant state encoder (module docstring).

    Per-device features (``3 + 2 N + 2 + 3 + 2 N``): the device's normalised offset, its
    normalised channel (real and imaginary parts), whether it transmits and whether it
    receives in this slot (from the raw pairing, exact 0/1), and its partner's normalised
    offset and channel (zeros when it is idle). Relations: where the system is best depends
    on the devices jointly (a pose serves pairs of devices), which a sum of per-device terms
    represents poorly, so every ordered pair ``(k, j)`` of devices is read by a shared pair
    network and pooled over ``j`` into device ``k``'s relations (a second-order set encoder)
    before the devices are pooled.
    """

    def __init__(self, state_dim: int, width: int, devices: int, elements: int, ris_frame: bool = False) -> None:
        super().__init__()
        self.k, self.n, self.ris_frame = devices, elements, ris_frame
        self.layout = device_layout(state_dim, devices, elements)
        self.uav_index = _uav_index(self.layout)
        self._counts: dict[int, tuple[int, dict[str, slice], torch.Tensor]] = {}  # other widths: other counts
        own = 3 + 2 * elements + (1 if ris_frame else 0)
        per_device = own + 2 + own
        self.pair_net = nn.Sequential(Linear(2 * per_device, width), nn.ReLU(), Linear(width, width), nn.ReLU())
        self.device_net = nn.Sequential(Linear(per_device + 2 * width, width), nn.ReLU(), Linear(width, width),
                                        nn.ReLU())
        self.combine = Linear(2 * width + len(self.uav_index), width)

    def geometry(self, width: int) -> tuple[int, dict[str, slice], torch.Tensor]:
        """(devices, observation slices, the UAV's entries) of an observation of ``width``
        entries: the model's own count, or any other (no weight depends on it)."""
        if width == self.layout["devices"].stop:
            return self.k, self.layout, self.uav_index
        if width not in self._counts:
            k = devices_of_width(width, self.n)
            lay = observation_slices(k, self.n, True)
            self._counts[width] = (k, lay, _uav_index(lay))
        return self._counts[width]

    def device_features(self, raw: torch.Tensor, normalised: torch.Tensor) -> torch.Tensor:
        """``(..., K, F)``: each device's features, in the layout's order."""
        k, lay, _ = self.geometry(raw.shape[-1])
        n = self.n
        lead = raw.shape[:-1]
        offset = normalised[..., lay["devices"]].reshape(*lead, k, 3)
        channel = torch.cat([normalised[..., lay["channel_real"]].reshape(*lead, k, n),
                             normalised[..., lay["channel_imag"]].reshape(*lead, k, n)], dim=-1)
        pairing = raw[..., lay["pairing"]].reshape(*lead, k, k)  # P[tx, rx]
        partner = pairing + pairing.transpose(-1, -2)  # a device has at most one partner: one 1 per row
        own = torch.cat([offset, channel], dim=-1)
        if self.ris_frame:
            own = torch.cat([own, RIS_FRAME_SCALE * self.elevations(raw).unsqueeze(-1)], dim=-1)
        role = torch.stack([pairing.sum(-1), pairing.sum(-2)], dim=-1)
        return torch.cat([own, role, partner @ own], dim=-1)

    def pair_features(self, f: torch.Tensor) -> torch.Tensor:
        """``(..., K, K, W)``: the pair network on every ordered pair ``[f_k, f_j]``. Its first
        layer is linear in the concatenation, ``W_1 [f_k, f_j] = W_1a f_k + W_1b f_j``: the two
        halves are applied once per device and added per pair (the same function as the
        network on the concatenated pairs, at a K-th of the first layer's work)."""
        first, second = self.pair_net[0], self.pair_net[2]
        half = f.shape[-1]
        mine = linear(f, first.weight[:, :half], first.bias)  # (..., K, W): W_1a f_k + b
        theirs = linear(f, first.weight[:, half:])  # (..., K, W): W_1b f_j
        hidden = (mine.unsqueeze(-2) + theirs.unsqueeze(-3)).relu_()  # (..., K, K, W), [k, j]; in place: a temporary
        return second(hidden).relu_()

    def elevations(self, raw: torch.Tensor) -> torch.Tensor:
        """``(..., K)``: each device's ``cos(theta)`` at the RIS, the sine of its elevation above
        the RIS plane (negative: behind it, docs/model.md section 3), from the raw observation:
        the device's offset from the UAV and the attitude's sines and cosines give the plane's
        normal ``n = R(zeta) e_z`` (eq. 10) and ``cos(theta_k) = <q_U - q_k, n> / |q_U - q_k|``."""
        k, lay, _ = self.geometry(raw.shape[-1])
        offset = raw[..., lay["devices"]].reshape(*raw.shape[:-1], k, 3)  # (q_k - q_U) / scale
        s, c = raw[..., lay["attitude_sin"]], raw[..., lay["attitude_cos"]]  # yaw, pitch, roll
        sy, sp, sr, cy, cp, cr = s[..., 0], s[..., 1], s[..., 2], c[..., 0], c[..., 1], c[..., 2]
        normal = torch.stack([cy * sp * cr + sy * sr, sy * sp * cr - cy * sr, cp * cr], dim=-1)  # (..., 3)
        along = (offset * normal.unsqueeze(-2)).sum(dim=-1)
        return -along / offset.norm(dim=-1).clamp_min(1e-9)

    def forward(self, raw: torch.Tensor, normalised: torch.Tensor) -> torch.Tensor:
        f = self.device_features(raw, normalised)  # (..., K, F)
        k, _, uav_index = self.geometry(raw.shape[-1])
        relations = _pool(self.pair_features(f), k)  # (..., K, 2W): device k's view of every j
        per_device = self.device_net(torch.cat([f, relations], dim=-1))
        uav = normalised[..., uav_index.to(normalised.device)]
        return self.combine(torch.cat([_pool(per_device, k), uav], dim=-1))


def make_state_encoder(kind: str, state_dim: int, width: int, devices: int = 0, elements: int = 0,
                       ris_frame: bool = False) -> nn.Module:
    """The state encoder named ``kind`` (:data:`STATE_ENCODERS`)."""
    if kind == "flat":
        return FlatEncoder(state_dim, width)
    if kind == "devices":
        return DeviceSetEncoder(state_dim, width, devices, elements, ris_frame)
    raise ConfigError(f"unknown state encoder {kind!r}; choose one of {', '.join(STATE_ENCODERS)}")


def pooled_over_devices(mean: NDArray[np.float64], std: NDArray[np.float64], devices: int, elements: int
                        ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """State statistics with every per-device entry replaced by its pool over the devices:
    channel entries per RIS element, offsets per axis, the pairing over all its entries (the
    pooled variance of equally many samples: the mean of the variances plus the variance of
    the means). The UAV's own entries are unchanged."""
    lay = observation_slices(devices, elements, True)
    mean, std = np.array(mean, dtype=np.float64), np.array(std, dtype=np.float64)
    groups = [(s, (devices, -1)) for s in PER_DEVICE_SLICES] + [("pairing", (1, -1))]
    for name, shape in groups:
        sl = lay[name]
        m, s = mean[sl].reshape(shape), std[sl].reshape(shape)
        if name == "pairing":
            m, s = m.reshape(-1, 1), s.reshape(-1, 1)
        pooled_m = m.mean(axis=0)
        pooled_v = (s**2 + m**2).mean(axis=0) - pooled_m**2
        mean[sl] = np.broadcast_to(pooled_m, m.shape).reshape(-1)
        std[sl] = np.broadcast_to(np.sqrt(np.maximum(pooled_v, 0.0)), m.shape).reshape(-1)
    return mean, std


def stats_for_devices(mean: NDArray[np.float64], std: NDArray[np.float64], devices: int, elements: int,
                      to: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Pooled state statistics (:func:`pooled_over_devices`: every device's entries the same)
    of observations with ``devices`` devices, laid out for ``to`` devices: the first device's
    entries repeated ``to`` times, the pairing's first entry filling its ``to x to`` entries,
    the UAV's own entries unchanged (only their place in the observation moves)."""
    src, dst = observation_slices(devices, elements, True), observation_slices(to, elements, True)
    out_mean, out_std = np.zeros(dst["devices"].stop), np.ones(dst["devices"].stop)
    for name in src:
        a, b = src[name], dst[name]
        if name in PER_DEVICE_SLICES:
            one = slice(a.start, a.start + (a.stop - a.start) // devices)  # the first device's entries
            out_mean[b], out_std[b] = np.tile(mean[one], to), np.tile(std[one], to)
        elif name == "pairing":
            out_mean[b], out_std[b] = mean[a.start], std[a.start]
        else:
            out_mean[b], out_std[b] = mean[a], std[a]
    return out_mean, out_std
