"""The numpy phase optimiser of uavris 0.1.0, read from this repository's history (not a copy in the tree).

``benchmarks/oracle_throughput.py`` measures today's optimiser against it in the same run. The
module is the one of commit :data:`COMMIT` (the last 0.1.0 commit before the compiled kernel),
with its one import that moved since (``uavris.env.streams`` is ``uavris.physics.streams``).
"""

from __future__ import annotations

import subprocess
import sys
import types
from pathlib import Path

COMMIT = "c34794d"  # uavris 0.1.0 (pyproject.toml version 0.1.0), the parent of e4f3006 (the numba kernel)
PATH = "src/uavris/agents/phase_optimizer.py"


def optimizer_v010() -> types.ModuleType:
    """0.1.0's optimiser as a module; SystemExit with one line where the git history is not here."""
    repo = Path(__file__).resolve().parents[1]
    try:
        source = subprocess.run(["git", "-C", str(repo), "show", f"{COMMIT}:{PATH}"], capture_output=True, text=True,
                                check=True).stdout
    except (OSError, subprocess.CalledProcessError) as e:
        raise SystemExit(f"uavris 0.1.0's optimiser is read from git history ({COMMIT}:{PATH}), which is not "
                         f"available here ({type(e).__name__}): run from a clone of the repository") from None
    source = source.replace("from uavris.env import streams", "from uavris.physics import streams")
    module = types.ModuleType("uavris_phase_optimizer_v010")
    sys.modules[module.__name__] = module  # its dataclasses look their module up
    exec(compile(source, f"{COMMIT}:{PATH}", "exec"), module.__dict__)  # noqa: S102 - this repository's own history
    return module
