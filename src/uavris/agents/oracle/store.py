"""Plans kept on disk, so that processes of one study (or one test run) plan each hall once.

Lives here: :func:`load` and :func:`save` of a plan and the poses it valued, under a :func:`key`
that names everything the plan is a function of, :func:`kept_in` (the store on for a block) and
:data:`STORE_ENV`, the variable that switches it on. Not here: the plan itself (:mod:`.planner`),
the in-process sharing of plans (:mod:`.policy`).

Why: an oracle's plan is a function of its settings, the system and the start alone (its random
numbers are the settings' seed), and of the code and the float path that compute it. Processes
that plan the same hall (a study's workers evaluating several halls each plan every training hall
for its transfer row; the strong experts each plan the paper's hall; the suite's test files plan
the same generated halls) would each pay seconds to a minute for the same numbers.

The key hashes the settings, the planning system and the start with a fingerprint of the code and
the float path, taken when this module is imported (the code the process runs, whatever happens
to the files later): every source file of the ``uavris`` package, the Python, C library, numpy
(and its BLAS and CPU features), scipy, numba and llvmlite versions, the CPU's model and flags, and
the environment that chooses the libraries' kernels (:mod:`uavris.float_paths`). A
change to any of them is another key. Only the project's own config classes are stored (a subclass
may compute differently). A file is plain numbers (``.npz`` read without pickle) with an HMAC
under this user's seal key (:func:`uavris.runs.seal.mac`): a store someone else filled or edited
cannot run code and is not taken; a file that does not read as a plan is planned again.

Off unless ``$UAVRIS_PLAN_STORE`` names a directory: a study keeps its workers' plans in its own
``plans/`` folder (:func:`kept_in`), the test suite one per run.
"""

from __future__ import annotations

import hashlib
import hmac
import io
import os
import platform
import sys
import warnings
import zipfile
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path
from typing import Iterator

import numpy as np

from uavris.agents.oracle.planner import Plan, PlanSettings
from uavris.config import SystemConfig
from uavris.errors import UavrisError
from uavris.float_paths import cpu_info, numpy_cpu_tables
from uavris.io import atomic_write_bytes
from uavris.runs.seal import mac

STORE_ENV = "UAVRIS_PLAN_STORE"
# the environment that chooses the libraries' kernels (uavris.float_paths). Not the thread counts: every
# process of uavris runs one thread per pool (engine.process.configure_threads, set after this module may
# have been imported), and the planner's kernels are serial (numba without parallel)
_FLOAT_ENV_PREFIXES = ("NUMBA_", "MKL_", "OPENBLAS_", "NPY_", "ATEN_", "ONEDNN_", "OMP_", "UAVRIS_NATIVE_FLOATS")
_NOT_NUMERICS = ("NUMBA_CACHE_DIR",)
_MEMO_KEY_BYTES = 1 + 6 * 8  # a memo key: exact flag, then the pose (position, attitude) as float64
# a plan file's arrays: dtype and shape (None: any length; "C", "M": the candidates', the memo's count)
_FIELDS = {"start": (np.float64, (3,)), "target": (np.float64, (3,)), "attitude": (np.float64, (3,)),
           "numbers": (np.float64, (5,)), "counts": (np.int64, (2,)), "candidate_places": (np.float64, ("C", 3)),
           "candidate_values": (np.float64, ("C", 2)), "memo_keys": (np.uint8, ("M", _MEMO_KEY_BYTES)),
           "memo_values": (np.float64, ("M",))}


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


def _cpu() -> str:
    info = cpu_info()
    return f"{info.get('model name', platform.processor())}\0{info.get('flags', '')}"


def _numpy_build() -> str:
    config = getattr(getattr(np, "__config__", None), "CONFIG", {})
    blas = config.get("Build Dependencies", {}).get("blas", {}) if isinstance(config, dict) else {}
    _, features = numpy_cpu_tables()  # the CPU features numpy's kernels use
    return f"{sorted(blas.items())}{sorted(k for k, on in features.items() if on)}"


def _fingerprint(package: Path) -> str:
    """A hash of the code and the float path a plan is computed with (module docstring)."""
    h = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        h.update(str(path.relative_to(package)).encode() + b"\0" + path.read_bytes() + b"\0")
    for name in ("numpy", "scipy", "numba", "llvmlite"):
        try:
            h.update(f"{name}={metadata.version(name)}\0".encode())
        except metadata.PackageNotFoundError:
            h.update(f"{name}=-\0".encode())
    h.update(f"{sys.version}\0{platform.libc_ver()}\0{platform.machine()}\0{_cpu()}\0{_numpy_build()}\0".encode())
    env = sorted((k, v) for k, v in os.environ.items() if k.startswith(_FLOAT_ENV_PREFIXES)
                 and k not in _NOT_NUMERICS and not k.endswith("_NUM_THREADS"))
    h.update(repr(env).encode())
    return h.hexdigest()


FINGERPRINT = _fingerprint(Path(__file__).resolve().parents[2])  # src/uavris: the code this process runs


def key(settings: PlanSettings, system: SystemConfig, start: tuple[float, ...]) -> str | None:
    """The file name a plan of ``settings`` in ``system`` from ``start`` is stored under; None where it
    is not stored (a subclass of the config classes, whose code the key does not cover)."""
    if type(settings) is not PlanSettings or type(system) is not SystemConfig:
        return None
    what = repr((settings, system, tuple(float(x) for x in start)))
    return hashlib.sha256(f"{FINGERPRINT}\0{what}".encode()).hexdigest()


def _mark(arrays: dict[str, np.ndarray], name: str) -> str:
    """The HMAC of a plan file's arrays and its name (a file copied under another key is not taken)."""
    h = hashlib.sha256(name.encode())
    for field in sorted(arrays):
        a = np.ascontiguousarray(arrays[field])
        h.update(f"{field}{a.dtype.str}{a.shape}".encode() + a.tobytes())
    return mac(h.digest())


_WARNED: set[str] = set()


def save(key_: str, plan: Plan, memo: dict[bytes, float]) -> None:
    """Store ``plan`` and the poses it valued (atomically: a reader sees all of it or nothing). A store
    that cannot be written (a full disk, a read-only folder) is a warning, once: the plan is made."""
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
    try:
        buffer = io.BytesIO()
        np.savez(buffer, **arrays, seal=np.frombuffer(_mark(arrays, key_).encode(), dtype=np.uint8))
        atomic_write_bytes(folder / f"{key_}.npz", buffer.getvalue())
    except (OSError, UavrisError) as e:  # UavrisError: the seal key cannot be made or read
        if str(folder) not in _WARNED:
            _WARNED.add(str(folder))
            warnings.warn(f"uavris: plans are not kept in {folder} ({e}); each process plans for itself",
                          stacklevel=2)


def _read(path: Path, key_: str) -> dict[str, np.ndarray] | None:
    """The arrays of the plan file at ``path``, where each is of its dtype and shape (:data:`_FIELDS`)
    and the file carries this user's mark for ``key_``; None otherwise."""
    with np.load(path, allow_pickle=False) as f:
        arrays = {name: f[name] for name in f.files}
    seal = arrays.pop("seal", None)
    if set(arrays) != set(_FIELDS):
        return None
    counts: dict[str, int] = {}
    for name, (dtype, shape) in _FIELDS.items():
        a = arrays[name]
        if a.dtype != np.dtype(dtype) or a.ndim != len(shape):
            return None
        for size, want in zip(a.shape, shape):
            if size != (counts.setdefault(want, size) if isinstance(want, str) else want):
                return None
    if seal is None or not hmac.compare_digest(seal.tobytes(), _mark(arrays, key_).encode()):
        return None
    return arrays


def load(key_: str, start: tuple[float, ...], settings: PlanSettings) -> tuple[Plan, dict[bytes, float]] | None:
    """The plan from ``start`` stored under ``key_`` and the poses it valued; None where there is none
    (or the store is off, or the file is not this user's plan: it is then planned again)."""
    folder = directory()
    if folder is None:
        return None
    try:
        a = _read(folder / f"{key_}.npz", key_)
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile, UavrisError):
        return None
    if a is None or tuple(float(x) for x in a["start"]) != tuple(float(x) for x in start):
        return None
    rate, start_rate, value, rate_se, _ = (float(x) for x in a["numbers"])
    travel, valued = (int(x) for x in a["counts"])
    plan = Plan(start=tuple(float(x) for x in start), target=a["target"], attitude=a["attitude"], rate=rate,
                start_rate=start_rate, travel_slots=travel, value=value, poses_valued=valued,
                candidates=tuple((tuple(float(x) for x in p), float(r), float(v))
                                 for p, (r, v) in zip(a["candidate_places"], a["candidate_values"])),
                rate_se=rate_se, front_margin_deg=settings.front_margin_deg)  # the margin the plan keeps
    return plan, {bytes(k): float(v) for k, v in zip(a["memo_keys"], a["memo_values"])}
