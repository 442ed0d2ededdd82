"""The command line with halls of one's own and its messages: the flags that set a hall
(--system.room, --layout) and in which order, every cell checked before the first runs,
results of two systems kept apart, bad input named as the user knows it, and intervals
printed as a user reads them."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from uavris.agents.evaluation import evaluate
from uavris.agents.references import reference_policy
from uavris.cli import evaluation as cli_evaluation
from uavris.cli import main
from uavris.cli import tools as cli_tools
from uavris.cli import training as cli_training
from uavris.config import PAPER_USERS, SCENARIOS, PropulsionParams, SystemConfig
from uavris.layouts import LayoutGenerator
from uavris.presets import EVAL_SEED

HALL_30 = """room: [30, 20, 6]
devices:
  - [5, 5, 1]
  - [12, 5, 1]
  - [25, 15, 0.5]
  - [18, 15, 0.5]
"""


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _one_line(capsys: pytest.CaptureFixture[str], code: int) -> str:
    out, err = capsys.readouterr()
    assert code == 2, (code, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("uavris: error: ") and "Traceback" not in out + err, err
    return lines[0]


def _only_json(out: Path) -> dict:
    (path,) = out.glob("*.json")
    return json.loads(path.read_text())


@pytest.fixture(scope="module")
def hall_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A smoke run trained in a 30 x 20 x 6 hall of a YAML layout file (about 6 s)."""
    root = tmp_path_factory.mktemp("hall30")
    (root / "hall.yaml").write_text(HALL_30)
    run = root / "run"
    assert main(["train", "--preset", "smoke", "--layout", str(root / "hall.yaml"), "--out", str(run),
                 "--no-progress"]) == 0
    return run


# ---------------------------------------------------------------- 1. --system.* flags and --layout
def test_system_room_applies_before_the_layout(hall_run: Path, tmp_path: Path) -> None:
    """A run of a 30 x 20 x 6 hall evaluated with the paper's devices in a 40 x 40 x 8 room:
    its own system, with the room the flag gives and the paper's devices and start."""
    from uavris.experiments.training.train_expert import load_run_policy

    cfg, policy = load_run_policy(hall_run)
    assert cfg.system.room == (30.0, 20.0, 6.0)
    out = tmp_path / "e"
    assert main(["evaluate", str(hall_run), "--layout", "paper", "--system.room", "40", "40", "8",
                 "--episodes", "2", "--out", str(out), "--no-progress"]) == 0
    got = _only_json(out)
    want = cfg.system.replace(room=(40.0, 40.0, 8.0), users=PAPER_USERS)
    assert got["system"] == want.to_dict() and got["start"] == list(SCENARIOS["fig2"].start)
    mean = evaluate(policy, want, SCENARIOS["fig2"], 2, EVAL_SEED).summary()["mean"]
    assert got["mean"] == pytest.approx(mean, abs=1e-12)


class _Built(Exception):
    """Raised by a command's library call in place of the work: the system the command built."""


def _stop_with_system(monkeypatch: pytest.MonkeyPatch, command: str) -> None:
    """Replace the library call ``command`` makes with one that raises the system it was given
    (plan: the hall its layout makes of it), so the test reads what the command line built."""
    import uavris.experiments.tools.benchmark as benchmark
    import uavris.experiments.tools.demo as demo
    import uavris.experiments.tools.evaluate as evaluate_tool
    import uavris.experiments.tools.plan as plan
    import uavris.experiments.tools.sweep as sweep
    import uavris.experiments.training.compare as compare

    def stop(system: SystemConfig) -> None:
        raise _Built(system)

    where, name, take = {
        "evaluate": (evaluate_tool, "evaluate_target", lambda *a, **k: k["system"]),
        "benchmark": (benchmark, "benchmark", lambda *a, **k: k["system"]),
        "demo": (demo, "run_demo", lambda *a, **k: a[3]),
        "plan": (plan, "plan_hall", lambda *a, **k: a[0].system(a[1])),
        "sweep": (sweep, "sweep", lambda *a, **k: k["base"]),
        "compare-algorithms": (compare, "compare_algorithms", lambda *a, **k: k["system"]),
    }[command]
    real = getattr(where, name)
    for module in (where, cli_evaluation, cli_tools, cli_training):  # the library's name, and a command's own
        if getattr(module, name, None) is real:
            monkeypatch.setattr(module, name, lambda *a, **k: stop(take(*a, **k)))


HALL_12_HIGH = HALL_30.replace("room: [30, 20, 6]", "room: [30, 20, 12]")


@pytest.mark.parametrize("command", ["evaluate", "benchmark", "demo", "plan", "sweep", "compare-algorithms"])
def test_system_flags_beside_a_layout_are_judged_in_its_hall(command: str, monkeypatch: pytest.MonkeyPatch,
                                                            tmp_path: Path) -> None:
    """--system.* flags beside --layout are judged in the hall the layout makes, not in the
    paper's: 3 active pairs among 8 devices (the paper's 4 allow 2), a ceiling of 11 m in a
    12 m room (the paper's is 8 m). Every command that takes a layout builds both lines."""
    hall = tmp_path / "high.yaml"
    hall.write_text(HALL_12_HIGH)
    start = {"evaluate": ["evaluate", "zero-action", "--out", str(tmp_path / "e")],
             "benchmark": ["benchmark", "zero-action", "--out", str(tmp_path / "b")],
             "demo": ["demo"], "plan": ["plan"],
             "sweep": ["sweep", "zero-action", "--param", "system.nx", "2", "--out", str(tmp_path / "s")],
             "compare-algorithms": ["compare-algorithms", "--out", str(tmp_path / "c")]}[command]
    _stop_with_system(monkeypatch, command)
    lines = ((["--layout", "layout-train-0-k8", "--system.max-active-pairs", "3"],
              dict(num_users=8, max_active_pairs=3)),
             (["--layout", str(hall), "--system.z-max", "11"], dict(room=(30.0, 20.0, 12.0), z_max=11.0)))
    for flags, want in lines:
        if command == "plan":  # its hall is its positional argument
            flags = flags[1:]
        with pytest.raises(_Built) as built:
            main([*start, *flags])
        system = built.value.args[0]
        assert type(system) is SystemConfig and {k: getattr(system, k) for k in want} == want, (command, flags)


def test_a_generated_layout_is_drawn_in_the_room_of_the_flag(tmp_path: Path) -> None:
    out = tmp_path / "e"
    assert main(["evaluate", "zero-action", "--layout", "layout-unseen-0", "--system.room", "60", "60", "8",
                 "--episodes", "1", "--out", str(out), "--no-progress"]) == 0
    got = _only_json(out)
    big = SystemConfig(room=(60.0, 60.0, 8.0))
    layout = LayoutGenerator().layout("unseen", 0, big)
    assert got["system"]["room"] == [60.0, 60.0, 8.0]
    assert got["system"]["users"] == [list(u) for u in layout.users] and got["start"] == list(layout.start)
    assert layout.users != LayoutGenerator().layout("unseen", 0).users  # not the 40 m hall's devices


@pytest.mark.parametrize("room", [("50", "50", "8"), ("40", "40", "8"), ("30", "20", "6")],
                         ids=["another", "the-default", "the-files-own"])
@pytest.mark.parametrize("command", ["evaluate", "demo", "train", "benchmark", "plan", "sweep"])
def test_a_layout_file_with_a_room_and_system_room_is_one_line(command: str, room: tuple[str, ...], tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A room given twice is one line whatever the values: the default's (which a parse cannot
    tell from no flag, and which ran a hall of neither room) and the file's own (which failed on
    the default ceiling before)."""
    hall = tmp_path / "hall.yaml"
    hall.write_text(HALL_30)
    before = _tree(tmp_path)
    args = {"evaluate": ["evaluate", "zero-action", "--episodes", "1", "--out", str(tmp_path / "e")],
            "demo": ["demo", "--episodes", "1"],
            "train": ["train", "--preset", "smoke", "--out", str(tmp_path / "run")],
            "benchmark": ["benchmark", "zero-action", "--preset", "smoke", "--out", str(tmp_path / "b")],
            "plan": ["plan", str(hall), "--out", str(tmp_path / "p" / "map")],
            "sweep": ["sweep", "zero-action", "--param", "system.nx", "2", "--out", str(tmp_path / "s")],
            }[command]
    layout = [] if command == "plan" else ["--layout", str(hall)]
    err = _one_line(capsys, main([*args, *layout, "--system.room", *room]))
    assert f"--layout {hall} sets the room; drop --system.room or the file's room" in err
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("command", [["evaluate", "zero-action", "--episodes", "1"], ["demo", "--episodes", "1"]])
def test_a_layout_and_the_papers_devices_given_by_flag_is_one_line(command: list[str], tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    devices = [str(c) for u in PAPER_USERS for c in u]  # the default's value: given all the same
    err = _one_line(capsys, main([*command, "--layout", "layout-unseen-1", "--system.users", *devices]))
    assert "--layout and --system.users both give the device positions" in err
    assert not any(tmp_path.iterdir())


# ---------------------------------------------------------------- 2. every benchmark cell checked first
def test_benchmark_checks_every_cell_before_the_first_runs(hall_run: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """The paper's unseen2 starts at y = 25 m, outside a hall 20 m deep: one line naming the
    cell, before unseen1 (which fits) has been evaluated, and nothing written."""
    assert SCENARIOS["unseen2"].start[1] > 20 >= SCENARIOS["unseen1"].start[1]
    out = tmp_path / "bench"
    before = _tree(hall_run)
    err = _one_line(capsys, main(["benchmark", str(hall_run), "--preset", "smoke", "--out", str(out),
                                  "--no-progress"]))
    assert "unseen2" in err and "flight region" in err, err
    assert not out.exists() and _tree(hall_run) == before


def test_benchmark_checks_the_layout_cells_too(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A safety distance no start in the 40 m hall keeps: one line naming the layout cell, nothing
    written (the generator refuses such a hall; a guard)."""
    out = tmp_path / "bench"
    err = _one_line(capsys, main(["benchmark", "zero-action", "--preset", "smoke", "--cells", "layouts",
                                  "--system.safety-distance", "30", "--out", str(out), "--no-progress"]))
    assert "layout-unseen-0" in err and "safety" in err, err
    assert not out.exists()


# ---------------------------------------------------------------- 3. evaluation files name the system
def test_evaluations_of_two_systems_into_one_folder_keep_both(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """Two transmit powers into one --out: two result files, each with its own system and the
    mean of its own evaluation; the same evaluation again names the same file."""
    out = tmp_path / "e"
    base = ["evaluate", "zero-action", "--scenario", "fig2", "--episodes", "2", "--out", str(out), "--no-progress"]
    names = {}
    for power in ("1", "2"):
        assert main([*base, "--system.tx-power-w", power]) == 0
        printed = capsys.readouterr().out
        (new,) = set(out.glob("*.json")) - set(names.values())
        names[power] = new
        assert str(new) in printed
    assert len(list(out.glob("*.csv"))) == 2
    for power, path in names.items():
        assert re.fullmatch(r"zero-action-fig2-seed1000000-n2-[0-9a-f]{8}\.json", path.name), path.name
        summary = json.loads(path.read_text())
        system = SystemConfig(tx_power_w=float(power))
        assert summary["system"]["tx_power_w"] == float(power)
        want = evaluate(reference_policy("zero-action", system), system, "fig2", 2, EVAL_SEED).summary()["mean"]
        assert summary["mean"] == pytest.approx(want, abs=1e-12)
    assert main([*base, "--system.tx-power-w", "2"]) == 0  # the same evaluation: the same name, replaced
    assert sorted(out.glob("*.json")) == sorted(names.values())
    assert main([*base, "--phase-control", "optimizer"]) == 0  # another phase control: another file
    assert len(list(out.glob("*.json"))) == 3


# ---------------------------------------------------------------- 5. messages
def test_a_layout_device_with_two_coordinates_says_so(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    hall = tmp_path / "hall.yaml"
    hall.write_text("devices:\n  - [15, 5, 1]\n  - [5, 5]\n  - [30, 20, 0.1]\n")
    err = _one_line(capsys, main(["evaluate", "zero-action", "--layout", str(hall), "--episodes", "1",
                                  "--out", str(tmp_path / "e")]))
    assert err.endswith(f"device D2 of {hall}: expected [x, y, z], got [5, 5]"), err
    assert not (tmp_path / "e").exists()


def test_system_users_not_in_threes_says_so(capsys: pytest.CaptureFixture[str]) -> None:
    err = _one_line(capsys, main(["evaluate", "zero-action", "--scenario", "fig2", "--system.users", "5", "5", "1",
                                  "15", "5"]))
    assert "--system.users takes x y z per device: a multiple of 3 numbers, got 5 values: 5 5 1 15 5" in err, err


def test_a_malformed_yaml_file_names_the_line_and_column(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A tab indents the third line's first character (YAML forbids tabs in indentation)."""
    hall = tmp_path / "hall.yaml"
    hall.write_text("name: hall\ndevices:\n\t- [15, 5, 1]\n")
    err = _one_line(capsys, main(["plan", str(hall), "--out", str(tmp_path / "p")]))
    assert f"{hall} is not valid YAML" in err and "(line 3, column 1)" in err, err


def test_a_device_is_named_as_the_user_knows_it() -> None:
    """Device k of a list (counted from 1, as the plots' D1, D2, ... and a file's devices) beside
    its index in SystemConfig.users."""
    from uavris.config import ConfigError

    with pytest.raises(ConfigError) as e:
        SystemConfig(users=((15.0, 5.0, 1.0), (50.0, 5.0, 1.0))).check()
    assert "SystemConfig.users[1] (device D2) must be a point inside the room" in str(e.value)
    with pytest.raises(ConfigError) as e:
        SystemConfig(users=((15.0, 5.0, 1.0), (25.0, 5.0, 1.0), (27.0, 5.0, 1.0))).check()
    assert "SystemConfig.users[2] (device D3) must be at least min_device_spacing" in str(e.value)
    assert "from device D2 = [25.0, 5.0, 1.0]" in str(e.value)


def test_python_evaluate_names_its_own_argument() -> None:
    from uavris.config import ConfigError

    system = SystemConfig()
    for kwargs, name in ((dict(episodes=0, seed=0), "episodes"), (dict(episodes=1, seed=-1), "seed")):
        with pytest.raises(ConfigError) as e:
            evaluate(reference_policy("zero-action", system), system, "fig2", **kwargs)
        assert str(e.value).startswith(f"{name} must be") and "--" not in str(e.value), str(e.value)


# ---------------------------------------------------------------- 6. statistics that read right
def _bench_summary(fractions: list[float]) -> dict:
    from uavris.experiments.tools.benchmark import _over

    cells = [{"cell": f"layout-unseen-{j}", "kind": "layout", "mean": 10 * f, "ci_low": 9 * f - 6, "ci_high": 11 * f,
              "zero_action": 5.0, "hover_optimizer": 8.0, "oracle": 10.0, "fraction_of_oracle": f,
              "minus_zero_action": 10 * f - 5, "minus_zero_action_low": 9 * f - 5, "minus_zero_action_high": 11 * f - 5,
              "minus_hover_optimizer": 10 * f - 8, "minus_hover_optimizer_low": 9 * f - 8,
              "minus_hover_optimizer_high": 11 * f - 8, "minus_oracle": 10 * f - 10, "minus_oracle_low": 9 * f - 10,
              "minus_oracle_high": 11 * f - 10}
             for j, f in enumerate(fractions)]
    return {"target": "t", "preset": "smoke", "episodes": 8, "seed": EVAL_SEED, "cells": cells, "over": _over(cells)}


def test_the_benchmark_prints_an_interval_over_cells_from_three_on() -> None:
    """Two halls: Student's t with one degree of freedom gives [11.5, 156.8] around 84.2%, which
    says nothing; the table says n/a instead, and its caption says why. Three: the interval."""
    from scipy import stats

    from uavris.experiments.tools.benchmark import benchmark_table

    two = benchmark_table(_bench_summary([0.5, 0.9]))
    row = next(line for line in two.splitlines() if "mean over 2 layouts" in line)
    assert "70.0% [n/a: 2 layouts]" in row and "+2.00 [n/a: 2 layouts]" in row, row
    assert "from 3" in two
    x = [0.5, 0.7, 0.9]
    half = stats.t.ppf(0.975, 2) * 0.2 / 3 ** 0.5  # sd 0.2 over 3 halls
    three = benchmark_table(_bench_summary(x))
    row = next(line for line in three.splitlines() if "mean over 3 layouts" in line)
    assert f"70.0% [{100 * (0.7 - half):.1f}, {100 * (0.7 + half):.1f}]" in row, row
    # a cell's rate interval is bounded below at 0 (9 x 0.5 - 6 < 0); its paired differences beside it
    cell = next(line for line in three.splitlines() if line.startswith("| layout-unseen-0 "))
    assert "5.00 [0.00, 5.50]" in cell and "-3.00 [-3.50, -2.50]" in cell and "-5.00 [-5.50, -4.50]" in cell, cell
    one = benchmark_table(_bench_summary([0.5]))
    assert "mean over" not in one  # one cell is its own row, never "the mean over 1 layouts"


def test_demo_prints_intervals_in_brackets_never_below_zero(capsys: pytest.CaptureFixture[str]) -> None:
    from scipy import stats

    from uavris.agents.references import REFERENCES

    assert main(["demo", "--episodes", "2", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    system = SystemConfig()
    for name in ("zero-action", "random", "hover-aligned"):
        x = evaluate(reference_policy(name, system), system, "fig2", 2, 1).avg_sum_rate
        half = stats.t.ppf(0.975, 1) * stats.sem(x)
        want = f"95% CI [{max(0.0, x.mean() - half):.2f}, {x.mean() + half:.2f}]"
        line = next(line for line in out.splitlines() if REFERENCES[name].label in line)
        assert want in line, (line, want)
    assert "[0.00, " in out  # random actions' interval reaches below 0 on these two episodes


def test_evaluate_prints_intervals_in_brackets_never_below_zero(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    from scipy import stats

    assert main(["evaluate", "random", "--scenario", "fig2", "--episodes", "2", "--seed", "1", "--out",
                 str(tmp_path / "r"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    system = SystemConfig()
    from uavris.agents.references import REFERENCE_SEED

    x = evaluate(reference_policy("random", system, REFERENCE_SEED), system, "fig2", 2, 1).avg_sum_rate
    half = stats.t.ppf(0.975, 1) * stats.sem(x)
    assert x.mean() - half < 0  # the interval the printout bounds
    assert f"(95% CI [0.00, {x.mean() + half:.2f}], IQM" in out, out
    assert main(["evaluate", "zero-action", "--scenario", "fig2", "--episodes", "1", "--out", str(tmp_path / "h"),
                 "--no-progress"]) == 0
    assert "(95% CI n/a, IQM" in capsys.readouterr().out  # one episode: no interval, not "nan-nan"


# ---------------------------------------------------------------- 7. the demo's horizon
@pytest.mark.parametrize("budget, label", [(None, "8,000"), ("4000", "4,000")])
def test_demo_header_says_when_the_energy_budget_ends_an_episode(budget: str | None, label: str,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """The slot the header names is the length of a simulated hovering episode."""
    flags = [] if budget is None else ["--system.energy-budget-j", budget]
    assert main(["demo", "--episodes", "1", *flags]) == 0
    header = capsys.readouterr().out.splitlines()[0]
    system = SystemConfig() if budget is None else SystemConfig(energy_budget_j=float(budget))
    slots = int(evaluate(reference_policy("zero-action", system), system, "fig2", 1, 0).length[0])
    assert slots < 100
    assert (f"T = 100 slots of 0.5 s, or until the {label} J energy budget is spent (hovering: slot {slots})"
            in header), header


@pytest.mark.parametrize("args, message", [
    (["evaluate", "zero-action", "--scenario", "fig2", "--layout", "layout-unseen-1"],
     "--scenario fig2 is a start in the paper's hall and --layout layout-unseen-1 a hall"),
    (["evaluate", "zero-action", "--scenario", "fig2", "--track", "strong"], "--track chooses the track of --row"),
    (["benchmark", "zero-action", "--cells", "scenarios", "--layout", "layout-unseen-1"],
     "--cells scenarios chooses among the protocol's cells"),
    (["sweep", "oracle", "hover-optimizer", "oracle", "--param", "system.nx", "2,4"], "oracle named more than once"),
    (["sweep", "oracle", "--param", "system.devices", "3,4", "--layout", "layout-unseen-1"],
     "sweeps generated halls of each count"),
    (["sweep", "oracle", "--param", "system.nx", "2,4", "--scenario", "fig2", "--layout", "layout-unseen-1"],
     "is a start in the paper's hall"),
])
def test_flags_that_conflict_are_one_line_and_write_nothing(args: list[str], message: str, tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    assert main([*args, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err, err
    assert not any(tmp_path.rglob("*")), list(tmp_path.rglob("*"))


def test_the_demo_names_a_layout_as_a_hall_and_counts_one_episode(capsys: pytest.CaptureFixture[str]) -> None:
    """``--layout`` is a hall, not a scenario of the paper's: the first line names it so; a
    named scenario is still one; one episode is "1 episode"."""
    assert main(["demo", "--episodes", "1", "--layout", "layout-unseen-3"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("uavris demo: hall layout-unseen-3 [") and ", 1 episode, " in first, first
    assert main(["demo", "--episodes", "1", "--scenario", "unseen1"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith("uavris demo: scenario unseen1 [") and ", 1 episode, " in first, first


def test_every_kind_of_system_flag_written_on_the_line_changes_the_targets_system():
    """A command parsed once applies exactly the --system.* flags written on the line to the base
    system (a target's own): a value, a boolean's --system.no-NAME, a field of the nested
    propulsion parameters (the base's others kept), and a flag written at its default value; the
    fields not written stay the base's, whatever the parse's defaults say."""
    from uavris.cli.evaluation import EvaluateArgs
    from uavris.cli.options import in_hall, written
    from uavris.cli.parsing import parse

    base = SystemConfig(horizon=30, learn_amplitudes=True, observe_devices=True,
                        propulsion=PropulsionParams(induced_w=90.0))
    args = ["zero-action", "--system.no-angle-dependent-reflection", "--system.propulsion.tip-speed", "110",
            "--system.v-max=3", "--system.nx", str(SystemConfig().nx)]
    got, hall, layout = in_hall(None, base, written(parse(EvaluateArgs, args, "uavris evaluate", "").system))
    assert hall is None and layout is None
    assert got == base.replace(angle_dependent_reflection=False, v_max=3.0,
                               propulsion=PropulsionParams(induced_w=90.0, tip_speed=110.0))
    assert got.horizon == 30 and got.learn_amplitudes and got.observe_devices and got.propulsion.induced_w == 90.0


# ------------------------------------------------------------- 7. every flag the user's, on every command
SYSTEM_COMMANDS = {  # each command that builds a system, as a line that stops before any work
    "evaluate": ["evaluate", "zero-action"], "benchmark": ["benchmark", "zero-action"], "demo": ["demo"],
    "plan": ["plan"], "sweep": ["sweep", "zero-action", "--param", "system.nx", "2"],
    "compare-algorithms": ["compare-algorithms"], "train": ["train", "--preset", "smoke"],
    "finetune-dt": ["finetune-dt", "--model", "m", "--preset", "smoke"],
    "reproduce": ["reproduce", "--preset", "smoke", "--estimate"]}


def _flags(command: list[str], capsys: pytest.CaptureFixture[str]) -> set[str]:
    assert main([*command, "--help"]) == 0  # the flags a row of the help defines, not those its prose names
    return set(re.findall(r"^[\s│]*(--[a-z][a-z0-9.-]*)", capsys.readouterr().out, re.MULTILINE))


def _flag_names(cls: type, prefix: str) -> set[str]:
    """The flag of every field of the config class ``cls`` (a nested config's fields, an optional one's
    too, under its name) but those it suppresses."""
    import dataclasses
    import typing

    import tyro

    hints = typing.get_type_hints(cls)
    extras = typing.get_type_hints(cls, include_extras=True)
    out: set[str] = set()
    for f in dataclasses.fields(cls):
        if tyro.conf.Suppress in getattr(extras[f.name], "__metadata__", ()) or f.metadata.get("internal"):
            continue  # not a flag by design (a model's data sizes: the dataset gives them; what a config keeps)
        name = f"{prefix}{f.name.replace('_', '-')}"
        nested = [t for t in (hints[f.name], *typing.get_args(hints[f.name])) if dataclasses.is_dataclass(t)]
        out |= _flag_names(nested[0], f"{name}.") if nested else {name}
    return out


@pytest.mark.parametrize("command", sorted(SYSTEM_COMMANDS))
def test_every_field_of_the_system_is_a_flag_of_every_command_that_builds_one(
        command: str, capsys: pytest.CaptureFixture[str]) -> None:
    """A field added to SystemConfig is a --system.* flag of every command that builds a system, with
    no edit of the command line's code (the flags are the config's fields); the written ones are taken
    field by field (test_every_kind_of_system_flag_written_on_the_line_changes_the_targets_system)."""
    from uavris.config import SystemConfig

    line = SYSTEM_COMMANDS[command] if command != "finetune-dt" else ["finetune-dt"]
    missing = _flag_names(SystemConfig, "--system.") - _flags(line, capsys)
    assert not missing, (command, sorted(missing))


@pytest.mark.parametrize("command, cls", [("train", "TrainConfig"), ("pretrain-dt", "PretrainConfig"),
                                          ("finetune-dt", "FinetuneConfig"), ("reproduce", "ReproduceConfig")])
def test_every_field_of_a_commands_config_is_one_of_its_flags(command: str, cls: str,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    from uavris.experiments.study.config import ReproduceConfig
    from uavris.experiments.training.finetune import FinetuneConfig
    from uavris.experiments.training.pretrain import PretrainConfig
    from uavris.experiments.training.train_expert import TrainConfig

    config = {"TrainConfig": TrainConfig, "PretrainConfig": PretrainConfig, "FinetuneConfig": FinetuneConfig,
              "ReproduceConfig": ReproduceConfig}[cls]
    missing = _flag_names(config, "--") - _flags([command], capsys)
    assert not missing, (command, sorted(missing))


def test_a_field_added_to_a_config_is_taken_where_written_even_at_its_default() -> None:
    """The build's rule is the config's fields, whatever they are: a config with a field of its own,
    its base (a file's, a model's) not at the default, takes the field where its flag is written,
    at its default value too, and keeps the base's where it is not."""
    import dataclasses

    from uavris.cli.options import flags_of, layered, written
    from uavris.cli.parsing import parse

    @dataclasses.dataclass(frozen=True)
    class Added:
        kept: int = 1
        added: float = 2.0  # a field new to the config
        maybe: int | None = None  # a field that takes None

    base = Added(kept=5, added=7.0, maybe=3)
    for line, want in ((["--added", "2.0"], Added(5, 2.0, 3)), (["--kept", "1"], Added(1, 7.0, 3)), ([], base),
                       (["--maybe", "None"], Added(5, 7.0, None))):
        assert layered(base, written(parse(flags_of(Added), line, "t", ""))) == want, line


LOW_HALL = HALL_30  # a 6 m room: the paper's ceiling of 8 m is above it


@pytest.mark.parametrize("command", sorted(SYSTEM_COMMANDS))
def test_a_ceiling_written_at_its_default_beside_a_lower_room_is_the_users(
        command: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """--system.z-max 8 (its default) beside the layout of a 6 m room is the user's ceiling, judged in
    that room (one line), never silently the room's; unwritten, the room caps it."""
    hall = tmp_path / "low.yaml"
    hall.write_text(LOW_HALL)
    monkeypatch.setattr(cli_training, "dt_system", lambda model: SystemConfig())  # finetune-dt's model: the paper's
    line = [*SYSTEM_COMMANDS[command], *(["--out", str(tmp_path / "o")] if command not in ("demo", "plan") else [])]
    layout = [str(hall)] if command == "plan" else ["--layout", str(hall)]
    err = _one_line(capsys, main([*line, *layout, "--system.z-max", "8"]))
    assert "z_max <= room height 6.0, got (2.0, 8.0)" in err, err
    assert not (tmp_path / "o").exists() and not list(tmp_path.glob("runs*"))


def test_a_flag_written_at_its_default_beside_a_file_or_a_model_is_the_users(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A file's (train --config), a model's (finetune-dt --model, evaluate's target) system is the
    base; a flag written at the library's default value is still the user's over it, and every
    field not written stays the base's."""
    import yaml

    from uavris.cli.training import parse_finetune, parse_train
    from uavris.experiments.tools.targets import Reference
    from uavris.presets import TRAIN

    own = SystemConfig(v_max=3.0, horizon=30)
    file = tmp_path / "run.yaml"
    file.write_text(yaml.safe_dump({"system": {"v_max": 3.0, "horizon": 30}, "total_steps": 999}))
    run = parse_train(["--config", str(file), "--system.v-max", "5", "--total-steps",
                       str(TRAIN["quick"]["total_steps"])]).run
    assert (run.system.v_max, run.system.horizon, run.total_steps) == (5.0, 30, TRAIN["quick"]["total_steps"])
    monkeypatch.setattr(cli_training, "dt_system", lambda model: own)
    tuned = parse_finetune(["--model", "m", "--scenario", "unseen1", "--system.v-max", "5"]).run
    assert (tuned.system.v_max, tuned.system.horizon) == (5.0, 30)
    monkeypatch.setattr(Reference, "own_system", lambda self: own)
    _stop_with_system(monkeypatch, "evaluate")
    with pytest.raises(_Built) as built:
        main(["evaluate", "zero-action", "--system.v-max", "5", "--out", str(tmp_path / "e")])
    assert (built.value.args[0].v_max, built.value.args[0].horizon) == (5.0, 30)


def test_a_room_written_beside_a_file_with_a_room_is_one_line_whatever_its_devices(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A file's room is the file's whatever its devices (here one above the paper's floor of 2 m,
    which only the file's own heights allow): --system.room beside it gives the room twice."""
    hall = tmp_path / "hi.yaml"
    hall.write_text(HALL_30.replace("[5, 5, 1]", "[5, 5, 2.5]"))
    err = _one_line(capsys, main(["demo", "--layout", str(hall), "--system.z-min", "3", "--system.z-max", "6",
                                  "--system.room", "40", "40", "8"]))
    assert f"--layout {hall} sets the room" in err, err


def test_a_named_scenario_flies_in_the_papers_hall_with_the_flags_written(hall_run: Path, tmp_path: Path) -> None:
    """A run of a 30 x 20 x 6 hall at the paper's fig2: the paper's devices in the room the flags
    give, judged once they apply (the paper's devices do not fit the run's own room)."""
    out = tmp_path / "e"
    assert main(["evaluate", str(hall_run), "--scenario", "fig2", "--system.room", "40", "40", "8",
                 "--system.z-max", "8", "--episodes", "1", "--out", str(out), "--no-progress"]) == 0
    got = _only_json(out)
    assert got["system"]["room"] == [40.0, 40.0, 8.0] and got["system"]["users"] == [list(u) for u in PAPER_USERS]


def test_none_written_is_none_only_where_the_field_takes_it(capsys: pytest.CaptureFixture[str]) -> None:
    """``None`` on the line is None for a field that takes it, and a value like any other (judged as
    one) for a field that does not: one line, never a traceback."""
    from uavris.cli.training import parse_train

    assert parse_train(["--system.max-active-pairs", "None"]).run.system.max_active_pairs is None
    err = _one_line(capsys, main(["train", "--algo", "sac", "--hyperparams.ent-coef", "None"]))
    assert "Hyperparams.ent_coef must be 'auto' or a number, got 'None'" in err, err


@pytest.mark.parametrize("line, message", [
    (["train", "--total-steps", "abc"], "--total-steps expects INT, got abc"),
    (["train", "--system.v-max", "fast"], "--system.v-max expects FLOAT, got fast"),
    (["train", "--algo", "None"], "--algo expects one of ddpg, ppo, sac, td3, got None"),
    (["reproduce", "--device-counts", "a"], "--device-counts expects [INT [INT ...]], got a"),
])
def test_a_value_of_the_wrong_type_names_the_flag_and_what_it_takes(line: list[str], message: str,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    err = _one_line(capsys, main(line))
    assert message in err, err
