"""What a (re)run prints about its stages: a stage finished earlier is "done earlier" with the
time it took then, never a time this invocation spent."""

from __future__ import annotations

from pathlib import Path

from uavris.experiments.engine.scheduling import StudyContext, stage_line
from uavris.experiments.engine.stages import StageRecord


class _Bar:
    def __init__(self) -> None:
        self.n, self.total, self.lines = 0.0, 100.0, []

    def write(self, line: str) -> None:
        self.lines.append(line)

    def refresh(self) -> None:
        pass

    def update(self, amount: float) -> None:
        self.n += amount


def test_a_stage_done_earlier_is_not_reported_as_a_time_spent_now():
    rec = StageRecord("compare", "abc", Path("x"), "skipped", 14.5 * 60, {})
    line = stage_line(rec)
    assert line == "stage compare [abc]: done earlier (14.5 min then), skipped"
    assert "skipped in" not in line


def test_a_stage_run_now_says_how_long_it_took():
    done = StageRecord("pretrain", "k", Path("x"), "done", 90.0, {})
    assert stage_line(done) == "stage pretrain [k]: done in 1.5 min"
    failed = StageRecord("pretrain", "k", Path("x"), "failed", 6.0, None, "boom; log x")
    assert stage_line(failed) == "stage pretrain [k]: failed in 0.1 min (boom; log x)"


def test_the_context_prints_the_line_through_the_bar():
    bar = _Bar()
    ctx = StudyContext(1, "local", None, bar)
    try:
        ctx.stage_done(StageRecord("compare", "abc", Path("x"), "skipped", 870.0, {}))
    finally:
        ctx.close()
    assert bar.lines == ["stage compare [abc]: done earlier (14.5 min then), skipped"]
