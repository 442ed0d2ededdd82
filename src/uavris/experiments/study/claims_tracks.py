"""The paper's Fig. 3 claims (Sec. V, the abstract, Sec. VI), judged in each track from its evaluation files.

Lives here: :func:`judge_scenario_track` (the paper and strong tracks: the training seed the
unit), the learning curves the claims read (:func:`expert_curve`, :func:`finetune_curve`), the
one rule that charges both sides of "fewer interactions" (:func:`interactions_needed`) and the
cells' shared rules (:func:`within_both_ways`, :func:`charged_both_ways`). Not here: the
deployment track (:mod:`.claims_deployment`), the comparison's claim
(:mod:`.claims_comparison`), the table (:mod:`.claims`).

Every claim is a paired difference per unit, judged by :func:`uavris.stats.judged`. In the
paper and strong tracks a study is one training seed: its DT, dataset and experts serve both
unseen scenarios, so the scenarios of a seed are averaged into one unit (pooling them as
units would count one seed's luck twice). "Fewer interactions" charges each side the
interactions until it first reaches :data:`LEVEL` of the expert's final evaluation (the
paper's "competitive performance"; zero for a side that starts there); a side that never
reaches it is charged its whole budget, a bound: a verdict resting on such a unit is "not
resolved", since its true value could widen the t interval past zero
(:func:`uavris.stats.judged_censored`), and its p-value is 1 (:func:`.judgement.judgement`). Where
the zero-shot DT already starts at the level, fine-tuning is charged nothing and the
difference is the pre-training's: each cell says in how many runs, and "fewer-finetuning"
judges fine-tuning's own part apart.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uavris.agents.references import ZERO_ACTION
from uavris.config import UNSEEN_SCENARIOS
from uavris.experiments.study.finished import Study
from uavris.experiments.study.judgement import NOT_TESTED, Judgement, judgement
from uavris.experiments.study.tracks import Track
from uavris.io import read_csv, read_json
from uavris.stats import HOLDS, NOT_RESOLVED, REFUTED, interactions_to_level, judged, judged_censored

WITHIN = 0.05  # "nearly the same performance" (paper Sec. V): within 5% of the expert's mean
LEVEL = 0.95  # "competitive performance" (abstract): the level both sides of "fewer interactions" must reach
SCENARIO_CLAIMS = ("zero-shot", "finetuned", "near-expert", "fluctuates", "dt-over-bc", "fewer", "fewer-finetuning",
                   "fewer-total")


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
    (fine-tuning censored), and whether the zero-shot DT was already there (``zero_shot_there``:
    fine-tuning charged nothing, the whole difference the pre-training's)."""
    level = LEVEL * final
    need_e, cens_e = interactions_to_level(*expert, level)
    need_f, cens_f = interactions_to_level(*finetune, level)
    return {"level": level, "expert": need_e, "finetune": need_f, "difference": need_e - need_f,
            "low_bound": cens_e, "high_bound": cens_f, "zero_shot_there": need_f == 0 and not cens_f}


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


def _pair_differences(u: dict[str, Any], evidence: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """What each claim compares in one (seed, scenario) pair (per-episode means and spreads);
    what it read appended to ``evidence`` (the rows' per-episode rates, both curves, the expert's
    final evaluation, the pre-training's interactions: the claims page's evidence)."""
    edir, res = u["edir"], u["res"]
    z, f, e = (episode_rates(edir, k) for k in ("dt-zero-shot", "dt-finetuned", "expert"))
    stronger = max(u["transfers"], key=lambda k: res[k]["mean"])  # the stronger transferred expert
    t = episode_rates(edir, stronger)
    bc = episode_rates(edir, "bc") if "bc" in res else None
    zero = episode_rates(edir, ZERO_ACTION) if ZERO_ACTION in res else None
    final = float(read_json(u["expert"] / "done.json")["final_eval"]["mean"])
    curves = expert_curve(u["expert"]), finetune_curve(u["finetune"])
    fewer = interactions_needed(*curves, final)
    if evidence is not None:
        rows = {"dt-zero-shot": z, "dt-finetuned": f, "expert": e, "transfer": t, "bc": bc, ZERO_ACTION: zero}
        evidence.append({"seed": u["seed"], "site": u["site"], "transfer": stronger,
                         "rows": {k: v.tolist() for k, v in rows.items() if v is not None},
                         "expert_curve": [c.tolist() for c in curves[0]],
                         "finetune_curve": [c.tolist() for c in curves[1]],
                         "expert_final": final, "pretraining": u["pretraining"]})
    return {"zero-shot": float(np.mean(z - t)), "finetuned": float(np.mean(f - z)),
            "near-expert": float(np.mean(f - (1 - WITHIN) * e)),
            "near-expert-above": float(np.mean((1 + WITHIN) * e - f)),
            "fluctuates": (float(np.std(z, ddof=1) - np.std(f, ddof=1)), float(np.std(t, ddof=1) - np.std(e, ddof=1))),
            "dt-over-bc": float(np.mean(z - bc)) if bc is not None else None,
            "expert-over-zero": float(np.mean(e - zero)) if zero is not None else None,
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


def judge_scenario_track(studies: Sequence[Study], track: Track,
                         evidence: list[dict[str, Any]] | None = None) -> list[Judgement]:
    """The Fig. 3 claims in the paper's unseen scenarios, one unit per training seed; what each
    (seed, scenario) pair read appended to ``evidence`` (:func:`_pair_differences`)."""
    units = _scenario_units(studies, track)
    name = track.name
    # a seed is a unit only with every unseen scenario of it finished (its mean is over all of them)
    sites = {u["site"] for u in units}
    units = [u for u in units if sum(v["seed"] == u["seed"] for v in units) == len(sites)]
    if not units:
        return [Judgement(c, name, NOT_TESTED, text="no unit finished") for c in SCENARIO_CLAIMS]
    pairs = [_pair_differences(u, evidence) for u in units]
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
    its scenarios' is. Said per unit: in how many scenario runs the zero-shot DT was already at
    the level (fine-tuning charged nothing there: that part of the difference is the
    pre-training's); "fewer-finetuning" judges fine-tuning's own part, over the seeds with a
    scenario run where the zero-shot DT was not there (each the mean of those runs)."""
    order, diff = by_seed(seeds, [p["fewer"]["difference"] for p in pairs])
    _, total = by_seed(seeds, [p["fewer"]["difference"] - p["pretraining"] for p in pairs])
    served = len(UNSEEN_SCENARIOS)  # one pre-training serves every unseen scenario
    _, shared = by_seed(seeds, [p["fewer"]["difference"] - p["pretraining"] / served for p in pairs])
    low = np.array([any(p["fewer"]["low_bound"] for s, p in zip(seeds, pairs) if s == k) for k in order])
    high = np.array([any(p["fewer"]["high_bound"] for s, p in zip(seeds, pairs) if s == k) for k in order])
    lows, highs = sum(p["fewer"]["low_bound"] for p in pairs), sum(p["fewer"]["high_bound"] for p in pairs)
    censored = (f"; the expert never reached the level in {lows} and fine-tuning in {highs} of {len(pairs)} "
                "scenario runs (their budgets counted: bounds, on which no verdict rests)") if lows or highs else ""
    there = [p["fewer"]["zero_shot_there"] for p in pairs]
    zero_shot = (f"; the zero-shot DT was already at the level in {sum(there)} of {len(pairs)} scenario runs "
                 "(fine-tuning charged 0 there: that part of the difference is the pre-training's, not fine-tuning's)")
    rule = (f"interactions the scenario's expert needed to first reach {LEVEL:.0%} of its final evaluation minus "
            "those the DT needed, zero-shot start included (0 where the zero-shot DT starts there)")
    worked = [(s, p) for s, p in zip(seeds, pairs) if not p["fewer"]["zero_shot_there"]]
    w_order, w_diff = by_seed([s for s, _ in worked], [p["fewer"]["difference"] for _, p in worked])
    w_low = np.array([any(p["fewer"]["low_bound"] for s, p in worked if s == k) for k in w_order], dtype=bool)
    w_high = np.array([any(p["fewer"]["high_bound"] for s, p in worked if s == k) for k in w_order], dtype=bool)
    own = (judgement("fewer-finetuning", name, judged_censored(w_diff, w_low, w_high),
                     f"training seeds {w_order}, each the mean of its scenario runs where the zero-shot DT was not "
                     "at the level", "seeds",
                     f"the same where fine-tuning had work to do (the zero-shot DT below the level): {len(worked)} of "
                     f"{len(pairs)} scenario runs") if worked else
           Judgement("fewer-finetuning", name, NOT_TESTED, text=f"the zero-shot DT was already at the level in every "
                                                                f"one of the {len(pairs)} scenario runs"))
    return [judgement("fewer", name, judged_censored(diff, low, high), unit, "seeds", rule + zero_shot + censored),
            own,
            charged_both_ways(
                judgement("fewer-total", name, judged_censored(total, low, high), unit, "seeds",
                          "the same minus the pre-training's interactions (its experts' training and the dataset)"
                          + censored),
                judgement("fewer-total", name, judged_censored(shared, low, high), unit, "seeds", ""),
                served)]
