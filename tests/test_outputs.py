"""Results are never lost (two targets into one --out) and every slot can be exported."""

from __future__ import annotations

import csv
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from uavris.cli import main

HALL = ("devices:\n  - [5, 5, 1]\n  - [25, 8, 1]\n  - [20, 20, 0.5]\n  - [6, 18, 1]\n"
        "start: [12, 12, 4]\nroom: [30, 24, 6]\n")  # a hall of one's own, smaller than the paper's


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_evaluations_of_several_targets_into_one_out_are_all_kept(tmp_path: Path) -> None:
    out = tmp_path / "e"
    means = {}
    for target in ("zero-action", "hover-optimizer", "random"):
        assert main(["evaluate", target, "--scenario", "fig2", "--episodes", "2", "--out", str(out),
                     "--no-progress"]) == 0
        (path,) = out.glob(f"{target}-fig2-*.json")
        means[target] = json.loads(path.read_text())["mean"]
    assert len(list(out.glob("*.json"))) == 3 and len(set(means.values())) == 3
    for target, mean in means.items():  # each file still holds its own evaluation
        (path,) = out.glob(f"{target}-fig2-*.json")
        assert json.loads(path.read_text())["mean"] == mean


def test_the_trajectory_export_adds_up_to_the_episodes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["evaluate", "hover-optimizer", "--scenario", "unseen1", "--episodes", "3", "--out", str(tmp_path),
                 "--trajectory", "--no-progress"]) == 0
    printed = capsys.readouterr().out
    (slots,) = tmp_path.glob("*-slots.csv")
    (episodes,) = [p for p in tmp_path.glob("*.csv") if p != slots]
    rows, eps = _rows(slots), _rows(episodes)
    assert (tmp_path / slots.name.replace("-slots.csv", "-trajectory.png")).stat().st_size > 1000
    for ep in eps:  # each episode's slots: as many as its length, their mean rate its average sum rate
        mine = [r for r in rows if r["episode_seed"] == ep["seed"]]
        assert len(mine) == int(ep["length"])
        assert np.mean([float(r["sum_rate"]) for r in mine]) == pytest.approx(float(ep["avg_sum_rate"]), rel=1e-12)
        assert float(mine[-1]["energy_j"]) == pytest.approx(float(ep["energy_j"]))
        assert [int(r["slot"]) for r in mine] == list(range(len(mine)))
    # the split by active pairs, recomputed from the slots
    summary = json.loads(episodes.with_suffix(".json").read_text())
    for m, part in summary["active_pairs"].items():
        mine = [float(r["sum_rate"]) for r in rows if r["active_pairs"] == m]
        assert part["share"] == pytest.approx(len(mine) / len(rows))
        assert part["rate"] == pytest.approx(np.mean(mine))
        assert f"slots with {m} active pair" in printed
    assert {r["active_pairs"] for r in rows} == {"1", "2"}  # the paper's 4 devices: one or two links a slot


def _holder(out: Path, record: bool) -> subprocess.Popen[bytes]:
    """Another process holding ``out``'s lock: through :func:`locked` (``record``), or as a
    holder stalled after creating the file and before writing who it is (an empty file)."""
    import sys

    code = (f"from uavris.runs.lock import locked\nwith locked({str(out)!r}, 'uavris sweep ...'):\n"
            "    print('held', flush=True)\n    import time; time.sleep(60)" if record else
            f"import fcntl, os, time\nfd = os.open({str(out / '.uavris.lock')!r}, os.O_RDWR | os.O_CREAT)\n"
            "fcntl.flock(fd, fcntl.LOCK_EX)\nprint('held', flush=True)\ntime.sleep(60)")
    other = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE)
    assert other.stdout is not None and other.stdout.readline().strip() == b"held"
    return other


@pytest.mark.parametrize("record", [True, False])
def test_a_directory_written_by_a_live_process_is_refused_and_a_killed_ones_lock_taken(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], record: bool) -> None:
    """The lock is the holder's from the moment its file exists (an empty file held is not
    taken over, however long it stays empty), and goes with its process (a kill -9 frees it)."""
    import signal
    import time

    from uavris.errors import UavrisError
    from uavris.runs.lock import LOCK_FILE, locked

    out = tmp_path / "s"
    out.mkdir()
    other = _holder(out, record)
    args = ["sweep", "zero-action", "--param", "system.rician-factor", "0,8", "--episodes", "2",
            "--system.horizon", "10", "--workers", "1", "--out", str(out), "--no-progress"]
    try:
        time.sleep(0.5)  # longer than any grace for a lock being written
        assert main(args) == 2
        err = capsys.readouterr().err
        assert "being written by" in err and len(err.strip().splitlines()) == 1
        assert (f"process {other.pid}" in err) == record
        assert not (out / "sweep.csv").exists()
    finally:
        other.send_signal(signal.SIGKILL)
        other.wait()
    assert main(args) == 0  # the lock of a process that no longer runs: taken
    assert (out / "sweep.csv").exists() and not (out / LOCK_FILE).exists()  # and released at the end
    with locked(out):  # in one process: a second writer is refused too
        with pytest.raises(UavrisError, match="being written by process"):
            with locked(out):
                pass
    assert not (out / LOCK_FILE).exists()


@pytest.mark.parametrize("command", [
    ["evaluate", "zero-action", "--scenario", "fig2", "--episodes", "2"],
    ["sweep", "zero-action", "--param", "system.nx", "2"],
    ["plan", "paper"],
    ["reproduce", "--preset", "smoke"],
])
def test_an_output_folder_that_cannot_be_written_is_one_line_before_any_work(
        command: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    # /proc/1 accepts no new file, even from root (where a chmod'ed folder would not stop a write)
    out = "/proc/1/uavris-out"
    if Path("/proc/1").is_dir() is False:
        pytest.skip("needs Linux's /proc")
    flag = ["--out", out + ("/map" if command[0] == "plan" else "")]
    assert main([*command, *flag]) == 2
    captured = capsys.readouterr()
    assert "cannot be written" in captured.err and len(captured.err.strip().splitlines()) == 1
    assert "average sum rate" not in captured.out and "report" not in captured.out


HELD = '''
import os
import time

import numpy as np

HOLD = {hold!r}


def held(obs):
    """Hovers (phases by the optimiser), after waiting while the file HOLD exists: a cell that
    cannot end before Ctrl-C."""
    while os.path.exists(HOLD):
        time.sleep(0.05)
    return np.zeros((obs.shape[0], 6), dtype=np.float32)


held.phase_control = "optimizer"
'''


def test_ctrl_c_in_a_sweep_leaves_one_line_and_a_resumable_state(tmp_path: Path) -> None:
    """Ctrl-C while cells run: one line, exit 130, the finished cells kept and no table; the rerun
    reuses them. The cells of ``held`` wait on a file until the rerun, so the interrupt always
    finds the sweep unfinished (a sweep of quick cells could end before the signal on a loaded
    machine: the race this test once lost)."""
    import signal
    import subprocess
    import sys
    import time

    hold = tmp_path / "hold"
    hold.touch()
    (tmp_path / "held.py").write_text(HELD.format(hold=str(hold)))
    out = tmp_path / "s"
    args = [sys.executable, "-m", "uavris", "sweep", "zero-action", str(tmp_path / "held.py") + ":held", "--param",
            "system.nx", "2,3", "--episodes", "2", "--workers", "2", "--out", str(out), "--no-progress"]
    # a suite started in the background by a shell (`make test &`) ignores SIGINT, and a child
    # inherits that: Ctrl-C is restored for the command, as a terminal's foreground job has it
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 300
    while not list((out / "cells").glob("*.json")) and time.time() < deadline:  # a zero-action cell done
        time.sleep(0.2)
    assert proc.poll() is None, proc.communicate()  # the held cells are still running
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group, the workers included
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    lines = [x for x in err.splitlines() if x.strip()]
    assert lines == ["uavris: interrupted; rerun the same command to continue (what finished is reused)"], err
    done = {p.name for p in (out / "cells").glob("*.json")}
    assert 1 <= len(done) <= 2 and not (out / "sweep.csv").exists()  # zero-action cells only
    hold.unlink()
    rerun = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    assert done < {p.name for p in (out / "cells").glob("*.json")} and (out / "sweep.csv").exists()
    assert len(list((out / "cells").glob("*.json"))) == 4


@pytest.mark.slow
def test_a_named_scenario_is_the_papers_hall_for_a_model_trained_in_another(tmp_path: Path,
                                                                            capsys: pytest.CaptureFixture[str]):
    """A model trained in a generated hall, evaluated at --scenario fig2 and benchmarked in
    unseen1/unseen2, flies the paper's hall (the references there are the report's), and says so."""
    from uavris.agents.evaluation import evaluate
    from uavris.agents.references import reference_policy
    from uavris.config import SystemConfig

    run = tmp_path / "run"
    assert main(["train", "--algo", "ppo", "--preset", "smoke", "--layout", "layout-unseen-0", "--out", str(run),
                 "--no-progress"]) == 0
    own = json.loads(next((run / "eval").glob("*.json")).read_text())["system"] if (run / "eval").exists() else None
    assert own is None or own["users"] != [list(u) for u in SystemConfig().users]
    capsys.readouterr()
    assert main(["evaluate", str(run), "--scenario", "fig2", "--episodes", "2", "--out", str(tmp_path / "e"),
                 "--no-progress"]) == 0
    assert "in fig2 (the paper's hall)" in capsys.readouterr().out
    (path,) = (tmp_path / "e").glob("run-fig2-*.json")
    summary = json.loads(path.read_text())
    assert summary["system"]["users"] == [list(u) for u in SystemConfig().users] and summary["hall"] == \
        "the paper's hall"
    assert main(["benchmark", str(run), "--preset", "smoke", "--cells", "scenarios", "--out", str(tmp_path / "b"),
                 "--no-progress"]) == 0
    rows = json.loads((tmp_path / "b" / "benchmark.json").read_text())["cells"]
    capsys.readouterr()
    hall = tmp_path / "hall.yaml"
    hall.write_text(HALL)  # a 30 x 24 x 6 m hall: outside the 40 x 40 x 8 m one it was trained in
    assert main(["evaluate", str(run), "--layout", str(hall), "--episodes", "2", "--out", str(tmp_path / "h"),
                 "--no-progress", "--no-references"]) == 0
    err = capsys.readouterr().err
    assert "uavris: warning: run was trained in a 40 x 40 x 8 m hall and flies a 30 x 24 x 6 m one" in err
    # benchmark and sweep say it too, once
    assert main(["benchmark", str(run), "--preset", "smoke", "--layout", str(hall), "--out", str(tmp_path / "hb"),
                 "--no-progress"]) == 0
    assert capsys.readouterr().err.count("was trained in a 40 x 40 x 8 m hall and flies a 30 x 24 x 6 m one") == 1
    assert main(["sweep", str(run), "--layout", str(hall), "--param", "system.rician-factor", "4,8", "--episodes",
                 "2", "--workers", "1", "--out", str(tmp_path / "hs"), "--no-progress"]) == 0
    assert capsys.readouterr().err.count("was trained in a 40 x 40 x 8 m hall and flies a 30 x 24 x 6 m one") == 1
    assert main(["evaluate", str(run), "--layout", "layout-unseen-1", "--episodes", "2", "--out",
                 str(tmp_path / "h"), "--no-progress", "--no-references"]) == 0
    assert "warning" not in capsys.readouterr().err  # another hall of the same room: no warning
    paper = SystemConfig()
    for row in rows:  # the zero action of each cell is the paper hall's, computed here independently
        want = evaluate(reference_policy("zero-action", paper), paper, row["cell"], 8, 1_000_000).avg_sum_rate.mean()
        assert row["zero_action"] == pytest.approx(want, rel=1e-12), row["cell"]


def test_the_simulator_installs_without_the_training_stack(tmp_path: Path) -> None:
    """`pip install uavris` (no extra) brings the simulator, the environments, the
    references and their commands; a command that needs torch says so in one line. Simulated by
    an import hook that hides what the `train` extra installs."""
    import subprocess
    import sys

    script = tmp_path / "no_train.py"
    script.write_text(
        "import importlib.abc, sys\n"
        "class Hide(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path, target=None):\n"
        "        if name.split('.')[0] in ('torch', 'stable_baselines3', 'tensorboard', 'minari', 'h5py',\n"
        "                                  'safetensors', 'ray'):\n"
        "            raise ModuleNotFoundError(f'No module named {name!r}', name=name)\n"
        "sys.meta_path.insert(0, Hide())\n"
        "import gymnasium as gym\n"
        "import uavris\n"
        "env = gym.make('uavris/UavRisD2D-v1')\n"
        "obs, _ = env.reset(seed=0)\n"
        "assert obs.shape == (158,)\n"
        "from uavris.cli import main\n"
        "assert main(['evaluate', 'oracle', '--scenario', 'fig2', '--episodes', '1', '--out', sys.argv[1],\n"
        "             '--no-progress']) == 0\n"
        "assert main(['plan', '--help']) == 0\n"
        "assert main(['plan', 'layout-unseen-1', '--grid-step', '10', '--out', sys.argv[1] + '/plan',\n"
        "             '--no-progress']) == 0\n"
        "assert main(['sweep', 'zero-action', 'hover-optimizer', '--param', 'system.nx', '2,4', '--episodes', '1',\n"
        "             '--workers', '1', '--out', sys.argv[1] + '/sweep', '--no-progress']) == 0\n"
        "assert main(['demo', '--episodes', '2']) == 0\n"
        "sys.exit(main(['train', '--preset', 'smoke', '--out', sys.argv[1] + '/run']))\n")
    proc = subprocess.run([sys.executable, str(script), str(tmp_path / "o")], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().splitlines()[-1].startswith("uavris: error: this needs the training stack")
    assert "Traceback" not in proc.stderr and "oracle in fig2" in proc.stdout



def test_sweep_and_benchmark_fly_your_own_hall(tmp_path: Path) -> None:
    """--layout on sweep and benchmark is the hall's devices, room and start, as in evaluate."""
    from uavris.agents.evaluation import evaluate
    from uavris.agents.references import reference_policy
    from uavris.config import SystemConfig
    from uavris.layouts import resolve_layout

    hall = tmp_path / "hall.yaml"
    hall.write_text(HALL)
    system, start = resolve_layout(str(hall), SystemConfig(horizon=10)).resolve(SystemConfig(horizon=10))
    assert system.room == (30.0, 24.0, 6.0) and tuple(start.start) == (12.0, 12.0, 4.0)
    assert main(["sweep", "zero-action", "--param", "system.nx", "2,4", "--layout", str(hall), "--episodes", "2",
                 "--system.horizon", "10", "--workers", "1", "--out", str(tmp_path / "s"), "--no-progress"]) == 0
    rows = _rows(tmp_path / "s" / "sweep.csv")
    for r in rows:
        cell = system.replace(nx=int(float(r["nx"])))
        want = evaluate(reference_policy("zero-action", cell), cell, start, 2, 1_000_000).avg_sum_rate.mean()
        assert float(r["mean"]) == pytest.approx(want, rel=1e-12)
    assert main(["benchmark", "zero-action", "--preset", "smoke", "--layout", str(hall), "--system.horizon", "10",
                 "--out", str(tmp_path / "b"), "--no-progress"]) == 0
    [row] = json.loads((tmp_path / "b" / "benchmark.json").read_text())["cells"]
    want = evaluate(reference_policy("zero-action", system), system, start, 8, 1_000_000).avg_sum_rate.mean()
    assert row["cell"] == "hall" and row["zero_action"] == pytest.approx(want, rel=1e-12)


def test_the_plan_maps_colour_scale_holds_the_target() -> None:
    from uavris.experiments.tools.plan import colour_limits

    rates = np.array([[30.0, np.nan], [45.5, 50.2]])
    assert colour_limits(rates, 52.12) == (30.0, 52.12)  # the map: 50.2 at most, the target 52.12
    assert colour_limits(rates, 40.0) == (30.0, 50.2)


def test_benchmark_and_claims_never_replace_another_invocations_results(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "b"
    base = ["--preset", "smoke", "--cells", "scenarios", "--system.horizon", "10", "--out", str(out), "--no-progress"]
    assert main(["benchmark", "zero-action", *base]) == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    capsys.readouterr()
    assert main(["benchmark", "hover-optimizer", *base]) == 2  # another target into the same --out
    assert "holds the benchmark of zero-action" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert main(["benchmark", "zero-action", *base]) == 0  # the same benchmark again: its own files
    claims = tmp_path / "c"
    claims.mkdir()
    (claims / "claims.json").write_text(json.dumps({"inputs": {"studies": ["runs/a"], "budgets": [],
                                                               "from_scratch": None}, "judgements": []}))
    assert main(["claims", str(tmp_path / "other-study"), "--out", str(claims)]) == 2
    assert "holds the claims of other studies (runs/a)" in capsys.readouterr().err
    assert not (claims / "claims.md").exists()


# ------------------------------------------------------------------------------ nothing written outside --out
def _files(root: Path) -> set[Path]:
    return {p for p in root.rglob("*") if p.is_file()}


@pytest.mark.parametrize("name", ["../../../../escape/hall", "lab/2F", "..", ".hidden", "a b", "/abs/hall"])
def test_a_hostile_hall_name_is_one_line_and_nothing_is_written(name: str, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    (work / "h.yaml").write_text(f"name: {json.dumps(name)}\n" + HALL)
    before = _files(tmp_path)
    for args in (["evaluate", "zero-action", "--layout", str(work / "h.yaml"), "--episodes", "1", "--out",
                  str(work / "out"), "--no-progress"],
                 ["plan", str(work / "h.yaml"), "--grid-step", "4", "--no-progress"]):
        cwd = os.getcwd()
        os.chdir(work)  # plan's default --out is relative: runs/plans/NAME
        try:
            assert main(args) == 2
        finally:
            os.chdir(cwd)
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "layout name" in err and "letters, digits" in err, err
    assert _files(tmp_path) == before  # nothing written, inside --out or out of it


def test_names_that_become_file_names_stay_one_part_of_a_name_inside_out(tmp_path: Path) -> None:
    """A hall named with a dot and a policy in a file, each evaluated into --out: every file it
    writes is inside --out, the policy's and the hall's names whole (no suffix cut at a dot)."""
    (tmp_path / "hall.yaml").write_text("name: lab.v2\n" + HALL)
    (tmp_path / "control.py").write_text("import numpy as np\n\ndef still(obs):\n"
                                         "    return np.zeros((obs.shape[0], 22), dtype=np.float32)\n")
    out = tmp_path / "out"
    for target in ("zero-action", f"{tmp_path / 'control.py'}:still"):
        assert main(["evaluate", target, "--layout", str(tmp_path / "hall.yaml"), "--episodes", "1", "--out",
                     str(out), "--no-progress", "--no-references"]) == 0
    written = _files(tmp_path) - {tmp_path / "hall.yaml", tmp_path / "control.py"}
    assert written and all(out in p.parents for p in written)
    names = sorted(p.name for p in written)
    assert any(n.startswith("zero-action-lab_v2-seed") and n.endswith(".json") for n in names), names
    assert any(n.startswith("control_py_still-lab_v2-seed") and n.endswith(".json") for n in names), names


def test_ctrl_c_while_the_command_line_starts_is_one_line(tmp_path: Path) -> None:
    """Ctrl-C during `uavris`'s imports (here raised by an import hook when the environments load,
    as a signal would arrive there) ends with the one line every later interrupt gives, no traceback."""
    import subprocess
    import sys

    script = tmp_path / "starting.py"
    script.write_text(
        "import importlib.abc, sys\n"
        "class Interrupt(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path, target=None):\n"
        "        if name == 'uavris.env':\n"
        "            raise KeyboardInterrupt\n"
        "sys.meta_path.insert(0, Interrupt())\n"
        "sys.argv[0] = 'uavris'  # as the console script runs\n"
        "from uavris.cli import main\n"
        "sys.exit(main(['demo']))\n")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 130 and proc.stderr.strip() == "uavris: interrupted", proc.stderr
    script.write_text(script.read_text().replace("sys.argv[0] = 'uavris'  # as the console script runs\n", ""))
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert proc.returncode != 130 and "KeyboardInterrupt" in proc.stderr  # the library's import: Python's own


# ------------------------------------------------------------------------------ one writer per output
# Each command into an output another process holds: one line naming the holder, nothing written there.
# The inputs need not exist: the lock is taken before anything is read.
WRITERS = {
    "train": ["train", "--algo", "ddpg", "--preset", "smoke", "--no-progress"],
    "evaluate": ["evaluate", "zero-action", "--scenario", "fig2", "--episodes", "1", "--no-progress"],
    "benchmark": ["benchmark", "zero-action", "--preset", "smoke", "--cells", "scenarios", "--no-progress"],
    "compare-algorithms": ["compare-algorithms", "--preset", "smoke", "--no-progress"],
    "collect": ["collect", "--experts", "no-such-run", "--no-progress"],
    "pretrain-dt": ["pretrain-dt", "--dataset", "no-such-dataset", "--preset", "smoke", "--no-progress"],
    "claims": ["claims", "no-such-study"],
    "plan": ["plan", "paper", "--no-progress"],
    "plot": ["plot", "no-such-run"],
    "from-scratch": ["from-scratch", "no-such-study"],
}
STEMS = {"plan": "map", "plot": "curves", "from-scratch": "from-scratch.json"}  # written into --out's folder


@pytest.mark.parametrize("name", list(WRITERS))
def test_every_command_that_writes_is_refused_where_another_writes(
        name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import signal

    out = tmp_path / "out"
    out.mkdir()
    other = _holder(out, record=True)
    try:
        target = out / STEMS[name] if name in STEMS else out
        assert main([*WRITERS[name], "--out", str(target)]) == 2
        err = capsys.readouterr().err
        assert f"being written by process {other.pid}" in err and len(err.strip().splitlines()) == 1, err
        assert sorted(p.name for p in out.iterdir()) == [".uavris.lock"]  # the holder's, nothing else
    finally:
        other.send_signal(signal.SIGKILL)
        other.wait()


def test_a_run_redone_with_force_keeps_its_lock(tmp_path: Path) -> None:
    """``--force`` clears the run directory but not the lock its writer holds: a second writer
    started meanwhile is still refused (a removed lock file would have let it lock a new one)."""
    from uavris.errors import UavrisError
    from uavris.io import LOCK_FILE
    from uavris.runs import prepare
    from uavris.runs.lock import locked

    run = tmp_path / "run"
    prepare(run, {"a": 1}, resume=False, force=False)
    (run / "checkpoints").mkdir()
    (run / "checkpoints" / "x.zip").write_bytes(b"old")
    with locked(run):
        assert prepare(run, {"a": 2}, resume=False, force=True) is False
        assert sorted(p.name for p in run.iterdir()) == [LOCK_FILE, "config.yaml"]
        with pytest.raises(UavrisError, match="being written by process"):
            with locked(run):
                pass


def test_two_policies_of_one_name_into_one_out_keep_two_results(tmp_path: Path) -> None:
    """``a/pol.py:go`` and ``b/pol.py:go`` (or two studies' ``model`` folders) read the same in a
    file name; the key of what was evaluated tells them apart, and each result records its model."""
    out = tmp_path / "e"
    for folder, accel in (("a", 0.0), ("b", 0.5)):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "pol.py").write_text(
            f"import numpy as np\n\ndef go(obs):\n    a = np.zeros((obs.shape[0], 22), np.float32)\n"
            f"    a[:, 0] = {accel}\n    return a\n")
    means = {}
    for folder in ("a", "b"):
        assert main(["evaluate", str(tmp_path / folder / "pol.py") + ":go", "--scenario", "fig2", "--episodes", "2",
                     "--no-references", "--out", str(out), "--no-progress"]) == 0
    results = [json.loads(p.read_text()) for p in sorted(out.glob("pol_py_go-*.json"))]
    assert len(results) == 2
    for r in results:
        means[r["model"]["models"][0]] = r["mean"]
    assert set(means) == {f"{tmp_path / f / 'pol.py'}:go" for f in ("a", "b")}
    assert len(set(means.values())) == 2


def test_a_directory_that_holds_no_policy_says_what_it_lacks(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "ctl" / "model").mkdir(parents=True)  # a controller whose controller.json is gone
    assert main(["evaluate", str(tmp_path / "ctl"), "--scenario", "fig2", "--episodes", "1"]) == 2
    err = capsys.readouterr().err
    assert "controller.json" in err and "config.yaml" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("command", [
    ["evaluate", "zero-action", "--scenario", "fig2", "--episodes", "1", "--no-progress"],
    ["sweep", "zero-action", "--param", "system.rician-factor", "0", "--episodes", "1", "--system.horizon", "5",
     "--workers", "1", "--no-progress"],
    ["reproduce", "--preset", "smoke", "--workers", "1", "--force", "compare", "--no-progress"],
])
def test_a_folder_link_inside_the_output_is_refused(command: list[str], tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """What a command writes below a link would land outside --out (a sweep's logs/, a study's
    stage that --force would clear): refused in one line, nothing written through it."""
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    (out / "stages").mkdir(parents=True)
    elsewhere.mkdir()
    (out / "logs").symlink_to(elsewhere, target_is_directory=True)
    (out / "stages" / "compare-0123456789ab").symlink_to(elsewhere, target_is_directory=True)
    assert main([*command, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "is a symbolic link" in err and len(err.strip().splitlines()) == 1
    assert not any(elsewhere.iterdir()) and sorted(p.name for p in out.iterdir()) == ["logs", "stages"]


def test_a_benchmark_in_ones_own_hall_records_that_hall(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """benchmark.json of ``--layout FILE``: the hall's system at the top (not the target's own), the
    file in its inputs and in each cell, the model; its table titled with the hall, and another
    file into the same --out refused."""
    from uavris.config import SystemConfig
    from uavris.layouts import read_layout

    (tmp_path / "mine.yaml").write_text(HALL)
    (tmp_path / "other.yaml").write_text(HALL.replace("[5, 5, 1]", "[6, 5, 1]"))
    out = tmp_path / "b"
    assert main(["benchmark", "zero-action", "--layout", str(tmp_path / "mine.yaml"), "--preset", "smoke",
                 "--out", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "benchmark.json").read_text())
    hall = read_layout(tmp_path / "mine.yaml").resolve(SystemConfig())[0]
    assert summary["system"]["users"] == [list(u) for u in hall.users] and summary["system"]["room"] == [30, 24, 6]
    assert summary["layout"] == summary["inputs"]["layout"] == str(tmp_path / "mine.yaml")
    assert summary["cells"][0]["hall"]["layout"] == str(tmp_path / "mine.yaml")
    assert summary["cells"][0]["hall"]["start"] == [12.0, 12.0, 4.0]
    assert summary["model"]["models"] == ["reference zero-action"]
    title = (out / "benchmark.md").read_text().splitlines()[0]
    assert "mine.yaml" in title and "protocol" not in title.split("(")[0], title
    capsys.readouterr()
    assert main(["benchmark", "zero-action", "--layout", str(tmp_path / "other.yaml"), "--preset", "smoke",
                 "--out", str(out), "--no-progress"]) == 2
    assert "holds the benchmark of" in capsys.readouterr().err


def test_names_too_long_for_a_file_system_are_one_line_before_any_work(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "long.yaml").write_text(HALL + "name: " + "x" * 250 + "\n")
    one = ["--episodes", "1", "--no-progress"]
    for args, says in ((["evaluate", "zero-action", "--layout", str(tmp_path / "long.yaml"), *one, "--out",
                         str(tmp_path / "e")], "has 250 characters; at most 100"),
                       (["plan", str(tmp_path / "long.yaml"), "--no-progress", "--out", str(tmp_path / "p" / "m")],
                        "at most 100"),
                       (["evaluate", "zero-action", "--scenario", "fig2", *one, "--out", str(tmp_path / ("y" * 300))],
                        "a folder name of 300 bytes")):
        assert main(args) == 2
        err = capsys.readouterr().err
        assert says in err and len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.yaml"]


def test_a_full_disk_is_one_line_and_leaves_no_temporary_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """ENOSPC while a result is written: one line naming the file and what to do, and a file
    another library writes (SB3's archive, its replay buffer) leaves no temporary copy."""
    import errno

    import uavris.experiments.tools.evaluate as evaluate_mod
    from uavris.io import atomic_save

    def full(path: Path) -> None:
        path.write_bytes(b"half of it")
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    with pytest.raises(OSError):
        atomic_save(tmp_path / "replay_buffer.pkl", full)
    assert list(tmp_path.iterdir()) == []

    def no_space(*args: object, **kwargs: object) -> None:
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "e" / "x.csv"))

    monkeypatch.setattr(evaluate_mod, "write_results", no_space)
    assert main(["evaluate", "zero-action", "--scenario", "fig2", "--episodes", "1", "--out", str(tmp_path / "e"),
                 "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"uavris: error: {tmp_path / 'e' / 'x.csv'}: No space left on device; free some space")
    assert len(err.strip().splitlines()) == 1
