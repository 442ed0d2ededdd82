"""Where the rate comes from: the study's main rows split by the number of active pairs, and their energy.

Feeds docs/results/rate-sources.md.

For the deployment track of a finished study (``--study``), in its first ``--halls`` unseen
halls (default 16), each row of ``--rows`` is evaluated again as the report evaluates it
(``uavris evaluate OUT --row KEY --layout HALL --trajectory``: the study's models, episodes
and safety layer) with every slot recorded. Printed per row, the mean over halls of: the
share of slots with one active link and with two (the pairing draw decides it, the same
for every row), the mean sum rate in each kind of slot, the average sum rate, and the
propulsion energy of an episode (J). The two-link slots are where interference decides the
rate (docs/model.md, "The regime"), the one-link slots where the received power does.

Run: ``python benchmarks/findings/rate_sources.py --study runs/quick`` (about 5 min on one core).
"""

from __future__ import annotations

import os
import pathlib
import sys

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # benchmarks/, for _machine.py
from _machine import cpu_model, pin_to_one_core, table  # noqa: E402

ROWS = ("dt-goal-safe", "dt-zero-shot-safe", "bc-safe", "plan-learned", "oracle-safe", "hover-optimizer",
        "zero-action")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", type=Path, required=True, help="a finished study with the deployment track")
    parser.add_argument("--halls", type=int, default=16, help="unseen halls (default: 16)")
    parser.add_argument("--rows", nargs="+", default=list(ROWS), help=f"row keys (default: {' '.join(ROWS)})")
    args = parser.parse_args(argv)
    pinning = pin_to_one_core()
    import torch

    torch.set_num_threads(1)
    from uavris.experiments.study.finished import Study
    from uavris.experiments.study.tracks import zero_shot_only
    from uavris.experiments.tools.evaluate import evaluate_target
    from uavris.presets import EVAL_SEED

    study = Study.open(args.study)
    rc = study.config
    _, unseen = study.sites("deployment")
    halls = [w for w in unseen if not zero_shot_only(w, rc.system)][:args.halls]  # the study's own halls
    print(f"# where the rate comes from\n- cpu: {cpu_model()}; {pinning}\n- study: {args.study}; "
          f"{len(halls)} unseen halls x {rc.eval_episodes} episodes per row\n", flush=True)
    rows = [("row", "slots with 1 link", "rate in them", "slots with 2 links", "rate in them", "average sum rate",
             "energy per episode (J)")]
    for key in args.rows:
        parts = []
        for site in halls:
            row = study.row(key, "deployment", site)
            with tempfile.TemporaryDirectory() as tmp:
                summary, _ = evaluate_target(row, site.scenario, rc.eval_episodes, EVAL_SEED, out=Path(tmp),
                                             system=site.system, trajectory=True, references=False)
            split = summary["active_pairs"]
            parts.append((split["1"]["share"], split["1"]["rate"], split["2"]["share"], split["2"]["rate"],
                          summary["mean"], summary["mean_energy_j"]))
        m = np.mean(parts, axis=0)
        rows.append((key, f"{m[0]:.0%}", f"{m[1]:.2f}", f"{m[2]:.0%}", f"{m[3]:.2f}", f"{m[4]:.2f}", f"{m[5]:,.0f}"))
        print(table(rows), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
