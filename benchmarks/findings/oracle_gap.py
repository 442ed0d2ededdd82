"""How far the oracle is from the best a much wider search finds, at 3 to 8 devices; and its cost.

Feeds docs/results/oracle-gap.md.

In this one process pinned to a single CPU, for each hall (default: 4 unseen halls of
``LayoutGenerator(devices=K)`` for K in 3, 4, 6, 8, and 2 halls of the other generator,
``layout-other-J-kK``, at 6 and 8: 20 halls), from the hall's start:

- today's planner without its global stage (``TEACHER``, what the demonstrations keep), timed;
- the oracle, :func:`uavris.agents.oracle.plan_target` with its global stage (the cheap ``R`` on a
  coarse grid of the whole region), timed: the ratio of the two is the cost the yardstick adds;
- the search, :func:`uavris.agents.oracle.search.exhaustive_plan`: a 2 m x 2 m x 1 m grid, a
  0.5 m grid around its 8 best places, 125 attitudes at the 12 best, a pattern search from the 6
  best, on draws that are not the planner's, over the poses the oracle may plan (every device 1
  degree in front of the RIS: its ``front_margin_deg``); timed, and its grids halved where it costs
  less than 10x the oracle (3 devices, where ``R`` is a closed form);
- both plans and staying valued by :func:`~uavris.agents.oracle.search.plan_gap` on the same 8
  fresh batches of draws (the planner's objective: the episode average of flying there).

Each hall's numbers are written to ``--out/HALL.json`` when it is done, and a rerun reads the
halls it finds there: the benchmark runs in parts. Printed: a row per hall; per device count
the oracle's mean fraction of the best found with its Student-t 95% CI over halls, the time
ratios. With ``--page`` and every hall done, the page is written.

Run: ``python benchmarks/findings/oracle_gap.py --out runs/oracle-gap --page docs/results/oracle-gap.md``
(about 1.5 hours on one core; halls of 8 devices take the longest).
"""

from __future__ import annotations

import os
import pathlib
import sys

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # benchmarks/, for _machine.py
from _machine import cpu_model, pin_to_one_core, table  # noqa: E402


def halls(counts: list[int], per_count: int, other_counts: list[int], other: int) -> list[tuple[str, str, int, int]]:
    """(name, split, index, devices) of every hall measured."""
    def name(split: str, j: int, k: int) -> str:
        return f"layout-{split}-{j}" + ("" if k == 4 else f"-k{k}")

    return ([(name("unseen", j, k), "unseen", j, k) for k in counts for j in range(per_count)]
            + [(name("other", j, k), "other", j, k) for k in other_counts for j in range(other)])


DEARER = 10  # the search costs at least this many times the oracle's time


def search(system: object, start: tuple, oracle_s: float, path: pathlib.Path) -> tuple[object, dict]:
    """The wide search of one hall in ``system`` (the oracle's planning system, its front margin
    included: the same poses allowed to both), read from ``path`` where an earlier run made it at
    least :data:`DEARER` times the oracle's cost in the same margin, or with none where its pose
    keeps the margin anyway (the search over more poses found one the margin allows: recorded as
    ``pose_keeps_margin``); else made (its grids halved, up to twice, until it is dear enough) and
    written there. The search does not depend on the oracle: a changed oracle reuses it."""
    from dataclasses import asdict, replace

    import numpy as np

    from uavris.agents.oracle.planner import held
    from uavris.agents.oracle.search import Found, SearchSettings, exhaustive_plan
    from uavris.io import read_json, write_json

    margin = system.front_margin_deg
    if path.exists():
        kept = read_json(path)
        found = Found(np.array(kept["target"]), np.array(kept["attitude"]), kept["value"], kept["poses_valued"])
        made_in = kept.get("front_margin_deg")
        if made_in != margin:
            kept["pose_keeps_margin"] = made_in is None and bool(held(system, found.target[None],
                                                                       found.attitude[None])[0])
        if kept["search_s"] >= DEARER * oracle_s and (made_in == margin or kept["pose_keeps_margin"]):
            return found, kept
    settings = SearchSettings()
    for _ in range(3):  # where R is cheap (3 devices), denser grids
        began = time.perf_counter()
        found = exhaustive_plan(system, start, settings)
        seconds = time.perf_counter() - began
        if seconds >= DEARER * oracle_s:
            break
        settings = replace(settings, grid_step=settings.grid_step / 2, z_step=settings.z_step / 2,
                           fine_step=settings.fine_step / 2)
    kept = {"target": found.target.tolist(), "attitude": found.attitude.tolist(), "value": found.value,
            "poses_valued": found.poses_valued, "search_s": seconds, "settings": asdict(settings),
            "front_margin_deg": margin}
    write_json(path, kept)
    return found, kept


def measure(split: str, j: int, k: int, out: pathlib.Path) -> dict:
    """One hall: today's planner, the oracle and the search (:func:`search`), timed, and their values
    on fresh draws."""
    import numpy as np

    from uavris.agents.oracle import plan_target
    from uavris.agents.oracle.planner import TEACHER, PlanSettings, holding
    from uavris.agents.oracle.search import plan_gap
    from uavris.config import SystemConfig
    from uavris.layouts import LayoutGenerator

    system, where = LayoutGenerator(devices=k).layout(split, j).resolve(SystemConfig())
    timed = {}
    began = time.perf_counter()
    teacher = plan_target(system, where.start, TEACHER)
    timed["teacher_s"] = time.perf_counter() - began
    began = time.perf_counter()
    oracle = plan_target(system, where.start)
    timed["oracle_s"] = time.perf_counter() - began
    found, kept = search(holding(system, PlanSettings().front_margin_deg), where.start, timed["oracle_s"],
                         out / f"{where.name}.search.json")
    timed["search_s"] = kept["search_s"]
    g, t = plan_gap(system, where.start, oracle, found), plan_gap(system, where.start, teacher, found)
    return {"devices": k, "split": split, "index": j, **timed, "poses_searched": found.poses_valued,
            "oracle_settings": str(PlanSettings()), "search_settings": kept["settings"],
            "search_margin_deg": kept.get("front_margin_deg"),
            "search_pose_keeps_margin": kept.get("pose_keeps_margin"),
            "oracle": g.oracle_value, "teacher": t.oracle_value, "search": g.search_value, "stay": g.stay_value,
            "search_minus_oracle": g.difference, "search_minus_oracle_se": g.difference_se,
            "oracle_target": np.round(oracle.target, 3).tolist(), "search_target": np.round(found.target, 3).tolist(),
            "oracle_attitude_deg": np.round(np.degrees(oracle.attitude), 1).tolist()}


def summary_rows(done: dict[str, dict]) -> tuple[list[tuple[str, ...]], list[tuple[str, ...]]]:
    """The per-hall table and the per-count table (fractions over halls with their t interval)."""
    from uavris.stats import over_units

    per_hall = [("hall", "devices", "oracle", "search", "stay", "today's planner", "search - oracle (SE)",
                 "oracle / search", "oracle s", "oracle s / today's s", "search s / oracle s")]
    for name, h in done.items():
        per_hall.append((name, str(h["devices"]), f"{h['oracle']:.2f}", f"{h['search']:.2f}", f"{h['stay']:.2f}",
                         f"{h['teacher']:.2f}", f"{h['search_minus_oracle']:+.2f} ({h['search_minus_oracle_se']:.2f})",
                         f"{h['oracle'] / h['search']:.1%}", f"{h['oracle_s']:.1f}",
                         f"{h['oracle_s'] / h['teacher_s']:.1f}x", f"{h['search_s'] / h['oracle_s']:.0f}x"))
    per_count = [("halls", "n", "oracle / search [95% CI over halls]", "today's planner / search",
                  "oracle s / today's s (mean s)", "search s / oracle s (mean s)")]
    groups: dict[str, list[dict]] = {}
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[3, 4, 6, 8], help="device counts (default 3 4 6 8)")
    parser.add_argument("--halls", type=int, default=4, help="unseen halls per device count (default 4)")
    parser.add_argument("--other-counts", type=int, nargs="*", default=[6, 8],
                        help="device counts of the other generator's halls (default 6 8)")
    parser.add_argument("--other", type=int, default=2, help="the other generator's halls per count (default 2)")
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("runs/oracle-gap"),
                        help="a folder of one JSON per hall, read back by a rerun (default runs/oracle-gap)")
    parser.add_argument("--page", type=pathlib.Path, help="write this Markdown page once every hall is done")
    args = parser.parse_args(argv)
    pinning = pin_to_one_core()
    from uavris.io import read_json, write_json

    args.out.mkdir(parents=True, exist_ok=True)
    from uavris.physics.phase_opt import compile_optimiser

    compile_optimiser()  # before any clock starts: a cold cache would time numba's compilation as a plan's
    todo = halls(args.counts, args.halls, args.other_counts, args.other)
    done: dict[str, dict] = {}
    from uavris.agents.oracle.planner import PlanSettings

    for name, split, j, k in todo:
        path = args.out / f"{name}.json"
        if not path.exists() or read_json(path).get("oracle_settings") != str(PlanSettings()):  # another oracle
            write_json(path, {**measure(split, j, k, args.out), "cpu": cpu_model()})
        done[name] = read_json(path)
        print(table(summary_rows({name: done[name]})[0]).splitlines()[-1], flush=True)
    per_hall, per_count = summary_rows(done)
    text = (f"- cpu: {cpu_model()}; {pinning}\n\n" + table(per_hall) + "\n\n" + table(per_count) + "\n")
    print("\n" + text, flush=True)
    if args.page is not None:
        intro = args.page.read_text().split("<!-- measured -->")[0] if args.page.exists() else ""
        args.page.write_text(intro + "<!-- measured -->\n" + text)
        print(f"wrote {args.page}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
