"""Collect (paper Sec. IV-B): the experts' deterministic trajectories as one Minari dataset.

Lives here: :func:`collect` and :func:`dataset_summary`. Not here: the dataset format
(:mod:`uavris.agents.dt.dataset`) and the rollouts (:func:`uavris.agents.dt.trajectories.record_episodes`).

Each expert run directory (``uavris train``) is rolled out
deterministically, without exploration noise, in its own scenario, ``N`` episodes per
expert, batched; all trajectories go into one Minari dataset (:mod:`uavris.agents.dt.dataset`)
with per-episode scenario, expert and seed. Episode seeds are ``seed + k N + j`` for expert
k (default seed 2,000,000: never an evaluation seed, which start at 1,000,000, and never a
fine-tuning seed, which start at 3,000,000).

The dataset id is ``uavris/<name>-vN``, ``<name>`` being the output directory's name
(:func:`uavris.agents.dt.dataset.dataset_id_for`), so ``minari.load_dataset(id)`` finds a
dataset written to ``$MINARI_DATASETS_PATH/uavris/<name>-vN``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uavris.agents.dt.dataset import DATASET_NAMESPACE, check_dataset_target, load_dataset, write_dataset
from uavris.agents.dt.trajectories import Trajectory, record_episodes
from uavris.agents.evaluation import MAX_EPISODES
from uavris.errors import UavrisError
from uavris.experiments.display.progress import progress_bar
from uavris.experiments.display.tables import counted
from uavris.experiments.training.train_expert import load_run_config, load_run_policy
from uavris.presets import COLLECT_SEED


def collect(experts: Sequence[str | Path], trajectories: int, out: str | Path, *, seed: int = COLLECT_SEED,
            force: bool = False, progress: bool = True, trust_pickle: bool = False) -> Path:
    """Roll every expert out ``trajectories`` times in its own scenario and write a dataset
    (an expert with SB3's archive only is loaded with ``trust_pickle`` only).

    The dataset records the environment spec (``uavris/UavRisD2D-v1``, the experts' system)
    for Minari's ``recover_environment``, in the first expert's scenario: a spec holds one
    scenario, each episode's own scenario is in its metadata.
    """
    if not experts:
        raise UavrisError("give at least one expert run directory (--experts RUN_DIR ...)")
    if not 1 <= trajectories <= MAX_EPISODES:
        raise UavrisError(f"--trajectories must be in [1, {MAX_EPISODES:,}], got {trajectories}")
    if seed < 0:
        raise UavrisError(f"--seed must be >= 0, got {seed}")
    out = Path(out)
    runs = []
    for run_dir in experts:
        run_dir = Path(run_dir)
        if not run_dir.is_dir():
            raise UavrisError(f"{run_dir} is not a directory (expected an expert run directory)")
        runs.append((run_dir, load_run_config(run_dir)))
    system = runs[0][1].system
    phase_control = runs[0][1].phase_control
    for run_dir, cfg in runs[1:]:
        if cfg.system.replace(users=system.users) != system or cfg.system.num_users != system.num_users:
            raise UavrisError(f"{run_dir} was trained with a different system configuration than {runs[0][0]}; "
                              "a dataset holds one system (its experts may differ only in where the devices are)")
        if cfg.phase_control != phase_control:
            raise UavrisError(f"{run_dir} sets the phases with phase control {cfg.phase_control!r}, {runs[0][0]} "
                              f"with {phase_control!r}; a dataset holds one action layout")
    check_dataset_target(out, force)  # before the rollouts, not only when writing
    bar = progress_bar(len(runs) * trajectories, "collect", "episode", progress)
    trajs: list[Trajectory] = []
    try:
        for k, (run_dir, cfg) in enumerate(runs):
            _, policy = load_run_policy(run_dir, trust_pickle=trust_pickle)
            seeds = seed + k * trajectories + np.arange(trajectories)
            for start in range(0, trajectories, 256):
                batch = record_episodes(policy, cfg.system, cfg.resolved_scenario, seeds[start:start + 256],
                                        expert=str(run_dir), expert_algo=cfg.algo, phase_control=phase_control)
                trajs.extend(batch)
                bar.update(len(batch))
    finally:
        bar.close()
    description = (f"uavris expert trajectories: {counted(len(runs), 'expert')} x "
                   f"{counted(trajectories, 'deterministic episode')} "
                   f"({', '.join(sorted({cfg.scenario for _, cfg in runs}))})")
    return write_dataset(out, trajs, system, description=description, force=force, phase_control=phase_control,
                         namespace=DATASET_NAMESPACE)


def dataset_summary(path: str | Path) -> dict[str, Any]:
    """Episodes, slots and mean average sum rate per scenario of a dataset."""
    ds = load_dataset(path)
    per = {}
    for scen in ds.scenarios:
        tr = [t for t in ds.trajectories if t.scenario == scen]
        per[scen] = {"episodes": len(tr), "avg_sum_rate": float(np.mean([t.episode_return / t.length for t in tr]))}
    return {"dataset_id": ds.dataset_id, "episodes": len(ds.trajectories), "slots": ds.num_slots, "scenarios": per}
