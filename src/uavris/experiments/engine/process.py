"""How a process of uavris runs its work, and what it runs on.

Lives here: :func:`configure_threads` (one thread in every thread pool: every job, the job
runner and the command line call it) and :func:`machine` (the line a report or a page says it
ran on). Not here: the jobs and their workers (:mod:`.jobs`), the float path itself
(:mod:`uavris.float_paths`).
"""

from __future__ import annotations

import os
import platform
import sys
from types import ModuleType

import numpy
from threadpoolctl import threadpool_limits  # loads no library: it limits the ones loaded when called

from uavris.float_paths import cpu_info, float_path

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


def configure_threads(torch_now: bool = True) -> None:
    """One thread in every thread pool of this process: torch's, and the BLAS and OpenMP
    libraries that numpy, scipy and torch load (threadpoolctl). Called where a process
    starts its work, never by a library call: by every job (:mod:`.jobs`), by the job
    runner before it starts workers, and by the command line (``torch_now=False``: torch is
    left to read the environment when a command imports it, so that ``--help`` stays quick).

    The machine's cores go to parallel jobs, not to threads within one. It also makes the
    numbers independent of the machine: a BLAS reduction split over another number of threads
    rounds differently, and OpenBLAS sizes its pool by the CPUs the process may use, so the
    same job pinned to one core and free on two gave different bits (docs/study.md,
    section 3). The environment variables make processes started from this one
    (the job runner's workers) start with one thread too.
    """
    for var in THREAD_VARIABLES:
        os.environ.setdefault(var, "1")
    import scipy.linalg  # noqa: F401  (after the variables: scipy's own BLAS reads them as it loads)

    torch = _torch() if torch_now or "torch" in sys.modules else None
    if torch is not None:  # None: `pip install uavris` without its training extra, nothing to set
        torch.set_num_threads(1)
    threadpool_limits(limits=1)


def _torch() -> ModuleType | None:
    """torch, where the train extra installed it; None in a light install."""
    try:
        import torch
    except ModuleNotFoundError:
        return None
    return torch


def machine() -> str:
    """The machine a study or benchmark ran on, for its report: CPU model (with its family and
    model numbers: two CPUs of one name may differ), CPUs, the float path its libraries ran
    (:func:`uavris.float_paths.float_path`), Python, numpy and torch versions (a verdict that
    flips with the CPU is not a finding: docs/study.md section 3)."""
    found = cpu_info()
    cpu = next((found[k] for k in ("model name", "Hardware", "Processor") if k in found),
               platform.processor() or "unknown CPU")
    if "cpu family" in found and "model" in found:
        cpu += f" (family {found['cpu family']}, model {found['model']})"

    torch = _torch()  # None: a light install (no [train] extra), a report or the claims of studies made elsewhere
    libraries = f"numpy {numpy.__version__}, " + ("no torch" if torch is None else f"torch {torch.__version__}")
    return f"{cpu}, {os.cpu_count()} CPUs, {float_path()}, Python {platform.python_version()}, {libraries}"
