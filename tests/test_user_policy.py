"""A user's own controller: `uavris evaluate MODULE:NAME`, `uavris benchmark`, and their bad input."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from uavris.cli import main

CONTROLLER = '''
import numpy as np
from uavris.config import SystemConfig
from uavris.env import observation_layout


def toward_centre(system=None):
    """Fly toward the middle of the hall (the position slice is centred); phases by the optimiser."""
    pos = observation_layout(system or SystemConfig())["position"]

    def policy(obs):
        a = np.zeros((obs.shape[0], 6), dtype=np.float32)
        a[:, :3] = np.clip(-2.0 * obs[:, pos], -1.0, 1.0)
        return a

    policy.phase_control = "optimizer"
    return policy


class Tilted:
    """An object policy: a constant full action (22 entries)."""

    def __call__(self, obs):
        return np.full((obs.shape[0], 22), 0.25, dtype=np.float32)


def wrong_shape(obs):
    return np.zeros((obs.shape[0], 5))


def wrong_rows(obs):
    return np.zeros((obs.shape[0] + 1, 22))


def non_finite(obs):
    a = np.zeros((obs.shape[0], 22))
    a[0, 3] = np.inf
    return a


def raises(obs):
    raise RuntimeError("boom")


def broken_factory():
    raise RuntimeError("no model file")


def for_the_system(system: SystemConfig):
    """A factory whose one parameter, required, is the system: the zero action of its size."""
    def policy(obs):
        return np.zeros((obs.shape[0], system.action_dim), dtype=np.float32)

    return policy


def two_required(obs, gain):
    return gain * np.zeros((obs.shape[0], 22))


NOT_A_POLICY = 3
'''


@pytest.fixture
def controller(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    pkg = tmp_path / "mypkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "control.py").write_text(CONTROLLER)
    (tmp_path / "broken.py").write_text("import numpy as np\ndef (:\n")
    monkeypatch.chdir(tmp_path)
    yield pkg / "control.py"
    for name in [m for m in sys.modules if m == "mypkg" or m.startswith("mypkg.")]:
        del sys.modules[name]


def _summary(out: Path) -> dict:
    return json.loads(next(out.glob("*.json")).read_text())


def _one_line(capsys: pytest.CaptureFixture[str], code: int) -> str:
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("uavris: error: ") and "\n" not in err and "Traceback" not in err
    return err


def test_module_and_file_score_as_the_python_api(controller: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    from uavris.agents.evaluation import evaluate
    from uavris.config import SystemConfig
    from uavris.experiments.tools.user_policy import load_user_policy

    args = ["--scenario", "unseen1", "--episodes", "3", "--no-progress"]
    assert main(["evaluate", "mypkg.control:toward_centre", *args, "--out", str(tmp_path / "m")]) == 0
    assert main(["evaluate", f"{controller}:toward_centre", *args, "--out", str(tmp_path / "f")]) == 0
    by_module, by_file = _summary(tmp_path / "m"), _summary(tmp_path / "f")
    direct = evaluate(load_user_policy("mypkg.control:toward_centre", SystemConfig()), SystemConfig(), "unseen1",
                      3, 1_000_000).avg_sum_rate.mean()
    assert by_module["mean"] == pytest.approx(direct, abs=1e-12)
    assert by_file["mean"] == pytest.approx(direct, abs=1e-12)
    # The references beside it are what `uavris evaluate` gives them on the same episodes.
    for name in ("oracle", "baseline:zero-action"):
        assert main(["evaluate", name, *args, "--out", str(tmp_path / name.replace(":", "_"))]) == 0
    assert by_module["references"]["oracle"]["mean"] == pytest.approx(_summary(tmp_path / "oracle")["mean"])
    zero = _summary(tmp_path / "baseline_zero-action")["mean"]
    assert by_module["references"]["zero-action"]["mean"] == pytest.approx(zero)
    oracle = by_module["references"]["oracle"]["mean"]
    assert by_module["fraction_of_oracle"] == pytest.approx(by_module["mean"] / oracle)
    # Flying toward the middle beats hovering where the paper's unseen1 starts.
    assert by_module["mean"] > by_module["references"]["zero-action"]["mean"]
    out = capsys.readouterr().out
    assert "of the oracle" in out and "beside it on the same episodes: oracle" in out


def test_a_factory_whose_one_required_parameter_is_the_system(controller: Path, tmp_path: Path) -> None:
    """`def make(system)` is a factory: it gets the system evaluated (2 x 2 elements here, so
    10 action entries; the paper's system would give 22) and scores as the zero action."""
    from uavris.agents.evaluation import evaluate
    from uavris.agents.references import reference_policy
    from uavris.config import SystemConfig

    assert main(["evaluate", "mypkg.control:for_the_system", "--scenario", "fig2", "--episodes", "2",
                 "--system.nx", "2", "--system.ny", "2", "--no-progress", "--out", str(tmp_path / "s")]) == 0
    small = SystemConfig(nx=2, ny=2)
    assert small.action_dim == 10
    want = evaluate(reference_policy("zero-action", small), small, "fig2", 2, 1_000_000).summary()["mean"]
    assert _summary(tmp_path / "s")["mean"] == pytest.approx(want, abs=1e-12)


def test_an_object_policy(controller: Path, tmp_path: Path) -> None:
    assert main(["evaluate", "mypkg.control:Tilted", "--scenario", "fig2", "--episodes", "2", "--no-progress",
                 "--out", str(tmp_path / "o")]) == 0
    assert np.isfinite(_summary(tmp_path / "o")["mean"])


@pytest.mark.parametrize("target, message", [
    ("mypkg.control:wrong_shape", "returned actions of shape (N, 5) for N observations; expected (N, 22)"),
    ("mypkg.control:wrong_rows", "returned actions of shape (N+1, 22) for N observations"),
    ("mypkg.control:non_finite", "returned a non-finite action (row 0, entry 3)"),
    ("mypkg.control:raises", "failed on an observation batch of shape (N, 158): RuntimeError: boom"),
    ("mypkg.control:broken_factory", "making the policy failed: RuntimeError: no model file"),
    ("mypkg.control:two_required", "two_required(obs, gain) requires 2 arguments; a policy takes one (the "
                                   "observation batch), a policy factory none or system"),
    ("mypkg.control:NOT_A_POLICY", "is a int, not a policy"),
    ("mypkg.control:missing", "has no attribute 'missing'"),
    ("mypkg.nothere:x", "cannot import module 'mypkg.nothere'"),
    ("nowhere.py:x", "no such file nowhere.py"),
    ("broken.py:x", "importing broken.py failed: SyntaxError"),
])
def test_bad_user_policy_is_one_line_and_writes_nothing(controller: Path, tmp_path: Path, target: str, message: str,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    for n, cmd in ((2, ["evaluate", target, "--scenario", "unseen1", "--episodes", "2"]),
                   (8, ["benchmark", target, "--preset", "smoke", "--cells", "scenarios"])):
        err = _one_line(capsys, main([*cmd, "--no-progress", "--out", str(tmp_path / "out")]))
        assert message.replace("N+1", str(n + 1)).replace("N", str(n)) in err, err
        assert not (tmp_path / "out").exists() and not (tmp_path / "runs").exists()


def test_benchmark_cells_are_the_reports_and_uavris_evaluates(controller: Path, tmp_path: Path) -> None:
    """Every cell's numbers equal `uavris evaluate` of the target and the references there, on
    the report's episodes; the layout cells are the study's unseen deployments."""
    from uavris.config import SystemConfig
    from uavris.experiments.study.tracks import TRACK_SPECS, sites
    from uavris.experiments.tools.benchmark import protocol_cells
    from uavris.layouts import resolve_layout
    from uavris.presets import STUDY

    cells = protocol_cells("smoke")
    assert [c.name for c in cells] == ["unseen1", "unseen2", "layout-unseen-0", "layout-unseen-1"]
    _, unseen = sites(TRACK_SPECS["deployment"], SystemConfig(), 1, STUDY["smoke"]["unseen_layouts"])
    for cell, dep in zip(cells[2:], unseen):
        hall, where = resolve_layout(cell.name).resolve(SystemConfig())
        assert dep.name == cell.name and dep.system.users == hall.users and dep.start == where.start

    out = tmp_path / "bench"
    assert main(["benchmark", "mypkg.control:toward_centre", "--preset", "smoke", "--no-progress",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "benchmark.json").read_text())
    assert summary["episodes"] == STUDY["smoke"]["eval_episodes"]
    rows = {r["cell"]: r for r in summary["cells"]}
    n = str(STUDY["smoke"]["eval_episodes"])
    for cell, place in (("unseen2", ["--scenario", "unseen2"]), ("layout-unseen-1", ["--layout", "layout-unseen-1"])):
        for target, key in (("mypkg.control:toward_centre", "mean"), ("oracle", "oracle"),
                            ("zero-action", "zero_action")):
            ev = tmp_path / "ev" / cell / target.replace(":", "_")
            assert main(["evaluate", target, *place, "--episodes", n, "--no-progress", "--out", str(ev)]) == 0
            assert rows[cell][key] == pytest.approx(_summary(ev)["mean"], abs=1e-12), (cell, target)
        assert rows[cell]["fraction_of_oracle"] == pytest.approx(rows[cell]["mean"] / rows[cell]["oracle"])
    table = (out / "benchmark.md").read_text()
    assert "| layout-unseen-1 |" in table and "mean over 2 layouts" in table


def test_benchmark_of_a_reference_and_a_bad_preset(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "b"
    assert main(["benchmark", "oracle", "--preset", "smoke", "--cells", "scenarios", "--no-progress",
                 "--out", str(out)]) == 0
    rows = json.loads((out / "benchmark.json").read_text())["cells"]
    assert [r["fraction_of_oracle"] for r in rows] == [1.0, 1.0]
    err = _one_line(capsys, main(["benchmark", "oracle", "--preset", "huge", "--out", str(tmp_path / "c")]))
    assert "invalid choice 'huge'" in err and not (tmp_path / "c").exists()


def test_your_policys_results_in_two_halls_are_two_files(controller: Path, tmp_path: Path) -> None:
    """FILE.py:NAME evaluated in two halls into its default folder: two results side by side,
    named after the file and the policy (a dot in the name once cut both to control.json)."""
    for hall in ("layout-unseen-1", "layout-unseen-2"):
        assert main(["evaluate", f"{controller}:toward_centre", "--layout", hall, "--episodes", "2",
                     "--no-progress", "--no-references"]) == 0
    default = tmp_path / "runs" / "policies"
    [folder] = [p for p in default.iterdir() if p.is_dir()]
    names = sorted(p.name for p in (folder / "eval").glob("*.json"))
    assert len(names) == 2 and all(n.startswith("control_py_toward_centre-layout-unseen-") for n in names), names


def test_evaluate_prints_and_records_the_paired_differences_to_the_references(controller: Path, tmp_path: Path,
                                                                              capsys: pytest.CaptureFixture[str]):
    """Beside "% of the oracle", your policy minus hovering with optimised phases and minus the
    oracle, paired on the same episodes with Student's t interval (recomputed here with SciPy from
    the references evaluated on their own)."""
    from scipy import stats as sps

    from uavris.agents.evaluation import evaluate
    from uavris.agents.references import reference_policy
    from uavris.config import SystemConfig

    out = tmp_path / "e"
    assert main(["evaluate", f"{controller}:toward_centre", "--scenario", "unseen1", "--episodes", "4", "--out",
                 str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    summary = _summary(out)
    mine = np.array([float(r["avg_sum_rate"]) for r in csv.DictReader(open(next(out.glob("*.csv"))))])
    for name in ("hover-optimizer", "oracle"):
        ref = evaluate(reference_policy(name, SystemConfig()), SystemConfig(), "unseen1", 4, 1_000_000).avg_sum_rate
        d = mine - ref
        lo, hi = sps.t.interval(0.95, 3, loc=d.mean(), scale=sps.sem(d))
        got = summary["paired"][name]
        assert got["mean"] == pytest.approx(d.mean(), abs=1e-9)
        assert (got["ci_low"], got["ci_high"]) == pytest.approx((lo, hi), abs=1e-9)
    assert "beside it on the same episodes: hover-optimizer" in printed and "minus it " in printed
    assert printed.count("(paired, 95% CI)") == 3  # the zero action, hovering with optimised phases, the oracle
