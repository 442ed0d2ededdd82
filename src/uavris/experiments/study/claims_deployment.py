"""The paper's Fig. 3 claims in the deployment track: the unseen hall the unit.

Lives here: :func:`judge_deployment` (every claim over the unseen halls, each hall's learned
rows averaged over the pre-training seeds), "fewer interactions" from ``uavris from-scratch``'s
measurement (:func:`deployment_fewer`) and :func:`dt_against_hovering`. Not here: the paper and
strong tracks and the rules the cells share (:mod:`.claims_tracks`), the table (:mod:`.claims`).

The fine-tuning claims judge the paper's DT fine-tuned by its Algorithm 1 (``--ablation``),
each side measured alike: "fine-tuning raises the DT" compares it with the same DT zero-shot
as the paper runs both, without the attitude safety layer that fine-tuning did not train with
(the difference under the layer is reported beside it, not judged); "fewer interactions"
charges the DT's fine-tuning rounds and the expert trained from scratch by curves measured the
same way: the study's evaluation episodes, under the safety layer the expert trained with.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uavris.agents.references import HOVER_OPTIMIZER, ORACLE
from uavris.experiments.study.claims_tracks import (
    LEVEL,
    SCENARIO_CLAIMS,
    WITHIN,
    charged_both_ways,
    episode_rates,
    interactions_needed,
    within_both_ways,
)
from uavris.experiments.study.finished import Study
from uavris.experiments.study.judgement import NOT_TESTED, Judgement, judgement
from uavris.experiments.study.tracks import TRACK_SPECS, Track, zero_shot_only
from uavris.experiments.tools.rows import variant_key
from uavris.stats import judged, judged_censored

DEPLOYMENT_DT = variant_key("dt-zero-shot", safe=True)  # the paper's DT (return-conditioned) under the safety layer
GOAL_DT = variant_key("dt-goal", safe=True)  # the goal-conditioned DT told the deployed place
# The fine-tuning claims are the paper's: its DT fine-tuned by its Algorithm 1 where every hall has it, else
# uavris's goal-conditioned DT fine-tuned by trying places, named in each cell's text. Each: the fine-tuned
# and the zero-shot rows as the paper runs them (no safety layer), the same under the layer, what it is.
FINETUNING = (("dt-finetuned", "dt-zero-shot", "the paper's DT fine-tuned in the hall by its Algorithm 1"),
              ("dt-goal-finetuned", "dt-goal", "uavris's goal-conditioned DT fine-tuned in the hall by trying places"))
BC = variant_key("bc", safe=True)
SAFE_ORACLE = variant_key(ORACLE, safe=True)


def _seed_rates(edir: Path, res: dict[str, Any], variant: str) -> list[list[float]]:
    """Each pre-training seed's per-episode rates of a row's variant (empty: no such row)."""
    return [episode_rates(edir, k).tolist() for k, s in res.items() if s.get("variant") == variant]


def seeds_mean(seeds: list[list[float]]) -> np.ndarray | None:
    """Per episode, the mean over the pre-training seeds (None: no seed)."""
    return np.mean(np.asarray(seeds, dtype=np.float64), axis=0) if seeds else None


def seeds_spread(seeds: list[list[float]]) -> float | None:
    """The spread over episodes (standard deviation) averaged over the pre-training seeds (the
    spread of their mean would shrink with their number); None: no seed."""
    return float(np.mean([np.std(s, ddof=1) for s in seeds])) if seeds else None


def _model_queries(study: Study, track: Track) -> str:
    """The model queries behind the deployment track's pre-training, as a phrase: the poses the
    demonstrations' plans valued with ``R`` and the learned value's labels (where recorded)."""
    demos = study.demonstrations(track) or {}
    labels = study.value_labels(track) or {}
    parts = []
    if "poses_valued" in demos:
        parts.append(f"{demos['poses_valued']:,} poses the plans valued")
    if labels:
        parts.append(f"{len(labels['counts']) * labels['halls'] * labels['poses']:,} label poses")
    return (" (model queries beside them, not environment interactions: " + " and ".join(parts)
            + ", each R of a pose: 24 pairings x 2 NLoS draws of optimised slots)") if parts else ""


def hall_rows(study: Study, track: Track, hall: str) -> dict[str, Any] | None:
    """What the deployment claims read in one unseen hall: each variant's seeds' per-episode
    rates (``rows``), the nearest training hall's plan (``transfer``); None where the hall's
    evaluation, its zero-shot DT or its transferred plan is missing."""
    found = study.evaluation(track, hall)
    if found is None:
        return None
    edir, res = found
    transfer = [k for k, v in res.items() if v["kind"] == "transfer" and v["rank"] == 0]
    variants = {DEPLOYMENT_DT, GOAL_DT, BC, SAFE_ORACLE,
                *(variant_key(v, safe=safe) for fine, start, _ in FINETUNING for v in (fine, start)
                  for safe in (False, True))}
    rows = {v: seeds for v in sorted(variants) if (seeds := _seed_rates(edir, res, v))}
    if DEPLOYMENT_DT not in rows or not transfer or SAFE_ORACLE not in rows:
        return None
    return {"hall": hall, "rows": rows, "transfer": episode_rates(edir, transfer[0]).tolist()}


def judge_deployment(study: Study, from_scratch: Sequence[dict[str, Any]] = (),
                     evidence: dict[str, Any] | None = None) -> list[Judgement]:
    """The Fig. 3 claims over the unseen halls (the unit), each hall's learned rows averaged
    over the pre-training seeds. The transferred expert is the nearest training hall's oracle
    plan; the expert trained where the DT is deployed is the oracle (whose demonstrations the
    DT learned from). Fine-tuning is the paper's DT fine-tuned by its Algorithm 1 where every
    hall has it, else the goal-conditioned DT fine-tuned by trying places: one of the two for
    all halls, named in each cell. ``from_scratch``: per hall, what ``uavris from-scratch``
    measured (:mod:`.from_scratch`). What each hall's cells read goes into ``evidence``
    (``halls``; "fewer": ``from_scratch``)."""
    track = TRACK_SPECS["deployment"]
    _, unseen = study.sites(track)
    halls = [h for w in unseen if not zero_shot_only(w, study.config.system)
             and (h := hall_rows(study, track, w.name)) is not None]
    if evidence is not None:
        evidence["halls"] = halls
    if not halls:
        return [Judgement(c, "deployment", NOT_TESTED, text="no unseen hall evaluated") for c in SCENARIO_CLAIMS]
    unit = f"{len(halls)} unseen halls, each the mean of its pre-training seeds"

    def over_halls(fn: Any) -> list[float] | None:
        """``fn(rows, transfer)`` in every hall, None where a hall lacks what it reads."""
        values = [fn({k: seeds_mean(v) for k, v in h["rows"].items()}, np.asarray(h["transfer"])) for h in halls]
        return None if any(v is None for v in values) else [float(v) for v in values]

    def cell(claim: str, values: list[float] | None, text: str, missing: str) -> Judgement:
        return (judgement(claim, "deployment", judged(values), unit, "halls", text) if values is not None else
                Judgement(claim, "deployment", NOT_TESTED, text=missing))

    out = [cell("zero-shot", over_halls(lambda r, t: np.mean(r[DEPLOYMENT_DT] - t)),
                "zero-shot DT (return-conditioned, safety layer) minus the nearest training hall's oracle plan, "
                "bps/Hz", "")]
    goal = over_halls(lambda r, t: np.mean(r[GOAL_DT] - t) if GOAL_DT in r else None)
    if goal is not None:
        out.append(cell("zero-shot", goal, "the same for the goal-conditioned DT told the deployed place "
                        "(uavris's controller; the cell's second entry)", ""))
    out += _finetuning_cells(halls, unit)
    out.append(cell("fluctuates", [float(np.std(h["transfer"], ddof=1) - np.std(h["rows"][SAFE_ORACLE][0], ddof=1))
                                   for h in halls],
                    "the nearest training hall's plan's spread minus the oracle's (the cell's last entry), bps/Hz", ""))
    out.append(cell("dt-over-bc", over_halls(lambda r, t: np.mean(r[DEPLOYMENT_DT] - r[BC]) if BC in r else None),
                    "zero-shot DT minus behaviour cloning on the same demonstrations (both under the safety layer, "
                    "means of their seeds), bps/Hz", "no behaviour cloning row"))
    return out + deployment_fewer(study, track, from_scratch, evidence)


def _finetuning_cells(halls: list[dict[str, Any]], unit: str) -> list[Judgement]:
    """"Fine-tuning raises the DT", "within 5% of the expert" and the first "fluctuates" entry,
    of the first fine-tuning of :data:`FINETUNING` that every hall has."""
    for fine, start, what in FINETUNING:
        plain = [variant_key(v) for v in (fine, start)]
        safe = [variant_key(v, safe=True) for v in (fine, start)]
        if not all(v in h["rows"] for h in halls for v in (*plain, *safe)):
            continue
        mean = {v: [seeds_mean(h["rows"][v]) for h in halls] for v in (*plain, *safe)}
        oracle = [np.asarray(h["rows"][SAFE_ORACLE][0]) for h in halls]
        raised = [float(np.mean(f - z)) for f, z in zip(mean[plain[0]], mean[plain[1]])]
        under = judged([float(np.mean(f - z)) for f, z in zip(mean[safe[0]], mean[safe[1]])])
        fine_s = mean[safe[0]]
        return [judgement("finetuned", "deployment", judged(raised), unit, "halls",
                          f"{what}, minus the same DT zero-shot, both as the paper runs them (without the attitude "
                          f"safety layer, which fine-tuning did not train with), bps/Hz; under the layer, not judged: "
                          f"{under['mean']:+.2f} [{under['ci_low']:+.2f}, {under['ci_high']:+.2f}]"),
                within_both_ways(
                    judgement("near-expert", "deployment", judged([float(np.mean(f - (1 - WITHIN) * o))
                                                                   for f, o in zip(fine_s, oracle)]), unit, "halls",
                              f"{what}, minus {1 - WITHIN:.0%} of the oracle (the track's expert), both under the "
                              "safety layer, bps/Hz"),
                    judgement("near-expert", "deployment", judged([float(np.mean((1 + WITHIN) * o - f))
                                                                   for f, o in zip(fine_s, oracle)]), unit, "halls",
                              f"{1 + WITHIN:.0%} of the oracle minus {what}")),
                judgement("fluctuates", "deployment",
                          judged([seeds_spread(h["rows"][safe[1]]) - seeds_spread(h["rows"][safe[0]])
                                  for h in halls]), unit, "halls",
                          f"the zero-shot DT's spread over evaluation episodes minus that of {what} (each the mean of "
                          "its seeds' standard deviations, both under the safety layer), bps/Hz")]
    ablation = "fine-tuning in the unseen halls runs with --ablation only"
    return [Judgement(c, "deployment", NOT_TESTED, text=ablation) for c in ("finetuned", "near-expert")] + [
        Judgement("fluctuates", "deployment", NOT_TESTED, text=ablation + " (its first entry)")]


def deployment_fewer(study: Study, track: Track, from_scratch: Sequence[dict[str, Any]],
                     evidence: dict[str, Any] | None = None) -> list[Judgement]:
    """"Fewer interactions" in the halls ``uavris from-scratch`` measured: the from-scratch
    expert's curve against the paper's DT's fine-tuning curve, both on the study's evaluation
    episodes under the safety layer, by :func:`interactions_needed`; the curves go into
    ``evidence["from_scratch"]``."""
    claims = ("fewer", "fewer-finetuning", "fewer-total")
    if not from_scratch:
        return [Judgement(c, "deployment", NOT_TESTED, text="needs the measurement of uavris from-scratch")
                for c in claims]
    if any("finetune_curve" not in h or "expert_curve" not in h for h in from_scratch):
        return [Judgement(c, "deployment", NOT_TESTED, text="its from-scratch.json holds no fine-tuning curves of the "
                          "paper's DT on the study's episodes (made by an earlier uavris): run uavris from-scratch "
                          "again") for c in claims]
    curves = [{"hall": h["hall"], "expert_curve": h["expert_curve"], "finetune_curve": h["finetune_curve"]}
              for h in from_scratch]
    pre = float((study.demonstrations(track) or {})["slots"])
    served = sum(1 for w in study.sites(track)[1] if not zero_shot_only(w, study.config.system))
    if evidence is not None:
        evidence["from_scratch"] = {"halls": curves, "pretraining": pre, "served": served}
    needs = []
    for h in curves:
        (ex, ey), (fx, fy) = ([np.asarray(v, dtype=np.float64) for v in c] for c in (h["expert_curve"],
                                                                                      h["finetune_curve"]))
        needs.append(interactions_needed((ex, ey), (fx, fy), float(ey[-1])))
    diff = [n["expert"] - n["finetune"] for n in needs]
    low, high = [n["low_bound"] for n in needs], [n["high_bound"] for n in needs]
    there = sum(n["zero_shot_there"] for n in needs)
    unit = f"{len(diff)} unseen halls (uavris from-scratch)"
    rule = (f"interactions hybrid PPO from scratch needed to first reach {LEVEL:.0%} of its final evaluation minus "
            "those the paper's DT fine-tuned by its Algorithm 1 needed (0 where its zero-shot start is there), both "
            "on the study's evaluation episodes under the safety layer; a side that never does is charged its "
            f"budget, a bound, on which no verdict rests; the zero-shot DT was already at the level in {there} of "
            f"{len(diff)} halls")
    worked = [i for i, n in enumerate(needs) if not n["zero_shot_there"]]
    own = judgement("fewer-finetuning", "deployment",
                    judged_censored([diff[i] for i in worked], [low[i] for i in worked], [high[i] for i in worked]),
                    f"{len(worked)} of those halls, where the zero-shot DT was below the level", "halls",
                    "the same where fine-tuning had work to do") if worked else \
        Judgement("fewer-finetuning", "deployment", NOT_TESTED, text="the zero-shot DT was at the level in every hall")
    return [judgement("fewer", "deployment", judged_censored(diff, low, high), unit, "halls", rule), own,
            charged_both_ways(
                judgement("fewer-total", "deployment", judged_censored(np.subtract(diff, pre), low, high), unit,
                          "halls", f"the same minus the {pre:,.0f} environment interactions of the oracle's "
                          "demonstrations" + _model_queries(study, track)),
                judgement("fewer-total", "deployment", judged_censored(np.subtract(diff, pre / served), low, high),
                          unit, "halls", ""),
                served)]


def dt_against_hovering(study: Study) -> list[tuple[int, dict[str, Any]]]:
    """Per device count of the deployment track's unseen halls of its own: the return-conditioned
    zero-shot DT (the mean of its seeds) minus hovering with optimised phases, both under the
    safety layer, over the halls (the unit)."""
    track = TRACK_SPECS["deployment"]
    if track not in study.config.tracks:
        return []
    _, unseen = study.sites(track)
    hover = variant_key(HOVER_OPTIMIZER, safe=True)
    per: dict[int, list[float]] = {}
    for w in unseen:
        if w.split != "unseen" or (found := study.evaluation(track, w.name)) is None:
            continue
        edir, res = found
        dt = seeds_mean(_seed_rates(edir, res, DEPLOYMENT_DT))
        if dt is not None and hover in res:
            per.setdefault(w.devices, []).append(float(np.mean(dt - episode_rates(edir, hover))))
    return [(k, judged(v)) for k, v in sorted(per.items())]
