"""Gymnasium environments of the UAV-RIS D2D system."""

from uavris.env.simulator import ActionError, BatchedSimulator, decode_action, observation_layout
from uavris.env.single import UavRisD2DEnv
from uavris.env.vector import UavRisD2DVectorEnv

ENV_ID = "uavris/UavRisD2D-v0"

__all__ = ["ENV_ID", "ActionError", "BatchedSimulator", "UavRisD2DEnv", "UavRisD2DVectorEnv", "decode_action",
           "observation_layout"]
