"""Wall-clock of `uavris reproduce --preset smoke` with 1 and 2 workers, local pool vs Ray.

Each configuration runs in a fresh temporary output folder, so every stage is computed.
Run on an otherwise idle machine: `.venv/bin/python benchmarks/reproduce_scaling.py`
(about 10-15 minutes on 2 cores). Prints a Markdown table and the speed-up of 2 workers
over 1 for each backend.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

from _machine import cpu_model  # noqa: E402  (benchmarks/_machine.py)


def run(backend: str, workers: int) -> float:
    from uavris.experiments.reproduce import ReproduceConfig, reproduce

    with tempfile.TemporaryDirectory(prefix=f"uavris-{backend}-{workers}-") as out:
        t0 = time.perf_counter()
        reproduce(ReproduceConfig("smoke"), out, workers=workers, backend=backend, progress=False)
        return time.perf_counter() - t0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--backends", nargs="+", default=["local", "ray"], choices=["local", "ray"])
    args = p.parse_args()
    print(f"# reproduce --preset smoke scaling\n\n- cpu: {cpu_model()}, {os.cpu_count()} cores\n"
          f"- command: {' '.join([sys.executable] + sys.argv)}\n")
    print("| backend | workers | wall clock (s) |\n|---|---:|---:|")
    times: dict[tuple[str, int], float] = {}
    for backend in args.backends:
        for workers in (1, 2):
            times[(backend, workers)] = run(backend, workers)
            print(f"| {backend} | {workers} | {times[(backend, workers)]:.0f} |", flush=True)
    for backend in args.backends:
        print(f"\n{backend}: 2 workers / 1 worker speed-up = {times[(backend, 1)] / times[(backend, 2)]:.2f}x")


if __name__ == "__main__":
    main()
