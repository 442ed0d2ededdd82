"""Demonstrations from many halls: the planning oracle's motion (and worse behaviours) as a DT dataset.

Lives here: :class:`DemonstrationConfig`, :func:`demonstrate` (the trajectories of a range of
generated halls, a job of the study) and :func:`collect_demonstrations` (every hall, one
Minari dataset). Not here: the oracle and the plan (:mod:`uavris.agents.oracle`), the dataset
format (:mod:`uavris.agents.dt.dataset`), the halls (:class:`uavris.layouts.LayoutGenerator`).

Why: an expert per hall (PPO imitating the oracle) costs minutes of training each and cannot
scale to thousands of halls; the planning oracle, which those experts imitate, costs one plan
per hall (docs/model.md section 19). A demonstration is an episode of the oracle's motion in
a generated training hall with the optimiser's phases, recorded as the deployment track's DT
reads it (the 6 motion entries; phase control "optimizer"), with the hall's devices and start
in the episode's metadata (so Minari's ``recover_environment`` plus the episode's layout
rebuild its environment: :func:`uavris.agents.dt.dataset.episode_environment`).

Quality (``DemonstrationConfig.quality``):

- ``"oracle"``: the oracle's motion only (demonstrations of one quality: a DT and behaviour
  cloning learn the same thing from them);
- ``"mixed"``: in every hall, on the same seeded episodes, the oracle, the oracle's plan of
  another hall flown here (:class:`uavris.agents.oracle.policy.PlannedFlight`), hovering at
  the start, and the oracle's motion with Gaussian noise (``noise`` on every motion entry),
  each with its true returns: the dataset on which return conditioning can matter.

Plans: the teacher (:data:`~uavris.agents.oracle.planner.TEACHER`: the planner without the
global stage that makes the yardstick and without the front margin the yardstick keeps; its
candidates ranked with ``R``, its pattern search on the cheap estimate) chooses each hall's
target, 4.1x cheaper than the same planner searching with ``R`` for plans worth 0.19% less on
average, 1.26% in the worst of 96 halls (docs/timings.md): a demonstration is training data,
not a reference, and the plan was most of a demonstration's cost (``exact_plans`` restores the
search with ``R``, the teacher before 0.4.0,
:data:`~uavris.agents.oracle.planner.EXACT_TEACHER`).

Value labels (``value_labels``, the deployment track's): the level poses each hall's plan
valued with ``R`` itself (the start and the screened candidates, and with exact plans the
level poses of the pattern search): places near the hall's best ones, where a learned value
of a pose must rank well (:mod:`uavris.agents.place`), at no cost beyond the plan.

Episode seeds: hall ``j``'s episodes are ``seed + j * episodes + i`` (``seed`` the collection
base, never an evaluation seed), the same for every behaviour of a hall.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Sequence, get_args

import numpy as np
from numpy.typing import NDArray

from uavris.agents.dt.dataset import DATASET_NAMESPACE, check_dataset_target, write_dataset
from uavris.agents.dt.trajectories import Trajectory, record_episodes
from uavris.agents.oracle.planner import EXACT_TEACHER, TEACHER, PlanSettings
from uavris.agents.oracle.policy import PlannedFlight, PlanningOracle
from uavris.agents.policy import Privileged
from uavris.config import DictConfig, SystemConfig
from uavris.env.simulator import BatchedSimulator
from uavris.errors import ConfigError
from uavris.experiments.display.progress import progress_bar
from uavris.experiments.display.tables import counted
from uavris.layouts import Layout, LayoutGenerator
from uavris.presets import COLLECT_SEED

Quality = Literal["oracle", "mixed"]
QUALITIES: tuple[str, ...] = get_args(Quality)
BEHAVIOURS: dict[str, tuple[str, ...]] = {"oracle": ("oracle",),
                                          "mixed": ("oracle", "other-plan", "hover", "noisy-oracle")}
MAX_HALLS = 100_000  # a typo's bound: beyond it a run would not fit memory or a day


@dataclass(frozen=True)
class DemonstrationConfig(DictConfig):
    """What a demonstration dataset holds (dumped with every dataset stage)."""

    halls: int  # generated training halls layout-train-0 .. halls-1
    episodes: int = 2  # episodes per hall (and per behaviour)
    quality: Quality = "oracle"  # oracle, or mixed (oracle, another hall's plan, hovering, noisy oracle)
    noise: float = 0.3  # std of the noise on the noisy oracle's motion entries (in [-1, 1] units)
    exact_plans: bool = False  # the teacher's pattern search with R (EXACT_TEACHER); False: TEACHER, 4.1x cheaper
    value_labels: bool = False  # the level poses the plans valued with R, beside each part (module docstring)
    layout_seed: int = 0  # seed of the layout generator
    seed: int = COLLECT_SEED  # first episode seed
    system: SystemConfig = dataclasses.field(default_factory=lambda: SystemConfig(observe_devices=True))

    def __post_init__(self) -> None:
        for name, top in (("halls", MAX_HALLS), ("episodes", 10_000)):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or not 1 <= v <= top:
                raise ConfigError(f"DemonstrationConfig.{name} must be an integer in [1, {top}], got {v!r}")
        if self.quality not in QUALITIES:
            raise ConfigError(f"DemonstrationConfig.quality must be one of {', '.join(QUALITIES)}, "
                              f"got {self.quality!r}")
        if not (np.isfinite(self.noise) and self.noise >= 0):
            raise ConfigError(f"DemonstrationConfig.noise must be a finite number >= 0, got {self.noise!r}")
        for name in ("layout_seed", "seed"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 0:
                raise ConfigError(f"DemonstrationConfig.{name} must be an integer >= 0, got {getattr(self, name)!r}")
        if not self.system.observe_devices:
            object.__setattr__(self, "system", self.system.replace(observe_devices=True))

    @property
    def behaviours(self) -> tuple[str, ...]:
        return BEHAVIOURS[self.quality]

    @property
    def teacher(self) -> PlanSettings:
        """The planner's settings of its plans (module docstring)."""
        return EXACT_TEACHER if self.exact_plans else TEACHER

    def layouts(self, first: int = 0, count: int | None = None) -> list[Layout]:
        """Training halls ``first .. first + count - 1`` (default: to the last)."""
        count = self.halls - first if count is None else count
        gen = LayoutGenerator(devices=self.system.num_users, seed=self.layout_seed)
        return [gen.layout("train", j, self.system) for j in range(first, first + count)]


def _noisy(oracle: PlanningOracle, sigma: float, rng: np.random.Generator) -> Privileged:
    def act(obs: NDArray[np.float32], sim: BatchedSimulator) -> NDArray[np.float32]:
        motion = oracle.motion_action(sim)
        return np.clip(motion + rng.normal(0.0, sigma, motion.shape), -1.0, 1.0).astype(np.float32)
    return Privileged(act)


def demonstrate(cfg: DemonstrationConfig, first: int = 0, count: int | None = None,
                on_hall: Any = None, labels: dict[str, list[NDArray]] | None = None,
                queries: dict[str, int] | None = None) -> list[Trajectory]:
    """The demonstrations of halls ``first .. first + count - 1`` (module docstring), hall by
    hall, behaviour by behaviour; ``on_hall()`` is called after each hall (progress). With
    ``labels`` (a dict of lists), the level poses its plan of each hall valued with ``R`` are
    added to it (users, position, rate, hall). ``queries`` gets ``poses_valued``: the model
    queries behind the plans (poses valued with the optimiser), which the claims count beside
    the environment interactions."""
    layouts = cfg.layouts(first, count)
    oracle = PlanningOracle(settings=cfg.teacher)
    resolved = [layout.resolve(cfg.system) for layout in layouts]
    out: list[Trajectory] = []
    for i, (system, where) in enumerate(resolved):
        j = first + i
        seeds = cfg.seed + j * cfg.episodes + np.arange(cfg.episodes)
        target = oracle.plan(system, where.start).target  # each demonstration records where it flew to
        for behaviour in cfg.behaviours:
            goal = target
            if behaviour == "oracle":
                policy: Any = Privileged(lambda obs, sim: oracle.motion_action(sim))
            elif behaviour == "hover":
                policy, goal = Privileged(lambda obs, sim: np.zeros((sim.num_envs, 6), dtype=np.float32)), where.start
            elif behaviour == "noisy-oracle":
                policy = _noisy(oracle, cfg.noise, np.random.default_rng([cfg.seed, j]))
            else:  # another hall's plan, flown here: the next hall of the range (wrapping)
                other_system, other_where = resolved[(i + 1) % len(resolved)]
                if len(resolved) == 1:  # a range of one hall: the next hall of the generator
                    other_system, other_where = cfg.layouts(j + 1, 1)[0].resolve(cfg.system)
                policy = PlannedFlight(oracle.plan(other_system, other_where.start))
                goal = policy.plan.target
            out.extend(record_episodes(policy, system, where, seeds, expert=behaviour, expert_algo="oracle",
                                       phase_control="optimizer", goal=goal))
        if labels is not None:
            poses, rates = oracle.valued_poses(system)
            level = np.all(poses[:, 3:] == 0.0, axis=1)
            labels.setdefault("users", []).append(np.broadcast_to(np.asarray(system.users),
                                                                  (int(level.sum()), system.num_users, 3)))
            labels.setdefault("position", []).append(poses[level, :3])
            labels.setdefault("rate", []).append(rates[level])
            labels.setdefault("hall", []).append(np.array([layouts[i].name] * int(level.sum())))
        if on_hall is not None:
            on_hall()
    if queries is not None:
        queries["poses_valued"] = int(sum(plan.poses_valued for plan in oracle.plans.values()))
    return out


def collect_demonstrations(cfg: DemonstrationConfig, out: str | Path, *, force: bool = False,
                           progress: bool = True, trajectories: Sequence[Trajectory] | None = None) -> Path:
    """Every hall's demonstrations (or the given ``trajectories``, made by :func:`demonstrate`
    in parts) as one Minari dataset at ``out``; returns its path."""
    out = Path(out)
    check_dataset_target(out, force)  # before the rollouts, not only when writing
    if trajectories is None:
        bar = progress_bar(cfg.halls, "demonstrations", "hall", progress)
        try:
            trajectories = demonstrate(cfg, on_hall=lambda: bar.update(1))
        finally:
            bar.close()
    description = (f"uavris demonstrations: {', '.join(cfg.behaviours)} in {counted(cfg.halls, 'generated hall')} x "
                   f"{counted(cfg.episodes, 'episode')} (layout seed {cfg.layout_seed})")
    return write_dataset(out, list(trajectories), cfg.system, description=description, force=force,
                         phase_control="optimizer", namespace=DATASET_NAMESPACE)
