"""Every benchmark script imports and answers ``--help`` (none can rot unnoticed): the throughput
scripts of ``make bench`` in ``benchmarks/`` and the measurements behind a page in
``benchmarks/findings/``, each naming the page it feeds."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(p for p in [*(ROOT / "benchmarks").glob("*.py"), *(ROOT / "benchmarks" / "findings").glob("*.py")]
                 if not p.name.startswith("_"))


def _load(path: Path, monkeypatch: pytest.MonkeyPatch):
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        monkeypatch.setenv(var, "1")  # the scripts set them at import; the test process keeps its own
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))  # as running benchmarks/X.py puts it first
    spec = importlib.util.spec_from_file_location(f"benchmark_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, module)  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("path", SCRIPTS, ids=[p.stem for p in SCRIPTS])
def test_every_benchmark_imports_and_answers_help(path: Path, monkeypatch, capsys):
    module = _load(path, monkeypatch)
    with pytest.raises(SystemExit) as done:
        module.main(["--help"])
    assert done.value.code == 0
    assert capsys.readouterr().out.startswith("usage: ")


def test_the_findings_name_the_page_each_feeds_and_make_bench_runs_the_rest():
    pages = {}
    for path in (ROOT / "benchmarks" / "findings").glob("*.py"):
        found = re.search(r"^Feeds (docs/\S+\.md)\.$", path.read_text(), re.M)
        assert found, f"{path.name} names no page it feeds"
        assert (ROOT / found.group(1)).is_file(), found.group(1)
        pages[path.stem] = found.group(1)
    assert pages
    bench = (ROOT / "Makefile").read_text().split("\nbench:", 1)[1].split("\n\n", 1)[0]
    ran = set(re.findall(r"benchmarks/(\w+)\.py", bench))
    assert ran == {p.stem for p in SCRIPTS if p.parent.name == "benchmarks"}  # every throughput script, no other


def test_the_cost_models_fit_names_unit_costs_the_model_has(monkeypatch):
    """``cost_model.py --fit`` scales groups of unit costs by name: each name is one of the cost model's."""
    from uavris.experiments.engine import costs

    module = _load(ROOT / "benchmarks" / "findings" / "cost_model.py", monkeypatch)
    missing = [name for group in module.GROUPS.values() for name in group if not hasattr(costs, name)]
    assert not missing, missing
