"""How far the oracle is from the best a much wider search finds, at 3 to 8 devices; and its cost.

Lives here: :func:`measure` (one hall: the demonstrations' teacher, the oracle and the wider
search, timed, valued on the same fresh draws), :func:`search` (the wider search of a hall,
kept on disk), :func:`summary_rows`, :func:`write_page` (``docs/results/oracle-gap.md``,
stamped) and :func:`main` (``python -m uavris.experiments.study.oracle_gap``, which
``uavris pages oracle-gap`` runs). Not here: the search itself
(:func:`uavris.agents.oracle.search.exhaustive_plan`), the oracle (:mod:`uavris.agents.oracle.planner`).

In one process (pin it to one core), for each hall (default: 4 unseen halls of
``LayoutGenerator(devices=K)`` for K in 3, 4, 6, 8, and 2 halls of the other generator at 6
and 8: 20 halls), from the hall's start: the demonstrations' teacher (``TEACHER``) and the
oracle, each timed; the search, seeded with the oracle's plan and finalists (so that it is a
superset of the oracle's: on its own objective it never returns less than they are worth),
over the poses the oracle may plan (every device 1 degree in front of the RIS), its grids
halved where it costs less than :data:`DEARER` times the oracle (3 devices, where ``R`` is a
closed form); both plans and staying valued by :func:`~uavris.agents.oracle.search.plan_gap`
on the same 8 fresh batches of draws. Each hall's numbers go to ``OUT/HALL.json`` when done,
and a rerun keeps the halls made by this oracle, teacher and search.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uavris.agents.oracle import plan_target
from uavris.agents.oracle.planner import TEACHER, PlanSettings, holding
from uavris.agents.oracle.search import Found, SearchSettings, exhaustive_plan, plan_gap, plan_seeds
from uavris.config import SystemConfig
from uavris.experiments.display.tables import markdown_table
from uavris.experiments.engine.process import configure_threads, machine
from uavris.experiments.study.stamp import make_stamp, stamped
from uavris.io import atomic_write_text, read_json, write_json
from uavris.layouts import LayoutGenerator
from uavris.physics.phase_opt import compile_optimiser
from uavris.stats import over_units

DEARER = 10  # the search costs at least this many times the oracle's time
FORMAT = 2  # 2: the search seeded with the oracle's poses, its fine grid 2 m each way


def halls(counts: Sequence[int], per_count: int, other_counts: Sequence[int], other: int,
          few_counts: Sequence[int] = (), few: int = 0) -> list[tuple[str, str, int, int]]:
    """(name, split, index, devices) of every hall measured: ``per_count`` unseen halls of each of
    ``counts``, ``few`` of each of ``few_counts`` and ``other`` of the other generator's at each of
    ``other_counts``."""
    def name(split: str, j: int, k: int) -> str:
        return f"layout-{split}-{j}" + ("" if k == 4 else f"-k{k}")

    return ([(name("unseen", j, k), "unseen", j, k) for k in counts for j in range(per_count)]
            + [(name("unseen", j, k), "unseen", j, k) for k in few_counts if k not in counts for j in range(few)]
            + [(name("other", j, k), "other", j, k) for k in other_counts for j in range(other)])


def search(system: Any, start: tuple, oracle_s: float, seeds: list, path: Path) -> tuple[Any, dict[str, Any]]:
    """The wide search of one hall in ``system`` (the oracle's planning system, its front margin
    included), seeded with ``seeds`` (the oracle's poses), read from ``path`` where an earlier run
    made the same search (its settings, seeds, margin and format) at least :data:`DEARER` times
    the oracle's cost; else made (its grids halved, up to twice, until it is dear enough) and
    written there."""
    seeded = [[np.asarray(q).tolist(), np.asarray(a).tolist()] for q, a in seeds]
    if path.exists():
        kept = read_json(path)
        same = all(kept.get(k) == v for k, v in (("format", FORMAT), ("seeds", seeded), ("base", str(SearchSettings())),
                                                  ("front_margin_deg", system.front_margin_deg)))
        if same and kept["search_s"] >= DEARER * oracle_s:
            return Found(np.array(kept["target"]), np.array(kept["attitude"]), kept["value"],
                         kept["poses_valued"]), kept
    settings = SearchSettings()
    for _ in range(3):  # where R is cheap (3 devices), denser grids
        began = time.perf_counter()
        found = exhaustive_plan(system, start, settings, seeds=seeds)
        seconds = time.perf_counter() - began
        if seconds >= DEARER * oracle_s:
            break
        settings = dataclasses.replace(settings, grid_step=settings.grid_step / 2, z_step=settings.z_step / 2,
                                       fine_step=settings.fine_step / 2)
    kept = {"target": found.target.tolist(), "attitude": found.attitude.tolist(), "value": found.value,
            "poses_valued": found.poses_valued, "search_s": seconds, "settings": dataclasses.asdict(settings),
            "front_margin_deg": system.front_margin_deg, "seeds": seeded, "format": FORMAT,
            "base": str(SearchSettings())}
    write_json(path, kept)
    return found, kept


def measure(split: str, j: int, k: int, out: Path) -> dict[str, Any]:
    """One hall: the teacher, the oracle and the search (:func:`search`), timed, and their values
    on the same fresh draws."""
    system, where = LayoutGenerator(devices=k).layout(split, j).resolve(SystemConfig())
    timed = {}
    began = time.perf_counter()
    teacher = plan_target(system, where.start, TEACHER)
    timed["teacher_s"] = time.perf_counter() - began
    began = time.perf_counter()
    oracle = plan_target(system, where.start)
    timed["oracle_s"] = time.perf_counter() - began
    found, kept = search(holding(system, PlanSettings().front_margin_deg), where.start, timed["oracle_s"],
                         plan_seeds(oracle), out / f"{where.name}.search.json")
    timed["search_s"] = kept["search_s"]
    g, t = plan_gap(system, where.start, oracle, found), plan_gap(system, where.start, teacher, found)
    return {"devices": k, "split": split, "index": j, **timed, "poses_searched": found.poses_valued,
            "search_settings": kept["settings"], "search_margin_deg": kept["front_margin_deg"],
            "oracle": g.oracle_value, "teacher": t.oracle_value, "search": g.search_value, "stay": g.stay_value,
            "search_minus_oracle": g.difference, "search_minus_oracle_se": g.difference_se,
            "oracle_target": np.round(oracle.target, 3).tolist(), "search_target": np.round(found.target, 3).tolist(),
            "oracle_attitude_deg": np.round(np.degrees(oracle.attitude), 1).tolist()}


def versions() -> dict[str, Any]:
    """What a hall's numbers were made by: a hall of another oracle, teacher or search is measured again."""
    return {"oracle_settings": str(PlanSettings()), "teacher_settings": str(TEACHER),
            "search_settings": str(SearchSettings()), "format": FORMAT}


def summary_rows(done: dict[str, dict[str, Any]]) -> tuple[list[tuple[str, ...]], list[tuple[str, ...]]]:
    """The per-hall table and the per-count table (fractions over halls with their t interval)."""
    per_hall = [("hall", "devices", "oracle", "search", "stay", "teacher", "search - oracle (SE)",
                 "oracle / search", "oracle s", "oracle s / teacher's s", "search s / oracle s")]
    for name, h in done.items():
        per_hall.append((name, str(h["devices"]), f"{h['oracle']:.2f}", f"{h['search']:.2f}", f"{h['stay']:.2f}",
                         f"{h['teacher']:.2f}", f"{h['search_minus_oracle']:+.2f} ({h['search_minus_oracle_se']:.2f})",
                         f"{h['oracle'] / h['search']:.1%}", f"{h['oracle_s']:.1f}",
                         f"{h['oracle_s'] / h['teacher_s']:.1f}x", f"{h['search_s'] / h['oracle_s']:.0f}x"))
    per_count = [("halls", "n", "oracle / search [95% CI over halls]", "teacher / search",
                  "oracle s / teacher's s (mean s)", "search s / oracle s (mean s)")]
    groups: dict[str, list[dict[str, Any]]] = {}
    for h in done.values():
        groups.setdefault(f"{h['devices']} devices" + (", other generator" if h["split"] == "other" else ""),
                          []).append(h)
    for label, hs in groups.items():
        f = over_units([h["oracle"] / h["search"] for h in hs])
        old = sum(h["teacher"] / h["search"] for h in hs) / len(hs)
        ts, to, tq = (sum(h[x] for h in hs) / len(hs) for x in ("teacher_s", "oracle_s", "search_s"))
        ci = f"[{f['ci_low']:.1%}, {f['ci_high']:.1%}]" if len(hs) >= 3 else "[n/a: fewer than 3 halls]"
        per_count.append((label, str(len(hs)), f"{f['mean']:.1%} {ci}", f"{old:.1%}", f"{to / ts:.1f}x ({to:.1f})",
                          f"{tq / to:.0f}x ({tq:.0f})"))
    return per_hall, per_count


def markdown(rows: list[tuple[str, ...]]) -> list[str]:
    return markdown_table(rows[0], rows[1:], "l" + "r" * (len(rows[0]) - 1))


def write_page(done: dict[str, dict[str, Any]], page: Path, out: Path, command: str) -> Path:
    """``docs/results/oracle-gap.md``, stamped: what is measured, then the two tables."""
    per_hall, per_count = summary_rows(done)
    lines = ["# How good the oracle is: its gap to a much wider search", "",
             "Every learned row of the study is read as a fraction of the oracle, so the oracle must be the optimum "
             "of its objective to a measured gap: the episode average of flying from rest at the hall's start to a "
             "pose and hovering there (docs/model.md section 19). In each hall below the oracle's plan is measured "
             "against the best pose of a search at least 10 times dearer "
             "(`uavris.agents.oracle.search.exhaustive_plan`: every feasible position of a 2 m x 2 m x 1 m grid, "
             "level; a 0.5 m grid within 2 m of its 8 best, as wide as the learned planner's finer grid; the 125 "
             "attitudes of +-20 degrees in yaw, pitch and roll at the 12 best; a pattern search in position and "
             "attitude from the 6 best and from the oracle's own plan and finalists, so that the search is a "
             "superset of the oracle's), over the poses the oracle may plan (every device 1 degree in front of the "
             "RIS), on draws that are not the planner's; where that costs less than 10 times the oracle (3 "
             "devices) its grids are halved until it does. The halls: the study's generator's unseen halls at "
             "each count (10 devices: never trained on), and the other generator's. The oracle's plan, the "
             "search's pose, staying at the start and the demonstrations' teacher's plan (`TEACHER`) are valued "
             "on the same 8 fresh batches of "
             "draws; 'search - oracle' is their paired difference (bps/Hz) with its standard error. The times are "
             "one process's seconds on one core.", "", f"Made by `{command}`.", "",
             *markdown(per_count), "", *markdown(per_hall), ""]
    stamp = make_stamp("oracle-gap", [out], None, command, halls=list(done))
    atomic_write_text(page, stamped(stamp, "\n".join(lines)))
    return page


def parser() -> argparse.ArgumentParser:
    """The measurement's command line (:func:`main`)."""
    parser = argparse.ArgumentParser(prog="python -m uavris.experiments.study.oracle_gap",
                                     description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[3, 4, 6, 8], help="device counts (default 3 4 6 8)")
    parser.add_argument("--halls", type=int, default=4, help="unseen halls per device count (default 4)")
    parser.add_argument("--other-counts", type=int, nargs="*", default=[6, 8],
                        help="device counts of the other generator's halls (default 6 8)")
    parser.add_argument("--other", type=int, default=2, help="the other generator's halls per count (default 2)")
    parser.add_argument("--few-counts", type=int, nargs="*", default=[10],
                        help="device counts measured in fewer unseen halls (default 10: never trained on)")
    parser.add_argument("--few", type=int, default=2, help="unseen halls per count of --few-counts (default 2)")
    parser.add_argument("--out", type=Path, default=Path("runs/oracle-gap"),
                        help="a folder of one JSON per hall, read back by a rerun (default runs/oracle-gap)")
    parser.add_argument("--page", type=Path, help="write this Markdown page (stamped) once every hall is done")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)

    configure_threads()
    args.out.mkdir(parents=True, exist_ok=True)
    compile_optimiser()  # before any clock starts: a cold cache would time numba's compilation as a plan's
    done: dict[str, dict[str, Any]] = {}
    for name, split, j, k in halls(args.counts, args.halls, args.other_counts, args.other, args.few_counts, args.few):
        path = args.out / f"{name}.json"
        if not path.exists() or any(read_json(path).get(key) != v for key, v in versions().items()):
            write_json(path, {**measure(split, j, k, args.out), **versions(), "cpu": machine()})
        done[name] = read_json(path)
        print(markdown(summary_rows({name: done[name]})[0])[-1], flush=True)
    per_hall, per_count = summary_rows(done)
    print("\n".join(["", *markdown(per_count)]), flush=True)
    if args.page is not None:
        command = "python -m uavris.experiments.study.oracle_gap " + " ".join(argv if argv is not None else
                                                                               sys.argv[1:])
        print(f"wrote {write_page(done, args.page, args.out, command.strip())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
