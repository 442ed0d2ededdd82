"""``uavris evaluate``: a run, a DT model, a reference or a user's policy on seeded episodes,
written as CSV and JSON (``OUT/TARGET-SCENARIO-seedSEED-nEPISODES-KEY``: TARGET the row,
reference or policy, :func:`file_token`; KEY 8 hex digits of the system, phase control,
start and model evaluated, :func:`evaluated_key`).

Lives here: :func:`evaluate_target` and :func:`write_results` (a target's per-episode
results); every policy that is not itself a reference is scored with the zero action,
hovering with the optimiser's phases and the oracle beside it on the same episodes. Not here: what a target names
(:mod:`.targets`), the evaluation itself (:func:`uavris.agents.evaluation.evaluate`).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from uavris.agents.evaluation import EpisodeResults, check_episodes, evaluate
from uavris.agents.oracle.bound import episode_bounds
from uavris.agents.policy import fit_policy
from uavris.agents.references import HOVER_OPTIMIZER, ORACLE, REFERENCE_SEED, ZERO_ACTION, reference_policy
from uavris.config import SCENARIOS, Scenario, SystemConfig, get_scenario
from uavris.env.rollout import policy_phase_control
from uavris.env.wrappers import check_phase_control
from uavris.errors import UavrisError
from uavris.experiments.display.progress import progress_bar
from uavris.experiments.tools.rows import Controller, Row, as_row, resolve_target
from uavris.experiments.tools.targets import Reference, Target
from uavris.experiments.tools.trajectory import SlotLog, rate_by_active_pairs, trajectory_plot, write_slots
from uavris.io import file_part, write_csv, write_json
from uavris.layouts import Layout, resolve_layout
from uavris.stats import t_interval


def evaluated_key(summary: dict[str, Any]) -> str:
    """8 hex digits of what was evaluated beyond the file name's readable part (the system, the
    phase control, the start and the model, :meth:`~.rows.Row.origin`): evaluations of
    another system or of another model of the same name (two studies' ``model`` folders, two
    ``pol.py:go``) into the same folder keep their own files, and the same evaluation again
    replaces its own."""
    what = {k: summary[k] for k in ("system", "phase_control", "start", "model")}
    return hashlib.sha256(json.dumps(what, sort_keys=True).encode()).hexdigest()[:8]


def write_results(res: EpisodeResults, summary: dict[str, Any], stem: Path, bound: Any = None) -> None:
    """The per-episode CSV (with each episode's bound where given,
    :func:`~uavris.agents.oracle.bound.episode_bounds`) and the summary JSON."""
    columns = [res.seeds.tolist(), res.avg_sum_rate.tolist(), res.episode_return.tolist(), res.length.tolist(),
               res.energy_used.tolist()] + ([] if bound is None else [np.asarray(bound).tolist()])
    header = ("seed", "avg_sum_rate", "return", "length", "energy_j") + (() if bound is None else ("bound",))
    write_csv(stem.parent / f"{stem.name}.csv", header, zip(*columns))
    write_json(stem.parent / f"{stem.name}.json", summary)


def evaluate_target(target: str | Target | Row, scenario: str | Scenario | None, episodes: int, seed: int,
                    out: Path | None = None, phase_control: str | None = None, device: str = "cpu",
                    progress: bool = False, system: SystemConfig | None = None,
                    layout: str | Layout | None = None, references: bool = True, trajectory: bool = False
                    ) -> tuple[dict[str, Any], Path]:
    """Evaluate ``target`` (a name :func:`~.rows.resolve_target` reads, a resolved
    :class:`~.targets.Target`, or a report's :class:`~.rows.Row`, evaluated as the report
    does: under the safety layer, held level, an ensemble, another hall's plan);
    ``phase_control="optimizer"`` replaces its phases by the optimiser's.

    ``system`` replaces the target's own system (the CLI's ``--system.*``); ``layout`` (a
    :class:`~uavris.layouts.Layout` or what :func:`~uavris.layouts.resolve_layout` reads)
    puts it in another hall: the layout's devices, and its start unless ``scenario`` names
    one. With ``progress`` a bar counts the simulated slots (the optimiser and the oracle
    take milliseconds per slot, so a long evaluation is visibly alive). Every target but a
    reference gets the zero action, hovering with the optimiser's phases and the oracle beside
    it on the same episodes (``references=False``: not). With ``trajectory`` every
    slot is written too (``STEM-slots.csv``: pose, active pairs, sum rate, energy), the
    first episode's flight drawn in the hall (``STEM-trajectory.png``), and the summary
    splits the rate by the number of active pairs."""
    check_episodes(episodes, seed, "--")  # the command's flags
    if phase_control is not None:
        check_phase_control(phase_control)
    if isinstance(target, (str, Path)):
        target = resolve_target(target)
    # a study's row, or one exported as a controller directory: named by its key
    study_row = isinstance(target, (Row, Controller))
    row = as_row(target)
    system = system or row.own_system()
    if layout is not None:
        hall = resolve_layout(layout, system)
        system, own = hall.resolve(system)
        scenario = scenario or own
    evaluated = row.system(system)
    loaded = row.load(evaluated, device)
    policy = fit_policy(loaded.policy, evaluated, row.key)
    if phase_control == "agent" and policy_phase_control(policy) == "optimizer":
        raise UavrisError(f"{row.key} acts on the motion only (trained with the optimiser setting the phases, "
                          "the strong track); it cannot be evaluated with --phase-control agent")
    scenario = scenario or loaded.scenario
    if scenario is None:
        raise UavrisError("--scenario (or --layout) is required for a baseline or a pre-trained DT (it has no "
                          "scenario of its own)")
    where = get_scenario(scenario)
    where.validate_for(evaluated)
    # every policy beside the three references the docs read results against (not a reference beside itself)
    reference = isinstance(row.target, Reference)
    beside = [] if reference or not references else [ZERO_ACTION, HOVER_OPTIMIZER, ORACLE]
    with progress_bar((1 + len(beside)) * episodes * system.horizon, f"evaluate {where.name}", "slot", progress,
                      leave=False) as bar:
        def run(policy: Any, mode: str | None, in_system: SystemConfig, log: SlotLog | None = None) -> EpisodeResults:
            def on_slot(sim: Any, obs: Any, executed: Any, alive: Any) -> None:
                bar.update(int(alive.sum()))
                if log is not None:
                    log.on_slot(sim, obs, executed, alive)

            return evaluate(policy, in_system, where, episodes, seed, phase_control=mode, on_slot=on_slot,
                            on_step=log.on_step if log is not None else None,
                            batch_size=256 if log is None else max(256, episodes))

        log = SlotLog(seed + np.arange(episodes)) if trajectory else None
        res = run(policy, phase_control, evaluated, log)
        # A user's policy: the references on the same episodes, so its number reads at once.
        refs = {name: run(reference_policy(name, system, REFERENCE_SEED), None, system) for name in beside}
    summary = {"target": row.key, **({"label": row.label_for(loaded.expert_kind)} if study_row else {}),
               "model": row.origin(), "scenario": where.name, "hall": hall_name(evaluated, layout, where.name),
               "layout": layout_origin(layout), "start": list(where.start), "seed": seed,
               "phase_control": phase_control or "as trained", **res.summary(), "system": evaluated.to_dict()}
    outside = outside_training(row, evaluated, file_token(row, study_row))
    if outside:
        summary["warning"] = outside
    # what no controller can exceed on these episodes (agents.oracle.bound): the room left above any result
    bound = episode_bounds(evaluated, res.seeds)
    summary["bound"] = {"mean": float(bound.mean()), "episodes_above": int((res.avg_sum_rate > bound).sum())}
    summary["fraction_of_bound"] = summary["mean"] / summary["bound"]["mean"]
    if refs:
        summary["references"] = {name: r.summary() for name, r in refs.items()}
        oracle = summary["references"][ORACLE]["mean"]
        summary["fraction_of_oracle"] = summary["mean"] / oracle if oracle > 0 else None
        # the target minus each reference, paired on the same episodes: the difference a comparison reads
        summary["paired"] = {name: paired_summary(res.avg_sum_rate - r.avg_sum_rate) for name, r in refs.items()}
    suffix = "-optimizer-phases" if phase_control == "optimizer" else ""
    stem = Path(out or results_dir(target)) / (f"{file_token(row, study_row)}-{file_part(where.name)}-seed{seed}"
                                               f"-n{episodes}{suffix}-{evaluated_key(summary)}")
    if log is not None:
        summary["active_pairs"] = {str(m): v for m, v in rate_by_active_pairs(log.rows).items()}
        write_slots(log, stem.parent / f"{stem.name}-slots.csv")
        trajectory_plot(log, evaluated, stem.parent / f"{stem.name}-trajectory",
                        f"{row.key} in {where.name}, episode seed {seed}")
    write_results(res, summary, stem, bound)
    return summary, stem.parent / f"{stem.name}.json"


def results_dir(target: Target | Row) -> Path:
    """Where ``evaluate`` writes a target's results without ``--out``: beside a run, model or
    controller (``DIR/eval``), ``runs/rows/ROW`` for a study's row, ``runs/baselines/NAME/eval``
    for a reference, ``runs/policies/FILE_py_NAME/eval`` for a user's policy."""
    if isinstance(target, Controller):
        return target.default_out()
    row = as_row(target)
    if isinstance(target, Row) or row.target is None:
        return Path("runs/rows") / row.key
    return row.target.default_out()


def paired_summary(d: Any) -> dict[str, float]:
    """A paired difference per episode: its mean and Student-t 95% interval."""
    low, high = t_interval(d)
    return {"mean": float(np.mean(d)), "ci_low": low, "ci_high": high}


def outside_training(row: Row, system: SystemConfig, name: str) -> str | None:
    """One line when a trained model flies a hall outside what it was trained in (another room,
    or a device beyond the training room's extent): its numbers are an extrapolation."""
    trained = row.target is not None and row.target.trained or bool(row.members)
    if not trained:
        return None
    own = row.own_system()
    beyond = any(c > r + 1e-9 for u in system.users for c, r in zip(u, own.room))
    if tuple(own.room) == tuple(system.room) and not beyond:
        return None
    size = " x ".join(f"{v:g}" for v in own.room)
    here = " x ".join(f"{v:g}" for v in system.room)
    return (f"{name} was trained in a {size} m hall and flies a {here} m one here"
            + (" with devices beyond its training room" if beyond else "") + ": an extrapolation")


def layout_origin(layout: str | Layout | None) -> str | None:
    """The layout a result was made in, as the result records it: a layout file's absolute path,
    a generated or named layout's name; None without one (the target's own hall)."""
    if layout is None:
        return None
    if isinstance(layout, Layout):
        return layout.name
    path = Path(layout)
    return str(path.resolve()) if path.suffix.lower() in (".yaml", ".yml") or path.is_file() else str(layout)


def hall_name(system: SystemConfig, layout: str | Layout | None, site: str) -> str:
    """The hall a result was made in, as the result records it (its devices are in its
    ``system``): the paper's, the layout named, or the hall of the site evaluated."""
    if system.users == SystemConfig().users and system.room == SystemConfig().room:
        return "the paper's hall"
    if isinstance(layout, str):
        return f"hall {Path(layout).name if layout.endswith(('.yaml', '.yml')) else layout}"
    if isinstance(layout, Layout):
        return f"hall {layout.name}"
    return f"{system.num_users} devices of layout {site}" if site not in SCENARIOS else \
        f"{system.num_users} devices of --system.users"


def file_token(row: Row, study_row: bool) -> str:
    """What a result file's name starts with: the row, the reference or the policy evaluated
    (a user's ``path/FILE.py:NAME`` as ``FILE_py_NAME``; two targets into one folder never
    share a file)."""
    return file_part(row.key) if study_row or row.target is None else row.target.file_token()
