"""Allocator tuning for large batched steps (Linux/glibc only, best effort).

A batched step of 1024 environments creates numpy temporaries of ~0.5-1 MB. glibc serves
blocks that size with fresh ``mmap`` calls and returns them on free, so every temporary
pays page faults; that alone cost ~40% of the step time in our benchmark. Raising the
mmap and trim thresholds keeps those blocks in the heap and reuses them. Set
``UAVRIS_NO_MALLOC_TUNING=1`` to leave the allocator alone.

Lives here: :func:`tune_allocator`, which :class:`uavris.env.simulator.BatchedSimulator`
calls for 64 environments or more (docs/model.md section 17). Not here: the one torch
thread per worker process (:func:`uavris.experiments.engine.process.configure_threads`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_done = False


def tune_allocator() -> bool:
    """Raise glibc's mmap/trim thresholds once per process. Returns True when applied."""
    global _done
    if _done or os.environ.get("UAVRIS_NO_MALLOC_TUNING") or not sys.platform.startswith("linux"):
        return _done
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        ok = libc.mallopt(_M_MMAP_THRESHOLD, 32 * 1024 * 1024) == 1
        ok = ok and libc.mallopt(_M_TRIM_THRESHOLD, 256 * 1024 * 1024) == 1
    except (OSError, AttributeError):
        ok = False
    _done = ok
    return ok
