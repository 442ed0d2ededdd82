"""The paper's three claims, judged in every track by one rule: ``uavris claims OUT [OUT ...]``.

Lives here: :data:`CLAIMS` (what the paper claims, in our words), :class:`Judgement` (one
claim in one track: its verdict, the paired difference that decides it and its 95% CI over
the unit of generalisation), :func:`judge_studies` (every claim of every track of one or
more studies, the paper and strong tracks pooled over studies run with ``--seed 0, 1, 2``)
and :func:`claims_table` (the claim x track table the README and the results page open
with). Not here: the rule itself (:func:`uavris.stats.verdict`: "holds" where the CI excludes
zero the claimed way, "refuted" the other way, "not resolved" otherwise), the studies' stages
(:mod:`.pipeline`), the report of one study (:mod:`.report`).

The units: in the paper and strong tracks one unit is a (training seed, unseen scenario)
pair, every learned model of it trained with that seed; in the deployment track a unit is an
unseen hall, its learned rows averaged over the pre-training seeds. Within a unit two rows
are compared on the same evaluation episodes (their per-episode difference averaged).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from uavris.agents.references import ORACLE
from uavris.errors import UavrisError
from uavris.experiments.display.tables import markdown_table
from uavris.experiments.study.finished import Study
from uavris.experiments.study.tracks import TRACK_SPECS, TRACKS, Track, zero_shot_only
from uavris.experiments.tools.targets import variant_key
from uavris.io import atomic_write_text, other_inputs, read_csv, read_json, write_json
from uavris.stats import HOLDS, NOT_RESOLVED, REFUTED, judged, paired_difference, steps_to_level, welch_difference

WITHIN = 0.05  # "nearly the same performance" (paper Sec. IV-C): within 5% of the expert's mean
CLAIMS: dict[str, str] = {
    "ddpg-best": "DDPG trains the best expert of DDPG, PPO, SAC and TD3 (Fig. 2)",
    "zero-shot": "the zero-shot DT scores above the experts transferred from training deployments (Fig. 3)",
    "near-expert": f"the fine-tuned DT is within {WITHIN:.0%} of the expert trained where it is deployed (Fig. 3)",
    "fewer": "fine-tuning needs fewer environment interactions than that expert needs to reach the fine-tuned "
             "level (Sec. IV-C)",
    "fewer-total": "the same, counting the interactions of the experts and demonstrations the DT was pre-trained on",
}
NOT_TESTED = "not tested"


@dataclass(frozen=True)
class Judgement:
    """One claim in one track: the mean paired difference over ``n`` units (``unit``), its 95%
    CI, the verdict, and what was compared (``text``, one sentence)."""

    claim: str
    track: str
    verdict: str
    mean: float = float("nan")
    ci_low: float = float("nan")
    ci_high: float = float("nan")
    n: int = 0
    unit: str = ""
    text: str = ""

    @property
    def cell(self) -> str:
        if self.verdict == NOT_TESTED:
            return "-"
        f = ",.0f" if abs(self.mean) >= 1000 else ",.2f"  # interactions as counts, rates to the hundredth
        ci = "" if math.isnan(self.ci_low) else f" [{self.ci_low:+{f}}, {self.ci_high:+{f}}]"
        return f"**{self.verdict}**: {self.mean:+{f}}{ci}"


def _judged(claim: str, track: str, diff: dict[str, Any], unit: str, text: str) -> Judgement:
    return Judgement(claim, track, diff["verdict"], diff["mean"], diff["ci_low"], diff["ci_high"], diff["n"], unit,
                     text)


# ------------------------------------------------------------------------------ reading a study
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
    labelled), so its evaluations sit after those."""
    imitation = run_dir / "imitation.csv"
    offset = _imitation_samples(run_dir)
    evals = read_csv(run_dir / "evals.csv") if (run_dir / "evals.csv").exists() else []
    x = offset + np.array([float(r["env_steps"]) for r in evals])
    y = np.array([float(r["mean"]) for r in evals])
    if imitation.exists() and (run_dir / "done.json").exists() and not x.size:  # imitation only: its final score
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


# ------------------------------------------------------------------------------ the comparison (Fig. 2)
def judge_comparison(scores: dict[str, Sequence[float]], track: str = "paper", budget: str = "") -> Judgement:
    """"DDPG is best" from each algorithm's final scores over its seeds (independent runs, so
    Welch's interval): holds where DDPG is above each other algorithm, refuted where another is
    above DDPG, each by a CI excluding zero; the estimate is DDPG minus the best other."""
    if "ddpg" not in scores or len(scores) < 2:
        return Judgement("ddpg-best", track, NOT_TESTED, text="the comparison has no DDPG run and another")
    others = {a: welch_difference(scores["ddpg"], s) for a, s in scores.items() if a != "ddpg"}
    closest = min(others, key=lambda a: others[a]["mean"])
    if any(d["verdict"] == REFUTED for d in others.values()):
        v = REFUTED
    elif all(d["verdict"] == HOLDS for d in others.values()):
        v = HOLDS
    else:
        v = NOT_RESOLVED
    n = len(scores["ddpg"])
    above = ", ".join(f"{a.upper()} {d['mean']:+.2f} " + ("(no interval: one seed)" if math.isnan(d["ci_low"]) else
                                                          f"[{d['ci_low']:+.2f}, {d['ci_high']:+.2f}]")
                      for a, d in others.items())
    seeds = ", ".join(f"{a.upper()} {len(s)}" for a, s in scores.items())
    return Judgement("ddpg-best", track, v, others[closest]["mean"], others[closest]["ci_low"],
                     others[closest]["ci_high"], n, "training seeds per algorithm",
                     f"DDPG minus each algorithm{budget} (seeds: {seeds}; Welch): {above}")


def comparison_scores(cdir: Path, steps: int | None = None) -> dict[str, list[float]]:
    """Each algorithm's scores over its seeds in a comparison: the final evaluations
    (``final_per_run.csv``), or with ``steps`` the first periodic evaluation at or after that many environment
    steps (a run of N steps evaluated at B < N is the run of budget B: the schedules are constant)."""
    scores: dict[str, list[float]] = {}
    if steps is None:
        for r in read_csv(cdir / "final_per_run.csv"):
            scores.setdefault(r["algo"], []).append(float(r["final_eval_mean"]))
        return scores
    for algo, curves in eval_curves(cdir).items():
        for x, y in curves:
            at = y[x >= steps]
            if at.size:  # the first evaluation at or after the budget (PPO evaluates at the end of a rollout)
                scores.setdefault(algo, []).append(float(at[0]))
    return scores


def eval_curves(cdir: Path) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """Each algorithm's runs in a comparison, in seed order: their periodic evaluations
    (environment steps, mean over the episodes); a run without any yet is left out."""
    from uavris.experiments.training.train_expert import load_run_config

    runs: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for run in sorted((Path(cdir) / "runs").iterdir(), key=lambda r: load_run_config(r).seed):
        rows = read_csv(run / "evals.csv") if (run / "evals.csv").exists() else []
        if rows:
            runs.setdefault(load_run_config(run).algo, []).append(
                (np.array([float(r["env_steps"]) for r in rows]), np.array([float(r["mean"]) for r in rows])))
    return runs


def fig2_zero_action() -> float:
    """The zero action's mean in ``fig2`` of the paper's system on the comparison's 32 episodes."""
    from uavris.agents.evaluation import evaluate
    from uavris.agents.references import ZERO_ACTION, reference_policy
    from uavris.config import SystemConfig
    from uavris.presets import EVAL_SEED

    return float(evaluate(reference_policy(ZERO_ACTION, SystemConfig()), SystemConfig(), "fig2", 32,
                          EVAL_SEED).avg_sum_rate.mean())


# ------------------------------------------------------------------------------ the scenario tracks
def _scenario_units(studies: Sequence[Study], track: Track) -> list[dict[str, Any]]:
    """One unit per (study seed, unseen scenario) with the evaluation and fine-tuning finished."""
    units = []
    for st in studies:
        if track not in st.config.tracks:
            continue
        _, unseen = st.sites(track)
        train_cost = _pretraining_interactions(st, track)
        for w in unseen:
            found = st.evaluation(track, w.name)
            ft = st.done(track.stage(f"finetune-{w.name}"))
            experts = st.done(track.stage("experts-unseen"))
            if found is None or ft is None or experts is None:
                continue
            edir, res = found
            transfers = [k for k, v in res.items() if v["kind"] == "transfer"]
            units.append({"seed": st.config.seed, "site": w.name, "edir": edir, "res": res, "transfers": transfers,
                          "finetune": ft / "model", "expert": experts / "runs" / w.name, "pretraining": train_cost})
    return units


def _pretraining_interactions(st: Study, track: Track) -> float:
    """The interactions behind the DT's pre-training: its training experts' and the dataset's rollouts."""
    experts = st.done(track.stage("experts-train"))
    total = sum(run_interactions(d) for d in sorted((experts / "runs").iterdir())) if experts else float("nan")
    slots = (st.result(track.stage("dataset")) or {}).get("slots")
    return total + float(slots) if slots is not None else float("nan")


def _stronger(edir: Path, res: dict[str, Any], keys: Sequence[str]) -> tuple[str, np.ndarray]:
    key = max(keys, key=lambda k: res[k]["mean"])
    return key, episode_rates(edir, key)


def judge_scenario_track(studies: Sequence[Study], track: Track) -> list[Judgement]:
    """The Fig. 3 claims in the paper's unseen scenarios, over (seed, scenario) units."""
    units = _scenario_units(studies, track)
    name = track.name
    if not units:
        return [Judgement(c, name, NOT_TESTED, text="no unit finished") for c in ("zero-shot", "near-expert", "fewer",
                                                                                  "fewer-total")]
    seeds = sorted({u["seed"] for u in units})
    unit = f"(seed, scenario) pairs: seeds {seeds} x {sorted({u['site'] for u in units})}"
    zs, ft, fewer, total, censored = [], [], [], [], 0
    for u in units:
        edir, res = u["edir"], u["res"]
        z = episode_rates(edir, "dt-zero-shot")
        _, t = _stronger(edir, res, u["transfers"])
        zs.append(float(np.mean(z - t)))
        f, e = episode_rates(edir, "dt-finetuned"), episode_rates(edir, "expert")
        ft.append(float(np.mean(f - (1 - WITHIN) * e)))
        fx, _ = finetune_curve(u["finetune"])
        x, y = expert_curve(u["expert"])
        need = steps_to_level(x, y, float(res["dt-finetuned"]["mean"]))
        if math.isnan(need):  # never reached in its budget: its whole budget is a lower bound
            censored += 1
            need = float(x[-1]) if x.size else float("nan")
        fewer.append(need - float(fx[-1]))
        total.append(need - float(fx[-1]) - u["pretraining"])
    note = (f"; the expert never reached the level in {censored} of {len(units)} units (its budget counted, a lower "
            "bound)") if censored else ""
    return [
        _judged("zero-shot", name, judged(zs), unit,
                "zero-shot DT minus the stronger transferred expert, bps/Hz, paired on the evaluation episodes"),
        _judged("near-expert", name, judged(ft), unit,
                f"fine-tuned DT minus {1 - WITHIN:.0%} of the expert trained in the scenario, bps/Hz"),
        _judged("fewer", name, judged(fewer), unit,
                "interactions the expert needed to reach the fine-tuned DT's level minus fine-tuning's" + note),
        _judged("fewer-total", name, judged(total), unit,
                "the same minus the pre-training's interactions (its experts' training and the dataset)" + note),
    ]


# ------------------------------------------------------------------------------ the deployment track
DEPLOYMENT_DT = variant_key("dt-zero-shot", safe=True)  # the paper's DT (return-conditioned) under the safety layer
GOAL_DT = variant_key("dt-goal", safe=True)  # the goal-conditioned DT told the learned planner's place
FINETUNED_DTS = (variant_key("dt-goal-finetuned", safe=True), variant_key("dt-finetuned", safe=True))


def _seeds_mean(edir: Path, res: dict[str, Any], variant: str) -> np.ndarray | None:
    """Per episode, the mean over the pre-training seeds of a row's variant (None: no such row)."""
    keys = [k for k, s in res.items() if s.get("variant") == variant]
    return np.mean([episode_rates(edir, k) for k in keys], axis=0) if keys else None


def judge_deployment(study: Study, from_scratch: Sequence[dict[str, float]] = ()) -> list[Judgement]:
    """The Fig. 3 claims over the unseen halls (the unit), each hall's learned rows averaged
    over the pre-training seeds. The transferred expert is the nearest training hall's oracle
    plan; the expert trained where the DT is deployed is the oracle (whose demonstrations the
    DT learned from), and fine-tuning the one that tries places (``--ablation``).
    ``from_scratch``: per hall, ``expert_to_level`` and ``finetune_interactions`` measured by
    ``uavris from-scratch`` (:mod:`.from_scratch`: an expert trained from scratch in the hall)."""
    track = TRACK_SPECS["deployment"]
    _, unseen = study.sites(track)
    zs, goal, ft, names = [], [], [], []
    for w in unseen:
        if zero_shot_only(w, study.config.system):
            continue
        found = study.evaluation(track, w.name)
        if found is None:
            continue
        edir, res = found
        dt = _seeds_mean(edir, res, DEPLOYMENT_DT)
        transfer = [k for k, v in res.items() if v["kind"] == "transfer" and v["rank"] == 0]
        if dt is None or not transfer:
            continue
        names.append(w.name)
        zs.append(float(np.mean(dt - episode_rates(edir, transfer[0]))))
        told = _seeds_mean(edir, res, GOAL_DT)
        if told is not None:
            goal.append(float(np.mean(told - episode_rates(edir, transfer[0]))))
        fine = next((f for f in (_seeds_mean(edir, res, v) for v in FINETUNED_DTS) if f is not None), None)
        if fine is not None:
            ft.append(float(np.mean(fine - (1 - WITHIN) * episode_rates(edir, variant_key(ORACLE, safe=True)))))
    unit = f"{len(names)} unseen halls"
    out = [_judged("zero-shot", "deployment", judged(zs), unit,
                   "zero-shot DT (return-conditioned, safety layer, mean of its seeds) minus the nearest training "
                   "hall's oracle plan, bps/Hz")] if len(zs) else \
        [Judgement("zero-shot", "deployment", NOT_TESTED, text="no unseen hall evaluated")]
    if goal and len(goal) == len(zs):
        out.append(_judged("zero-shot", "deployment", judged(goal), unit,
                           "the same for the goal-conditioned DT told the learned planner's place (uavris's "
                           "controller; the cell's second entry)"))
    if len(ft) == len(names) and ft:
        out.append(_judged("near-expert", "deployment", judged(ft), unit,
                           f"DT fine-tuned in the hall minus {1 - WITHIN:.0%} of the oracle (the track's expert), "
                           "both under the safety layer, bps/Hz"))
    elif from_scratch:
        near = [h["level"] - (1 - WITHIN) * h["oracle"] for h in from_scratch]
        out.append(_judged("near-expert", "deployment", judged(near),
                           f"{len(near)} unseen halls (uavris from-scratch)",
                           f"DT fine-tuned by trying places (mean of its seeds) minus {1 - WITHIN:.0%} of the oracle "
                           "(the track's expert), both under the safety layer, bps/Hz"))
    else:
        out.append(Judgement("near-expert", "deployment", NOT_TESTED,
                             text="fine-tuning in the unseen halls runs with --ablation only"))
    if from_scratch:
        need = [h["expert_to_level"] for h in from_scratch]
        spent = [h["finetune_interactions"] for h in from_scratch]
        unit_fs = f"{len(need)} unseen halls (uavris from-scratch)"
        out.append(_judged("fewer", "deployment", paired_difference(need, spent), unit_fs,
                           "interactions hybrid PPO from scratch needed to reach the fine-tuned level (its 200,000 "
                           "steps where it never did: a lower bound) minus fine-tuning's"))
        pre = float(study.result(track.stage("dataset"))["slots"])
        out.append(_judged("fewer-total", "deployment", paired_difference(np.subtract(need, pre), spent), unit_fs,
                           f"the same minus the {pre:,.0f} interactions of the oracle's demonstrations"))
    else:
        out += [Judgement(c, "deployment", NOT_TESTED, text="needs the measurement of uavris from-scratch")
                for c in ("fewer", "fewer-total")]
    return out


# ------------------------------------------------------------------------------ every track
def judge_studies(studies: Sequence[Study], budgets: Sequence[tuple[Path, int]] = (),
                  from_scratch: Sequence[dict[str, float]] = ()) -> list[Judgement]:
    """Every claim in every track the ``studies`` ran: the paper and strong tracks over
    every study that ran them (one seed each: run them with ``--seed 0``, ``1``, ``2``), the
    deployment track from the first study that ran it (its seeds are within it). ``budgets``:
    (comparison, environment steps): the comparison's runs judged at that budget too
    (``uavris compare-algorithms --steps N --eval-every B``)."""
    pooled = [s for s in studies if any(not t.layouts for t in s.config.tracks)]  # the seeds of the scenario tracks
    seeds = [s.config.seed for s in pooled]
    if len(set(seeds)) != len(seeds):
        raise UavrisError(f"the studies of the paper and strong tracks share a seed ({seeds}): run each with its "
                          "own --seed")
    out: list[Judgement] = []
    compare = next((d for s in studies if (d := s.done("compare"))), None)
    if any(TRACK_SPECS["paper"] in s.config.tracks for s in studies):
        out.append(judge_comparison(comparison_scores(compare),
                                    budget=f", final evaluation at {studies[0].config.compare_steps:,} steps")
                   if compare else Judgement("ddpg-best", "paper", NOT_TESTED, text="no finished comparison"))
    for cdir, steps in budgets:
        scores = comparison_scores(Path(cdir), steps)
        if not scores:
            raise UavrisError(f"{cdir}: no run of the comparison was evaluated at {steps:,} steps")
        out.append(judge_comparison(scores, budget=f", first evaluation at or after {steps:,} steps of "
                                                   f"{Path(cdir).name}"))
    for name in TRACKS:
        track = TRACK_SPECS[name]
        ran = [s for s in studies if track in s.config.tracks]
        if not ran:
            continue
        if name != "paper":
            out.append(Judgement("ddpg-best", name, NOT_TESTED,
                                 text="the track's experts are not trained by DRL (they imitate the oracle)"))
        out += judge_deployment(ran[0], from_scratch) if track.layouts else judge_scenario_track(ran, track)
    return out


def claims_table(judgements: Sequence[Judgement]) -> list[str]:
    """The claim x track table (markdown lines): each cell the verdict and the mean paired
    difference with its 95% CI (bps/Hz, or interactions for the "fewer" rows)."""
    tracks = [t for t in TRACKS if any(j.track == t for j in judgements)]
    rows = []
    for claim, text in CLAIMS.items():
        cells = []
        for t in tracks:
            found = [j for j in judgements if j.claim == claim and j.track == t]
            cells.append(" / ".join(j.cell for j in found) if found else "-")
        rows.append((text, *cells))
    return markdown_table(("claim", *tracks), rows, "l" + "l" * len(tracks))


def budget_table(cdir: Path, budgets: Sequence[int], zero: float) -> list[str]:
    """Each algorithm of a comparison at each budget: its seeds' mean with the Student-t 95% CI,
    and against doing nothing (``zero``, the zero action's mean on the same episodes): "above"
    holds where the CI of the seeds' scores minus that mean excludes zero upwards (markdown lines)."""
    rows = []
    for steps in budgets:
        for algo, scores in comparison_scores(Path(cdir), steps).items():
            d = paired_difference(scores, [zero] * len(scores))
            ci = "" if math.isnan(d["ci_low"]) else f"[{d['ci_low'] + zero:.2f}, {d['ci_high'] + zero:.2f}]"
            rows.append((f"{steps:,}", algo.upper(), len(scores), f"{np.mean(scores):.2f}", ci,
                         " ".join(f"{x:.2f}" for x in scores), d["verdict"]))
    return [f"The zero action (doing nothing) in `fig2`: {zero:.2f} bps/Hz on the same 32 episodes.", "",
            *markdown_table(("env steps", "algorithm", "seeds", "mean", "95% CI (t, over seeds)", "each seed",
                             "above the zero action"), rows, "lrrrlll")]


def budget_figure(cdir: Path, stem: Path, zero: float) -> list[Path]:
    """The periodic evaluations of a comparison's runs against environment steps (log axis):
    each seed thin, the mean of the seeds that reached a step thick, beside the zero action
    (``zero``, on the same episodes) (PNG and PDF)."""
    from uavris.agents.references import REFERENCES, ZERO_ACTION
    from uavris.experiments.display.plots import plt, reference_lines, save_figure

    fig, ax = plt.subplots(figsize=(5.4, 3.6))
    runs = eval_curves(cdir)
    for i, (algo, curves) in enumerate(sorted(runs.items())):
        for x, y in curves:
            ax.plot(x, y, "-", color=f"C{i}", lw=0.6, alpha=0.5)
        longest = max(curves, key=lambda c: c[0].size)[0]
        mean = [np.mean([y[j] for x, y in curves if x.size > j]) for j in range(longest.size)]
        seeds = f"{len(curves)} seed{'s' * (len(curves) != 1)}"
        ax.plot(longest, mean, "-", color=f"C{i}", lw=1.8, label=f"{algo.upper()} (mean of {seeds}; thin: each)")
    # hovering with optimised phases (36 bps/Hz) and the oracle (43) are far above: named in the page, not drawn
    reference_lines(ax, {ZERO_ACTION: (REFERENCES[ZERO_ACTION].label, zero)})
    ax.set_xscale("log")
    ticks = [t for t in (12_500, 25_000, 50_000, 100_000, 200_000, 400_000, 800_000, 1_600_000)
             if t <= max(c[0].max() for cs in runs.values() for c in cs) * 1.01]
    ax.set_xticks(ticks, [f"{t / 1000:g}k" for t in ticks])
    ax.xaxis.set_minor_formatter(plt.NullFormatter())
    ax.set_xlabel("environment steps of training")
    ax.set_ylabel("average sum rate, 32 episodes (bps/Hz)")
    ax.set_title("fig2: the periodic evaluations at every budget", fontsize=9)
    ax.legend(fontsize=6, frameon=False, loc="lower right")
    return save_figure(fig, stem)


def write_claims(outs: Sequence[Path], dest: Path, budgets: Sequence[tuple[Path, int]] = (),
                 from_scratch: Path | None = None) -> Path:
    """Judge (:func:`judge_studies`) and write ``dest/claims.md`` and ``dest/claims.json`` (its
    inputs and judgements); the markdown's path. Claims of other inputs in ``dest``: one line."""
    inputs = {"studies": [str(o) for o in outs], "budgets": [[str(d), b] for d, b in budgets],
              "from_scratch": str(from_scratch) if from_scratch else None}
    old = other_inputs(Path(dest) / "claims.json", inputs, "inputs")
    if old is not None:
        raise UavrisError(f"{dest} holds the claims of other studies ({', '.join(old.get('studies', []))}); give "
                          "this one another --out (nothing there is replaced)")
    halls = read_json(from_scratch)["halls"] if from_scratch is not None else ()
    judgements = judge_studies([Study.open(o) for o in outs], budgets, halls)
    lines = ["# The paper's claims, judged", "",
             "\n".join(claims_table(judgements)), "",
             "Each cell: the verdict, the mean paired difference over the units and its 95% CI (Student's t; "
             "Welch's for the comparison). A claim **holds** where the CI excludes zero the claimed way, is "
             "**refuted** where it excludes zero the other way, and is **not resolved** otherwise. What each cell "
             "compares:", ""]
    for j in judgements:
        if j.verdict != NOT_TESTED:
            lines.append(f"- {j.track}, {j.claim}: {j.text}; {j.n} units ({j.unit}).")
        else:
            lines.append(f"- {j.track}, {j.claim}: not tested: {j.text}.")
    if budgets:
        zero = fig2_zero_action()
        figs = budget_figure(budgets[0][0], Path(dest) / "budget", zero)
        lines += ["", "## The comparison at each budget", "", f"![budget]({figs[0].name})", "",
                  *budget_table(budgets[0][0], [b for _, b in budgets], zero)]
    lines += ["", f"Studies: {', '.join(str(o) for o in outs)}" + (f"; comparison {budgets[0][0]}" if budgets else "")
              + (f"; from scratch: {from_scratch}" if from_scratch else "") + ".", ""]
    path = Path(dest) / "claims.md"
    atomic_write_text(path, "\n".join(lines))
    write_json(Path(dest) / "claims.json", {"inputs": inputs, "judgements": [asdict(j) for j in judgements]})
    return path
