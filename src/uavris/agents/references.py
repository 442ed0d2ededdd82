"""Every reference policy by name: what ``uavris evaluate NAME`` and every report use.

Lives here: the registry :data:`REFERENCES` and :func:`reference_policy`. Not here: the
policies themselves (:mod:`.baselines`, :mod:`.oracle`).

A result is only interesting next to doing nothing (``zero-action``: hovering level with equal phases) and the
oracle; the others place it in between. Each entry makes a batch policy for a system
from a seed for its own randomness (random actions, the optimiser's random starts);
reports and the CLI use seed 0, so the same reference gives the same numbers everywhere.
The evaluation episodes are chosen separately (:func:`uavris.agents.evaluation.evaluate`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from uavris.agents.baselines import hover, hover_aligned, hover_random_phases, random_policy
from uavris.agents.oracle import greedy_oracle_policy, oracle_policy
from uavris.agents.policy import Constant
from uavris.config import SystemConfig
from uavris.env.wrappers import MOTION_DIM
from uavris.errors import ConfigError

REFERENCE_SEED = 0


@dataclass(frozen=True)
class Reference:
    """A named reference policy."""

    label: str  # what the reports call it
    make: Callable[[SystemConfig, int], Any]


REFERENCES: dict[str, Reference] = {
    "zero-action": Reference("zero action (hover, level, equal phases)", lambda c, seed: hover(c)),
    "random": Reference("random actions", random_policy),
    "hover-random-phases": Reference("hover, random phases", hover_random_phases),
    "hover-aligned": Reference("hover, co-phased for the strongest pair", lambda c, seed: hover_aligned()),
    "hover-optimizer": Reference("hover with the optimiser's phases",
                                 lambda c, seed: Constant(np.zeros(MOTION_DIM, dtype=np.float32), "optimizer")),
    "oracle": Reference("oracle (planning)", lambda c, seed: oracle_policy(seed=seed)),
    "oracle-greedy": Reference("oracle (greedy lookahead, 0.1.0)", lambda c, seed: greedy_oracle_policy(seed=seed)),
}

# The two a result is always read against, and the ceiling for the motion of the strong track.
ZERO_ACTION, ORACLE, HOVER_OPTIMIZER = "zero-action", "oracle", "hover-optimizer"


def reference_policy(name: str, config: SystemConfig | None = None, seed: int = REFERENCE_SEED) -> Any:
    """The reference ``name`` (a key of :data:`REFERENCES`) for ``config`` (default: the paper's)."""
    if name not in REFERENCES:
        raise ConfigError(f"unknown reference {name!r}; choose one of {', '.join(REFERENCES)}")
    return REFERENCES[name].make(config or SystemConfig(), seed)
