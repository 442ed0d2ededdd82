"""Every reference policy by name: what ``uavris evaluate NAME`` and every report use.

A result is only interesting next to doing nothing (``hover``, the zero action) and the
oracle; the others place it in between. Each entry makes a batch policy from a seed for
its own randomness (random actions, the optimiser's random starts); reports and the CLI
use seed 0, so the same reference gives the same numbers everywhere. The evaluation
episodes are chosen separately (:func:`uavris.agents.evaluation.evaluate`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from uavris.agents.baselines import BatchPolicy, hover, hover_aligned, hover_random_phases, random_policy
from uavris.agents.hybrid import with_optimised_phases
from uavris.agents.oracle import greedy_oracle_policy, oracle_policy

REFERENCE_SEED = 0


@dataclass(frozen=True)
class Reference:
    """A named reference policy."""

    label: str  # what the reports call it
    make: Callable[[int], BatchPolicy]


def _hover_motion(obs: np.ndarray, sim: object) -> np.ndarray:
    return np.zeros((obs.shape[0], 6), dtype=np.float32)


REFERENCES: dict[str, Reference] = {
    "hover": Reference("zero action (hover, level, equal phases)", lambda seed: hover()),
    "random": Reference("random actions", random_policy),
    "hover-random-phases": Reference("hover, random phases", hover_random_phases),
    "hover-aligned": Reference("hover, co-phased for the strongest pair", lambda seed: hover_aligned()),
    "hover-optimizer": Reference("hover with the optimiser's phases", lambda seed: with_optimised_phases(_hover_motion)),
    "oracle": Reference("oracle (planning)", lambda seed: oracle_policy(seed=seed)),
    "oracle-greedy": Reference("oracle (greedy lookahead, 0.1.0)", lambda seed: greedy_oracle_policy(seed=seed)),
}

# The two a result is always read against, and the ceiling for the motion of the strong track.
ZERO_ACTION, ORACLE, HOVER_OPTIMIZER = "hover", "oracle", "hover-optimizer"


def reference_policy(name: str, seed: int = REFERENCE_SEED) -> BatchPolicy:
    """The reference ``name`` (a key of :data:`REFERENCES`); raises ``KeyError`` naming the choices."""
    if name not in REFERENCES:
        raise KeyError(f"unknown reference {name!r}; choose one of {', '.join(REFERENCES)}")
    return REFERENCES[name].make(seed)
