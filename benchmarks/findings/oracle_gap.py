"""How far the oracle is from the best a much wider search finds, at 3 to 8 devices; and its cost.

Feeds docs/results/oracle-gap.md.

The measurement is :mod:`uavris.experiments.study.oracle_gap` (``uavris pages oracle-gap``
runs the same); this script pins it to one core.

Run: ``python benchmarks/findings/oracle_gap.py --out runs/oracle-gap --page docs/results/oracle-gap.md``
(hours on one core, resumable per hall; halls of 8 devices take the longest).
"""

from __future__ import annotations

import os
import pathlib
import sys

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_variable] = "1"

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # benchmarks/, for _machine.py
from _machine import pin_to_one_core  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    from uavris.experiments.study.oracle_gap import main as measure

    if not (argv or sys.argv[1:]) or "--help" not in (argv or sys.argv[1:]):
        print(pin_to_one_core(), flush=True)
    return measure(argv)


if __name__ == "__main__":
    raise SystemExit(main())
