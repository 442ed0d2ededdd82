"""Shared benchmark set-up: one core, and a description of the machine for the report."""

from __future__ import annotations

import os


def pin_to_one_core() -> str:
    """Restrict this process to the first CPU it may run on; describe the outcome."""
    if not hasattr(os, "sched_setaffinity"):
        return "not pinned (os.sched_setaffinity unavailable on this platform)"
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return f"pinned to CPU {cpu}"


def cpu_model() -> str:
    """The machine, as every report of uavris describes it (:func:`uavris.experiments.engine.process.machine`)."""
    from uavris.experiments.engine.process import machine

    return machine()


def table(rows: list[tuple[str, ...]]) -> str:
    """A Markdown table with padded columns (readable in a terminal too); ``rows[0]`` is the header."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["| " + " | ".join(c.ljust(w) for c, w in zip(rows[0], widths)) + " |",
             "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    lines += ["| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |" for r in rows[1:]]
    return "\n".join(lines)
