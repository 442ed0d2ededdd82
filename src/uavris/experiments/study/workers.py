"""The study's worker entry points: what a worker process runs for a stage's job.

Lives here: one picklable function per kind of job (:func:`dataset_job`,
:func:`demonstrations_job`, :func:`merge_demonstrations`, :func:`pretrain_job`,
:func:`finetune_job`, :func:`evaluate_job`; an expert's is
:func:`uavris.experiments.training.train_expert.train_job`) and the evaluation of every row
of a track in one unseen site (:func:`evaluate_rows`). Each takes plain values or frozen
dataclasses (a config as a dict, paths as strings, sites and rows), so that a process pool
or Ray can ship it. Not here:
which jobs a stage submits (:mod:`.pipeline`), the job runner (:mod:`uavris.experiments.engine`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np
from scipy.stats import spearmanr

from uavris import physics as ph
from uavris.agents.dt.dataset import load_dataset
from uavris.agents.evaluation import evaluate
from uavris.agents.oracle import PlanningOracle
from uavris.agents.oracle.objective import assessed_rate
from uavris.agents.place.planner import learned_plan
from uavris.agents.place.value import predict
from uavris.agents.references import ORACLE
from uavris.experiments.study.kept_rows import keep, row_key, take
from uavris.experiments.study.tracks import TRACK_SPECS, Track
from uavris.experiments.tools.evaluate import write_results
from uavris.experiments.tools.rows import Row
from uavris.experiments.tools.targets import LearnedValue
from uavris.experiments.tools.trajectory import SlotLog, write_slots
from uavris.experiments.training import finetune, pretrain
from uavris.experiments.training.collect import collect, dataset_summary
from uavris.experiments.training.demonstrations import DemonstrationConfig, collect_demonstrations, demonstrate
from uavris.experiments.training.values import ValueFitConfig, ValueLabelsConfig, fit, make_labels, write_label_part
from uavris.io import read_json, write_json
from uavris.layouts import Site
from uavris.presets import EVAL_SEED
from uavris.runs import read_done
from uavris.stats import summarize


def dataset_job(expert_dirs: list[str], trajectories: int, out: str) -> dict[str, Any]:
    """Collect the experts' trajectories into a dataset; returns its summary."""
    return dataset_summary(collect(expert_dirs, trajectories, out, force=True, progress=False))


QUERIES_FILE = "queries.json"  # a demonstration part's model queries (poses its plans valued)


def demonstrations_job(cfg_dict: dict[str, Any], first: int, count: int, out: str) -> dict[str, Any]:
    """Demonstrations of halls ``first .. first + count - 1`` as a dataset of their own at ``out``."""
    cfg = DemonstrationConfig.from_dict(cfg_dict)
    labels: dict[str, list[Any]] | None = {} if cfg.value_labels else None
    queries: dict[str, int] = {}
    trajectories = demonstrate(cfg, first, count, labels=labels, queries=queries)
    if labels:  # the plans' valued poses: labels of the learned value (a part beside the dataset's)
        part = Path(out)
        write_label_part(part.parent.parent / "labels" / f"{part.name}.npz",
                         **{k: np.concatenate(v) for k, v in labels.items()})
    collect_demonstrations(cfg, out, force=True, progress=False, trajectories=trajectories)
    write_json(Path(out) / QUERIES_FILE, queries)  # beside the part's dataset, which the merge sums
    return {"halls": count, "episodes": len(trajectories)}


def merge_demonstrations(cfg_dict: dict[str, Any], parts: Sequence[str], out: str) -> dict[str, Any]:
    """The parts' demonstrations, in hall order, as one dataset at ``out``; returns its summary."""
    cfg = DemonstrationConfig.from_dict(cfg_dict)
    trajectories = [tr for part in parts for tr in load_dataset(part).trajectories]
    summary = dataset_summary(collect_demonstrations(cfg, out, force=True, progress=False, trajectories=trajectories))
    by = {}  # the dataset's quality per behaviour (the per-hall table would list thousands of halls)
    for tr in trajectories:
        by.setdefault(tr.expert, []).append(tr.episode_return / tr.length)
    queries = [Path(p) / QUERIES_FILE for p in parts]
    return {k: v for k, v in summary.items() if k != "scenarios"} | {
        "halls": len(summary["scenarios"]), "behaviours": {b: float(np.mean(v)) for b, v in by.items()},
        **({"poses_valued": sum(read_json(q)["poses_valued"] for q in queries)} if all(q.exists() for q in queries)
           else {})}


def best_demonstrations_job(cfg_dict: dict[str, Any], source: str, fraction: float, out: str) -> dict[str, Any]:
    """The ``fraction`` of the demonstrations at ``source`` with the highest returns (filtered
    behaviour cloning's data: the field's baseline), in their order, as one dataset at ``out``."""
    trajectories = load_dataset(source).trajectories
    keep = max(1, round(fraction * len(trajectories)))
    best = set(np.argsort([-tr.episode_return for tr in trajectories], kind="stable")[:keep].tolist())
    chosen = [tr for i, tr in enumerate(trajectories) if i in best]
    cfg = DemonstrationConfig.from_dict(cfg_dict)
    summary = dataset_summary(collect_demonstrations(cfg, out, force=True, progress=False, trajectories=chosen))
    return {k: v for k, v in summary.items() if k != "scenarios"} | {
        "halls": len(summary["scenarios"]), "of": len(trajectories),
        "mean_return": float(np.mean([tr.episode_return for tr in chosen]))}


def pretrain_job(cfg_dict: dict[str, Any], out: str, device: str = "cpu") -> dict[str, Any]:
    """Pre-train (or resume) a DT; returns its done.json."""
    model_dir = Path(out)  # pretrain.pretrain read when the job runs: tests/test_reproduce.py replaces it
    pretrain.pretrain(pretrain.PretrainConfig.from_dict(cfg_dict), model_dir, resume=model_dir.exists(),
                      progress=False, device=device)
    return read_done(model_dir)


def value_labels_job(cfg_dict: dict[str, Any], count: int, first: int, n: int, out: str) -> dict[str, Any]:
    """The learned value's labels of training halls ``first .. first + n - 1`` of ``count``
    devices, a part at ``out``."""
    make_labels(ValueLabelsConfig.from_dict(cfg_dict), count, first, n, out)
    return {"count": count, "halls": n}


def value_fit_job(cfg_dict: dict[str, Any], parts: Sequence[str], out: str) -> dict[str, Any]:
    """The learned value fitted to the label ``parts``, a checkpoint at ``out``; returns its done record."""
    fit(ValueFitConfig.from_dict(cfg_dict), parts, out)
    return read_json(Path(out) / "done.json")


def finetune_job(cfg_dict: dict[str, Any], out: str, device: str = "cpu") -> dict[str, Any]:
    """Fine-tune (or resume) a DT; returns its done.json."""
    model_dir = Path(out)
    finetune.finetune(finetune.FinetuneConfig.from_dict(cfg_dict), model_dir, resume=model_dir.exists(),
                      progress=False, device=device)
    return read_done(model_dir)


# The evaluation stages' results: 2 records each row's facts (uavris.experiments.tools.rows.Row.facts),
# which the report and the claims read; 3 the planner a goal-conditioned row is told its place by (the
# headline DT: the semi-amortised place, no longer V's argmax); 4 the oracle's plan and flight keeping every
# device 1 degree in front of the RIS (PlanSettings.front_margin_deg); 5 the goal-conditioned DT told the deployed
# place (V proposes, R disposes) and its row flown by the oracle's controller (plan-deployed, for plan-semi). Part
# of the stages' keys, so that a
# study of an earlier format is evaluated again rather than read without them.
RESULTS_FORMAT = 5


def evaluate_job(out: str, site: Site, track: str, episodes: int, rows: Sequence[Row], kept: str | None = None,
                 reuse: bool = True) -> dict[str, Any]:
    """Every row of a track in one unseen site on the same seeded episodes (see :func:`evaluate_rows`)."""
    return evaluate_rows(Path(out), site, TRACK_SPECS[track], episodes, rows, Path(kept) if kept else None, reuse)


class _Whereabouts:
    """What :func:`evaluate_rows` records of an evaluation besides the rates, slot by slot:
    the share of slots in which a device is behind the RIS plane (docs/model.md section 3),
    each episode's last pose, and every slot (``log``; its ``on_step`` is the rollout's too)."""

    def __init__(self, system: Any, episodes: int) -> None:
        self.users = np.asarray(system.users, dtype=np.float64)
        self.behind, self.slots = 0, 0
        self.pos, self.att = np.zeros((episodes, 3)), np.zeros((episodes, 3))
        self.log = SlotLog(EVAL_SEED + np.arange(episodes))

    def __call__(self, sim: Any, obs: Any, executed: Any, alive: Any) -> None:
        self.behind += int((ph.worst_elevation(sim.att, sim.pos, self.users) <= 0.0)[alive].sum())
        self.slots += int(alive.sum())
        self.pos[alive], self.att[alive] = sim.pos[alive], sim.att[alive]
        self.log.on_slot(sim, obs, executed, alive)

    def end_pose(self) -> tuple[Any, Any]:
        """The episodes' median last position and attitude (angles in [-pi, pi))."""
        return np.median(self.pos, axis=0), np.median(np.mod(self.att + np.pi, 2 * np.pi) - np.pi, axis=0)


def _decomposition(system: Any, rec: _Whereabouts) -> dict[str, Any]:
    """Where a policy ended and what that pose is worth: the expected sum rate with optimised
    phases (the planner's R, on the fresh draws plans state their numbers with, so that it
    pairs with the oracle's target's) at its median end position, level and with its own
    attitude, and the share of its slots with a device behind the RIS (docs/study.md section 2)."""
    pos, att = rec.end_pose()
    (level, own), _ = assessed_rate(system, np.stack([pos, pos]), np.stack([np.zeros(3), att]))
    return {"end_position": pos.tolist(), "end_attitude_deg": np.degrees(att).tolist(),
            "end_rate_level": float(level), "end_rate_own": float(own),
            "behind_share": rec.behind / max(rec.slots, 1)}


def evaluate_rows(out: Path, site: Site, track: Track, episodes: int, rows: Sequence[Row], kept: Path | None = None,
                  reuse: bool = True) -> dict[str, Any]:
    """Every row (:func:`~.tracks.track_rows`: the learned rows and the references) in ``site``,
    each in its own system (:meth:`~uavris.experiments.tools.rows.Row.system`: under the
    safety layer where the row says so), on episodes ``EVAL_SEED ..``; per-episode CSVs in
    ``out``, named by the rows' keys, and the first episode slot by slot in ``out/slots`` (what
    the report draws). Each summary records what its row is (:meth:`Row.facts
    <uavris.experiments.tools.rows.Row.facts>`). In the deployment track every summary also holds the
    decomposition of :func:`_decomposition`, and the oracle's its plan's target
    (:func:`oracle_target`). With ``kept`` (the study's :data:`.kept_rows.KEPT_ROWS_DIR`), a row
    evaluated before with the same inputs is copied from there instead of flown again (not
    without ``reuse``: a run with ``--force``), and a row flown here is kept there (:mod:`.kept_rows`).
    """
    result = {row.key: _row_kept_or_evaluated(out, site, track, episodes, row, kept, reuse) for row in rows}
    if track.layouts:
        oracle = PlanningOracle()
        result[ORACLE].update(oracle_target(site, oracle))
        for row in rows:
            if isinstance(row.target, LearnedValue) and not row.target.top_k:
                result[row.key].update(value_accuracy(site, row.target.planner_model(), oracle))
    return result


def _row_kept_or_evaluated(out: Path, site: Site, track: Track, episodes: int, row: Row, kept: Path | None,
                           reuse: bool) -> dict[str, Any]:
    key = row_key(site, track.name, episodes, row, RESULTS_FORMAT) if kept is not None else None
    if kept is None or key is None:
        return evaluate_row(out, site, track, episodes, row)
    summary = take(kept, key, out, row) if reuse else None
    if summary is None:
        summary = evaluate_row(out, site, track, episodes, row)
        keep(kept, key, out, row)
    return summary


def first_episode_slots(evaluation: Path, row: str) -> Path:
    """Where an evaluation stage's directory keeps row ``row``'s first episode, slot by slot."""
    return evaluation / "slots" / f"{row}.csv"


def evaluate_row(out: Path, site: Site, track: Track, episodes: int, row: Row) -> dict[str, Any]:
    """One row of :func:`evaluate_rows`: its per-episode CSV and summary in ``out`` (named by its
    key), its first episode slot by slot in ``out/slots``; the summary."""
    system = row.system(site.system)
    loaded = row.load(system)
    rec = _Whereabouts(system, episodes)
    res = evaluate(loaded.policy, system, site.scenario, episodes, EVAL_SEED, on_slot=rec, on_step=rec.log.on_step)
    write_slots(rec.log, first_episode_slots(out, row.key), EVAL_SEED)  # the report draws it
    summary = {"policy": row.key, "label": row.label_for(loaded.expert_kind), **row.facts(),
               "scenario": site.name, "track": track.name, **res.summary(),
               **{f"boot_{k}": v for k, v in summarize(res.avg_sum_rate).items()},
               **(_decomposition(system, rec) if track.layouts else {})}
    write_results(res, summary, out / row.key)
    return summary


def oracle_target(where: Site, oracle: Any = None) -> dict[str, Any]:
    """The planning oracle's target in ``where``: its pose, R there with its attitude
    (``plan_rate``, with its standard error) and level (``plan_rate_level``, what
    :func:`_decomposition`'s place gap compares an end position with, on the same draws)."""
    plan = (oracle or PlanningOracle()).plan(where.system, where.scenario.start)
    (level,), _ = assessed_rate(where.system, plan.target, np.zeros(3))
    return {"plan_rate": plan.rate, "plan_rate_se": plan.rate_se, "plan_rate_level": float(level),
            "plan_target": plan.target.tolist(), "plan_attitude_deg": np.degrees(plan.attitude).tolist()}


def value_accuracy(where: Site, value: Any, oracle: Any) -> dict[str, Any]:
    """How well a learned value ``V`` knows ``where`` (docs/places.md): Spearman's rank correlation of
    ``V`` with ``R`` over the level poses the planning ``oracle`` valued there with ``R``
    (``value_rank_correlation``), and ``R`` at ``V``'s argmax, level, on the draws a plan states
    its numbers with (``value_target_rate_level``: the oracle's ``plan_rate_level`` is its match)."""
    system, start = where.system, where.scenario.start
    oracle.plan(system, start)
    poses, rates = oracle.valued_poses(system)
    level = np.all(poses[:, 3:] == 0.0, axis=1)
    v = predict(value, np.asarray(system.users, dtype=np.float64), poses[level, :3])
    rho = float(spearmanr(v, rates[level]).statistic) if level.sum() > 2 else float("nan")
    (at,), _ = assessed_rate(system, learned_plan(value, system, start).target, np.zeros(3))
    return {"value_rank_correlation": rho, "value_poses": int(level.sum()), "value_target_rate_level": float(at)}
