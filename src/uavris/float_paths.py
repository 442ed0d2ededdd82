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
leaves every library to choose. A process that imported numpy or torch before uavris keeps the
paths they chose (a library cannot change them once loaded), so its workers are told to keep
theirs too (``UAVRIS_NATIVE_FLOATS=1`` in the environment they inherit): a result made in the
process and one made in a worker then agree, and on a CPU with AVX-512 a warning says that the
numbers may differ from another CPU's in the last digits (import uavris first, or set
:data:`PINNED` in the environment).
"""

from __future__ import annotations

import os
import platform
import sys
import warnings
from importlib import metadata

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
    """numpy's dispatch targets and the CPU features it found (its private tables; ``numpy.core``
    before numpy 2): the kernels numpy may choose from are the targets whose feature is on."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__ as targets
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:
        from numpy.core._multiarray_umath import __cpu_dispatch__ as targets
        from numpy.core._multiarray_umath import __cpu_features__ as features
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
    try:
        from threadpoolctl import threadpool_info

        blas = sorted({str(i.get("architecture")) for i in threadpool_info() if i.get("internal_api") == "openblas"})
    except ImportError:
        blas = []
    torch = sys.modules.get("torch")
    capability = torch.backends.cpu.get_cpu_capability() if torch is not None else None
    if not numpy_avx512 and blas in ([], [PINNED["OPENBLAS_CORETYPE"]]) and capability in (None, "AVX2", "DEFAULT"):
        return "the AVX2 path" + (" (its AVX-512 switched off)" if _has_flag("avx512f") else "")
    kernels = [f"numpy {'AVX-512' if numpy_avx512 else 'AVX2'}", *(f"OpenBLAS {b}" for b in blas),
               *([f"torch {capability}"] if capability else [])]
    return f"native kernels ({', '.join(kernels)})"


def pin_float_paths() -> dict[str, str]:
    """Set the environment that pins every library to the AVX2 path (module docstring), where it
    applies: an x86-64 CPU with AVX2, numpy and torch not yet loaded, no ``UAVRIS_NATIVE_FLOATS``.
    Returns what it set."""
    if os.environ.get("UAVRIS_NATIVE_FLOATS") or platform.machine().lower() not in ("x86_64", "amd64"):
        return {}
    if not _has_flag("avx2"):
        return {}
    if "numpy" in sys.modules or "torch" in sys.modules:
        # Too late for this process; its workers follow it rather than take another path.
        os.environ["UAVRIS_NATIVE_FLOATS"] = "1"
        if _has_flag("avx512f"):
            warnings.warn("uavris: numpy or torch was imported before uavris, so this process and its workers use "
                          "this CPU's AVX-512 kernels and the numbers may differ from another CPU's in the last digits "
                          "(import uavris first)", stacklevel=3)
        return {"UAVRIS_NATIVE_FLOATS": "1"}
    wanted = {"NPY_DISABLE_CPU_FEATURES": _numpy_names(), **PINNED}
    done = {k: v for k, v in wanted.items() if k not in os.environ}
    os.environ.update(done)
    return done
