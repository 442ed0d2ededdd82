"""How the deployment track's generalisation grows with data: zero-shot score in unseen
layouts against the number of training layouts.

Feeds docs/halls.md.

Runs the study's own deployment track (``uavris reproduce --track deployment``) with
``--train-layouts`` the largest point and ``--scaling`` the others: one set of experts and
one dataset, and a DT pre-trained on the episodes of the first N training layouts for each
point N, every DT scored zero-shot in the same unseen layouts on the same episodes. Prints,
per point, the zero-shot DT's fraction of the oracle (mean and 95% CI over unseen layouts)
and its ratio to the two policies it must beat there: the expert of the nearest training
layout and hovering with the optimiser's phases. The figure is the report's
(``OUT/figures/deploy-scaling.png``); the rest of the track (BC, fine-tuning, the per-layout
tables) is in ``OUT/report.md``. Rerunning with more points reuses what is finished.

Run on an otherwise idle machine (quick preset, points 4-32: about 35 minutes on 2 cores;
the paper preset is the same curve with the paper's budgets)::

    .venv/bin/python benchmarks/findings/deployment_scaling.py
    .venv/bin/python benchmarks/findings/deployment_scaling.py --preset paper --points 4 8 16 32
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # benchmarks/, for _machine.py
from _machine import cpu_model  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--preset", default="quick", choices=("smoke", "quick", "paper"))
    parser.add_argument("--points", type=int, nargs="+", default=[4, 8, 16, 32], help="training-layout counts")
    parser.add_argument("--unseen", type=int, default=None, help="unseen layouts (default: the preset's)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, default=None, help="study folder (default runs/scaling-PRESET)")
    args = parser.parse_args(argv)

    from uavris.agents.references import HOVER_OPTIMIZER, ORACLE
    from uavris.experiments.study.config import ReproduceConfig
    from uavris.experiments.study.finished import Study
    from uavris.experiments.study.report.deployment import NEAREST, layout_scores
    from uavris.experiments.study.reproduce import reproduce
    from uavris.stats import over_units

    points = sorted(set(args.points))
    unseen = {} if args.unseen is None else {"unseen_layouts": args.unseen}
    # the data curve's smaller training sets are rows of the ablation
    rc = ReproduceConfig(args.preset, track="deployment", train_layouts=points[-1], scaling=tuple(points[:-1]),
                         ablation=True, **unseen)
    out = args.out or Path(f"runs/scaling-{args.preset}")
    t0 = time.perf_counter()
    reproduce(rc, out, workers=args.workers, progress=False)
    wall = time.perf_counter() - t0
    study = Study.open(out)
    track = rc.tracks[0]
    _, unseen = study.sites(track)
    results = {w.name: found[1] for w in unseen if (found := study.evaluation(track, w.name)) is not None}
    scores = layout_scores(results)
    print(f"deployment track, preset {args.preset}: {len(unseen)} unseen layouts x {rc.eval_episodes} episodes; "
          f"machine: {cpu_model()}, {args.workers} workers; wall clock {wall / 60:.1f} min")
    print(f"{'training layouts':>16} | {'zero-shot DT / oracle':>28} | {'DT / nearest expert':>19} | "
          f"{'DT / hover, optimiser':>21}")
    for n in points:
        key = "dt-zero-shot" if n == points[-1] else f"dt-zero-shot-n{n}"
        frac = over_units([scores[lay][key] / scores[lay][ORACLE] for lay in scores])
        vs_near = sum(scores[lay][key] for lay in scores) / sum(scores[lay][NEAREST] for lay in scores)
        vs_hover = sum(scores[lay][key] for lay in scores) / sum(scores[lay][HOVER_OPTIMIZER] for lay in scores)
        print(f"{n:>16} | {frac['mean']:>8.1%} [{frac['ci_low']:.1%}, {frac['ci_high']:.1%}] | {vs_near:>18.3f}x | "
              f"{vs_hover:>20.3f}x")
    print(f"figure: {out / 'figures' / 'deploy-scaling.png'}; report: {out / 'report.md'}")


if __name__ == "__main__":
    main()
