"""Gymnasium environments of the UAV-RIS D2D system.

``uavris/UavRisD2D-v1`` is registered here, not with the classes as entry points but with
:func:`make_env` / :func:`make_vector_env`: an ``EnvSpec`` is stored as JSON (Minari
datasets keep one), so its ``config`` kwarg comes back as a plain dict, and
``gymnasium.make(spec)`` must accept that as well as a :class:`SystemConfig`. They also
take a hall (``layout=``: ``paper``, a generated name, a YAML file or a
:class:`~uavris.layouts.Layout`) and the hybrid controller (``phase_control="optimizer"``:
6 motion entries, the per-slot optimiser sets the phases).
"""

from __future__ import annotations

from typing import Any, Mapping

import gymnasium as gym

from uavris.config import Scenario, SystemConfig
from uavris.env.simulator import ActionError, BatchedSimulator, decode_action, observation_layout
from uavris.env.single import UavRisD2DEnv
from uavris.env.vector import UavRisD2DVectorEnv
from uavris.layouts import Layout, resolve_layout

ENV_ID = "uavris/UavRisD2D-v1"


def _system(config: SystemConfig | Mapping[str, Any] | None) -> SystemConfig | None:
    # A partial dict takes today's defaults for the missing fields, like SystemConfig.from_dict.
    return SystemConfig.from_dict(dict(config)) if isinstance(config, Mapping) else config


def _place(config: SystemConfig | Mapping[str, Any] | None, scenario: str | Scenario | None,
           layout: str | Layout | None) -> tuple[SystemConfig | None, str | Scenario]:
    """The system and the start: ``layout`` sets the devices (and a room, if it has one) of
    ``config`` and, unless ``scenario`` is given, the start."""
    system = _system(config)
    if layout is None:
        return system, "fig2" if scenario is None else scenario
    hall, own = resolve_layout(layout, system or SystemConfig()).resolve(system or SystemConfig())
    return hall, own if scenario is None else scenario


def make_env(config: SystemConfig | Mapping[str, Any] | None = None, scenario: str | Scenario | None = None,
             layout: str | Layout | None = None, **kwargs: Any) -> UavRisD2DEnv:
    """:class:`UavRisD2DEnv`, ``config`` also as a dict (``SystemConfig.to_dict()``), in the hall
    ``layout`` (default: the system's own devices) from ``scenario`` (default ``fig2``, or the
    layout's start)."""
    return UavRisD2DEnv(*_place(config, scenario, layout), **kwargs)


def make_vector_env(num_envs: int = 1, config: SystemConfig | Mapping[str, Any] | None = None,
                    scenario: str | Scenario | None = None, layout: str | Layout | None = None,
                    **kwargs: Any) -> UavRisD2DVectorEnv:
    """:class:`UavRisD2DVectorEnv`, with the arguments of :func:`make_env`."""
    return UavRisD2DVectorEnv(num_envs, *_place(config, scenario, layout), **kwargs)


# Registered once per process, whichever of `import uavris` or `import uavris.env` comes first.
if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point="uavris.env:make_env", vector_entry_point="uavris.env:make_vector_env")

__all__ = ["ENV_ID", "ActionError", "BatchedSimulator", "UavRisD2DEnv", "UavRisD2DVectorEnv", "decode_action",
           "make_env", "make_vector_env", "observation_layout"]
