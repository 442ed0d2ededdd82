"""An evaluation stage run again after a row is added: its kept rows copied against every row flown again.

Feeds docs/timings.md.

Issue 68's lever "a row's evaluation keyed by that row's own inputs".

A finished study's evaluation of one hall is made again with one row more, the way a study
does it when its rows change (``uavris.experiments.study.workers.evaluate_rows``), twice in one
run, one core:

- **today's code without the lever**: every row flown again (``kept=None``);
- **with kept rows**: the rows kept by an earlier evaluation copied (``uavris.experiments.study.kept_rows``),
  the added row flown.

The kept rows are made first, by an evaluation of the hall with the study's own rows into a
scratch folder (not timed). The added row is hovering with the optimiser's phases under another
name (a row the study does not have). Both results must be the same numbers row by row; the
script prints the two times and their ratio.

Run from the repository root, on a finished make run (``make run``: runs/quick)::

    .venv/bin/python benchmarks/findings/kept_rows.py runs/quick --hall layout-unseen-1
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/, for _machine.py
from _machine import cpu_model, pin_to_one_core  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("study", type=Path, help="a finished study with a deployment track (runs/quick)")
    parser.add_argument("--hall", default="layout-unseen-1", help="one of its unseen halls")
    args = parser.parse_args(argv)
    pinned = pin_to_one_core()

    from uavris.experiments.engine.process import configure_threads
    from uavris.experiments.study.finished import Study
    from uavris.experiments.study.tracks import TRACK_SPECS
    from uavris.experiments.study.workers import evaluate_rows
    from uavris.experiments.tools.rows import Row

    configure_threads()
    study = Study.open(args.study)
    track = TRACK_SPECS["deployment"]
    [site] = [s for s in study.sites(track)[1] if s.name == args.hall]
    rows = study.track(track.name).rows_in(site, study.pipeline)
    added = Row.reference("hover-optimizer").replace(name="hover-optimizer-again", label="hovering, again")
    episodes = study.config.eval_episodes
    with tempfile.TemporaryDirectory() as tmp:
        kept = Path(tmp) / "rows"
        evaluate_rows(Path(tmp) / "first", site, track, episodes, rows, kept)  # the study's rows, kept
        t0 = time.perf_counter()
        again = evaluate_rows(Path(tmp) / "all", site, track, episodes, [*rows, added])
        t_all = time.perf_counter() - t0
        t0 = time.perf_counter()
        copied = evaluate_rows(Path(tmp) / "kept", site, track, episodes, [*rows, added], kept)
        t_kept = time.perf_counter() - t0
    same = all(again[k]["mean"] == copied[k]["mean"] for k in again)
    print(f"machine: {cpu_model()}; {pinned}")
    print(f"study: {args.study}, hall {site.name}: {len(rows)} rows and one added, {episodes} episodes")
    print(f"every row flown again (without the lever): {t_all:.1f} s")
    print(f"kept rows copied, the added row flown:      {t_kept:.1f} s")
    print(f"ratio (without / with): {t_all / t_kept:.1f}x; the same numbers row by row: {same}")


if __name__ == "__main__":
    main()
