"""The README and the docs run: every Python block of README.md and of every docs page executes on its
own and quietly (an empty stderr, as a user runs it: with the CPU's own kernels and with numpy's
AVX-512 kernels off), what they say about presets is the code's, and the quick run's results they
quote are the report's."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
# Every page whose Python blocks run: the README and the documentation site's pages.
PAGES = [README, *sorted(DOCS.rglob("*.md"))]
SKIP_MARK = "# readme: skip"  # in a block that is too long for the suite (documented there)


def _python_blocks(page: Path = README) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", page.read_text(encoding="utf-8"), flags=re.S | re.M)


BLOCKS = [(page, index) for page in PAGES for index in range(len(_python_blocks(page)))]


def test_readme_has_python_blocks() -> None:
    assert len(_python_blocks()) >= 3


def test_readme_is_a_front_page() -> None:
    """Under 150 lines, a runnable example (a Python block, which the test below runs) within its
    first 40, and no table of verdicts (the results pages hold it)."""
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 150
    assert lines.index("```python") < 40
    assert not any(line.startswith("| claim |") for line in lines)


def test_docs_have_python_blocks() -> None:
    """The pages the README's examples moved to still hold them (the collection is not empty)."""
    for name in ("getting-started.md", "controller.md", "halls.md", "environment.md"):
        assert _python_blocks(DOCS / name), name


def _as_a_user_runs(avx512_off: bool) -> dict[str, str]:
    """This environment without what ``import uavris`` (tests/conftest.py) set in it: a user's shell,
    where a block that imports numpy first gets numpy's own kernels; ``avx512_off``: with numpy's
    AVX-512 kernels forced off, as on a CPU without them."""
    from uavris.float_paths import PINNED, _numpy_names

    env = {k: v for k, v in os.environ.items() if k not in ("NPY_DISABLE_CPU_FEATURES", "UAVRIS_NATIVE_FLOATS",
                                                            *PINNED)}
    return env | ({"NPY_DISABLE_CPU_FEATURES": _numpy_names()} if avx512_off else {})


@pytest.mark.parametrize("page, index", BLOCKS, ids=[f"{p.relative_to(ROOT)}-{i}" for p, i in BLOCKS])
def test_python_block_runs_on_its_own(page: Path, index: int, tmp_path: Path) -> None:
    """Each block in a fresh interpreter (no imports carried over from another block), in a user's
    environment, silent on stderr: on this CPU's kernels and again with numpy's AVX-512 kernels off."""
    block = _python_blocks(page)[index]
    if SKIP_MARK in block:
        pytest.skip("marked as too long for the test suite")
    script = tmp_path / f"block{index}.py"
    script.write_text(block, encoding="utf-8")
    for avx512_off in (False, True):
        proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True,
                              timeout=300, env=_as_a_user_runs(avx512_off))
        where = f"{page.relative_to(ROOT)} block {index}" + (" (numpy's AVX-512 off)" if avx512_off else "")
        assert proc.returncode == 0, f"{where} failed:\n{block}\n{proc.stderr[-2000:]}"
        assert proc.stderr == "", f"{where} wrote to stderr:\n{proc.stderr[-2000:]}"


PRESET_PAGE = DOCS / "experts.md"  # the presets' sentence (it was the README's)


def test_preset_numbers_are_the_codes() -> None:
    """The preset sentence (docs/experts.md, once the README's) states the training budgets and
    evaluation episodes of :mod:`uavris.presets`, and so does any other page that states them."""
    from uavris.presets import TRAIN

    for page in PAGES:
        text = " ".join(page.read_text(encoding="utf-8").split())
        for preset in ("smoke", "quick", "paper"):
            found = list(re.finditer(rf"`{preset}` \(([\d,.]+) (M )?env steps per run, (\d+) evaluation episodes",
                                     text))
            assert found or page != PRESET_PAGE, f"{PRESET_PAGE.name} does not state the {preset} preset's budget"
            for m in found:
                steps = float(m.group(1).replace(",", "")) * (1_000_000 if m.group(2) else 1)
                assert steps == TRAIN[preset]["total_steps"], (page.name, preset)
                assert int(m.group(3)) == TRAIN[preset]["eval_episodes"], (page.name, preset)


QUICK_REPORT = DOCS / "results" / "quick-report.md"
RESULTS_PAGE = DOCS / "results.md"  # the results of a quick run (they were the README's)


def _section(text: str, title: str) -> str:
    start = text.index(title)
    end = text.find("\n## ", start + len(title))
    return text[start:end if end >= 0 else len(text)]


def test_readme_results_are_the_reports() -> None:
    """Every score and fraction the results page (docs/results.md, once the README's section)
    quotes from a quick run is one the committed report of that run states, in its row: the
    page copies, never retypes. The report is `runs/quick/report.md` of the run the section names."""
    report = QUICK_REPORT.read_text(encoding="utf-8")
    title = "## Results of a quick run"
    pages = [page for page in PAGES if page != QUICK_REPORT and title in page.read_text(encoding="utf-8")]
    assert RESULTS_PAGE in pages, f"{RESULTS_PAGE.name} has no section {title!r}"
    for page in pages:  # the results page, and any other page that holds such a section
        section = _section(page.read_text(encoding="utf-8"), title)
        assert len(_tables(section)) >= 4 and len(re.findall(r"\d+\.\d\d", section)) > 100, "it quotes the report"
        assert not _misplaced(section, report), page.name


QUOTE = re.compile(r"<!-- quotes (results/[\w./-]+\.md)(?: \(historical\))? -->(.*?)<!-- /quotes -->", re.S)
QUOTING = ("halls.md", "study.md", "places.md")  # pages that quote the committed report in their prose
# The prose pages whose every score quotes a results page (or says why it does not): the check that a
# number they state is the number its source page states.
PROSE = (README, DOCS / "results.md", DOCS / "places.md", DOCS / "study.md", DOCS / "halls.md")
UNQUOTED = re.compile(r"<!-- unquoted: ([^>]+?) -->(.*?)<!-- /unquoted -->", re.S)
SCORE = re.compile(r"(?<![\w.+-])[+-]?\d+\.\d\d(?![\d.])|(?<![\w.])\d+\.\d%")  # 2-decimal rates, 1-decimal shares


def test_docs_quotes_are_the_reports() -> None:
    """Every passage of a page that quotes a committed report (marked ``<!-- quotes
    results/FILE.md -->`` ... ``<!-- /quotes -->``) has that report's numbers, in their rows:
    a quote is copied, never retyped, and goes stale with the report it quotes. The pages
    that quote the report in their prose mark their quotes (the results page's section and
    the README are checked whole, above)."""
    quotes = 0
    for page in PAGES:
        for m in QUOTE.finditer(page.read_text(encoding="utf-8")):
            report = DOCS / m.group(1)
            assert report.is_file(), f"{page.name} quotes {m.group(1)}, which is not committed"
            assert not _misplaced(m.group(2), report.read_text(encoding="utf-8")), (page.name, m.group(2)[:80])
            quotes += 1
    for name in QUOTING:
        assert QUOTE.search((DOCS / name).read_text(encoding="utf-8")), f"{name} quotes the report unmarked"
    assert quotes >= len(QUOTING)


def unsourced(text: str) -> list[str]:
    """The scores of a prose page that no marked passage holds: outside code blocks, every
    2-decimal number and 1-decimal percentage must lie in a quote of a results page (checked
    against it above) or in a passage that says why it quotes none (``<!-- unquoted: WHY -->``
    ... ``<!-- /unquoted -->``: a measurement no results page holds, named there)."""
    rest = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    rest = re.sub(r"Python \d+\.\d+", "", QUOTE.sub("", UNQUOTED.sub("", rest)))  # a version, not a score
    return [line.strip()[:100] for line in rest.splitlines() if SCORE.search(line)]


@pytest.mark.parametrize("page", PROSE, ids=[p.name for p in PROSE])
def test_every_score_of_a_prose_page_quotes_a_results_page_or_says_why_not(page: Path) -> None:
    text = page.read_text(encoding="utf-8")
    assert not unsourced(text), unsourced(text)[:10]
    for m in UNQUOTED.finditer(text):
        assert len(m.group(1).split()) >= 3, f"{page.name}: say where the numbers come from: {m.group(0)[:80]}"


def test_an_unmarked_or_retyped_score_of_a_prose_page_is_caught() -> None:
    assert unsourced("The DT scores 98.5% of the oracle.") == ["The DT scores 98.5% of the oracle."]
    assert not unsourced("<!-- quotes results/quick-report.md -->98.5%<!-- /quotes --> and Python 3.11.7 in\n"
                         "```\n1.23\n```")
    assert not unsourced("<!-- unquoted: measured by benchmarks/x.py -->1.23<!-- /unquoted -->")
    assert unsourced("Python 3.11.7, 2026-11-28, 512 halls, Python 3.11 or later") == []


def test_a_retyped_quote_is_caught() -> None:
    bad = "<!-- quotes results/quick-report.md -->the zero-shot DT reaches 91.7% of the oracle<!-- /quotes -->"
    m = QUOTE.search(bad)
    assert m and _misplaced(m.group(2), QUICK_REPORT.read_text(encoding="utf-8"))


def _numbers(line: str) -> list[str]:
    """The whole numbers of a line, in order, signs and percent signs kept ("unseen1" has none)."""
    return re.findall(r"(?<![\w.+-])[+-]?\d[\d,]*(?:\.\d+)?%?(?!\.?\d)", line)


def _tables(text: str) -> dict[str, list[str]]:
    """Every table's body rows, under its header line (tables with the same header pooled)."""
    out: dict[str, list[str]] = {}
    lines = text.splitlines()
    for i, line in enumerate(lines[:-1]):
        if line.startswith("|") and lines[i + 1].startswith("|---") and not (i and lines[i - 1].startswith("|")):
            body = out.setdefault(line, [])
            for row in lines[i + 2:]:
                if not row.startswith("|"):
                    break
                body.append(row)
    return out


def _label(row: str) -> str:
    return row.strip("|").split("|")[0].strip()


def _misplaced(section: str, report: str) -> list[str]:
    """What ``section`` quotes that ``report`` does not state in the same place: a table row's
    numbers must be those of the report's row of the same label in a table of the same header;
    a bullet that copies one of the report's (the same start, up to its bold claim or its first
    colon) must have that bullet's numbers; any other score (prose: 2-decimal numbers, 1-decimal
    percentages) must be in the report as a whole number (not "0.93" inside "40.93", nor "3.11"
    of "Python 3.11.7", nor "7.06" for "-7.06")."""
    bad = []
    ours, theirs = _tables(section), _tables(report)
    in_tables = set()
    for header, rows in ours.items():
        if header not in theirs:
            bad.append(f"a table the report does not have: {header}")
            continue
        for row in rows:
            in_tables.add(row)
            same = [r for r in theirs[header] if _label(r) == _label(row)]
            if not any(_numbers(r) == _numbers(row) for r in same):
                bad.append(row)
    report_lines = report.splitlines()
    for line in section.splitlines():
        if line in in_tables or line.startswith("|") or not _numbers(line):
            continue
        if line.startswith("- "):
            bold = re.match(r"- [^*]*\*\*[^*]+\*\*", line)
            key = bold.group(0) if bold else line.split(": ")[0] + ": "
            copies = [r for r in report_lines if r.startswith(key)]
            if copies:
                if not any(_numbers(r) == _numbers(line) for r in copies):
                    bad.append(line)
                continue
        scores = [q for q in _numbers(line) if re.fullmatch(r"[+-]?\d+\.\d\d|\d+\.\d%", q)]  # not "47.2 min"
        bad += [f"{q} ({line})" for q in scores if not _whole(q, report) and not _whole(q.lstrip("+"), report)]
    return bad


def _whole(number: str, text: str) -> bool:
    """``number`` occurs in ``text`` as a whole number: "0.93" is not found inside "40.93" or
    "0.931", nor an unsigned "7.06" in "-7.06" (an unsigned number may drop a "+", not a "-")."""
    return re.search(rf"(?<![\d.{'' if number[0] in '+-' else '-'}]){re.escape(number)}(?!\d|\.\d)",
                     text) is not None


def test_numbers_are_matched_whole():
    assert _whole("0.93", "DT 0.93 bps/Hz") and _whole("+1.20", "diff +1.20 [") and _whole("59.1%", "(59.1%)")
    assert not _whole("0.93", "DT 40.93 bps/Hz") and not _whole("0.93", "0.931") and not _whole("9.1%", "59.1%")
    assert not _whole("3.11", "Python 3.11.7") and not _whole("7.06", "-7.06 [") and _whole("-7.06", "x -7.06 [")
    assert _numbers("| layout-unseen-0 | -21.21 | 40.93 (96%) | 23,639 | train3 | [8.14, 10.19] |") == [
        "-21.21", "40.93", "96%", "23,639", "8.14", "10.19"]


REPORT = """| policy | mean | fraction |
|---|---:|---:|
| DDPG | 9.17 | 21% |
| oracle | 40.93 | 100% |

| policy | paper, unseen1 |
|---|---:|
| oracle | 43.13 (100%) |

- paper track, unseen1: **fine-tuned DT within 5% of the expert**: holds (fine-tuned 10.92 vs expert 11.10, -1.6%).
- deployment track: **DT minus BC**: -7.06 [-13.65, -0.48] bps/Hz, below zero.
Prose: the oracle reaches 42.96 in Fig. 2."""


@pytest.mark.parametrize("readme, ok", [
    ("| policy | mean | fraction |\n|---|---:|---:|\n| oracle | 40.93 | 100% |", True),
    ("| policy | mean | fraction |\n|---|---:|---:|\n| oracle | 0.93 | 100% |", False),  # inside 40.93
    ("| policy | mean | fraction |\n|---|---:|---:|\n| oracle | 9.17 | 21% |", False),  # DDPG's row
    ("| policy | paper, unseen1 |\n|---|---:|\n| oracle | 40.93 (100%) |", False),  # another table's
    ("- paper track, unseen1: **fine-tuned DT within 5% of the expert**: holds (fine-tuned 10.92 vs expert 11.10, "
     "-1.6%).", True),
    ("- paper track, unseen1: **fine-tuned DT within 5% of the expert**: holds (fine-tuned 0.92 vs expert 11.10, "
     "-1.6%).", False),
    ("- deployment track: **DT minus BC**: +7.06 [-13.65, -0.48] bps/Hz, below zero.", False),  # the sign
    ("The oracle: 42.96 and 9.17; DT minus BC -7.06.", True), ("The oracle: 2.96.", False),
    ("DT minus BC 7.06.", False), ("Python 3.11.7: 0.93.", False)])
def test_readme_numbers_are_found_in_their_row(readme: str, ok: bool) -> None:
    assert (not _misplaced(readme, REPORT)) == ok, _misplaced(readme, REPORT)


@pytest.mark.parametrize("page", [README, DOCS / "getting-started.md"], ids=["README", "getting-started"])
def test_first_examples_print_the_same_every_time(page: Path, tmp_path: Path) -> None:
    """A reader who runs a first example twice sees the same numbers: every random draw in it
    is seeded (the environment's and the action space's)."""
    for index, block in enumerate(_python_blocks(page)):
        script = tmp_path / f"block{index}.py"
        script.write_text(block, encoding="utf-8")
        runs = [subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True,
                               timeout=300) for _ in range(2)]
        assert all(r.returncode == 0 for r in runs), runs[0].stderr[-2000:]
        assert runs[0].stdout == runs[1].stdout, (index, runs[0].stdout, runs[1].stdout)
