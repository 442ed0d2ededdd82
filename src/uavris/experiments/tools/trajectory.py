"""What happened in every slot of an evaluation: the UAV's pose, the active pairs and the rate.

Lives here: :class:`SlotLog` (rollout hooks recording each slot of each episode), its CSV
(:func:`write_slots`, ``uavris evaluate --trajectory``), where the rate comes from
(:func:`rate_by_active_pairs`: slots with one active link against two) and the plot of the
first episode's flight in the hall (:func:`trajectory_plot`). Not here: the rollout loop
(:func:`uavris.env.rollout.rollout`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from uavris.config import SystemConfig
from uavris.io import write_csv

SLOT_COLUMNS = ("episode_seed", "slot", "x", "y", "z", "yaw_deg", "pitch_deg", "roll_deg", "active_pairs",
                "sum_rate", "energy_j")


class SlotLog:
    """Rollout hooks (``on_slot``, ``on_step``) that keep one row per counted slot of every episode."""

    def __init__(self, seeds: NDArray[np.int64]) -> None:
        self.seeds = np.asarray(seeds)
        self.rows: list[tuple[Any, ...]] = []
        self._slot = 0
        self._before: tuple[NDArray, NDArray, NDArray] | None = None

    def on_slot(self, sim: Any, obs: Any, executed: Any, alive: NDArray[np.bool_]) -> None:
        # the pose the slot's rate was earned in, and the links active in it (drawn before the action)
        self._before = (sim.pos.copy(), np.degrees(sim.att), sim.pairing.sum(axis=(-2, -1)))

    def on_step(self, sim: Any, reward: NDArray[np.float64], alive: NDArray[np.bool_]) -> None:
        assert self._before is not None
        pos, att, pairs = self._before
        for j in np.flatnonzero(alive):
            self.rows.append((int(self.seeds[j]), self._slot, *np.round(pos[j], 4), *np.round(att[j], 3),
                              int(round(pairs[j])), float(reward[j]), float(sim.energy[j])))
        self._slot += 1


def write_slots(log: SlotLog, path: Path, episode: int | None = None) -> Path:
    """The slots as CSV (:data:`SLOT_COLUMNS`), episode by episode; only episode seed ``episode``'s where given."""
    rows = [r for r in log.rows if episode is None or r[0] == episode]
    write_csv(path, SLOT_COLUMNS, sorted(rows, key=lambda r: (r[0], r[1])))
    return path


def rate_by_active_pairs(rows: list[tuple[Any, ...]] | list[dict[str, Any]]) -> dict[int, dict[str, float]]:
    """Per number of active pairs: its share of the slots and the mean sum rate in those slots."""
    pairs = np.array([int(r["active_pairs"] if isinstance(r, dict) else r[8]) for r in rows])
    rate = np.array([float(r["sum_rate"] if isinstance(r, dict) else r[9]) for r in rows])
    return {int(m): {"share": float(np.mean(pairs == m)), "rate": float(rate[pairs == m].mean())}
            for m in np.unique(pairs)}


def trajectory_plot(log: SlotLog, system: SystemConfig, stem: Path, title: str) -> list[Path]:
    """The first episode's flight seen from above in the hall, coloured by the slot's sum rate,
    with the devices (PNG and PDF)."""
    from uavris.experiments.display.plots import plt, save_figure

    first = [r for r in log.rows if r[0] == log.rows[0][0]]
    xy = np.array([(r[2], r[3]) for r in first])
    rate = np.array([r[9] for r in first])
    fig, ax = plt.subplots(figsize=(4.8, 4.2))
    ax.plot(xy[:, 0], xy[:, 1], "-", color="0.6", lw=0.8, zorder=1)
    sc = ax.scatter(xy[:, 0], xy[:, 1], c=rate, s=12, cmap="viridis", zorder=2)
    fig.colorbar(sc, ax=ax, label="sum rate in the slot (bps/Hz)")
    ax.plot(*xy[0], "k^", ms=7, label="start")
    users = np.asarray(system.users)
    ax.plot(users[:, 0], users[:, 1], "rs", ms=6, label="devices")
    for k, u in enumerate(users):
        ax.annotate(f"D{k + 1}", u[:2], textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.set_xlim(0, system.room[0])
    ax.set_ylim(0, system.room[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=8)
    # below the map, where it hides no device
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)
    return save_figure(fig, stem)
