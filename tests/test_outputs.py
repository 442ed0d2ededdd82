"""Issue 38: results are never lost (two targets into one --out) and every slot can be exported."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from uavris.cli import main


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
