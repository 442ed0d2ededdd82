"""Experts initialised from the oracle's demonstrations: behaviour cloning with DAgger.

Lives here: :class:`ImitationConfig` and :func:`imitate`, which fits an SB3 PPO policy
acting on the 6 motion entries (the hybrid action of :mod:`uavris.env.wrappers`; the phase
optimiser sets the phases) to the planning oracle's motion. Not here: the run directory,
checkpoints and the RL that may follow (:mod:`uavris.experiments.training.train_expert`).

Why (docs/study.md, "Strong track"): end-to-end RL does not learn the 16 phases at any
budget we could afford, and RL on the motion alone needs 100-150k env steps per scenario
to pass hovering with the optimiser's phases, by little. The planning oracle moves well
and its motion depends only on what the observation holds (position, velocity, attitude)
given its plan, so a policy of the observation can learn it.

Method. Round 0 rolls the teacher (the planning oracle) out on ``episodes`` seeded
episodes of the run's scenario and records (observation, teacher's motion action); every
later round rolls the current student out (deterministic) and labels the states it visits
with the teacher's action (DAgger, Ross, Gordon, Bagnell 2011), so the student learns to
recover from its own mistakes. After each round the student is fitted to all the data so
far: ``epochs`` passes of mean-squared error between its deterministic action (the mean
of PPO's Gaussian) and the label, Adam. The rollouts need no phase optimisation: the
phases do not change the states the UAV visits (only the rewards), so they are left at
the zero action's. Episode seeds: ``4,000,000 + 10,000 seed + round x episodes + j``,
never an evaluation, collection or fine-tuning seed. After imitation PPO's exploration
standard deviation is set to ``action_std`` for the RL that may follow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from uavris.agents.oracle import PlanningOracle
from uavris.agents.policy import Privileged
from uavris.config import ConfigError, DictConfig, Scenario, SystemConfig, unkeyed
from uavris.env.rollout import rollout
from uavris.env.simulator import BatchedSimulator
from uavris.presets import IMITATION_SEED

TEACHERS: tuple[str, ...] = ("oracle",)


@dataclass(frozen=True)
class ImitationConfig(DictConfig):
    """Behaviour cloning with DAgger from a teacher (see the module docstring)."""

    teacher: str = "oracle"  # whose actions the student imitates (the oracle, the one teacher there is)
    rounds: int = 6  # round 0: the teacher's own episodes; rounds 1..: DAgger
    episodes: int = 32  # episodes per round
    epochs: int = 30  # passes over all data after each round
    batch_size: int = 256  # transitions per gradient step of behaviour cloning
    learning_rate: float = 1e-3  # Adam's step size in behaviour cloning
    action_std: float = 0.2  # PPO's exploration standard deviation afterwards
    # evaluate the student after every round (its learning curve, not one point); keyed only when set
    evaluate_rounds: bool = unkeyed(False)

    def __post_init__(self) -> None:
        if self.teacher not in TEACHERS:
            raise ConfigError(f"ImitationConfig.teacher must be one of {', '.join(TEACHERS)}, got {self.teacher!r}")
        for name in ("rounds", "episodes", "epochs", "batch_size"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ConfigError(f"ImitationConfig.{name} must be an integer >= 1, got {v!r}")
        for name in ("learning_rate", "action_std"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ConfigError(f"ImitationConfig.{name} must be a finite number > 0, got {v!r}")


def _rollout(config: SystemConfig, scenario: str | Scenario, seeds: NDArray[np.int64], teacher: Any,
             student: Any | None) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """States visited by the teacher (``student`` None) or the student, with the teacher's labels."""
    states: list[NDArray[np.float32]] = []
    labels: list[NDArray[np.float32]] = []

    def label(sim: BatchedSimulator, obs: NDArray[np.float32], executed: NDArray, alive: NDArray[np.bool_]) -> None:
        states.append(obs[alive])
        labels.append(teacher.motion_action(sim)[alive])

    def full(motion: NDArray[np.float32]) -> NDArray[np.float32]:
        action = np.zeros((len(motion), config.action_dim), dtype=np.float32)  # phases: the zero action's
        action[:, :3], action[:, -3:] = motion[:, :3], motion[:, 3:]
        return action

    actor = (Privileged(lambda obs, sim: full(teacher.motion_action(sim))) if student is None
             else (lambda obs: full(student(obs))))
    rollout(actor, config, scenario, seeds, on_slot=label)
    return np.concatenate(states), np.concatenate(labels)


def imitate(model: Any, config: SystemConfig, scenario: str | Scenario, cfg: ImitationConfig, seed: int,
            on_round: Any = None) -> list[dict[str, float]]:
    """Fit ``model`` (SB3 PPO on the motion action) to the teacher; returns one log row per round.

    ``on_round(row)`` is called after every round (progress, TensorBoard).
    """
    import torch

    policy = model.policy
    if not hasattr(policy, "log_std"):
        raise ConfigError("imitation is implemented for PPO (a Gaussian policy with a state-independent std)")
    teacher = PlanningOracle(seed=0)
    device = policy.device

    def student(obs: NDArray[np.float32]) -> NDArray[np.float32]:
        with torch.no_grad():
            out = policy._predict(torch.as_tensor(obs, device=device), deterministic=True)
        return np.clip(out.cpu().numpy(), -1.0, 1.0)

    gen = torch.Generator().manual_seed(seed)
    opt = torch.optim.Adam(policy.parameters(), lr=cfg.learning_rate)
    states: list[NDArray[np.float32]] = []
    labels: list[NDArray[np.float32]] = []
    log = []
    base = IMITATION_SEED + 10_000 * seed
    for r in range(cfg.rounds):
        seeds = base + r * cfg.episodes + np.arange(cfg.episodes)
        s, y = _rollout(config, scenario, seeds, teacher, None if r == 0 else student)
        if r > 0:  # how far the student's own motion is from the teacher's on the states it visits
            gap = float(np.mean((student(s) - y) ** 2))
        states.append(s)
        labels.append(y)
        x_all = torch.as_tensor(np.concatenate(states), device=device)
        y_all = torch.as_tensor(np.concatenate(labels), device=device)
        policy.train()
        losses = []
        for _ in range(cfg.epochs):
            order = torch.randperm(len(x_all), generator=gen)
            for start in range(0, len(order), cfg.batch_size):
                idx = order[start:start + cfg.batch_size]
                pred = policy._predict(x_all[idx], deterministic=True)
                loss = torch.mean((pred - y_all[idx]) ** 2)
                opt.zero_grad()
                loss.backward()
                opt.step()
                losses.append(loss.item())
        policy.eval()
        last_epoch = losses[-max(1, len(losses) // cfg.epochs):]
        row = {"round": r, "samples": int(len(x_all)), "loss": float(np.mean(last_epoch)),
               "student_gap": gap if r > 0 else float("nan")}
        log.append(row)
        if on_round is not None:
            on_round(row)
    with torch.no_grad():
        policy.log_std.fill_(math.log(cfg.action_std))
    return log
