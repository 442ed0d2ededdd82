"""Numbers as text: Markdown tables, values, percentages and confidence intervals, "n/a" for what is missing.

Lives here: :func:`markdown_table` (every table a report, a comparison, a benchmark or an
estimate prints) and the formats of its cells: :func:`num`, :func:`signed`, :func:`pct`
and :func:`with_ci` / :func:`interval` / :func:`rate_interval`; :func:`counted` (a count
and its noun, singular for one). A value that is missing (None) or undefined (NaN: an
interval over one sample, a fraction of a zero oracle) prints as ``n/a``, never as a
number. Not here: the statistics (:mod:`uavris.stats`).
"""

from __future__ import annotations

import math
from typing import Any, Callable, Iterable, Mapping, Sequence

from uavris.stats import MIN_UNITS

MISSING = "n/a"
Fmt = Callable[[Any], str]


def _missing(x: Any) -> bool:
    return x is None or (isinstance(x, float) and math.isnan(x))


def counted(n: int, noun: str, fmt: str = "") -> str:
    """``n`` (formatted by ``fmt``, e.g. ``","``) and ``noun``, plural unless ``n`` is 1:
    "1 episode", "32 episodes" (a printed "1 episodes" reads as a typo)."""
    return f"{n:{fmt}} {noun if n == 1 else noun + 's'}"


def num(x: float | None, digits: int = 2) -> str:
    """``x`` to ``digits`` decimals."""
    return MISSING if _missing(x) else f"{x:.{digits}f}"


def signed(x: float | None, digits: int = 2) -> str:
    """``x`` with its sign, ``+1.25`` or ``-0.40`` (a difference)."""
    return MISSING if _missing(x) else f"{x:+.{digits}f}"


def pct(x: float | None, digits: int = 1) -> str:
    """A fraction as a percentage, ``0.903`` -> ``90.3%``."""
    return MISSING if _missing(x) else f"{x:.{digits}%}"


def fraction(x: float, of: float, digits: int = 0) -> str:
    """``x / of`` as a percentage (``n/a`` when ``of`` is zero or undefined)."""
    return MISSING if _missing(of) or not of else pct(x / of, digits)


def interval(low: float | None, high: float | None, fmt: Fmt = num) -> str:
    """``[low, high]``, or ``n/a`` when the interval is undefined."""
    return MISSING if _missing(low) else f"[{fmt(low)}, {fmt(high)}]"


def rate_interval(low: float | None, high: float | None) -> str:
    """A sum rate's interval ``[low, high]`` (bps/Hz), bounded below at 0: a rate is never
    negative, though the t interval of a few spread-out episodes reaches below 0."""
    return interval(low, high) if low is None or _missing(low) else interval(max(0.0, low), high)


def with_ci(s: Mapping[str, float], fmt: Fmt = num) -> str:
    """A summary's ``mean [ci_low, ci_high]`` (its missing bounds as ``n/a``); over fewer than
    :data:`uavris.stats.MIN_UNITS` units (a summary's ``n``) the mean alone, saying so: an
    interval over two units is too wide to read and supports no verdict."""
    if s.get("n", MIN_UNITS) < MIN_UNITS:
        return f"{fmt(s['mean'])} (no CI: {counted(int(s['n']), 'unit')})"
    return f"{fmt(s['mean'])} [{fmt(s['ci_low'])}, {fmt(s['ci_high'])}]"


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[Any]], align: str | None = None) -> list[str]:
    """A Markdown table as lines: ``header``, the alignment row (``align``: one letter per
    column, ``l`` left or ``r`` right; default all left) and ``rows`` (cells as given,
    ``str()`` of each)."""
    align = align or "l" * len(header)
    if len(align) != len(header):
        raise ValueError(f"align {align!r} has {len(align)} columns, the header {len(header)}")
    rule = "|" + "".join("---:|" if a == "r" else "---|" for a in align)
    return ["| " + " | ".join(header) + " |", rule] + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
