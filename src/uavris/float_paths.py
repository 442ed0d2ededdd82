"""One float path on every x86-64 CPU, so that the references give the same numbers everywhere.

Lives here: :func:`pin_float_paths`, which ``import uavris`` calls before numpy or torch load, and
:data:`PINNED`, what it sets. Not here: the computations (they are written once, whatever the CPU).

Why: numpy, OpenBLAS, MKL and torch choose their kernels by the CPU they run on. An Intel Xeon
with AVX-512 and an AMD EPYC with AVX2 then round a transcendental function, a dot product or a
matrix product differently (numpy's AVX-512 exp, log and sin of float64 against libm's, OpenBLAS's
SkylakeX kernels against its Haswell ones), and an oracle's plan that chooses between two places
worth nearly the same went one way on one machine and the other way on the other (docs/timings.md,
"One float path"). Every x86-64 CPU that runs uavris has AVX2, so that level is the one path:
the AVX-512 kernels are switched off before the libraries load, in this process and in every
worker it starts (they inherit the environment). The cost is the AVX-512 kernels' speed on the
CPUs that have them.

What a user set is kept (the variables are set only where absent), and ``UAVRIS_NATIVE_FLOATS=1``
leaves every library to choose. A process that imported numpy or torch before uavris (a
Gymnasium or SB3 script, a notebook) keeps the paths they chose (a library cannot change them
once loaded), so its workers are told to keep theirs too (``UAVRIS_NATIVE_FLOATS=1`` in the
environment they inherit): a result made in the process and one made in a worker then agree.
That is said where it matters, not at the import: using the simulator, an env or a policy is the
same on either path to the last digits or so, and a user who did not choose the order of imports
should not be told at once that their numbers are wrong. Where a result is written to be compared
with another machine's (:func:`warn_if_unpinned`: ``reproduce``, ``benchmark`` and the claims
run from Python), a CPU with AVX-512 gets one warning; :func:`status` says the path at any time,
and every report's machine line names it (:func:`float_path`).
"""

from __future__ import annotations

import os
import platform
import sys
import warnings
from importlib import metadata

from threadpoolctl import threadpool_info  # loads no library: it lists the ones loaded when called

# numpy 2.4 dispatches by x86-64 levels (X86_V3 is AVX2, X86_V4 AVX-512), earlier releases by features
_NUMPY_AVX512 = {"levels": "X86_V4 AVX512_ICL AVX512_SPR",
                 "features": "AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL "
                             "AVX512_SPR"}
PINNED: dict[str, str] = {
    "OPENBLAS_CORETYPE": "Haswell",  # numpy's and scipy's BLAS: the AVX2 kernels
    "MKL_CBWR": "AVX2",  # torch's MKL: conditional numerical reproducibility on the AVX2 path
    "MKL_ENABLE_INSTRUCTIONS": "AVX2",
    "ONEDNN_MAX_CPU_ISA": "AVX2",  # torch's oneDNN
    "ATEN_CPU_CAPABILITY": "avx2",  # torch's own vectorised kernels
}


def _numpy_names() -> str:
    try:
        major, minor = (int(x) for x in metadata.version("numpy").split(".")[:2])
    except (metadata.PackageNotFoundError, ValueError):
        return _NUMPY_AVX512["levels"]
    return _NUMPY_AVX512["levels" if (major, minor) >= (2, 4) else "features"]


def cpu_info() -> dict[str, str]:
    """The first CPU's fields of ``/proc/cpuinfo`` (``model name``, ``cpu family``, ``model``,
    ``flags``, ...); empty where there is none (not Linux)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            first = f.read().split("\n\n", 1)[0]
    except OSError:
        return {}
    fields = (line.partition(":") for line in first.splitlines())
    return {key.strip(): value.strip() for key, sep, value in fields if sep}


def _has_flag(flag: str) -> bool:
    return flag in cpu_info().get("flags", "").split()


def numpy_cpu_tables() -> tuple[list[str], dict[str, bool]]:
    """numpy's dispatch targets and the CPU features it found (its private tables): the kernels numpy
    may choose from are the targets whose feature is on. Imported here, not at the top: this module
    runs before numpy loads its kernels (:func:`pin_float_paths`)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__ as targets
    from numpy._core._multiarray_umath import __cpu_features__ as features

    return list(targets), dict(features)


def float_path() -> str:
    """The kernels this process's libraries run, in words (a report's machine line), read from the
    libraries as loaded, not from the environment: numpy's dispatch targets, OpenBLAS's kernels
    (threadpoolctl) and torch's capability where torch is loaded. On x86-64: the AVX2 path (saying
    where the CPU's AVX-512 is switched off), or native kernels, each library's named."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return "the libraries' own kernels"
    targets, features = numpy_cpu_tables()
    numpy_avx512 = any(features.get(k) for k in targets if "AVX512" in k or k == "X86_V4")
    blas = sorted({str(i.get("architecture")) for i in threadpool_info() if i.get("internal_api") == "openblas"})
    torch = sys.modules.get("torch")
    capability = torch.backends.cpu.get_cpu_capability() if torch is not None else None
    if not numpy_avx512 and blas in ([], [PINNED["OPENBLAS_CORETYPE"]]) and capability in (None, "AVX2", "DEFAULT"):
        return "the AVX2 path" + (" (its AVX-512 switched off)" if _has_flag("avx512f") else "")
    kernels = [f"numpy {'AVX-512' if numpy_avx512 else 'AVX2'}", *(f"OpenBLAS {b}" for b in blas),
               *([f"torch {capability}"] if capability else [])]
    return f"native kernels ({', '.join(kernels)})"


_LATE = False  # numpy or torch was loaded before uavris: this process keeps their kernels (pin_float_paths)
_WARNED: set[str] = set()


def status() -> str:
    """This process's float path in one line, and why: pinned by ``import uavris`` (or by the
    user's environment), native by ``UAVRIS_NATIVE_FLOATS``, or native because numpy or torch was
    imported before uavris."""
    path = float_path()
    if not path.startswith("native"):
        return f"{path}: pinned before numpy and torch loaded" if path.startswith("the AVX2") else path
    if _LATE:
        return f"{path}: numpy or torch was imported before uavris, which pins the path only before they load"
    if os.environ.get("UAVRIS_NATIVE_FLOATS"):
        return f"{path}: UAVRIS_NATIVE_FLOATS is set"
    return f"{path}: the environment chose them"


def _caller_level() -> int:
    """The ``stacklevel`` of the first frame outside uavris: a warning points at the user's line,
    whichever of uavris's functions the user called."""
    frame, level = sys._getframe(1), 1
    package = os.path.dirname(os.path.abspath(__file__))
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(package + os.sep):
        frame, level = frame.f_back, level + 1
    return level


def warn_if_unpinned(what: str) -> None:
    """One warning per process and ``what`` where a result meant to be compared with another
    machine's is made on this CPU's AVX-512 kernels because numpy or torch was imported before
    uavris (a script that sets ``UAVRIS_NATIVE_FLOATS`` chose its path and is not warned; one that
    set the pinned environment itself runs the AVX2 path and is not either)."""
    if _LATE and _has_flag("avx512f") and what not in _WARNED and float_path().startswith("native"):
        _WARNED.add(what)
        warnings.warn(f"uavris: {what} runs on this CPU's AVX-512 kernels because numpy or torch was imported "
                      "before uavris: its numbers may differ from another CPU's in the last digits (import uavris "
                      "first; uavris.float_paths.status())", stacklevel=_caller_level())


def pin_float_paths() -> dict[str, str]:
    """Set the environment that pins every library to the AVX2 path (module docstring), where it
    applies: an x86-64 CPU with AVX2, numpy and torch not yet loaded, no ``UAVRIS_NATIVE_FLOATS``.
    Returns what it set."""
    if os.environ.get("UAVRIS_NATIVE_FLOATS") or platform.machine().lower() not in ("x86_64", "amd64"):
        return {}
    if not _has_flag("avx2"):
        return {}
    if "numpy" in sys.modules or "torch" in sys.modules:
        # Too late for this process; its workers follow it rather than take another path. Said where a
        # result meant for comparison is made (warn_if_unpinned), not here.
        global _LATE
        _LATE = True
        os.environ["UAVRIS_NATIVE_FLOATS"] = "1"
        return {"UAVRIS_NATIVE_FLOATS": "1"}
    wanted = {"NPY_DISABLE_CPU_FEATURES": _numpy_names(), **PINNED}
    done = {k: v for k, v in wanted.items() if k not in os.environ}
    os.environ.update(done)
    return done
