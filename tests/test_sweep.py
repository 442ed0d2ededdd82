"""`uavris sweep`: the sum rate of policies over a grid of system parameters, each cell checked
against an evaluation of its own and the intervals against SciPy; a rerun skips finished cells."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from scipy import stats as sps

from tests.conftest import keep_figures
from uavris.agents.evaluation import evaluate
from uavris.agents.references import reference_policy
from uavris.cli import main as cli_main
from uavris.config import ConfigError, SystemConfig
from uavris.experiments.tools.sweep import parse_axis, sweep
from uavris.layouts import LayoutGenerator

SHORT = SystemConfig(horizon=20)


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_parameters_and_values_parse_or_are_one_line():
    assert parse_axis("system.tx-power-dbm", "-10:30:10").values == (-10.0, 0.0, 10.0, 20.0, 30.0)
    assert parse_axis("nx", "2,4,8").values == (2.0, 4.0, 8.0)
    assert parse_axis("system.rician_factor", "0:1:0.25").values == (0.0, 0.25, 0.5, 0.75, 1.0)
    for name, spec, what in (("system.wingspan", "1,2", "not a numeric system parameter"),
                             ("system.nx", "1:0:1", "start:stop:step"), ("system.nx", "2.5,4", "whole numbers"),
                             ("system.rician-factor", "0:1000:0.001", "between 1 and"),
                             ("system.devices", "1,4", "whole numbers >= 2"),
                             ("system.rician-factor", "nan,2", "every value must be a finite number, got nan")):
        with pytest.raises(ConfigError, match=what):
            parse_axis(name, spec)


def test_each_cell_is_the_policy_evaluated_in_that_system(tmp_path):
    """dBm to watts, the same seeded episodes in every cell, Student's t over the episodes."""
    paths = sweep(["hover-optimizer"], [parse_axis("system.tx-power-dbm", "0,20")], tmp_path, base=SHORT,
                  episodes=3)
    rows = _rows(paths[0])
    assert [float(r["tx_power_dbm"]) for r in rows] == [0.0, 20.0]
    for r, watts in zip(rows, (1e-3, 0.1)):
        system = SHORT.replace(tx_power_w=watts)
        res = evaluate(reference_policy("hover-optimizer", system), system, "fig2", 3, 1_000_000)
        x = res.avg_sum_rate
        lo, hi = sps.t.interval(0.95, 2, loc=x.mean(), scale=sps.sem(x))
        assert float(r["mean"]) == pytest.approx(x.mean(), rel=1e-12)
        assert (float(r["ci_low"]), float(r["ci_high"])) == pytest.approx((lo, hi), rel=1e-9)
        assert r["unit"] == "episodes" and int(r["samples"]) == 3
    assert float(rows[1]["mean"]) > float(rows[0]["mean"])  # 20 dB more power: a higher rate
    for p in paths[1:]:
        assert p.stat().st_size > 5000  # the figure
    cells = sorted((tmp_path / "cells").iterdir())
    stamps = [c.stat().st_mtime_ns for c in cells]
    sweep(["hover-optimizer"], [parse_axis("system.tx-power-dbm", "0,20")], tmp_path, base=SHORT, episodes=3)
    assert [c.stat().st_mtime_ns for c in sorted((tmp_path / "cells").iterdir())] == stamps  # skipped


def test_a_devices_sweep_is_over_generated_halls(tmp_path):
    paths = sweep(["zero-action"], [parse_axis("system.devices", "3")], tmp_path, base=SHORT, episodes=2, halls=2)
    [row] = _rows(paths[0])
    means = []
    for layout in LayoutGenerator(devices=3, seed=0).layouts("unseen", 2, SHORT):
        system, where = layout.resolve(SHORT)
        means.append(evaluate(reference_policy("zero-action", system), system, where, 2, 1_000_000).avg_sum_rate.mean())
    assert row["unit"] == "halls" and int(row["samples"]) == 2
    assert float(row["mean"]) == pytest.approx(np.mean(means), rel=1e-12)
    lo, hi = sps.t.interval(0.95, 1, loc=np.mean(means), scale=sps.sem(means))
    assert float(row["ci_low"]) == pytest.approx(lo, rel=1e-9)


def test_the_command_writes_the_csv_and_a_bad_grid_is_one_line(tmp_path, capsys):
    out = tmp_path / "s"
    assert cli_main(["sweep", "zero-action", "--param", "system.rician-factor", "0,8", "--param", "system.nx", "2,4",
                     "--episodes", "2", "--system.horizon", "10", "--workers", "1", "--out", str(out),
                     "--no-progress"]) == 0
    rows = _rows(out / "sweep.csv")
    assert len(rows) == 4 and {(r["rician_factor"], r["nx"]) for r in rows} == {
        ("0.0", "2.0"), ("0.0", "4.0"), ("8.0", "2.0"), ("8.0", "4.0")}  # the columns named after the parameters
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert cli_main(["sweep", "zero-action", "--param", "system.rician-factor", "0,4", "--episodes", "2",
                     "--system.horizon", "10", "--workers", "1", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "holds another sweep (the parameters differ: rician_factor 0, 8 and nx 2, 4 there)" in err, err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before  # nothing replaced
    assert cli_main(["sweep", "zero-action", "--param", "system.nx", "0:4:0", "--out", str(tmp_path / "t")]) == 2
    assert "start:stop:step" in capsys.readouterr().err
    assert not (tmp_path / "t").exists()
    assert cli_main(["sweep", "nothing-at-all", "--param", "system.nx", "2", "--out", str(tmp_path / "u")]) == 2
    assert not (tmp_path / "u").exists()


def test_legends_name_a_model_by_its_folder():
    from uavris.experiments.tools.sweep import policy_label

    assert policy_label("runs/quick/stages/deploy-pretrain-0a1b2c3d4e5f/model") == "deploy-pretrain-0a1b2c3d4e5f"
    assert policy_label("hover-optimizer") == "hover-optimizer"
    assert policy_label("runs/ppo-fig2") == "ppo-fig2"


def _kept_figure(monkeypatch):
    """The sweep's figure, drawn and kept instead of written."""
    from uavris.experiments.tools import sweep as sweep_module

    return keep_figures(monkeypatch, sweep_module)


def test_every_sweepable_parameter_is_labelled_by_its_name_and_unit(tmp_path, monkeypatch):
    """An axis reads "noise power (dBm)", not "noise dbm": every parameter a sweep accepts has
    a label of its own, and the title names the hall the rates are of."""
    from uavris.experiments.tools.sweep import LABELS, Axis, sweepable

    assert sweepable() <= set(LABELS)
    for name in sweepable():
        assert Axis(name, (1.0,)).label == LABELS[name] and "_" not in LABELS[name], name
    kept = _kept_figure(monkeypatch)
    sweep(["zero-action"], [parse_axis("system.noise-dbm", "-80,-70")], tmp_path, base=SHORT, episodes=2)
    [ax] = kept[0].axes
    assert ax.get_xlabel() == "noise power (dBm)"
    assert ax.get_title().splitlines()[0] == "the paper's hall, start fig2"


HALL = """name: two-pairs
devices:
  - [8, 9, 1]
  - [14, 11, 0.5]
  - [30, 28, 1.2]
  - [26, 32, 0]
start: [20, 20, 4.5]
"""


def test_a_sweep_in_a_layout_is_titled_by_it_and_a_moved_device_is_named_when_refused(tmp_path, monkeypatch,
                                                                                      capsys):
    """The figure of a sweep in a layout file's hall names that hall; the same sweep after the
    file's second device moved is refused with what differs (the hall, that device), not as
    "a sweep of other parameters"."""
    hall, out = tmp_path / "two-pairs.yaml", tmp_path / "s"
    hall.write_text(HALL)
    kept = _kept_figure(monkeypatch)
    args = ["sweep", "zero-action", "--param", "system.rician-factor", "0,8", "--layout", str(hall), "--episodes",
            "2", "--system.horizon", "10", "--workers", "1", "--out", str(out), "--no-progress"]
    assert cli_main(args) == 0
    assert kept[0].axes[0].get_title().splitlines()[0] == "hall two-pairs"
    capsys.readouterr()
    hall.write_text(HALL.replace("[14, 11, 0.5]", "[15, 11, 0.5]"))
    assert cli_main(args) == 2
    err = capsys.readouterr().err
    assert "holds another sweep (the hall differs: device 2 moved from [14, 11, 0.5] to [15, 11, 0.5])" in err, err
    assert "parameters" not in err
