"""One claim judged in one track: :class:`Judgement`, and :func:`judgement` (one from per-unit differences).

Lives here: what a cell of the claims table holds (its verdict, the mean difference, its 95%
CI, its unit and their count) and the rule that a cell with fewer than
:data:`uavris.stats.MIN_UNITS` units is "not measured". Not here: the verdict rule itself
(:func:`uavris.stats.verdict`), what each claim compares (:mod:`.claims_tracks`,
:mod:`.claims_comparison`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from uavris.stats import MIN_UNITS, NOT_MEASURED, t_p_value

NOT_TESTED = "not tested"


@dataclass(frozen=True)
class Judgement:
    """One claim in one track: the mean paired difference over ``n`` units (``unit``, a
    sentence; ``units``, the noun the cell prints: "seeds", "halls"), its 95% CI, the verdict,
    and what was compared (``text``, one sentence)."""

    claim: str
    track: str
    verdict: str
    mean: float = float("nan")
    ci_low: float = float("nan")
    ci_high: float = float("nan")
    n: int = 0
    unit: str = ""
    units: str = ""
    text: str = ""
    p: float = float("nan")  # two-sided, from the interval (uavris.stats.t_p_value), before any correction
    p_holm: float = float("nan")  # after Holm's correction over the claims table (uavris.experiments.study.claims)

    @property
    def count(self) -> str:
        """"5 seeds", "1 hall": the units and their number."""
        units = self.units or "units"
        return f"{self.n} {units[:-1] if self.n == 1 and units.endswith('s') else units}"

    @property
    def cell(self) -> str:
        if self.verdict == NOT_TESTED:
            return "-"
        count = f" ({self.count})" if self.units else ""
        f = ",.0f" if abs(self.mean) >= 1000 else ",.2f"  # interactions as counts, rates to the hundredth
        if self.verdict == NOT_MEASURED:  # the estimate, without an interval or a verdict
            return f"**{NOT_MEASURED}**" + ("" if math.isnan(self.mean) else f": {self.mean:+{f}}") + count
        ci = "" if math.isnan(self.ci_low) else f" [{self.ci_low:+{f}}, {self.ci_high:+{f}}]"
        return f"**{self.verdict}**: {self.mean:+{f}}{ci}{count}"


def judgement(claim: str, track: str, diff: dict[str, Any], unit: str, units: str, text: str) -> Judgement:
    """The cell of ``diff`` (:func:`uavris.stats.judged`'s or :func:`uavris.stats.judged_censored`'s):
    "not measured" below :data:`MIN_UNITS` units, whatever its interval says; its p-value 1 where a
    unit is censored."""
    v = diff["verdict"] if diff["n"] >= MIN_UNITS else NOT_MEASURED
    # a censored unit's value is only a bound: the interval and its p-value hold at the bounds alone, so the
    # cell is no evidence for any verdict (p = 1: it must not take an early rank in Holm's order)
    p = 1.0 if diff.get("censored") else t_p_value(diff["mean"], diff["ci_low"], diff["ci_high"], diff["n"] - 1)
    return Judgement(claim, track, v, diff["mean"], diff["ci_low"], diff["ci_high"], int(diff["n"]), unit, units, text,
                     p)


__all__ = ["NOT_TESTED", "Judgement", "judgement"]
