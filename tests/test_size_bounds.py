"""A value that sets a size (grid poses, episodes, trajectories, halls, seeds) is refused above a
stated bound: one line, exit 2, nothing written; a mistyped 0.01 or 10^9 never starts a run that
exhausts memory."""

from __future__ import annotations

import subprocess
import sys

import pytest

from uavris.config import SystemConfig
from uavris.experiments.tools.plan import MAX_MAP_POSES, check_grid


def _cli(tmp_path, *args: str) -> subprocess.CompletedProcess:
    code = "import sys; from uavris.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run([sys.executable, "-c", code, *args], cwd=tmp_path, capture_output=True, text=True,
                          timeout=120)


def test_the_grid_bound_counts_the_poses_of_the_map():
    system = SystemConfig()  # 40 x 40 m floor
    assert check_grid(system, 2.0) == 21 * 21 and check_grid(system, 0.5) == 81 * 81
    assert 81 * 81 <= MAX_MAP_POSES < 201 * 201
    with pytest.raises(Exception, match=r"--grid-step 0.2 m makes a 201 x 201 grid \(40,401 poses\)"):
        check_grid(system, 0.2)


@pytest.mark.parametrize("args, names", [
    (["plan", "paper", "--grid-step", "0.01", "--out", "out/x"], "--grid-step 0.01"),
    (["evaluate", "zero-action", "--episodes", "1000000000", "--out", "out"], "--episodes"),
    (["reproduce", "--preset", "smoke", "--train-layouts", "10000000", "--out", "out"], "--train-layouts"),
    (["reproduce", "--preset", "smoke", "--eval-episodes", "1000000000", "--out", "out"], "--eval-episodes"),
    (["reproduce", "--preset", "smoke", "--dt-seeds", "1000", "--out", "out"], "--dt-seeds"),
])
def test_a_size_beyond_its_bound_is_one_line_exit_2_and_nothing_written(tmp_path, args, names):
    proc = _cli(tmp_path, *args)
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = [line for line in proc.stderr.strip().splitlines() if line.strip()]
    assert len(lines) == 1 and names in lines[0] and "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []
