"""What the learned value is trained on: poses of training halls and the planner's ``R`` there.

Lives here: :func:`label_poses` (where in a hall poses are drawn) and :func:`hall_labels`
(the poses of one hall with their ``R``). Not here: the halls (:mod:`uavris.layouts`), the
network (:mod:`.value`), the study's labels stage and its cache
(:mod:`uavris.experiments.training.values`).

Poses: a third uniform over the flight region, a third low (the best poses of a hall are
mostly near the floor of the region, close to a pair of devices), a third around the
best points of the planner's cheap screen (:func:`uavris.agents.oracle.planner.screen`:
within 2 m of its best local maxima), so that the labels are dense where the argmax is,
each outside the safety balls. ``R`` is the planner's own value
(:func:`~uavris.agents.oracle.objective.expected_optimised_rate`: the pairings, 2 NLoS draws,
the optimiser every slot, level), its common random numbers seeded per hall: a hall's
labels are consistent among themselves, and the noise of different halls' is independent,
so a network fitted over many halls averages it out. With ``tilted``, every position whose
surface can be turned towards the devices (the oracle's global stage's tilt,
:func:`uavris.agents.oracle.planner.facing_attitudes`, under its front margin) is labelled a
second time with that attitude: where the oracle gains from tilting, the value must know it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from uavris.agents.oracle.objective import expected_optimised_rate, feasible
from uavris.agents.oracle.planner import SAFE_MARGIN_DEG, holding, screen, turned_towards
from uavris.config import SystemConfig

LOW_BAND = 1.5  # m above the region's floor: the low third of the poses
NEAR_SCREEN = 2.0  # m around the screen's best points: the last third


def label_poses(config: SystemConfig, count: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """``count`` feasible positions ``(count, 3)`` of ``config``'s hall (module docstring)."""
    lo, hi = np.asarray(config.region_low), np.asarray(config.region_high)
    peaks, _ = screen(config, 2.0)
    out: list[NDArray[np.float64]] = []
    kinds = np.arange(count) % 3
    for kind in (0, 1, 2):
        need = int((kinds == kind).sum())
        got = np.zeros((0, 3))
        while len(got) < need:
            if kind == 0:
                q = rng.uniform(lo, hi, (4 * need, 3))
            elif kind == 1:
                q = rng.uniform(lo, hi, (4 * need, 3))
                q[:, 2] = rng.uniform(lo[2], min(hi[2], lo[2] + LOW_BAND), len(q))
            else:
                centres = peaks[rng.integers(0, min(len(peaks), 6), 4 * need)]
                q = np.clip(centres + rng.uniform(-NEAR_SCREEN, NEAR_SCREEN, centres.shape), lo, hi)
            got = np.concatenate([got, q[feasible(config, q)]])[:need]
        out.append(got)
    return np.concatenate(out)


def hall_labels(config: SystemConfig, count: int, seed: int, tilted: bool = False
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``count`` positions of ``config``'s hall (:func:`label_poses`), level, and with ``tilted``
    each that the surface can be turned at again with that attitude (module docstring): the
    positions, attitudes and ``R`` of every pose, the positions and the common random numbers
    both from ``seed``."""
    config.check()
    rng = np.random.default_rng([seed, 1])
    q = label_poses(config, count, rng)
    att = np.zeros_like(q)
    if tilted:
        facing, turned = turned_towards(holding(config, SAFE_MARGIN_DEG), q)
        q, att = np.concatenate([q, q[turned]]), np.concatenate([att, facing[turned]])
    return q, att, expected_optimised_rate(config, q, att, seed=seed)
