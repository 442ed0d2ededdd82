"""Expert trajectories for the Decision Transformer, and the statistics the model takes from them.

Lives here: :class:`Trajectory` (paper eq. 14), returns-to-go (eq. 15), the elite selection
of fine-tuning (eq. 18 and its paired variant), the recording of episodes and the state
normalisation. Not here: the Minari files (:mod:`.dataset`), the context windows the model
trains on and the training itself (:mod:`.training`).

- :func:`record_episodes` rolls any policy out on seeded episodes with the one rollout loop
  (:func:`uavris.env.rollout.rollout`) and keeps every trajectory: the observations S_t
  (plus the final one), the actions actually executed (clipped to [-1, 1]; the 6 motion
  entries under the optimiser) and the rewards.
- :func:`returns_to_go` is R_hat_t = sum_{t' >= t} r(t'), computed from the stored rewards
  (never stored itself, so relabelling is automatic).

Normalisation (:func:`normalisation_from`): per-component state mean and standard deviation
over all stored states, the standard deviation floored at 0.1 (observation components are
of order 1 by construction; the floor keeps a component the experts barely vary, such as
a level attitude, from being blown up when it does vary in a new scenario), and the return
scale = the largest episode return, so that R_hat / scale lies in [0, 1] on the data.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal, Sequence, get_args

import numpy as np
from numpy.typing import NDArray

from uavris.config import Scenario, SystemConfig, get_scenario
from uavris.env.rollout import rollout
from uavris.errors import DatasetError

STATE_STD_FLOOR = 0.1


@dataclass(frozen=True, eq=False)
class Trajectory:
    """One episode tau (paper eq. 14) with where it came from."""

    observations: NDArray[np.float32]  # (T + 1, obs_dim): S_1 .. S_T and the final observation
    actions: NDArray[np.float32]  # (T, act_dim), as executed (clipped to [-1, 1])
    rewards: NDArray[np.float64]  # (T,) r(t), bps/Hz
    terminated: bool  # energy budget exhausted
    truncated: bool  # horizon reached
    scenario: str
    seed: int
    expert: str = ""
    expert_algo: str = ""
    start: tuple[float, ...] | None = None  # the UAV's start (None: a trajectory made without a hall)
    users: tuple[tuple[float, ...], ...] | None = None  # the devices of the episode's layout (likewise)
    goal: tuple[float, ...] | None = None  # where it flew to (a demonstration's plan target; None: not told)

    @property
    def length(self) -> int:
        return int(self.rewards.shape[0])

    @property
    def episode_return(self) -> float:
        """sum_t r(t), the quantity eq. (18) ranks by."""
        return float(self.rewards.sum())


def returns_to_go(rewards: NDArray[np.floating]) -> NDArray[np.float64]:
    """R_hat_t = sum_{t' >= t} r(t') (paper eq. 15, undiscounted)."""
    r = np.asarray(rewards, dtype=np.float64)
    return np.cumsum(r[::-1])[::-1].copy()


EliteRule = Literal["return", "paired"]  # fine-tuning's elite selection (--selection)
ELITE_RULES: tuple[str, ...] = get_args(EliteRule)


def select_elites(trajectories: Sequence[Trajectory], k: int, rule: str = "return") -> list[Trajectory]:
    """The K elites, best first; ties keep collection order.

    ``rule="return"``: the K largest returns (paper eq. 18). ``rule="paired"``: the K largest
    returns relative to the mean return of the candidates with the same episode seed.
    Episodes with the same seed share every random draw (channels, pairings: common random
    numbers), so this difference measures what the actions did, not the luck of the draw
    (docs/model.md, departures).
    """
    if not 1 <= k <= len(trajectories):
        raise ValueError(f"k must be in [1, {len(trajectories)}], got {k}")
    if rule not in ELITE_RULES:
        raise ValueError(f"unknown elite rule {rule!r}; choose one of {', '.join(ELITE_RULES)}")
    score = np.array([tr.episode_return for tr in trajectories])
    if rule == "paired":
        seeds = np.array([tr.seed for tr in trajectories])
        for s in np.unique(seeds):
            group = seeds == s
            score[group] -= score[group].mean()
    order = sorted(range(len(trajectories)), key=lambda i: -score[i])
    return [trajectories[i] for i in order[:k]]


# ------------------------------------------------------------------------------ collection
def record_episodes(policy: Any, config: SystemConfig, scenario: str | Scenario,
                    seeds: Sequence[int] | NDArray[np.integer], *, expert: str = "", expert_algo: str = "",
                    phase_control: str | None = None, batch_size: int = 256,
                    goal: NDArray | Sequence[float] | None = None) -> list[Trajectory]:
    """Roll ``policy`` out on one episode per seed, ``batch_size`` episodes per simulator.

    Episode j is the one a single environment produces after ``reset(seed=seeds[j])``, as in
    :func:`uavris.agents.evaluation.evaluate`. Returns the trajectories in seed order. With
    ``phase_control="optimizer"`` (default: the policy's own) the trajectories keep only the
    6 motion entries of the executed actions (the phases were the optimiser's, a function
    of the state). ``goal`` (``(3,)`` or one per seed, m) is where the episodes flew to, recorded
    with them (a goal-conditioned DT trains on it).
    """
    seeds = np.asarray(seeds, dtype=np.int64)
    goals = None if goal is None else np.broadcast_to(np.asarray(goal, dtype=np.float64), (len(seeds), 3))
    out: list[Trajectory] = []
    for start in range(0, len(seeds), batch_size):
        b = rollout(policy, config, scenario, seeds[start:start + batch_size], phase_control=phase_control, record=True)
        where = get_scenario(scenario)
        out.extend(Trajectory(b.observations[i, :b.lengths[i] + 1].copy(), b.actions[i, :b.lengths[i]].copy(),
                              b.rewards[i, :b.lengths[i]].copy(), bool(b.terminated[i]), not bool(b.terminated[i]),
                              where.name, int(b.seeds[i]), expert, expert_algo, where.start, config.users,
                              None if goals is None else tuple(float(c) for c in goals[start + i]))
                   for i in range(len(b.seeds)))
    return out


# ------------------------------------------------------------------------------ normalisation
@dataclass(frozen=True)
class Normalisation:
    """State mean/std and return scale the model is trained and deployed with."""

    state_mean: NDArray[np.float64]
    state_std: NDArray[np.float64]
    return_scale: float


def normalisation_from(trajectories: Sequence[Trajectory], std_floor: float = STATE_STD_FLOOR) -> Normalisation:
    """Statistics of the states S_1..S_T of ``trajectories`` (see the module docstring)."""
    if not trajectories:
        raise DatasetError("no trajectories to compute normalisation statistics from")
    states = np.concatenate([tr.observations[:-1] for tr in trajectories]).astype(np.float64)
    returns = np.array([tr.episode_return for tr in trajectories])
    scale = float(returns.max()) if returns.max() > 0 else 1.0
    return Normalisation(states.mean(axis=0), np.maximum(states.std(axis=0), std_floor), scale)


def default_target_return(trajectories: Sequence[Trajectory], quantile: float = 0.9) -> float:
    """The documented default target return: the ``quantile`` of the episode returns."""
    return float(np.quantile([tr.episode_return for tr in trajectories], quantile))
