"""uavris: UAV-mounted RIS-assisted dynamic D2D communications (simulator, experts, DT).

``import uavris`` registers the Gymnasium environment ``uavris/UavRisD2D-v0``.
"""

import gymnasium as _gym

from uavris.config import SCENARIOS, ConfigError, Scenario, SystemConfig, get_scenario
from uavris.env import ENV_ID, UavRisD2DEnv, UavRisD2DVectorEnv

__version__ = "0.1.0"

if ENV_ID not in _gym.registry:
    _gym.register(
        id=ENV_ID,
        entry_point="uavris.env.single:UavRisD2DEnv",
        vector_entry_point="uavris.env.vector:UavRisD2DVectorEnv",
    )

__all__ = ["ENV_ID", "SCENARIOS", "ConfigError", "Scenario", "SystemConfig", "UavRisD2DEnv", "UavRisD2DVectorEnv",
           "get_scenario"]
