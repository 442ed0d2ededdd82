"""Batched, seeded evaluation of any batch policy.

Evaluation episode j with seed s is the episode a single environment produces after
``reset(seed=s + j)``, so every policy is scored on the same channel and pairing draws.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from uavris.agents.baselines import BatchPolicy
from uavris.config import Scenario, SystemConfig
from uavris.env.simulator import BatchedSimulator


@dataclass(frozen=True)
class EpisodeResults:
    """Per-episode outcomes of an evaluation."""

    avg_sum_rate: NDArray[np.float64]  # mean of r(t) over the episode's slots, bps/Hz
    episode_return: NDArray[np.float64]  # sum of r(t)
    length: NDArray[np.int64]
    energy_used: NDArray[np.float64]
    seeds: NDArray[np.int64]

    def summary(self, confidence: float = 0.95) -> dict[str, float]:
        x = self.avg_sum_rate
        mean = float(np.mean(x))
        if len(x) > 1:
            half = float(stats.t.ppf(0.5 + confidence / 2, len(x) - 1) * stats.sem(x))
        else:
            half = float("nan")
        return {"episodes": int(len(x)), "mean": mean, "ci_low": mean - half, "ci_high": mean + half,
                "std": float(np.std(x, ddof=1)) if len(x) > 1 else 0.0,
                "iqm": float(stats.trim_mean(x, 0.25)), "mean_length": float(np.mean(self.length)),
                "mean_energy_j": float(np.mean(self.energy_used))}


def evaluate(policy: BatchPolicy, config: SystemConfig, scenario: str | Scenario, episodes: int, seed: int,
             batch_size: int = 256) -> EpisodeResults:
    """Run ``episodes`` episodes (seeds ``seed .. seed + episodes - 1``) in batches."""
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    out = []
    for start in range(0, episodes, batch_size):
        n = min(batch_size, episodes - start)
        out.append(_evaluate_batch(policy, config, scenario, seed + start + np.arange(n)))
    cat = [np.concatenate(parts) for parts in zip(*out)]
    return EpisodeResults(cat[0] / cat[1], cat[0], cat[1].astype(np.int64), cat[2], seed + np.arange(episodes))


def _evaluate_batch(policy: BatchPolicy, config: SystemConfig, scenario: str | Scenario,
                    seeds: NDArray[np.int64]) -> tuple[NDArray, NDArray, NDArray]:
    sim = BatchedSimulator(config, scenario, len(seeds))
    sim.seed(seeds)
    sim.reset()
    total = np.zeros(len(seeds))
    length = np.zeros(len(seeds))
    energy = np.zeros(len(seeds))
    alive = np.ones(len(seeds), dtype=bool)
    while alive.any():
        reward, terminated, truncated, _ = sim.step(np.asarray(policy(sim.observe(), sim)))
        total += np.where(alive, reward, 0.0)
        length += alive
        energy = np.where(alive, sim.energy, energy)
        alive &= ~(terminated | truncated)
    return total, length, energy
