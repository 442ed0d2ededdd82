"""Evaluate a run directory or a baseline on seeded episodes and write CSV/JSON."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from uavris.agents.baselines import BASELINES
from uavris.agents.evaluation import EpisodeResults, evaluate
from uavris.config import SystemConfig, get_scenario
from uavris.experiments.io import UavrisError, write_csv, write_json
from uavris.agents.hybrid import check_phase_control, with_optimised_phases
from uavris.experiments.training import (
    configure_torch_threads,
    final_model_path,
    load_model,
    load_run_config,
    run_policy,
)

BASELINE_PREFIX = "baseline:"


def resolve_policy(target: str, seed: int) -> tuple[Any, SystemConfig, str | None, Path | None]:
    """(batch policy, system config, the run's own scenario, run directory) for a target."""
    if target.startswith(BASELINE_PREFIX):
        name = target[len(BASELINE_PREFIX):]
        if name not in BASELINES:
            raise UavrisError(f"unknown baseline {name!r}; choose one of {', '.join(BASELINES)}")
        return BASELINES[name](seed), SystemConfig(), None, None
    run_dir = Path(target)
    if not run_dir.is_dir():
        raise UavrisError(f"{run_dir} is not a directory (expected a run directory or baseline:NAME)")
    from uavris.experiments.dt_pipeline import dt_model_dir, load_dt_policy

    if dt_model_dir(run_dir) is not None:  # a Decision Transformer model or DT run directory
        policy, system, scenario = load_dt_policy(run_dir)
        return policy, system, scenario, run_dir
    cfg = load_run_config(run_dir)
    configure_torch_threads()
    model = load_model(final_model_path(run_dir), cfg.algo)
    return run_policy(model, cfg), cfg.system, cfg.scenario, run_dir


def write_results(res: EpisodeResults, summary: dict[str, Any], stem: Path) -> None:
    rows = zip(res.seeds.tolist(), res.avg_sum_rate.tolist(), res.episode_return.tolist(), res.length.tolist(),
               res.energy_used.tolist())
    write_csv(stem.with_suffix(".csv"), ("seed", "avg_sum_rate", "return", "length", "energy_j"), rows)
    write_json(stem.with_suffix(".json"), summary)


def evaluate_target(target: str, scenario: str | None, episodes: int, seed: int,
                    out: Path | None = None, phase_control: str | None = None) -> tuple[dict[str, Any], Path]:
    """Evaluate ``target``; ``phase_control="optimizer"`` replaces its phases by the optimiser's."""
    if episodes < 1:
        raise UavrisError(f"--episodes must be >= 1, got {episodes}")
    if phase_control is not None:
        check_phase_control(phase_control)
    policy, system, own_scenario, run_dir = resolve_policy(target, seed)
    if phase_control == "optimizer":
        policy = with_optimised_phases(policy)
    scenario = scenario or own_scenario
    if scenario is None:
        raise UavrisError("--scenario is required for a baseline or a pre-trained DT (it has no scenario of its own)")
    get_scenario(scenario).validate_for(system)
    res = evaluate(policy, system, scenario, episodes, seed)
    summary = {"target": target, "scenario": scenario, "seed": seed, "phase_control": phase_control or "as trained",
               **res.summary()}
    if out is None:
        base = run_dir if run_dir is not None else Path("runs/baselines") / target[len(BASELINE_PREFIX):]
        out = base / "eval"
    suffix = "-optimizer-phases" if phase_control == "optimizer" else ""
    stem = Path(out) / f"{scenario}-seed{seed}-n{episodes}{suffix}"
    write_results(res, summary, stem)
    return summary, stem.with_suffix(".json")
