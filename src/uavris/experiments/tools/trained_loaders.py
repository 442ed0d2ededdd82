"""What the trained kinds of target are read and loaded with: torch, in one module.

Lives here: nothing of its own; the functions :mod:`.targets`' trained kinds (a learned value,
a DT model, an expert's run) call to read their files and load their policies, imported from
their modules. They need the ``train`` extra (torch, safetensors, SB3), so :mod:`.targets`
imports this module where a target of one of those kinds is read or loaded, and nowhere else:
a light install evaluates references and a user's policy. Not here: the kinds themselves
(:mod:`.targets`), the loaders' own code (:mod:`uavris.agents.place.checkpoint`,
:mod:`uavris.agents.place.planner`, :mod:`uavris.agents.dt.checkpoint`,
:mod:`uavris.agents.dt.policy`, :mod:`uavris.experiments.training.train_expert`).
"""

from __future__ import annotations

from uavris.agents.dt.checkpoint import dt_model_dir, dt_system
from uavris.agents.dt.policy import load_dt_policy
from uavris.agents.place.checkpoint import load_value
from uavris.agents.place.planner import LearnedPlanner, PlaceSettings
from uavris.experiments.training.train_expert import load_run_config, load_run_policy

__all__ = ["LearnedPlanner", "PlaceSettings", "dt_model_dir", "dt_system", "load_dt_policy", "load_run_config",
           "load_run_policy", "load_value"]
