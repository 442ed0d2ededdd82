"""Same inputs, same bits: whatever process runs a job and however its compiled kernels came to be."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

# Solve 64 seeded two-pair slots and print the phases' bits: the phase optimiser's numba
# kernels are what every optimised-phase number of the study goes through.
PROGRAM = """
import numpy as np
from uavris.config import SystemConfig
from uavris.env.simulator import BatchedSimulator
from uavris.physics.phase_opt import optimize_slot_phases
sim = BatchedSimulator(SystemConfig(), "fig2", 64)
sim.seed(np.arange(64))
sim.reset()
pairing = np.zeros_like(sim.pairing)
pairing[:, 0, 1] = pairing[:, 2, 3] = 1
print(optimize_slot_phases(sim.config, sim.channels, sim.cos_theta, pairing).phases.tobytes().hex())
"""


def _solve(cache_dir: str) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache_dir}
    return subprocess.run([sys.executable, "-c", PROGRAM], env=env, capture_output=True, text=True,
                          check=True).stdout.strip()


@pytest.mark.slow
def test_compiled_and_cached_kernels_give_the_same_bits(tmp_path):
    """numba compiles the kernels in the first process and later ones load them from its cache;
    with the helpers inlined into their caller (inline="always") both paths run the same
    code. Before, LLVM inlined them only when compiling (fast-math then reassociated across
    the calls), and a cached load linked them separately: the study's numbers depended on
    whether a job's process had compiled the kernels or not (docs/study.md, section 3)."""
    fresh = _solve(str(tmp_path))  # empty cache: compiled here, then written
    assert any(tmp_path.rglob("*.nbi"))
    cached = _solve(str(tmp_path))  # loaded from the cache
    assert fresh == cached and len(fresh) == 64 * 16 * 16
