"""The paper's Fig. 3 claims (Sec. V, the abstract, Sec. VI), judged in each track from its evaluation files.

Lives here: :func:`judge_scenario_track` (the paper and strong tracks: the training seed the
unit), :func:`judge_deployment` (the deployment track: the unseen hall the unit), the
learning curves they read (:func:`expert_curve`, :func:`finetune_curve`) and the one rule
that charges both sides of "fewer interactions" (:func:`interactions_needed`). Not here: the
comparison's claim (:mod:`.claims_comparison`), the table (:mod:`.claims`).

Every claim is a paired difference per unit, judged by :func:`uavris.stats.judged`. In the
paper and strong tracks a study is one training seed: its DT, dataset and experts serve both
unseen scenarios, so the scenarios of a seed are averaged into one unit (pooling them as
units would count one seed's luck twice). "Fewer interactions" charges each side the
interactions until it first reaches :data:`LEVEL` of the expert's final evaluation (the
paper's "competitive performance"; zero for a side that starts there); a side that never
reaches it is charged its whole budget, a bound: a verdict resting on such a unit is "not
resolved", since its true value could widen the t interval past zero
(:func:`uavris.stats.judged_censored`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uavris.agents.references import HOVER_OPTIMIZER, ORACLE, ZERO_ACTION
from uavris.config import UNSEEN_SCENARIOS
from uavris.experiments.study.finished import Study
from uavris.experiments.study.judgement import NOT_TESTED, Judgement, judgement
from uavris.experiments.study.tracks import TRACK_SPECS, Track, zero_shot_only
from uavris.experiments.tools.targets import variant_key
from uavris.io import read_csv, read_json
from uavris.stats import HOLDS, NOT_RESOLVED, REFUTED, interactions_to_level, judged, judged_censored

WITHIN = 0.05  # "nearly the same performance" (paper Sec. V): within 5% of the expert's mean
LEVEL = 0.95  # "competitive performance" (abstract): the level both sides of "fewer interactions" must reach
SCENARIO_CLAIMS = ("zero-shot", "finetuned", "near-expert", "fluctuates", "dt-over-bc", "fewer", "fewer-total")


# ------------------------------------------------------------------------------ curves
def episode_rates(edir: Path, row: str) -> np.ndarray:
    """The per-episode average sum rates of ``row`` in the evaluation stage ``edir``."""
    return np.array([float(r["avg_sum_rate"]) for r in read_csv(edir / f"{row}.csv")])


def _imitation_samples(run_dir: Path) -> float:
    """The environment interactions of an expert's imitation rollouts (0 without imitation)."""
    imitation = run_dir / "imitation.csv"
    return float(read_csv(imitation)[-1]["samples"]) if imitation.exists() else 0.0


def expert_curve(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """An expert's periodic evaluations against the environment interactions it had used: an
    expert that imitated the oracle first interacted for its imitation rollouts (the states it
    labelled), so its RL evaluations sit after those, and its imitation rounds' evaluations
    (``evaluate_rounds``) at the rollouts each round had used."""
    imitation = run_dir / "imitation.csv"
    offset = _imitation_samples(run_dir)
    evals = read_csv(run_dir / "evals.csv") if (run_dir / "evals.csv").exists() else []
    x = offset + np.array([float(r["env_steps"]) for r in evals])
    y = np.array([float(r["mean"]) for r in evals])
    rounds = [r for r in read_csv(imitation) if np.isfinite(float(r.get("eval_mean") or "nan"))] \
        if imitation.exists() else []
    if rounds:  # evaluated after every imitation round: the curve's points before any RL step (whose step 0
        after = x > offset  # is the last round's student again)
        x = np.concatenate([[float(r["samples"]) for r in rounds], x[after]])
        y = np.concatenate([[float(r["eval_mean"]) for r in rounds], y[after]])
    elif imitation.exists() and (run_dir / "done.json").exists() and not x.size:  # imitation only: its final score
        x, y = np.array([offset]), np.array([float(read_json(run_dir / "done.json")["final_eval"]["mean"])])
    return x, y


def finetune_curve(model_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """A fine-tuning run's evaluations against its environment interactions (0: the zero-shot DT)."""
    rows = read_csv(model_dir / "finetune.csv")
    return (np.array([float(r["env_interactions"]) for r in rows]), np.array([float(r["eval_mean"]) for r in rows]))


def run_interactions(run_dir: Path) -> float:
    """The environment interactions an expert's training used: its imitation rollouts and RL steps."""
    x, _ = expert_curve(run_dir)
    steps = float(read_json(run_dir / "timing.json").get("env_steps", 0)) if (run_dir / "timing.json").exists() \
        else 0.0
    return max(_imitation_samples(run_dir) + steps, float(x[-1]) if x.size else 0.0)


def interactions_needed(expert: tuple[np.ndarray, np.ndarray], finetune: tuple[np.ndarray, np.ndarray],
                        final: float) -> dict[str, Any]:
    """Both sides of "fewer interactions" charged alike: each the interactions until its curve
    first reaches :data:`LEVEL` x ``final`` (the expert's final evaluation), censored at its
    budget where it never does. Returns the expert's minus fine-tuning's (``difference``),
    and whether that is only a lower bound (the expert censored) or an upper bound
    (fine-tuning censored)."""
    level = LEVEL * final
    need_e, cens_e = interactions_to_level(*expert, level)
    need_f, cens_f = interactions_to_level(*finetune, level)
    return {"level": level, "expert": need_e, "finetune": need_f, "difference": need_e - need_f,
            "low_bound": cens_e, "high_bound": cens_f}


# ------------------------------------------------------------------------------ the scenario tracks
def _scenario_units(studies: Sequence[Study], track: Track) -> list[dict[str, Any]]:
    """One entry per (study seed, unseen scenario) with the evaluation and fine-tuning finished."""
    units = []
    for st in studies:
        if track not in st.config.tracks:
            continue
        _, unseen = st.sites(track)
        pretraining = _pretraining_interactions(st, track)
        experts = st.experts(track, unseen=True)
        for w in unseen:
            found = st.evaluation(track, w.name)
            ft = st.finetuned(track, w.name)
            if found is None or ft is None or experts is None:
                continue
            edir, res = found
            transfers = [k for k, v in res.items() if v["kind"] == "transfer"]
            units.append({"seed": st.config.seed, "site": w.name, "edir": edir, "res": res, "transfers": transfers,
                          "finetune": ft / "model", "expert": experts / "runs" / w.name,
                          "pretraining": pretraining})
    return units


def _pretraining_interactions(st: Study, track: Track) -> float:
    """The interactions behind the DT's pre-training: its training experts' and the dataset's rollouts."""
    experts = st.experts(track)
    total = sum(run_interactions(d) for d in sorted((experts / "runs").iterdir())) if experts else float("nan")
    slots = (st.demonstrations(track) or {}).get("slots")
    return total + float(slots) if slots is not None else float("nan")


def by_seed(seeds: Sequence[int], values: Sequence[float]) -> tuple[list[int], np.ndarray]:
    """The mean of ``values`` over the entries of each seed (its unseen scenarios): one unit a seed."""
    order = sorted(set(seeds))
    return order, np.array([np.mean([v for s, v in zip(seeds, values) if s == k]) for k in order])


def _pair_differences(u: dict[str, Any]) -> dict[str, Any]:
    """What each claim compares in one (seed, scenario) pair (per-episode means and spreads)."""
    edir, res = u["edir"], u["res"]
    z, f, e = (episode_rates(edir, k) for k in ("dt-zero-shot", "dt-finetuned", "expert"))
    t = episode_rates(edir, max(u["transfers"], key=lambda k: res[k]["mean"]))  # the stronger transferred expert
    final = float(read_json(u["expert"] / "done.json")["final_eval"]["mean"])
    fewer = interactions_needed(expert_curve(u["expert"]), finetune_curve(u["finetune"]), final)
    return {"zero-shot": float(np.mean(z - t)), "finetuned": float(np.mean(f - z)),
            "near-expert": float(np.mean(f - (1 - WITHIN) * e)),
            "near-expert-above": float(np.mean((1 + WITHIN) * e - f)),
            "fluctuates": (float(np.std(z, ddof=1) - np.std(f, ddof=1)), float(np.std(t, ddof=1) - np.std(e, ddof=1))),
            "dt-over-bc": float(np.mean(z - episode_rates(edir, "bc"))) if "bc" in res else None,
            "expert-over-zero": float(np.mean(e - episode_rates(edir, ZERO_ACTION))) if ZERO_ACTION in res else None,
            "fewer": fewer, "pretraining": u["pretraining"]}


def within_both_ways(below: Judgement, above: Judgement) -> Judgement:
    """"Within 5% of the expert" read both ways, as an equivalence (two one-sided tests, each
    by its paired 95% CI over the units): ``below`` judges "the DT minus 95% of the expert > 0",
    ``above`` "105% of the expert minus the DT > 0". It holds where both hold, is refuted where
    either is refuted (the DT below 95% of the expert, or above 105% of it: not "nearly the
    same performance"), and is not resolved otherwise. The cell shows the side that decides (a
    refuted side, else one not resolved, else ``below``), the text both; its p-value, which
    Holm's correction reads, is the deciding side's, the larger of the two where both hold (a
    verdict that needs both sides is as sure as its weaker one). A cell that is not judged
    (too few units) is ``below`` as it is."""
    if below.verdict not in (HOLDS, REFUTED, NOT_RESOLVED):
        return below
    sides = (below, above)
    refuted = [j for j in sides if j.verdict == REFUTED]
    unresolved = [j for j in sides if j.verdict == NOT_RESOLVED]
    decides = refuted[0] if refuted else unresolved[0] if unresolved else below
    verdict = REFUTED if refuted else NOT_RESOLVED if unresolved else HOLDS
    p = max(below.p, above.p) if verdict == HOLDS else decides.p
    text = (f"{below.text} ({below.mean:+.2f} [{below.ci_low:+.2f}, {below.ci_high:+.2f}]); and {above.text} "
            f"({above.mean:+.2f} [{above.ci_low:+.2f}, {above.ci_high:+.2f}]): within only where both are above zero")
    return dataclasses.replace(decides, verdict=verdict, p=p, text=text)


def charged_both_ways(whole: Judgement, per_site: Judgement, served: int) -> Judgement:
    """"Fewer interactions, counting pre-training" under both charging rules: ``whole`` charges
    the whole pre-training to each unseen hall or scenario, ``per_site`` spreads it over the
    ``served`` ones it serves (each pays its share). Neither rule is the one true charge, so the
    cell gives a verdict only where both give the same one, and is not resolved otherwise; it
    shows the whole charge, its text both, and its p-value (which Holm's correction reads) is
    the larger of the two where they agree (a verdict that needs both is as sure as its weaker
    one) and 1 where they do not (no evidence for either verdict: it must not take an early rank
    in Holm's order and loosen the others' thresholds). A cell that is not judged (too few
    units) is ``whole`` as it is."""
    if whole.verdict not in (HOLDS, REFUTED, NOT_RESOLVED):
        return whole
    agree = whole.verdict == per_site.verdict
    text = (f"{whole.text}, charged whole to each ({whole.mean:+,.0f} [{whole.ci_low:+,.0f}, {whole.ci_high:+,.0f}]: "
            f"{whole.verdict}) and spread over the {served} it serves ({per_site.mean:+,.0f} [{per_site.ci_low:+,.0f}, "
            f"{per_site.ci_high:+,.0f}]: {per_site.verdict}); a verdict only where both rules give it")
    return dataclasses.replace(whole, verdict=whole.verdict if agree else NOT_RESOLVED, text=text,
                               p=max(whole.p, per_site.p) if agree else 1.0)


def against_a_real_expert(near: Judgement, expert_over_zero: dict[str, Any] | None) -> Judgement:
    """"Within 5% of the expert" says something only of an expert that does better than doing
    nothing. Where the expert is not above the zero action by its paired 95% CI over the same
    units (``expert_over_zero``, :func:`uavris.stats.judged`'s), the zero action would "hold" as
    well, so a "holds" becomes "not resolved" and the cell says why; a "refuted" stands (the DT
    is outside 95-105% of even that expert)."""
    if expert_over_zero is None or expert_over_zero["verdict"] == HOLDS or near.verdict != HOLDS:
        return near
    d = expert_over_zero
    return dataclasses.replace(near, verdict=NOT_RESOLVED, text=(
        f"{near.text}; vacuous here: the expert is not above the zero action (expert minus zero action "
        f"{d['mean']:+.2f} [{d['ci_low']:+.2f}, {d['ci_high']:+.2f}] bps/Hz), which would come within 5% of it too"))


def judge_scenario_track(studies: Sequence[Study], track: Track) -> list[Judgement]:
    """The Fig. 3 claims in the paper's unseen scenarios, one unit per training seed."""
    units = _scenario_units(studies, track)
    name = track.name
    # a seed is a unit only with every unseen scenario of it finished (its mean is over all of them)
    sites = {u["site"] for u in units}
    units = [u for u in units if sum(v["seed"] == u["seed"] for v in units) == len(sites)]
    if not units:
        return [Judgement(c, name, NOT_TESTED, text="no unit finished") for c in SCENARIO_CLAIMS]
    pairs = [_pair_differences(u) for u in units]
    seeds = [u["seed"] for u in units]
    unit = (f"training seeds {sorted(set(seeds))}, each the mean of its unseen scenarios "
            f"{sorted({u['site'] for u in units})}")

    def per_seed(key: str, at: int | None = None) -> dict[str, Any]:
        _, v = by_seed(seeds, [p[key] if at is None else p[key][at] for p in pairs])
        return judged(v)

    out = [judgement("zero-shot", name, per_seed("zero-shot"), unit, "seeds",
                     "zero-shot DT minus the stronger transferred expert, bps/Hz, paired on the evaluation episodes"),
           judgement("finetuned", name, per_seed("finetuned"), unit, "seeds",
                     "fine-tuned DT minus the zero-shot DT it started from, bps/Hz"),
           against_a_real_expert(within_both_ways(
               judgement("near-expert", name, per_seed("near-expert"), unit, "seeds",
                         f"fine-tuned DT minus {1 - WITHIN:.0%} of the expert trained in the scenario, bps/Hz"),
               judgement("near-expert", name, per_seed("near-expert-above"), unit, "seeds",
                         f"{1 + WITHIN:.0%} of the expert minus the fine-tuned DT")),
               None if any(p["expert-over-zero"] is None for p in pairs) else per_seed("expert-over-zero")),
           judgement("fluctuates", name, per_seed("fluctuates", 0), unit, "seeds",
                     "the zero-shot DT's spread over evaluation episodes (standard deviation of each episode's "
                     "average sum rate) minus the fine-tuned DT's, bps/Hz"),
           judgement("fluctuates", name, per_seed("fluctuates", 1), unit, "seeds",
                     "the stronger transferred expert's spread minus the scenario's expert's (the cell's second "
                     "entry)")]
    lacking = sorted({s for s, p in zip(seeds, pairs) if p["dt-over-bc"] is None})
    if not lacking:
        out.append(judgement("dt-over-bc", name, per_seed("dt-over-bc"), unit, "seeds",
                             "zero-shot DT minus behaviour cloning on the same dataset, bps/Hz"))
    else:
        out.append(Judgement("dt-over-bc", name, NOT_TESTED, text=f"the studies of seeds {lacking} have no behaviour "
                             "cloning row (made by an earlier uavris: run them again)"))
    return out + _fewer(name, seeds, pairs, unit)


def _fewer(name: str, seeds: list[int], pairs: list[dict[str, Any]], unit: str) -> list[Judgement]:
    """"Fewer interactions" over seeds: a seed's difference is a lower (upper) bound where one of
    its scenarios' is."""
    order, diff = by_seed(seeds, [p["fewer"]["difference"] for p in pairs])
    _, total = by_seed(seeds, [p["fewer"]["difference"] - p["pretraining"] for p in pairs])
    served = len(UNSEEN_SCENARIOS)  # one pre-training serves every unseen scenario
    _, shared = by_seed(seeds, [p["fewer"]["difference"] - p["pretraining"] / served for p in pairs])
    low = np.array([any(p["fewer"]["low_bound"] for s, p in zip(seeds, pairs) if s == k) for k in order])
    high = np.array([any(p["fewer"]["high_bound"] for s, p in zip(seeds, pairs) if s == k) for k in order])
    lows, highs = sum(p["fewer"]["low_bound"] for p in pairs), sum(p["fewer"]["high_bound"] for p in pairs)
    censored = (f"; the expert never reached the level in {lows} and fine-tuning in {highs} of {len(pairs)} "
                "scenario runs (their budgets counted: bounds, on which no verdict rests)") if lows or highs else ""
    rule = (f"interactions the scenario's expert needed to first reach {LEVEL:.0%} of its final evaluation minus "
            "those fine-tuning needed (0 where the zero-shot DT starts there)")
    return [judgement("fewer", name, judged_censored(diff, low, high), unit, "seeds", rule + censored),
            charged_both_ways(
                judgement("fewer-total", name, judged_censored(total, low, high), unit, "seeds",
                          "the same minus the pre-training's interactions (its experts' training and the dataset)"
                          + censored),
                judgement("fewer-total", name, judged_censored(shared, low, high), unit, "seeds", ""),
                served)]


# ------------------------------------------------------------------------------ the deployment track
DEPLOYMENT_DT = variant_key("dt-zero-shot", safe=True)  # the paper's DT (return-conditioned) under the safety layer
GOAL_DT = variant_key("dt-goal", safe=True)  # the goal-conditioned DT told the semi-amortised place
FINETUNED_DTS = (variant_key("dt-goal-finetuned", safe=True), variant_key("dt-finetuned", safe=True))
# The fine-tuning claims are the paper's: its DT fine-tuned by its Algorithm 1 where every hall has it,
# else uavris's goal-conditioned DT fine-tuned by trying places, named in each cell's text.
FINETUNING = ((FINETUNED_DTS[1], DEPLOYMENT_DT, "the paper's DT fine-tuned in the hall by its Algorithm 1"),
              (FINETUNED_DTS[0], GOAL_DT, "uavris's goal-conditioned DT fine-tuned in the hall by trying places"))
BC = variant_key("bc", safe=True)


def _seeds_mean(edir: Path, res: dict[str, Any], variant: str) -> np.ndarray | None:
    """Per episode, the mean over the pre-training seeds of a row's variant (None: no such row)."""
    keys = [k for k, s in res.items() if s.get("variant") == variant]
    return np.mean([episode_rates(edir, k) for k in keys], axis=0) if keys else None


def _seeds_spread(edir: Path, res: dict[str, Any], variant: str) -> float | None:
    """The spread over episodes (standard deviation) of a row's variant, averaged over its
    pre-training seeds (the spread of their mean would shrink with their number)."""
    keys = [k for k, s in res.items() if s.get("variant") == variant]
    return float(np.mean([np.std(episode_rates(edir, k), ddof=1) for k in keys])) if keys else None


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


def judge_deployment(study: Study, from_scratch: Sequence[dict[str, Any]] = ()) -> list[Judgement]:
    """The Fig. 3 claims over the unseen halls (the unit), each hall's learned rows averaged
    over the pre-training seeds. The transferred expert is the nearest training hall's oracle
    plan; the expert trained where the DT is deployed is the oracle (whose demonstrations the
    DT learned from). Fine-tuning is the paper's DT fine-tuned by its Algorithm 1 where every
    hall has it, else the goal-conditioned DT fine-tuned by trying places (``--ablation``): one
    of the two for all halls, named in each cell.
    ``from_scratch``: per hall, what ``uavris from-scratch`` measured (:mod:`.from_scratch`:
    an expert trained from scratch in the hall, its learning curve)."""
    track = TRACK_SPECS["deployment"]
    _, unseen = study.sites(track)
    rows: dict[str, list[float]] = {k: [] for k in ("zero-shot", "goal", "fluct-expert", "dt-over-bc",
                                                      *(f"{c} {v}" for c in ("finetuned", "near-expert",
                                                                              "near-expert-above", "fluct-dt")
                                                        for v, _, _ in FINETUNING))}
    names = []
    for w in unseen:
        found = None if zero_shot_only(w, study.config.system) else study.evaluation(track, w.name)
        if found is None:
            continue
        edir, res = found
        dt = _seeds_mean(edir, res, DEPLOYMENT_DT)
        transfer = [k for k, v in res.items() if v["kind"] == "transfer" and v["rank"] == 0]
        if dt is None or not transfer:
            continue
        names.append(w.name)
        moved = episode_rates(edir, transfer[0])
        oracle = episode_rates(edir, variant_key(ORACLE, safe=True))
        rows["zero-shot"].append(float(np.mean(dt - moved)))
        told = _seeds_mean(edir, res, GOAL_DT)
        if told is not None:
            rows["goal"].append(float(np.mean(told - moved)))
        bc = _seeds_mean(edir, res, BC)
        if bc is not None:
            rows["dt-over-bc"].append(float(np.mean(dt - bc)))
        rows["fluct-expert"].append(float(np.std(moved, ddof=1) - np.std(oracle, ddof=1)))
        for fine_variant, start_variant, _ in FINETUNING:
            fine = _seeds_mean(edir, res, fine_variant)
            start = _seeds_mean(edir, res, start_variant)
            if fine is not None and start is not None:
                rows[f"finetuned {fine_variant}"].append(float(np.mean(fine - start)))
                rows[f"near-expert {fine_variant}"].append(float(np.mean(fine - (1 - WITHIN) * oracle)))
                rows[f"near-expert-above {fine_variant}"].append(float(np.mean((1 + WITHIN) * oracle - fine)))
                before, after = (_seeds_spread(edir, res, v) or 0.0 for v in (start_variant, fine_variant))
                rows[f"fluct-dt {fine_variant}"].append(before - after)
    unit = f"{len(names)} unseen halls, each the mean of its pre-training seeds"
    if not names:
        return [Judgement(c, "deployment", NOT_TESTED, text="no unseen hall evaluated") for c in SCENARIO_CLAIMS]

    def complete(key: str) -> bool:
        return len(rows[key]) == len(names)

    out = [judgement("zero-shot", "deployment", judged(rows["zero-shot"]), unit, "halls",
                     "zero-shot DT (return-conditioned, safety layer) minus the nearest training hall's oracle plan, "
                     "bps/Hz")]
    if complete("goal"):
        out.append(judgement("zero-shot", "deployment", judged(rows["goal"]), unit, "halls",
                             "the same for the goal-conditioned DT told the semi-amortised place (uavris's "
                             "controller; the cell's second entry)"))
    ablation = "fine-tuning in the unseen halls runs with --ablation only"
    judged_ft = next(((v, what) for v, _, what in FINETUNING if complete(f"finetuned {v}")), None)
    if judged_ft is not None:
        v, what = judged_ft
        out += [judgement("finetuned", "deployment", judged(rows[f"finetuned {v}"]), unit, "halls",
                          f"{what}, minus the same DT zero-shot, both under the safety layer, bps/Hz"),
                within_both_ways(
                    judgement("near-expert", "deployment", judged(rows[f"near-expert {v}"]), unit, "halls",
                              f"{what}, minus {1 - WITHIN:.0%} of the oracle (the track's expert), "
                              "both under the safety layer, bps/Hz"),
                    judgement("near-expert", "deployment", judged(rows[f"near-expert-above {v}"]), unit, "halls",
                              f"{1 + WITHIN:.0%} of the oracle minus {what}")),
                judgement("fluctuates", "deployment", judged(rows[f"fluct-dt {v}"]), unit, "halls",
                          f"the zero-shot DT's spread over evaluation episodes minus that of {what} (each the "
                          "mean of its seeds' standard deviations), bps/Hz")]
    else:
        out += [Judgement(c, "deployment", NOT_TESTED, text=ablation) for c in ("finetuned", "near-expert")]
        out.append(Judgement("fluctuates", "deployment", NOT_TESTED, text=ablation + " (its first entry)"))
    out.append(judgement("fluctuates", "deployment", judged(rows["fluct-expert"]), unit, "halls",
                         "the nearest training hall's plan's spread minus the oracle's (the cell's last entry), "
                         "bps/Hz"))
    out.append(judgement("dt-over-bc", "deployment", judged(rows["dt-over-bc"]), unit, "halls",
                         "zero-shot DT minus behaviour cloning on the same demonstrations (both under the safety "
                         "layer, means of their seeds), bps/Hz") if complete("dt-over-bc") else
               Judgement("dt-over-bc", "deployment", NOT_TESTED, text="no behaviour cloning row"))
    return out + _deployment_fewer(study, track, from_scratch)


def _deployment_fewer(study: Study, track: Track, from_scratch: Sequence[dict[str, Any]]) -> list[Judgement]:
    """"Fewer interactions" in the halls ``uavris from-scratch`` measured: the from-scratch
    expert's curve against each seed's fine-tuning curve (places tried), by :func:`interactions_needed`."""
    if not from_scratch:
        return [Judgement(c, "deployment", NOT_TESTED, text="needs the measurement of uavris from-scratch")
                for c in ("fewer", "fewer-total")]
    if any("expert_curve" not in h for h in from_scratch):
        return [Judgement(c, "deployment", NOT_TESTED, text="its from-scratch.json holds no learning curves (made by "
                          "an earlier uavris): run uavris from-scratch again") for c in ("fewer", "fewer-total")]
    diff, low, high = [], [], []
    for h in from_scratch:
        x, y = (np.asarray(v, dtype=np.float64) for v in h["expert_curve"])
        res = (study.evaluation(track, h["hall"]) or (None, {}))[1]
        seeds = sorted({v["seed"] or 0 for v in res.values() if v.get("variant") == FINETUNED_DTS[0]})
        needs = [interactions_needed((x, y), finetune_curve(t[0] / "model"), float(y[-1]))
                 for t in (study.places_tried(track, h["hall"], s) for s in seeds) if t is not None]
        if not needs:
            continue
        diff.append(float(needs[0]["expert"] - np.mean([n["finetune"] for n in needs])))
        low.append(needs[0]["low_bound"])
        high.append(any(n["high_bound"] for n in needs))
    pre = float((study.demonstrations(track) or {})["slots"])
    unit = f"{len(diff)} unseen halls (uavris from-scratch), fine-tuning the mean of its seeds"
    rule = (f"interactions hybrid PPO from scratch needed to first reach {LEVEL:.0%} of its final evaluation minus "
            "those fine-tuning by trying places needed (0 where its zero-shot start is there); a side that never "
            "does is charged its budget, a bound, on which no verdict rests. Not alike: fine-tuning's curve is its "
            "own evaluations (8 "
            "episodes, without the safety layer), the expert's the study's episodes under it")
    served = sum(1 for w in study.sites(track)[1] if not zero_shot_only(w, study.config.system))
    return [judgement("fewer", "deployment", judged_censored(diff, low, high), unit, "halls", rule),
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
    per: dict[int, list[float]] = {}
    for w in unseen:
        if w.split != "unseen" or (found := study.evaluation(track, w.name)) is None:
            continue
        edir, res = found
        dt = _seeds_mean(edir, res, DEPLOYMENT_DT)
        hover = variant_key(HOVER_OPTIMIZER, safe=True)
        if dt is not None and hover in res:
            per.setdefault(w.devices, []).append(float(np.mean(dt - episode_rates(edir, hover))))
    return [(k, judged(v)) for k, v in sorted(per.items())]
