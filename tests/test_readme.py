"""The README runs: every Python block executes on its own, and what it says about presets is the code's."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
SKIP_MARK = "# readme: skip"  # in a block that is too long for the suite (documented there)


def _python_blocks() -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", README.read_text(encoding="utf-8"), flags=re.S | re.M)


def test_readme_has_python_blocks() -> None:
    assert len(_python_blocks()) >= 3


@pytest.mark.parametrize("index", range(len(_python_blocks())))
def test_python_block_runs_on_its_own(index: int, tmp_path: Path) -> None:
    """Each block in a fresh interpreter (no imports carried over from another block)."""
    block = _python_blocks()[index]
    if SKIP_MARK in block:
        pytest.skip("marked as too long for the test suite")
    script = tmp_path / f"block{index}.py"
    script.write_text(block, encoding="utf-8")
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"README block {index} failed:\n{block}\n{proc.stderr[-2000:]}"


def test_preset_numbers_are_the_codes() -> None:
    """The README's preset sentence states the training budgets and evaluation episodes of
    :mod:`uavris.presets`."""
    from uavris.presets import TRAIN_EVAL, TRAIN_STEPS

    text = " ".join(README.read_text(encoding="utf-8").split())
    for preset in ("smoke", "quick", "paper"):
        m = re.search(rf"`{preset}` \(([\d,.]+) (M )?env steps per run, (\d+) evaluation episodes", text)
        assert m, f"README does not state the {preset} preset's budget"
        steps = float(m.group(1).replace(",", "")) * (1_000_000 if m.group(2) else 1)
        assert steps == TRAIN_STEPS[preset], preset
        assert int(m.group(3)) == TRAIN_EVAL[preset][1], preset


QUICK_REPORT = README.parent / "docs" / "results" / "quick-report.md"


def _section(text: str, title: str) -> str:
    start = text.index(title)
    end = text.find("\n## ", start + len(title))
    return text[start:end if end >= 0 else len(text)]


def test_readme_results_are_the_reports() -> None:
    """Every score and fraction the README quotes from a quick run (2-decimal numbers, 1-decimal
    percentages) is one the committed report of that run states: the README copies, never
    retypes. The report is `runs/quick/report.md` of the run the section names."""
    report = QUICK_REPORT.read_text(encoding="utf-8")
    section = _section(README.read_text(encoding="utf-8"), "## Results of a quick run")
    quoted = set(re.findall(r"(?<![\d.])[+-]?\d+\.\d\d(?!\d|\.\d)", section))  # not a version's "3.11" of 3.11.7
    quoted |= set(re.findall(r"(?<![\d.])\d+\.\d%", section))
    assert len(quoted) > 40, "the results section quotes the report's numbers"
    missing = sorted(q for q in quoted if not _whole(q, report) and not _whole(q.lstrip("+"), report))
    assert not missing, f"README numbers not in {QUICK_REPORT.name}: {missing}"


def _whole(number: str, text: str) -> bool:
    """``number`` occurs in ``text`` as a whole number: "0.93" is not found inside "40.93" or "0.931"."""
    return re.search(rf"(?<![\d.]){re.escape(number)}(?!\d|\.\d)", text) is not None


def test_numbers_are_matched_whole():
    assert _whole("0.93", "DT 0.93 bps/Hz") and _whole("+1.20", "diff +1.20 [") and _whole("59.1%", "(59.1%)")
    assert not _whole("0.93", "DT 40.93 bps/Hz") and not _whole("0.93", "0.931") and not _whole("9.1%", "59.1%")
    assert not _whole("3.11", "Python 3.11.7")
