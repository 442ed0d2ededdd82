"""A learned value of a pose: ``V(devices, pose)``, the planner's ``R`` without its optimiser.

Lives here: :class:`PoseValue` (the network), :func:`device_features` (what it reads of each
device), :class:`ValueLabels` (poses, their halls and ``R``) and :func:`fit_value` (its
training). Not here: the labels' making (:mod:`.labels`), the argmax over a hall and the
planner built on it (:mod:`.planner`), checkpoints (:mod:`.checkpoint`).

``R(q)`` (:func:`uavris.agents.oracle.objective.expected_optimised_rate`) is the expected sum
rate of a UAV hovering level at ``q`` with the optimiser's phases every slot: tens of
milliseconds a pose (hundreds with 8 devices), so the planner can value only a few dozen
poses of a hall. ``V`` learns it from the devices as seen from the pose, and answers a whole
hall's grid in milliseconds; its argmax is a place (docs/places.md: fit the value of a pose,
which is smooth and unimodal in its input, and take its argmax, rather than regress the
place, which averages the modes).

The network is a set encoder (Deep Sets with pairs): each device ``i`` is described by its
offset from the pose and what follows from it (:func:`device_features`); a device network
embeds each; a pair network embeds every ordered pair ``(i, j)`` (both embeddings and the
devices' distance: a link and its interference); the pair embeddings' mean and the device
embeddings' mean, with ``1/K``, go through a head to ``R``. No weight's shape depends on
``K``, the means carry across counts, and any order of the devices gives the same value:
the means sum in a sorted order (:func:`_ordered_mean`), so what is left is how the CPU's
matrix kernels round a device's row at another place in the batch (bit for bit with
AVX-512 kernels; within 2 float32 ulps with AVX2 ones, as on an AMD EPYC of Zen 2/3).

A pose has an attitude: ``R`` of the RIS at ``q`` tilted by ``att`` is ``R`` of a level RIS at
``q`` whose devices are turned by the inverse rotation about it (the channel and the phases
see the devices only in the surface's frame: eq. (10)-(11); measured equal to 0.03% with the
optimiser's draws), so ``V`` reads a tilted pose as a level one in the devices' places seen from
the surface (:func:`in_ris_frame`), and learns the tilts from labels at tilted poses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from uavris import physics as ph
from uavris.config import DictConfig
from uavris.errors import ConfigError

FEATURES = 7  # per device: offset / 10 m (3), log(distance / 10 m), horizontal distance / 10 m, sin elevation, K
RATE_SCALE = 50.0  # bps/Hz: R / RATE_SCALE is of order 1


def device_features(users: NDArray | torch.Tensor, position: NDArray | torch.Tensor) -> torch.Tensor:
    """What :class:`PoseValue` reads of each device seen from ``position``: ``(..., K, FEATURES)``
    from devices ``(..., K, 3)`` and positions ``(..., 3)`` (m): the offset over 10 m, the log
    of the distance over 10 m (path loss is a power of it), the horizontal distance, the sine
    of the device's elevation below the RIS (a level RIS faces down: the incidence), and ``1/K``."""
    u = torch.as_tensor(users, dtype=torch.float32)
    q = torch.as_tensor(position, dtype=torch.float32)
    d = u - q.unsqueeze(-2)
    dist = d.norm(dim=-1, keepdim=True).clamp_min(0.1)
    k = torch.full_like(dist, 1.0 / u.shape[-2])
    return torch.cat([d / 10.0, torch.log(dist / 10.0), d[..., :2].norm(dim=-1, keepdim=True) / 10.0,
                      -d[..., 2:] / dist, k], dim=-1)


def in_ris_frame(users: NDArray, position: NDArray, attitude: NDArray) -> NDArray[np.float64]:
    """The devices ``(K, 3)`` (or ``(P, K, 3)``) as a level RIS at each position ``(P, 3)`` would
    see them where the RIS is tilted by ``attitude`` ``(P, 3)``: ``q + R(att)^T (u - q)``
    (eq. (10)'s rotation), ``(P, K, 3)``."""
    q = np.asarray(position, dtype=np.float64)
    att = np.asarray(attitude, dtype=np.float64)
    rot = ph.rotation_matrix(att[:, 0], att[:, 1], att[:, 2])  # (P, 3, 3): columns the RIS axes
    d = np.broadcast_to(np.asarray(users, dtype=np.float64), (len(q), *np.shape(users)[-2:])) - q[:, None]
    return q[:, None] + np.einsum("pkj,pji->pki", d, rot)


def _mlp(sizes: Sequence[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(a, b), nn.ReLU()]
    return nn.Sequential(*layers[:-1])


def _ordered_mean(x: torch.Tensor, dim: int) -> torch.Tensor:
    """The mean over ``dim`` of ``x``'s values sorted per feature: the same sum whatever the
    order of the devices (a sum in another order rounds differently)."""
    return torch.sort(x, dim=dim).values.mean(dim=dim)


@dataclass(frozen=True)
class ValueConfig(DictConfig):
    """The size of :class:`PoseValue`."""

    width: int = 64  # embedding width of the device and pair networks and of the head

    def __post_init__(self) -> None:
        if not isinstance(self.width, int) or isinstance(self.width, bool) or self.width < 1:
            raise ConfigError(f"ValueConfig.width must be an integer >= 1, got {self.width!r}")


class PoseValue(nn.Module):
    """``V(devices, position)`` ~ ``R`` (module docstring)."""

    def __init__(self, cfg: ValueConfig = ValueConfig()) -> None:
        super().__init__()
        self.cfg = cfg
        w = cfg.width
        self.device = _mlp([FEATURES, w, w])
        # the pair network's first layer on [h_i, x_i, h_j, x_j, |u_i - u_j|], applied as its two
        # halves per device and added per pair (the same function, a K-th of the first layer's work)
        self.pair_first = nn.Linear(2 * (w + FEATURES) + 1, w)
        self.pair_second = nn.Linear(w, w)
        self.head = _mlp([2 * w + 1, w, w, 1])

    def forward(self, users: torch.Tensor, position: torch.Tensor) -> torch.Tensor:
        """``V`` in bps/Hz, ``(B,)``, of positions ``(B, 3)`` in halls of devices ``(B, K, 3)``
        (one ``K`` per call; a batch of several counts goes call by call)."""
        users = torch.as_tensor(users, dtype=torch.float32)
        x = device_features(users, position)  # (B, K, F)
        h = self.device(x)
        k, w = x.shape[-2], self.cfg.width
        i, j = torch.triu_indices(k, k, 1)
        i, j = torch.cat([i, j]), torch.cat([j, i])  # every ordered pair
        apart = (users[:, i] - users[:, j]).norm(dim=-1, keepdim=True) / 10.0
        hx = torch.cat([h, x], dim=-1)
        weight, half = self.pair_first.weight, w + FEATURES
        mine = nn.functional.linear(hx, weight[:, :half], self.pair_first.bias)  # (B, K, w)
        theirs = nn.functional.linear(hx, weight[:, half:2 * half])
        p = self.pair_second((mine[:, i] + theirs[:, j] + apart * weight[:, -1]).relu())
        z = torch.cat([_ordered_mean(p, 1), _ordered_mean(h, 1), x[:, :1, -1]], dim=-1)
        return RATE_SCALE * self.head(z).squeeze(-1)


@dataclass(frozen=True, eq=False)
class ValueLabels:
    """Poses of halls and their ``R``: ``users`` ``(n, K, 3)`` per count ``K``, positions
    ``(n, 3)``, ``rate`` ``(n,)``, the hall (a name) each pose is in and its ``attitude``
    ``(n, 3)`` (level where not given)."""

    users: dict[int, NDArray[np.float64]]
    position: dict[int, NDArray[np.float64]]
    rate: dict[int, NDArray[np.float64]]
    hall: dict[int, NDArray[np.str_]]
    attitude: dict[int, NDArray[np.float64]] | None = None

    @property
    def size(self) -> int:
        return sum(len(r) for r in self.rate.values())

    def seen(self, k: int) -> NDArray[np.float64]:
        """The devices of count ``k``'s poses in the RIS's frame (:func:`in_ris_frame`): what ``V`` reads."""
        att = None if self.attitude is None else self.attitude.get(k)
        if att is None or not np.any(att):
            return self.users[k]
        tilted = np.any(att != 0.0, axis=1)  # a level pose's devices as they are, bit for bit
        out = np.array(self.users[k], dtype=np.float64)
        out[tilted] = in_ris_frame(self.users[k][tilted], self.position[k][tilted], att[tilted])
        return out


def fit_value(labels: ValueLabels, cfg: ValueConfig = ValueConfig(), *, steps: int = 3000, batch: int = 256,
              lr: float = 1e-3, seed: int = 0, on_step: Callable[[int, float], None] | None = None) -> PoseValue:
    """:class:`PoseValue` fitted to ``labels`` by the mean squared error of ``V / RATE_SCALE``
    (Adam, a cosine decay of the rate): each step draws its batch from one count, chosen with
    probability proportional to its poses, so every pose is as likely as in one set."""
    if labels.size == 0:
        raise ConfigError("no value labels to fit")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    model = PoseValue(cfg)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
    counts = sorted(labels.rate)
    seen = {k: labels.seen(k) for k in counts}
    share = np.array([len(labels.rate[k]) for k in counts], dtype=np.float64)
    share /= share.sum()
    model.train()
    for step in range(1, steps + 1):
        k = counts[int(rng.choice(len(counts), p=share))]
        idx = rng.integers(0, len(labels.rate[k]), min(batch, len(labels.rate[k])))
        pred = model(torch.as_tensor(seen[k][idx]), torch.as_tensor(labels.position[k][idx]))
        loss = torch.mean(((pred - torch.as_tensor(labels.rate[k][idx], dtype=torch.float32)) / RATE_SCALE) ** 2)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        schedule.step()
        if on_step is not None:
            on_step(step, float(loss.detach()))
    return model.eval()


def predict(model: PoseValue, users: NDArray, positions: NDArray, attitudes: NDArray | None = None,
            chunk: int = 1024) -> NDArray[np.float64]:
    """``V`` of positions ``(P, 3)`` in one hall of devices ``users`` ``(K, 3)``, ``(P,)``: level,
    or with the RIS tilted by ``attitudes`` ``(P, 3)`` (:func:`in_ris_frame`)."""
    out = []
    tilted = attitudes is not None and bool(np.any(attitudes))
    u = torch.as_tensor(np.asarray(users, dtype=np.float32))
    with torch.inference_mode():
        for start in range(0, len(positions), chunk):
            part = np.asarray(positions[start:start + chunk])
            q = torch.as_tensor(np.asarray(part, dtype=np.float32))
            seen = (torch.as_tensor(in_ris_frame(users, part, np.asarray(attitudes)[start:start + chunk])
                                    .astype(np.float32)) if tilted else u.expand(len(q), *u.shape))
            out.append(model(seen, q).double().numpy())
    return np.concatenate(out) if out else np.zeros(0)
