"""The report's stage table and schedule: when each stage ran, and on which workers.

Lives here: :func:`stage_table` (the report's "Stages" section: status, start, end and wall
clock of every stage, and the worker slots that ran its jobs) and :func:`schedule_figure` (a
Gantt chart of the jobs per worker). Not here: the schedule's record (written by
:mod:`uavris.experiments.engine.scheduling` into ``OUT/schedule.json``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

from uavris.experiments.display.plots import plt, save_figure
from uavris.experiments.display.tables import markdown_table
from uavris.experiments.engine.stages import StageRecord

TRACK_COLORS = {"compare": "#7f7f7f", "paper": "#1f77b4", "strong": "#2ca02c", "deployment": "#ff7f0e"}


def _minutes(t: float, origin: float) -> str:
    return "-" if math.isnan(t) else f"{(t - origin) / 60:.1f}"


def stage_table(records: Sequence[StageRecord], jobs: Sequence[dict[str, Any]], origin: float) -> list[str]:
    """Markdown lines: one row per stage with its status, its start and end (minutes after the
    invocation began), its wall clock and the worker slots of its jobs."""
    workers: dict[str, set[int]] = {}
    for j in jobs:
        if j["worker"] is not None:
            workers.setdefault(j["stage"], set()).add(int(j["worker"]))
    rows = []
    for r in sorted(records, key=lambda r: (math.isnan(r.start), r.start, r.name)):
        rows.append((r.name, f"`{r.key}`", r.status + (f" ({r.error})" if r.error else ""),
                     _minutes(r.start, origin), _minutes(r.end, origin), f"{r.wall_s / 60:.1f}",
                     ", ".join(str(w) for w in sorted(workers.get(r.name, ()))) or "-"))
    return markdown_table(("stage", "key", "status", "start (min)", "end (min)", "wall clock (min)", "workers"), rows,
                          "lllrrrl")


def schedule_figure(jobs: Sequence[dict[str, Any]], workers: int, stem: Path, groups: dict[str, str]
                    ) -> list[Path] | None:
    """Every job of the invocation as a bar on its worker's row (minutes), coloured by the track
    its stage belongs to (``groups``: each stage's :attr:`~uavris.experiments.engine.stages.Stage.group`)."""
    placed = [j for j in jobs if j["worker"] is not None and not math.isnan(j["start"])]
    if not placed:
        return None
    fig, ax = plt.subplots(figsize=(6.4, 0.5 * workers + 1.4))
    for j in placed:
        color = TRACK_COLORS.get(groups.get(j["stage"], ""), "k")
        ax.barh(j["worker"], (j["end"] - j["start"]) / 60, left=j["start"] / 60, height=0.7, color=color,
                edgecolor="k" if j["ok"] else "r", lw=0.3)
    for name, color in TRACK_COLORS.items():
        ax.barh(-10, 0, color=color, label=name)  # legend entries only
    ax.set_ylim(-0.6, workers - 0.4)
    ax.set_yticks(range(workers))
    ax.set_yticklabels([f"worker {w}" for w in range(workers)])
    ax.set_xlabel("minutes since the start of this invocation")
    ax.set_title("schedule: every job on its worker, coloured by track", fontsize=8)
    ax.legend(fontsize=7, ncol=4, frameon=False, loc="upper center", bbox_to_anchor=(0.5, -0.35))
    return save_figure(fig, stem)
