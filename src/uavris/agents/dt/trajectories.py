"""Expert trajectories for the Decision Transformer, as the model trains on them.

Lives here: :class:`Trajectory` (paper eq. 14), returns-to-go (eq. 15), the elite selection
of fine-tuning (eq. 18 and its paired variant), the recording of episodes, the state
normalisation and the context windows of L_OFF (eq. 16) and L_FT (eq. 19), of one set or of
sets of several device counts (:class:`MixedWindows`). Not here: the
Minari files (:mod:`.dataset`).

- :func:`record_episodes` rolls any policy out on seeded episodes with the one rollout loop
  (:func:`uavris.env.rollout.rollout`) and keeps every trajectory: the observations S_t
  (plus the final one), the actions actually executed (clipped to [-1, 1]; the 6 motion
  entries under the optimiser) and the rewards.
- :func:`returns_to_go` is R_hat_t = sum_{t' >= t} r(t'), computed from the stored rewards
  (never stored itself, so relabelling is automatic).
- :class:`TrainingWindows` samples context windows.

Normalisation (:func:`normalisation_from`): per-component state mean and standard deviation
over all stored states, the standard deviation floored at 0.1 (observation components are
of order 1 by construction; the floor keeps a component the experts barely vary, such as
a level attitude, from being blown up when it does vary in a new scenario), and the return
scale = the largest episode return, so that R_hat / scale lies in [0, 1] on the data.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, Sequence, get_args

import numpy as np
import torch
from numpy.typing import NDArray

from uavris.config import Scenario, SystemConfig, get_scenario
from uavris.env.rollout import rollout
from uavris.errors import DatasetError

if TYPE_CHECKING:
    from uavris.agents.dt.config import DTConfig

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
    start: tuple[float, ...] | None = None  # the UAV's start (None: datasets from before it was recorded)
    users: tuple[tuple[float, ...], ...] | None = None  # the devices of the episode's layout (likewise)

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
                    phase_control: str | None = None, batch_size: int = 256) -> list[Trajectory]:
    """Roll ``policy`` out on one episode per seed, ``batch_size`` episodes per simulator.

    Episode j is the one a single environment produces after ``reset(seed=seeds[j])``, as in
    :func:`uavris.agents.evaluation.evaluate`. Returns the trajectories in seed order. With
    ``phase_control="optimizer"`` (default: the policy's own) the trajectories keep only the
    6 motion entries of the executed actions (the phases were the optimiser's, a function
    of the state).
    """
    seeds = np.asarray(seeds, dtype=np.int64)
    out: list[Trajectory] = []
    for start in range(0, len(seeds), batch_size):
        b = rollout(policy, config, scenario, seeds[start:start + batch_size], phase_control=phase_control, record=True)
        where = get_scenario(scenario)
        out.extend(Trajectory(b.observations[i, :b.lengths[i] + 1].copy(), b.actions[i, :b.lengths[i]].copy(),
                              b.rewards[i, :b.lengths[i]].copy(), bool(b.terminated[i]), not bool(b.terminated[i]),
                              where.name, int(b.seeds[i]), expert, expert_algo, where.start, config.users)
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


# ------------------------------------------------------------------------------ training windows
class TrainingWindows:
    """All slots of a set of trajectories, ready to be cut into context windows.

    A window is the ``context`` slots ending at a slot chosen uniformly among all slots;
    near an episode's start it is left-padded, exactly as the history a deployed DT sees
    at that slot (:mod:`uavris.agents.dt.policy`). The loss covers every real slot of it.

    With ``whole_episodes`` (the banded DT, which reads episodes from slot 0) a sample is
    instead one whole episode chosen uniformly, left-padded to the longest episode.
    """

    def __init__(self, trajectories: Sequence[Trajectory], context: int, whole_episodes: bool = False) -> None:
        if not trajectories:
            raise DatasetError("no trajectories to train on")
        lengths = np.array([tr.length for tr in trajectories])
        self.whole_episodes = whole_episodes
        self.model_context = context
        self.context = int(lengths.max()) if whole_episodes else context
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        self.episode_end = starts + lengths - 1
        self.states = np.concatenate([tr.observations[:-1] for tr in trajectories]).astype(np.float32)
        self.actions = np.concatenate([tr.actions for tr in trajectories]).astype(np.float32)
        self.rtg = np.concatenate([returns_to_go(tr.rewards) for tr in trajectories]).astype(np.float32)
        self.timesteps = np.concatenate([np.arange(n) for n in lengths]).astype(np.int64)
        self.episode_start = np.repeat(starts, lengths)

    @classmethod
    def for_model(cls, trajectories: Sequence[Trajectory], model_config: DTConfig) -> TrainingWindows:
        """The samples a model of this :class:`~uavris.agents.dt.model.DTConfig` trains on."""
        return cls(trajectories, model_config.context, whole_episodes=model_config.attention == "banded")

    @property
    def num_slots(self) -> int:
        return int(self.rtg.shape[0])

    @property
    def samples_per_epoch(self) -> int:
        """Samples of one epoch: one window per slot, or, for whole episodes, ``context``
        draws per episode, so that an epoch predicts about as many actions either way (a
        window predicts ``context`` of them, an episode all of its slots)."""
        return len(self.episode_end) * self.model_context if self.whole_episodes else self.num_slots

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, torch.Tensor]:
        """``batch_size`` windows: rtg (B, K), states (B, K, S), actions (B, K, A),
        timesteps (B, K), valid (B, K); padded entries are zero."""
        if self.whole_episodes:
            ends = self.episode_end[rng.integers(0, len(self.episode_end), batch_size)]
        else:
            ends = rng.integers(0, self.num_slots, batch_size)
        pos = ends[:, None] + np.arange(1 - self.context, 1)
        valid = pos >= self.episode_start[ends][:, None]
        idx = np.where(valid, pos, ends[:, None])
        pad = ~valid
        states, actions = self.states[idx], self.actions[idx]
        rtg, steps = self.rtg[idx], self.timesteps[idx]
        states[pad], actions[pad], rtg[pad], steps[pad] = 0.0, 0.0, 0.0, 0
        return {"returns_to_go": torch.from_numpy(rtg), "states": torch.from_numpy(states),
                "actions": torch.from_numpy(actions), "timesteps": torch.from_numpy(steps),
                "valid": torch.from_numpy(valid)}


class MixedWindows:
    """The windows of several sets of trajectories whose observations differ in width (halls
    of different numbers of devices, read by one device-set encoder): each batch is drawn
    from one set, chosen with probability proportional to its slots, so every slot is as
    likely to be trained on as in one set, and a batch stacks observations of one width."""

    def __init__(self, parts: Sequence[TrainingWindows]) -> None:
        if not parts:
            raise DatasetError("no trajectories to train on")
        self.parts = list(parts)
        slots = np.array([p.num_slots for p in self.parts], dtype=np.float64)
        self._weights = slots / slots.sum()

    @property
    def num_slots(self) -> int:
        return sum(p.num_slots for p in self.parts)

    @property
    def samples_per_epoch(self) -> int:
        return sum(p.samples_per_epoch for p in self.parts)

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, torch.Tensor]:
        """``batch_size`` windows of one set (:meth:`TrainingWindows.sample`)."""
        return self.parts[int(rng.choice(len(self.parts), p=self._weights))].sample(batch_size, rng)
