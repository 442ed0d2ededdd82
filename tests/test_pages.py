"""Every results page from one version: each committed page current by its stamp or listed as
historical with its reason, a check that fails on a stale, unlisted or unmarked page, the stamp
read as JSON only, and `uavris pages` running its studies in order, stopping on a failure."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import sys
from pathlib import Path

import pytest

from uavris.errors import UavrisError
from uavris.experiments.study import pages as pages_module
from uavris.experiments.study.pages import PAGES, StudyRun, check_pages, link_finished_stages, run_studies, studies
from uavris.experiments.study.stamp import (
    HISTORICAL_FILE,
    current_versions,
    historical_banner,
    make_stamp,
    read_stamp,
    stale,
    stamp_block,
    stamped,
)
from uavris.io import read_yaml

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"


def test_every_committed_results_page_is_current_or_listed_as_historical():
    """The CI check: a page older than this code's results format, oracle or teacher is listed in
    historical.yaml with its reason and says so at its top; no listed page is current."""
    assert check_pages(RESULTS) == []
    assert {p.name for p in RESULTS.glob("*.md")} >= {PAGES[p].file for p in PAGES}  # every page it makes is here


def _results(tmp_path: Path) -> Path:
    """A results folder of three pages: one current (stamped now), one historical, one unstamped."""
    d = tmp_path / "results"
    d.mkdir()
    (d / "now.md").write_text(stamped(make_stamp("now"), "# Now\n\nText.\n"))
    (d / "old.md").write_text(f"# Old\n\n{historical_banner('made by an older oracle')}\n\n## Section\n")
    (d / HISTORICAL_FILE).write_text("old.md: made by an older oracle\n")
    return d


def test_the_check_fails_on_an_edited_stamp_an_unlisted_page_or_an_unmarked_one(tmp_path):
    d = _results(tmp_path)
    assert check_pages(d) == []
    now = (d / "now.md").read_text()
    stamp = read_stamp(now)
    for field, value in (("oracle_version", stamp.oracle_version - 1), ("results_format", 0),
                         ("teacher", {**stamp.teacher, "check_batches": 99})):
        (d / "now.md").write_text(stamped(dataclasses.replace(stamp, **{field: value}), now))
        [problem] = check_pages(d)
        assert "now.md is older than this code" in problem and field.replace("_", " ") in problem
    (d / "now.md").write_text(now.replace(stamp_block(stamp), ""))  # no stamp at all
    assert "no stamp" in check_pages(d)[0]
    (d / "now.md").write_text(now)
    (d / HISTORICAL_FILE).write_text("old.md: made by an older oracle\nnow.md: listed though current\n")
    assert check_pages(d) == [f"now.md is current, yet listed as historical in {HISTORICAL_FILE}"]
    (d / HISTORICAL_FILE).write_text("old.md: another reason\n")  # the page's banner no longer says the reason
    assert "does not say so at its top" in check_pages(d)[0]
    (d / HISTORICAL_FILE).write_text("old.md: made by an older oracle\ngone.md: a page that is not here\n")
    assert check_pages(d) == [f"gone.md is listed in {HISTORICAL_FILE} but is not a page here"]
    (d / HISTORICAL_FILE).write_text("- a list, not a mapping\n")
    assert "expected a mapping" in check_pages(d)[0]


def test_a_stamp_is_this_codes_versions_and_reads_back_as_written():
    stamp = make_stamp("quick-report", ["runs/quick"], "quick", "uavris reproduce --preset quick", seed=0)
    assert stale(stamp) == [] and {k: getattr(stamp, k) for k in current_versions()} == current_versions()
    text = stamped(stamp, "# Page\n")
    assert text.startswith("<!-- uavris-page\n") and text.endswith("# Page\n")
    assert read_stamp(text) == stamp and read_stamp(stamped(stamp, text)) == stamp  # restamping replaces it
    assert json.loads(text.split("\n", 1)[1].split("\n-->")[0])["page"] == "quick-report"
    assert read_stamp("# A page\n") is None and stale(None) == ["no stamp (made before pages were stamped)"]
    assert stamp.machine and stamp.float_path and len(stamp.date) == 10


@pytest.mark.parametrize("block", ['{"page": ', '!!python/object/apply:os.system ["echo hi"]',
                                   '{"page": "x", "unknown_field": 1}'])
def test_a_stamp_that_is_not_ours_is_one_line_and_runs_nothing(block):
    """JSON only: a YAML tag that would call a function is an error, as is a field of no stamp."""
    with pytest.raises(UavrisError, match="its stamp is not one uavris writes"):
        read_stamp(f"<!-- uavris-page\n{block}\n-->\n# Page\n", "page.md")


def test_the_historical_pages_are_not_quoted_as_current():
    """The README and the results page may quote a historical page only marked as such
    (``<!-- quotes results/X.md (historical) -->``), and a current page never so marked."""
    import re

    listed = read_yaml(RESULTS / HISTORICAL_FILE)
    for page in (RESULTS.parents[1] / "README.md", RESULTS.parent / "results.md"):
        for m in re.finditer(r"<!-- quotes results/([\w./-]+\.md)( \(historical\))? -->", page.read_text()):
            assert bool(m.group(2)) == (m.group(1) in listed), (page.name, m.group(0))


def _stage(study: Path, name: str, done: bool = True) -> Path:
    d = study / "stages" / name
    (d / "model").mkdir(parents=True)
    (d / "model" / "weights.bin").write_bytes(b"w" * 100)
    if done:
        (d / "stage.json").write_text("{}")
    return d


def test_a_study_starts_from_anothers_finished_stages_linked_not_copied(tmp_path):
    src, dst = tmp_path / "a", tmp_path / "b"
    done = _stage(src, "compare-aaaaaaaaaaaa")
    _stage(src, "pretrain-bbbbbbbbbbbb", done=False)  # unfinished: its own study runs it
    own = _stage(dst, "evaluate-cccccccccccc")
    assert link_finished_stages(src, dst) == 1
    linked = dst / "stages" / done.name
    assert (linked / "model" / "weights.bin").read_bytes() == b"w" * 100
    assert os.stat(linked / "model" / "weights.bin").st_ino == os.stat(done / "model" / "weights.bin").st_ino
    assert not (dst / "stages" / "pretrain-bbbbbbbbbbbb").exists() and own.exists()
    assert link_finished_stages(src, dst) == 0  # a rerun links nothing twice
    assert not list((dst / "stages").glob(".*"))  # no folder left half-made


def test_the_pages_read_studies_that_exist_and_run_after_what_they_start_from():
    for preset in ("smoke", "quick"):
        table = studies(preset, 5)
        for page in PAGES.values():
            needed = pages_module._needed([page.name], preset, 5)
            names = [r.name for r in needed]
            assert set(page.reads(5)) <= set(names)
            for i, r in enumerate(needed):
                assert all(names.index(d) < i for d in (*r.reuse, *r.after)), (page.name, r.name)
                assert table[r.name] == r
    assert [s for s in PAGES["claims"].reads(3) if s.startswith(("paper-s", "strong-s"))] == [
        "paper-s1", "strong-s1", "paper-s2", "strong-s2"]
    budget = studies("quick")["budget"].command(Path("runs/pages"), "quick")
    assert budget[budget.index("--steps") + 1] == "100000" and budget[budget.index("--eval-every") + 1] == "12500"


def test_a_failed_study_stops_the_ones_after_it_with_one_line_naming_its_log(tmp_path, monkeypatch):
    """A study whose command fails (here: a study directory that is none) is named with its log,
    and the study that follows it never starts."""
    bad = StudyRun("bad", ("from-scratch", str(tmp_path / "nothing"), "--out", str(tmp_path / "x.json")), "x.json")
    later = StudyRun("later", ("claims", str(tmp_path / "nothing")), "later", after=("bad",))
    said: list[str] = []
    with pytest.raises(UavrisError, match=r"bad failed: see .*bad\.log"):
        run_studies([bad, later], tmp_path / "runs", "smoke", jobs=2, workers=1, say=said.append)
    assert "not a study" in (tmp_path / "runs" / ".pages" / "bad.log").read_text()
    assert not (tmp_path / "runs" / ".pages" / "later.log").exists()
    assert any(line.startswith("[pages] bad: uavris from-scratch") for line in said)


def test_pages_list_names_every_page_and_its_commands_and_runs_nothing(tmp_path, capsys):
    from uavris.cli import main

    assert main(["pages", "--list", "--preset", "smoke", "--runs", str(tmp_path / "r")]) == 0
    printed = capsys.readouterr().out
    for name, page in PAGES.items():
        assert f"{name} (docs/results/{page.file})" in printed
    assert f"uavris reproduce --preset smoke --out {tmp_path / 'r'}/quick" in printed
    assert not (tmp_path / "r").exists()
    assert main(["pages", "no-such-page"]) == 2 and "no page no-such-page" in capsys.readouterr().err
    assert main(["pages", "--seeds", "2", "--list"]) == 2


def test_a_study_of_pages_stops_when_pages_is_stopped(tmp_path):
    """SIGTERM to `uavris pages` (a batch system's stop) stops the study it runs: nothing of it is
    left running."""
    import signal
    import subprocess
    import time

    code = ("import sys, time; from pathlib import Path; from uavris.experiments.study import pages as p\n"
            "p.run_studies([p.StudyRun('s', ('reproduce', '--preset', 'smoke', '--out', sys.argv[1]), 's')], "
            "Path(sys.argv[2]), 'smoke', 1, 1)\n")
    runs = tmp_path / "runs"
    proc = subprocess.Popen([sys.executable, "-c", code, str(tmp_path / "study"), str(runs)])
    log = runs / ".pages" / "s.log"
    deadline = time.monotonic() + 120
    while not (log.exists() and log.stat().st_size) and time.monotonic() < deadline:
        time.sleep(0.2)
    children = [int(p) for p in Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split()]
    assert children
    proc.send_signal(signal.SIGTERM)  # no handler in this process: it dies at once, as under SIGKILL

    def alive(pid: int) -> bool:
        try:
            return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
        except OSError:
            return False

    proc.wait(60)
    deadline = time.monotonic() + 60  # the study stops its own workers first
    while any(alive(c) for c in children) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not any(alive(c) for c in children)
    shutil.rmtree(tmp_path, ignore_errors=True)
