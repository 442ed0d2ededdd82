"""What the slot memo saves: the same work with and without it, in one run, the same bits checked.

The alternative is today's code with no memo (every multi-pair slot solved, as before the memo
existed): ``objective.SLOT_MEMO`` set to None. Measurements, in this one process pinned to a
single CPU with BLAS/OpenMP limited to one thread, each timed with a fresh memo and with none:

1. ``plan``: the planning oracle's plan of a generated unseen hall of each ``--devices``
   count from scratch (:func:`uavris.agents.oracle.planner.plan_target`). The planner keeps
   its own memo of poses, so few slots repeat here: this row shows what the memo costs where
   it has little to serve.
2. ``evaluation``: the evaluation stages of the deployment track (every row of the track in
   each unseen hall: the oracle's plan, the learned planner's place told to every
   goal-conditioned row and seed, each row's end pose assessed) of a smoke study
   (``ReproduceConfig("smoke", track="deployment")``, 25-slot episodes), run once to train its
   models and then again, with ``--force`` on its evaluation stages, once per side. Every
   file of every evaluation stage must be the same bit for bit on both sides.

Prints the machine, the command line, a Markdown table with the ratio and the share of the
solved slots the memo served, and PASS/FAIL for the bits. Exits 0: a report, not a test.

Run from the repository root::

    .venv/bin/python benchmarks/slot_memo.py                    # about 6 minutes
    .venv/bin/python benchmarks/slot_memo.py --devices 4 --skip-study    # about 20 s
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_variable] = "1"

import uavris  # noqa: E402, F401, I001 - first: it pins the float path before numpy loads
import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from functools import partial  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Callable  # noqa: E402

import numpy as np  # noqa: E402
from _machine import cpu_model, pin_to_one_core, table  # noqa: E402

from uavris.agents.oracle import objective  # noqa: E402
from uavris.agents.oracle.planner import plan_target  # noqa: E402
from uavris.config import SystemConfig  # noqa: E402
from uavris.experiments.study.config import ReproduceConfig  # noqa: E402
from uavris.experiments.study.reproduce import reproduce  # noqa: E402
from uavris.layouts import LayoutGenerator  # noqa: E402
from uavris.physics.phase_opt import compile_optimiser  # noqa: E402
from uavris.physics.slot_memo import SlotMemo  # noqa: E402

# The smoke study of the test suite's deployment track (tests/conftest.py: SMOKE_SYSTEM).
STUDY = ReproduceConfig("smoke", track="deployment", eval_episodes=2, dt_seeds=2,
                        system=SystemConfig(horizon=25, energy_budget_j=2000.0))


def both_sides(work: Callable[[], object]) -> tuple[float, float, object, object, float]:
    """``work`` without a memo and with a fresh one: the two times, the two results, the share served."""
    out = []
    for memo in (None, SlotMemo()):
        objective.SLOT_MEMO = memo  # what every R of this process solves through
        began = time.perf_counter()
        got = work()
        out.append((time.perf_counter() - began, got, memo))
    (plain_s, plain, _), (memo_s, memoised, memo) = out
    return plain_s, memo_s, plain, memoised, memo.hits / max(memo.hits + memo.solved, 1)


def exact(value: object) -> str:
    """A value written so that two are equal exactly when their bits are (Python's float repr round-trips)."""
    return repr(value.tolist() if isinstance(value, np.ndarray) else value)


def stage_files(out: Path) -> dict[str, bytes]:
    """Every file of the study's evaluation stages but their logs and wall clocks, by path."""
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted((out / "stages").glob("deploy-evaluate-*/**/*"))
            if p.is_file() and p.suffix != ".log" and p.name != "timing.json"}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--devices", type=int, nargs="+", default=[4, 8])
    parser.add_argument("--skip-study", action="store_true", help="only the plans")
    args = parser.parse_args(argv)
    pinned = pin_to_one_core()
    print(f"# slot memo: {cpu_model()}, {pinned}\n\ncommand: {' '.join(sys.argv)}\n", flush=True)
    compile_optimiser()
    rows = [("work", "without memo (s)", "with memo (s)", "ratio", "slots served by the memo", "same bits")]
    same_everywhere = True
    for k in args.devices:
        system, where = LayoutGenerator(devices=k).layout("unseen", 0).resolve(SystemConfig())
        plain_s, memo_s, plain, memoised, share = both_sides(partial(plan_target, system, where.start))
        same = all(exact(getattr(plain, f)) == exact(getattr(memoised, f))
                   for f in ("target", "attitude", "rate", "rate_se", "value", "candidates"))
        same_everywhere &= same
        rows.append((f"plan, {k} devices", f"{plain_s:.1f}", f"{memo_s:.1f}", f"{plain_s / memo_s:.2f}x",
                     f"{share:.0%}", "yes" if same else "NO"))
    if not args.skip_study:
        with tempfile.TemporaryDirectory(prefix="uavris-slot-memo-") as tmp:
            out = Path(tmp)
            os.environ["UAVRIS_PLAN_STORE"] = str(out / "plans")  # the study's plans: made anew on each side
            reproduce(STUDY, out / "study", workers=1, progress=False)
            force = sorted(p.name.rsplit("-", 1)[0] for p in (out / "study" / "stages").glob("deploy-evaluate-*"))

            def evaluation() -> dict[str, bytes]:
                for p in (out / "plans").glob("*"):
                    p.unlink()
                reproduce(STUDY, out / "study", workers=1, progress=False, force=force)
                return stage_files(out / "study")

            plain_s, memo_s, plain, memoised, share = both_sides(evaluation)
            same = plain == memoised
            same_everywhere &= same
            rows.append((f"evaluation: {len(force)} stages of a smoke study", f"{plain_s:.1f}", f"{memo_s:.1f}",
                         f"{plain_s / memo_s:.2f}x", f"{share:.0%}", "yes" if same else "NO"))
    print(table(rows))
    print()
    print("PASS: the same bits with and without the memo" if same_everywhere
          else "FAIL: the memo changed a number")
    return 0


if __name__ == "__main__":
    sys.exit(main())
