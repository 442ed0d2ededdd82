"""Batched, seeded evaluation of any policy: the average sum rate of every episode.

Lives here: :func:`evaluate` and :class:`EpisodeResults`. Not here: the rollout loop
(:func:`uavris.env.rollout.rollout`) and the interval statistics (:mod:`uavris.stats`).

Evaluation episode j with seed s is the episode a single environment produces after
``reset(seed=s + j)``, so every policy is scored on the same channel and pairing draws.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from uavris import stats
from uavris.agents.policy import fit_policy
from uavris.config import Scenario, SystemConfig
from uavris.env.rollout import SlotHook, StepHook, rollout
from uavris.errors import ConfigError


@dataclass(frozen=True)
class EpisodeResults:
    """Per-episode outcomes of an evaluation."""

    avg_sum_rate: NDArray[np.float64]  # mean of r(t) over the episode's slots, bps/Hz
    episode_return: NDArray[np.float64]  # sum of r(t)
    length: NDArray[np.int64]
    energy_used: NDArray[np.float64]
    seeds: NDArray[np.int64]

    def summary(self, confidence: float = 0.95) -> dict[str, float]:
        """Mean with its Student-t interval over episodes, std, IQM, mean length and energy."""
        x = self.avg_sum_rate
        low, high = stats.t_interval(x, confidence)
        return {"episodes": int(len(x)), "mean": float(np.mean(x)), "ci_low": low, "ci_high": high,
                "std": float(np.std(x, ddof=1)) if len(x) > 1 else 0.0,
                "iqm": float(stats.iqm(x)), "mean_length": float(np.mean(self.length)),
                "mean_energy_j": float(np.mean(self.energy_used))}


MAX_EPISODES = 100_000  # a typo's bound (a recorded batch of 10^9 episodes would not fit memory)


def check_episodes(episodes: int, seed: int, prefix: str = "") -> None:
    """Episodes ``seed .. seed + episodes - 1`` must be at least one and at most
    :data:`MAX_EPISODES`, with non-negative seeds; the message names them with ``prefix``
    ("--" where they are command-line flags).

    Callers that do work before :func:`evaluate` (load a model, open a progress bar, print a
    header) call it first, so bad input fails before anything is shown or loaded.
    """
    if not 1 <= episodes <= MAX_EPISODES:
        raise ConfigError(f"{prefix}episodes must be in [1, {MAX_EPISODES:,}], got {episodes}")
    if seed < 0:
        raise ConfigError(f"{prefix}seed must be >= 0, got {seed}")


def evaluate(policy: Any, config: SystemConfig, scenario: str | Scenario, episodes: int, seed: int,
             batch_size: int = 256, phase_control: str | None = None,
             on_slot: SlotHook | None = None, on_step: StepHook | None = None) -> EpisodeResults:
    """Run ``episodes`` episodes (seeds ``seed .. seed + episodes - 1``) in batches of ``batch_size``.

    ``phase_control="optimizer"`` executes the policy's motion with the optimiser's phases
    (default: the policy's own ``phase_control``); ``on_slot`` is passed to
    :func:`~uavris.env.rollout.rollout` (progress bars use it), and ``on_step`` (a slot's
    reward: :class:`uavris.experiments.tools.trajectory.SlotLog`). With hooks, keep
    ``episodes <= batch_size``: the rows of a batch are its episodes.
    """
    check_episodes(episodes, seed)
    policy = fit_policy(policy, config)
    parts = [rollout(policy, config, scenario, seed + start + np.arange(min(batch_size, episodes - start)),
                     phase_control=phase_control, on_slot=on_slot, on_step=on_step)
             for start in range(0, episodes, batch_size)]
    returns = np.concatenate([p.returns for p in parts])
    length = np.concatenate([p.lengths for p in parts])
    energy = np.concatenate([p.energy_used for p in parts])
    return EpisodeResults(returns / length, returns, length.astype(np.int64), energy, seed + np.arange(episodes))
