"""uavris: UAV-mounted RIS-assisted dynamic D2D communications (simulator, experts, DT).

``import uavris`` registers the Gymnasium environment ``uavris/UavRisD2D-v1`` (in :mod:`uavris.env`).
Lives here: the package's public names. Not here: anything else; the layers are
``physics`` -> ``env`` -> ``agents`` -> ``experiments`` -> ``cli`` (README, Layout).
"""

import os as _os
import sys as _sys

from uavris.float_paths import pin_float_paths

pin_float_paths()  # before numpy and torch load: the references' numbers the same on every CPU (float_paths)

try:
    from uavris.config import SCENARIOS, ConfigError, Scenario, SystemConfig, get_scenario
    from uavris.env import ENV_ID, UavRisD2DEnv, UavRisD2DVectorEnv
except KeyboardInterrupt:
    if _os.path.basename(_sys.argv[0]) in ("uavris", "-m"):  # Ctrl-C while `uavris` starts: one line, as later
        print("uavris: interrupted", file=_sys.stderr)
        raise SystemExit(130) from None
    raise

__version__ = "0.3.0"

__all__ = ["ENV_ID", "SCENARIOS", "ConfigError", "Scenario", "SystemConfig", "UavRisD2DEnv", "UavRisD2DVectorEnv",
           "get_scenario"]
