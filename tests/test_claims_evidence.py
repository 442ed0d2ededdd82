"""The committed claims page against its committed evidence (docs/results/claims-evidence/ and
claims.json): every cell printed as its record says, every verdict one its interval and Holm's
correction allow, and the paper and strong tracks' cells derived again here from the seed
studies' reports, with scipy's t interval, to the reports' printed precision."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"
EVIDENCE = RESULTS / "claims-evidence"
TRACK_SECTIONS = {"paper": "## Paper track", "strong": "## Strong track"}

pytestmark = pytest.mark.skipif(not (RESULTS / "claims.json").exists(), reason="no committed claims.json")


def _judgements() -> list[dict]:
    return json.loads((RESULTS / "claims.json").read_text())["judgements"]


def test_every_cell_of_the_page_is_its_record_and_every_study_has_its_report():
    """Each judged cell as the page prints it: interactions (a mean of 1,000 or more) as counts, rates
    to the hundredth; the evidence folder holds exactly the judged studies' reports."""
    page = (RESULTS / "claims.md").read_text()
    table = page[page.index("| claim |"):]
    table = table[:table.index("\n\n")]
    for j in _judgements():
        if j["verdict"] in ("holds", "refuted", "not resolved"):
            f = "+,.0f" if abs(j["mean"]) >= 1000 else "+,.2f"
            cell = f"**{j['verdict']}**: {j['mean']:{f}} [{j['ci_low']:{f}}, {j['ci_high']:{f}}]"
            assert cell in table, (j["track"], j["claim"], cell)
    studies = json.loads((RESULTS / "claims.json").read_text())["inputs"]["studies"]
    assert sorted(p.stem for p in EVIDENCE.glob("*.md")) == sorted(Path(s).name for s in studies)


def test_every_verdict_is_one_its_interval_and_holms_correction_allow():
    """Holm's step-down adjustment computed here over the judged cells' p-values; a verdict
    stands only where its adjusted p is at most 0.05 and its interval excludes zero its way."""
    judged = [j for j in _judgements() if j["verdict"] in ("holds", "refuted", "not resolved")
              and j["p"] is not None and math.isfinite(j["p"])]
    assert len(judged) >= 20
    p = np.array([j["p"] for j in judged])
    order = np.argsort(p, kind="stable")
    adjusted = np.empty_like(p)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (len(p) - rank) * p[i]))
        adjusted[i] = running
    for j, a in zip(judged, adjusted):
        assert j["p_holm"] == pytest.approx(a, abs=1e-12), (j["track"], j["claim"])
        if j["verdict"] == "holds":
            assert a <= 0.05 and j["ci_low"] > 0, (j["track"], j["claim"])
        if j["verdict"] == "refuted":
            assert a <= 0.05 and j["ci_high"] < 0, (j["track"], j["claim"])


def _scenario_rows(report: str, section: str) -> dict[str, dict[str, float]]:
    """{unseen scenario: {row: mean}} of one track's section of a study's report."""
    part = report[report.index(section):]
    part = part[:part.index("\n## ", 1)]
    out: dict[str, dict[str, float]] = {}
    for block in part.split("### Unseen scenario ")[1:]:
        scenario = block.split()[0]
        out[scenario] = {m.group(1): float(m.group(2))
                         for m in re.finditer(r"^\| ([^|]+?) \| (-?\d+\.\d+) \|", block, re.M)}
    return out


def _units(track: str) -> dict[str, list[float]]:
    """Each study's unit (its unseen scenarios averaged) of three cells, from its report."""
    units: dict[str, list[float]] = {"zero-shot": [], "finetuned": [], "dt-over-bc": []}
    for path in sorted(EVIDENCE.glob("*.md")):
        report = path.read_text()
        if TRACK_SECTIONS[track] not in report:
            continue
        per: dict[str, list[float]] = {k: [] for k in units}
        for rows in _scenario_rows(report, TRACK_SECTIONS[track]).values():
            transferred = max(v for k, v in rows.items() if " transferred from " in k)
            per["zero-shot"].append(rows["zero-shot DT"] - transferred)
            per["finetuned"].append(rows["fine-tuned DT"] - rows["zero-shot DT"])
            bc = next(v for k, v in rows.items() if k.startswith("behaviour cloning"))
            per["dt-over-bc"].append(rows["zero-shot DT"] - bc)
        for k, v in per.items():
            units[k].append(float(np.mean(v)))
    return units


@pytest.mark.parametrize("track", list(TRACK_SECTIONS))
def test_the_seed_tracks_cells_follow_from_the_studies_reports(track):
    """Each unit a study: the paired mean of two rows equals the difference of their means, which
    its report prints to 0.005, so a unit is known to 0.01, the mean to 0.01 and the interval's
    half-width to t * 0.01 / sqrt(n - 1) (the standard deviation moves by at most the error's norm
    over sqrt(n - 1))."""
    cells = {j["claim"]: j for j in _judgements() if j["track"] == track and j["claim"] in ("zero-shot", "finetuned",
                                                                                              "dt-over-bc")}
    for claim, values in _units(track).items():
        j = cells[claim]
        assert len(values) == j["n"] >= 3, (track, claim)
        mean = float(np.mean(values))
        half = stats.t.ppf(0.975, len(values) - 1) * np.std(values, ddof=1) / math.sqrt(len(values))
        t = stats.t.ppf(0.975, len(values) - 1)
        tolerance = 0.0101 + t * 0.0101 / math.sqrt(len(values) - 1)
        assert j["mean"] == pytest.approx(mean, abs=0.0101), (track, claim)
        assert j["ci_low"] == pytest.approx(mean - half, abs=tolerance), (track, claim)
        assert j["ci_high"] == pytest.approx(mean + half, abs=tolerance), (track, claim)
