"""Plans kept on disk, so that processes of one study (or one test run) plan each hall once.

Lives here: :func:`load` and :func:`save` of a plan and the poses it valued, under a key that
names everything the plan is a function of, and :data:`STORE_ENV`, the variable that switches
the store on. Not here: the plan itself (:mod:`.planner`), the in-process sharing of plans
(:mod:`.policy`).

Why: an oracle's plan is a function of its settings, the system and the start alone (its random
numbers are the settings' seed), and of the code and the float path that compute it. Processes
that plan the same hall (a study's workers evaluating several halls each plan every training hall
for its transfer row; the strong experts each plan the paper's hall; the suite's test files plan
the same generated halls) would each pay seconds to a minute for the same numbers.

The key hashes the settings, the planning system and the start with a fingerprint of the code and
the float path: every source file of the ``uavris`` package, the versions of numpy, scipy and
numba, the CPU kind, and the environment that pins the libraries' kernels
(:mod:`uavris.float_paths`). A change to any of them is another key, so a stored plan is always
the one this code would make here. A file is plain numbers (``.npz`` read without pickle): a store
someone else filled cannot run code; one that does not read as a plan is planned again.

Off unless ``$UAVRIS_PLAN_STORE`` names a directory: a study keeps its workers' plans in its own
``plans/`` folder (:func:`kept_in`), the test suite one per run.
"""

from __future__ import annotations

import functools
import hashlib
import io
import os
import platform
import zipfile
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from typing import Iterator

import numpy as np

from uavris.agents.oracle.planner import Plan, PlanSettings
from uavris.config import SystemConfig
from uavris.float_paths import PINNED
from uavris.io import atomic_write_bytes

STORE_ENV = "UAVRIS_PLAN_STORE"
# the environment that chooses the libraries' kernels (uavris.float_paths) and numba's target
_FLOAT_ENV = ("UAVRIS_NATIVE_FLOATS", "NPY_DISABLE_CPU_FEATURES", *PINNED, "NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")
_MEMO_KEY_BYTES = 1 + 6 * 8  # a memo key: exact flag, then the pose (position, attitude) as float64


@contextmanager
def kept_in(folder: Path) -> Iterator[Path]:
    """The store on in ``folder`` for the block, in this process and the workers it starts (they
    inherit the environment); a store the user named is kept instead."""
    named = os.environ.get(STORE_ENV)
    if named:
        yield Path(named)
        return
    os.environ[STORE_ENV] = str(folder)
    try:
        yield folder
    finally:
        os.environ.pop(STORE_ENV, None)


def directory() -> Path | None:
    """The store's directory (``$UAVRIS_PLAN_STORE``), or None: off."""
    named = os.environ.get(STORE_ENV)
    return Path(named) if named else None


@functools.lru_cache(maxsize=1)
def fingerprint() -> str:
    """A hash of the code and the float path a plan is computed with (module docstring)."""
    h = hashlib.sha256()
    package = Path(__file__).resolve().parents[2]  # src/uavris
    for path in sorted(package.rglob("*.py")):
        h.update(str(path.relative_to(package)).encode() + b"\0" + path.read_bytes() + b"\0")
    for name in ("numpy", "scipy", "numba", "llvmlite"):
        try:
            h.update(f"{name}={metadata.version(name)}\0".encode())
        except metadata.PackageNotFoundError:
            h.update(f"{name}=-\0".encode())
    h.update(f"{platform.machine()}\0{_cpu_kind()}\0".encode())
    h.update(repr(sorted((k, os.environ.get(k)) for k in _FLOAT_ENV)).encode())
    return h.hexdigest()


def _cpu_kind() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            return next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), "")
    except OSError:
        return platform.processor()


def key(settings: PlanSettings, system: SystemConfig, start: tuple[float, ...]) -> str:
    """The file name a plan of ``settings`` in ``system`` from ``start`` is stored under."""
    what = repr((settings, system, tuple(float(x) for x in start)))
    return hashlib.sha256(f"{fingerprint()}\0{what}".encode()).hexdigest()


def save(key_: str, plan: Plan, memo: dict[bytes, float]) -> None:
    """Store ``plan`` and the poses it valued (atomically: a reader sees all of it or nothing)."""
    folder = directory()
    if folder is None:
        return
    cands = plan.candidates
    margin = np.nan if plan.front_margin_deg is None else plan.front_margin_deg
    arrays = {
        "start": np.asarray(plan.start, dtype=np.float64), "target": plan.target, "attitude": plan.attitude,
        "numbers": np.array([plan.rate, plan.start_rate, plan.value, plan.rate_se, margin], dtype=np.float64),
        "counts": np.array([plan.travel_slots, plan.poses_valued], dtype=np.int64),
        "candidate_places": np.array([c[0] for c in cands], dtype=np.float64).reshape(len(cands), 3),
        "candidate_values": np.array([c[1:] for c in cands], dtype=np.float64).reshape(len(cands), 2),
        "memo_keys": np.frombuffer(b"".join(memo), dtype=np.uint8).reshape(len(memo), _MEMO_KEY_BYTES),
        "memo_values": np.fromiter(memo.values(), dtype=np.float64, count=len(memo)),
    }
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    atomic_write_bytes(folder / f"{key_}.npz", buffer.getvalue())


def load(key_: str) -> tuple[Plan, dict[bytes, float]] | None:
    """The plan stored under ``key_`` and the poses it valued; None where there is none (or the store is
    off, or the file does not read as a plan: it is then planned again)."""
    folder = directory()
    if folder is None:
        return None
    try:
        with np.load(folder / f"{key_}.npz", allow_pickle=False) as f:
            a = {name: f[name] for name in f.files}
        rate, start_rate, value, rate_se, margin = (float(x) for x in a["numbers"])
        travel, valued = (int(x) for x in a["counts"])
        keys = a["memo_keys"]
        if keys.ndim != 2 or keys.shape[1] != _MEMO_KEY_BYTES or len(keys) != len(a["memo_values"]):
            return None
        plan = Plan(
            start=tuple(float(x) for x in a["start"]), target=a["target"].astype(np.float64),
            attitude=a["attitude"].astype(np.float64), rate=rate, start_rate=start_rate, travel_slots=travel,
            value=value, poses_valued=valued,
            candidates=tuple((tuple(float(x) for x in p), float(r), float(v))
                             for p, (r, v) in zip(a["candidate_places"], a["candidate_values"])),
            rate_se=rate_se, front_margin_deg=None if np.isnan(margin) else margin)
        memo = {bytes(k): float(v) for k, v in zip(keys, a["memo_values"])}
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
        return None
    if plan.target.shape != (3,) or plan.attitude.shape != (3,):
        return None
    return plan, memo
