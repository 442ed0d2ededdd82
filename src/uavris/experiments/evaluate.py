"""``uavris evaluate``: a run, a DT model, a reference or a user's policy on seeded episodes,
written as CSV and JSON.

Lives here: resolving what a target names (:func:`resolve_policy`) and writing its
per-episode results; a user's policy (``MODULE:NAME`` or ``FILE.py:NAME``,
:mod:`uavris.experiments.user_policy`) is scored with the zero action and the oracle beside
it on the same episodes. Not here: the evaluation itself (:func:`uavris.agents.evaluation.evaluate`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from uavris.agents.evaluation import EpisodeResults, check_episodes, evaluate
from uavris.agents.policy import check_policy_fits
from uavris.agents.references import ORACLE, REFERENCE_SEED, REFERENCES, ZERO_ACTION, reference_policy
from uavris.config import Scenario, SystemConfig, get_scenario
from uavris.env.rollout import policy_phase_control
from uavris.env.wrappers import check_phase_control
from uavris.errors import UavrisError
from uavris.experiments.dt_runs import dt_model_dir, dt_system, load_dt_policy
from uavris.experiments.jobs import configure_threads
from uavris.experiments.train_expert import load_run_config, load_run_policy
from uavris.experiments.user_policy import is_user_target, load_user_policy
from uavris.io import write_csv, write_json
from uavris.layouts import Layout, resolve_layout

BASELINE_PREFIX = "baseline:"


def reference_name(target: str) -> str | None:
    """The reference a target names (``NAME`` or ``baseline:NAME``), or None for a path.
    An existing directory is always a run, even if its name is a reference's."""
    name = target[len(BASELINE_PREFIX):] if target.startswith(BASELINE_PREFIX) else target
    if target.startswith(BASELINE_PREFIX) or (name in REFERENCES and not Path(target).is_dir()):
        if name not in REFERENCES:
            raise UavrisError(f"unknown baseline {name!r}; choose one of {', '.join(REFERENCES)}")
        return name
    return None


@dataclass(frozen=True)
class Target:
    """What ``uavris evaluate`` resolved a target to."""

    policy: Any  # batch policy
    system: SystemConfig
    scenario: Scenario | None  # the run's own (None: a reference or a pre-trained DT)
    run_dir: Path | None  # None for a reference


def target_system(target: str) -> SystemConfig:
    """The system a target was made for, read from its configuration only (no model is loaded):
    a run's, a DT checkpoint's, or the paper's for a reference. ``uavris evaluate`` uses it as
    the default that ``--system.*`` and ``--layout`` change."""
    if is_user_target(target) or reference_name(target) is not None:
        return SystemConfig()
    path = Path(target)
    if not path.is_dir():
        raise UavrisError(f"{path} is not a directory (expected a run directory, a model directory or one of the "
                          f"references {', '.join(REFERENCES)})")
    if dt_model_dir(path) is not None:
        return dt_system(path)
    return load_run_config(path).system


def resolve_policy(target: str, device: str = "cpu", system: SystemConfig | None = None) -> Target:
    """Resolve a run directory, DT model directory or reference name (a reference for ``system``,
    default the paper's).

    References use their own fixed seed (:data:`uavris.agents.references.REFERENCE_SEED`),
    so ``uavris evaluate oracle`` gives the numbers of the reports whatever episodes it is
    evaluated on.
    """
    if is_user_target(target):
        system = system or SystemConfig()
        return Target(load_user_policy(target, system), system, None, None)
    name = reference_name(target)
    if name is not None:
        system = system or SystemConfig()
        return Target(reference_policy(name, system, REFERENCE_SEED), system, None, None)
    run_dir = Path(target)
    target_system(target)  # a missing path or a foreign directory: one line before any loading
    if dt_model_dir(run_dir) is not None:  # a Decision Transformer model or DT run directory
        policy, system, scenario = load_dt_policy(run_dir, device=device)
        return Target(policy, system, scenario, run_dir)
    configure_threads()
    cfg, policy = load_run_policy(run_dir, device)
    return Target(policy, cfg.system, cfg.resolved_scenario, run_dir)


def write_results(res: EpisodeResults, summary: dict[str, Any], stem: Path) -> None:
    rows = zip(res.seeds.tolist(), res.avg_sum_rate.tolist(), res.episode_return.tolist(), res.length.tolist(),
               res.energy_used.tolist())
    write_csv(stem.with_suffix(".csv"), ("seed", "avg_sum_rate", "return", "length", "energy_j"), rows)
    write_json(stem.with_suffix(".json"), summary)


def evaluate_target(target: str, scenario: str | Scenario | None, episodes: int, seed: int,
                    out: Path | None = None, phase_control: str | None = None, device: str = "cpu",
                    progress: bool = False, system: SystemConfig | None = None,
                    layout: str | Layout | None = None, references: bool = True) -> tuple[dict[str, Any], Path]:
    """Evaluate ``target``; ``phase_control="optimizer"`` replaces its phases by the optimiser's.

    ``system`` replaces the target's own system (the CLI's ``--system.*``); ``layout`` (a
    :class:`~uavris.layouts.Layout` or what :func:`~uavris.layouts.resolve_layout` reads)
    puts it in another hall: the layout's devices, and its start unless ``scenario`` names
    one. With ``progress`` a bar counts the simulated slots (the optimiser and the oracle
    take milliseconds per slot, so a long evaluation is visibly alive). A user's policy gets the
    zero action and the oracle beside it (``references=False``: not)."""
    check_episodes(episodes, seed)
    if phase_control is not None:
        check_phase_control(phase_control)
    system = system or target_system(target)
    if layout is not None:
        hall = resolve_layout(layout, system)
        system, own = hall.resolve(system)
        scenario = scenario or own
    resolved = resolve_policy(target, device, system)
    policy, run_dir = resolved.policy, resolved.run_dir
    check_policy_fits(policy, system, target)
    if phase_control == "agent" and policy_phase_control(policy) == "optimizer":
        raise UavrisError(f"{target} acts on the motion only (trained with the optimiser setting the phases, the "
                          "strong track); it cannot be evaluated with --phase-control agent")
    scenario = scenario or resolved.scenario
    if scenario is None:
        raise UavrisError("--scenario (or --layout) is required for a baseline or a pre-trained DT (it has no "
                          "scenario of its own)")
    where = get_scenario(scenario)
    where.validate_for(system)
    user = is_user_target(target)
    beside = [ZERO_ACTION, ORACLE] if user and references else []
    from tqdm.auto import tqdm

    with tqdm(total=(1 + len(beside)) * episodes * system.horizon, unit="slot", desc=f"evaluate {where.name}",
              disable=not progress, dynamic_ncols=True, leave=False) as bar:
        def run(policy: Any, mode: str | None) -> EpisodeResults:
            return evaluate(policy, system, where, episodes, seed, phase_control=mode,
                            on_slot=lambda sim, obs, executed, alive: bar.update(int(alive.sum())))

        res = run(policy, phase_control)
        # A user's policy: the references on the same episodes, so its number reads at once.
        references = {name: run(reference_policy(name, system, REFERENCE_SEED), None) for name in beside}
    summary = {"target": target, "scenario": where.name, "start": list(where.start), "seed": seed,
               "phase_control": phase_control or "as trained", **res.summary(), "system": system.to_dict()}
    if references:
        summary["references"] = {name: r.summary() for name, r in references.items()}
        oracle = summary["references"][ORACLE]["mean"]
        summary["fraction_of_oracle"] = summary["mean"] / oracle if oracle > 0 else None
    if out is None:
        if user:
            base = Path("runs/policies") / re.sub(r"[^\w.-]+", "_", target)
        else:
            base = run_dir if run_dir is not None else Path("runs/baselines") / str(reference_name(target))
        out = base / "eval"
    suffix = "-optimizer-phases" if phase_control == "optimizer" else ""
    stem = Path(out) / f"{where.name}-seed{seed}-n{episodes}{suffix}"
    write_results(res, summary, stem)
    return summary, stem.with_suffix(".json")
