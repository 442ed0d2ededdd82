"""The paper's claims, judged in every track by one rule: ``uavris claims OUT [OUT ...]``.

Lives here: :data:`CLAIMS` (what the paper claims, in our words, and where), :func:`judge_studies`
(every claim of every track of one or more studies, the paper and strong tracks pooled over
studies run with ``--seed 0, 1, 2, ...``), :func:`claims_table` (the claim x track table the
README and the results page open with) and :func:`write_claims` (the claims page). Not here:
the rule itself (:func:`uavris.stats.verdict`: "holds" where the CI excludes zero the claimed
way, "refuted" the other way, "not resolved" otherwise), what each claim compares
(:mod:`.claims_tracks`, :mod:`.claims_comparison`), a cell (:mod:`.judgement`).

The units: in the paper and strong tracks one unit is a training seed (a study), its unseen
scenarios averaged; in the deployment track a unit is an unseen hall, its learned rows
averaged over the pre-training seeds. Within a unit two rows are compared on the same
evaluation episodes. A cell with fewer than three units is "not measured".
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any, Sequence

from uavris.errors import UavrisError
from uavris.experiments.display.tables import markdown_table
from uavris.experiments.engine.process import machine
from uavris.experiments.study.claims_comparison import (
    budget_figure,
    budget_table,
    comparison_scores,
    fig2_zero_action,
    judge_comparison,
)
from uavris.experiments.study.claims_deployment import dt_against_hovering, judge_deployment
from uavris.experiments.study.claims_tracks import LEVEL, WITHIN, judge_scenario_track
from uavris.experiments.study.config import AUTO
from uavris.experiments.study.finished import Study
from uavris.experiments.study.judgement import NOT_TESTED, Judgement, judgement
from uavris.experiments.study.stage_names import COMPARE, value_stage
from uavris.experiments.study.stamp import make_stamp, stamped
from uavris.experiments.study.tracks import TRACK_SPECS, TRACKS
from uavris.float_paths import warn_if_unpinned
from uavris.io import atomic_write_text, other_inputs, read_json, replace_folder, to_plain, write_json
from uavris.stats import HOLDS, MIN_UNITS, NOT_RESOLVED, REFUTED, holm

ALPHA = 0.05  # the family-wise error rate of the claims table (Holm)
# How far the float path moves what the table judges (docs/timings.md, "The float path"; measured there).
FLOAT_PATHS = ("Every number of a study is of the float path it ran: uavris pins numpy, OpenBLAS and torch to "
               "their AVX2 kernels (`uavris.float_paths`), and on that path an AMD EPYC of Zen 3 and one of Zen 5 "
               "(with AVX-512) gave the same bits for the whole quick study, its references on an Intel Xeon too. "
               "On another path (`UAVRIS_NATIVE_FLOATS=1`) the learned rows are another random draw: two verdicts "
               "of the 0.3.0 table read differently on an Intel Xeon and an AMD EPYC, natively.")

CLAIMS: dict[str, str] = {
    "ddpg-best": "DDPG trains the best expert of DDPG, PPO, SAC and TD3 (Fig. 2, Sec. V)",
    "zero-shot": "the zero-shot DT scores above the experts transferred from training deployments (Fig. 3, Sec. V)",
    "finetuned": "fine-tuning raises the DT above its zero-shot start (Sec. V)",
    "near-expert": f"the fine-tuned DT is within {WITHIN:.0%} of the expert trained where it is deployed "
                   "(Fig. 3, Sec. V)",
    "fluctuates": "the zero-shot DT and the transferred experts fluctuate more over episodes than the fine-tuned DT "
                  "and the expert (Sec. V)",
    "fewer": f"the pre-trained DT, fine-tuned, reaches {LEVEL:.0%} of the expert's final level in fewer environment "
             "interactions than the expert (abstract, Sec. VI; its zero-shot start counted: 0 where it is there)",
    "fewer-finetuning": "the same, fine-tuning's own part: where the zero-shot DT is not already at that level",
    "fewer-total": "the same, counting the interactions of the experts and demonstrations the DT was pre-trained on "
                   "(charged whole to each hall or scenario and spread over those it serves: a verdict only where "
                   "both agree)",
    "dt-over-bc": "the DT scores above behaviour cloning on the same data (not the paper's: the field's baseline)",
}
# What the claims page lists as not measured, with what measuring it would cost.
NOT_MEASURED_CLAIMS = (
    ("Fig. 2's absolute values and ranking at the paper's budget (DDPG, PPO, SAC and TD3 to convergence, the "
     "paper's 256x256 networks)", "about 150 core-hours for the paper track alone (`uavris reproduce --preset paper "
     "--estimate`)"),
    ("Fig. 3 at the paper's scale (DDPG experts, the paper's dataset and DT)", "the same run"),
)


def judge_studies(studies: Sequence[Study], budgets: Sequence[tuple[Path, int]] = (),
                  from_scratch: Sequence[dict[str, Any]] = (),
                  evidence: dict[str, Any] | None = None) -> list[Judgement]:
    """Every claim in every track the ``studies`` ran: the paper and strong tracks over
    every study that ran them (one seed each, the unit: run them with ``--seed 0`` to ``4``), the
    deployment track from the first study that ran it (its seeds are within it). ``budgets``:
    (comparison, environment steps): the comparison's runs judged at that budget too
    (``uavris compare-algorithms --steps N --eval-every B``), only where every algorithm has
    its seeds there. What every cell read goes into ``evidence`` (``comparison``: each budget's
    scores per algorithm; ``scenario``: each track's (seed, scenario) pairs; ``deployment``),
    from which each cell can be computed again (the claims page's ``units.json``)."""
    check_seeds(studies)
    ev: dict[str, Any] = evidence if evidence is not None else {}
    ev.update({"comparison": [], "scenario": {}, "deployment": {}})
    out: list[Judgement] = []
    compare = next((d for s in studies if (d := s.done(COMPARE))), None)
    if any(TRACK_SPECS["paper"] in s.config.tracks for s in studies):
        if compare:
            scores = comparison_scores(compare)
            ev["comparison"].append({"budget": "final", "steps": studies[0].config.compare_steps, "scores": scores})
            out.append(judge_comparison(scores, budget=f", final evaluation at {studies[0].config.compare_steps:,} "
                                                       "steps"))
        else:
            out.append(Judgement("ddpg-best", "paper", NOT_TESTED, text="no finished comparison"))
    for cdir, steps in budgets:
        scores = comparison_scores(Path(cdir), steps)
        if not scores:
            raise UavrisError(f"{cdir}: no run of the comparison was evaluated at {steps:,} steps")
        ev["comparison"].append({"budget": "at", "steps": steps, "scores": scores})
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
        if track.layouts:
            out += judge_deployment(ran[0], from_scratch, ev["deployment"])
        else:
            out += judge_scenario_track(ran, track, ev["scenario"].setdefault(name, []))
    return out


def check_seeds(studies: Sequence[Study]) -> None:
    """The units of a scenario track are its studies' seeds: two studies that ran the same track
    with one seed are one unit counted twice (a paper-track and a strong-track study may share one)."""
    for name in TRACKS:
        track = TRACK_SPECS[name]
        seeds = [s.config.seed for s in studies if track in s.config.tracks and not track.layouts]
        if len(set(seeds)) != len(seeds):
            raise UavrisError(f"the studies of the {name} track share a seed ({seeds}): run each with its own --seed")


def holm_corrected(judgements: Sequence[Judgement]) -> list[Judgement]:
    """The table's verdicts corrected for its many cells: Holm's step-down method
    (:func:`uavris.stats.holm`) over every judged cell (holds, refuted or not resolved, its
    p-value from its interval). A "holds" or "refuted" whose adjusted p is above 0.05 becomes
    "not resolved" and its text says so; every judged cell records ``p_holm``. The intervals
    stay the unadjusted 95% CIs."""
    family = [i for i, j in enumerate(judgements)
              if j.verdict in (HOLDS, REFUTED, NOT_RESOLVED) and math.isfinite(j.p)]
    adjusted = dict(zip(family, holm([judgements[i].p for i in family]))) if family else {}
    out = []
    for i, j in enumerate(judgements):
        if i not in adjusted:
            out.append(j)
            continue
        p = float(adjusted[i])
        if j.verdict in (HOLDS, REFUTED) and p > ALPHA:
            out.append(replace(j, verdict=NOT_RESOLVED, p_holm=p, text=(
                f"{j.text}; {j.verdict} by its own interval (p = {j.p:.3f}), not resolved after Holm's correction "
                f"over the table's {len(family)} judged cells (adjusted p = {p:.3f})")))
        else:
            out.append(replace(j, p_holm=p))
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


def _from_scratch_halls(path: Path, studies: Sequence[Study]) -> list[dict[str, Any]]:
    """The halls of ``uavris from-scratch``'s file, which must have measured the deployment study
    judged here (hall names repeat across studies)."""
    measured = read_json(path)
    deployment = next((st for st in studies if TRACK_SPECS["deployment"] in st.config.tracks), None)
    if deployment is None or Path(measured.get("study", "")).resolve() != deployment.out.resolve():
        raise UavrisError(f"{path} measured the study {measured.get('study')!r}, not the deployment study judged "
                          f"here ({deployment.out if deployment else 'none'})")
    return list(measured["halls"])


def rests_on(studies: Sequence[Study]) -> list[str]:
    """What the verdicts rest on (markdown bullet lines): the budgets and departures from the
    paper that decide them, read from the studies where they are data (the comparison's choice,
    each track's preset), and the return-conditioned DT against hovering with optimised phases at
    each device count of a deployment study (:func:`dt_against_hovering`)."""
    lines = []
    for st in studies:
        if (compare := st.done(COMPARE)) is not None:
            if st.config.expert_algo != AUTO:
                chosen, why = st.config.expert_algo, "chosen by --expert-algo"
            else:
                chosen, why = read_json(compare / "summary.json").get("expert") or "?", "the comparison's choice"
            lines.append(f"- The paper track's budget: the `{st.config.preset}` preset, "
                         f"{st.config.compare_steps:,} environment steps per comparison run; its experts are "
                         f"**{chosen.upper()}**, {why} (the paper's are DDPG).")
            break
    lines += [
        "- The strong track's experts imitate the planning oracle's motion with optimised phases; the deployment "
        "track's expert is the oracle itself. Neither is trained by DRL.",
        "- The data are scaled down from the paper's (its dataset, DT and fine-tuning rounds at the preset's size: "
        "`uavris.presets`), over fewer fine-tuning rounds. Fine-tuning keeps its elite episodes by a paired ranking "
        "within each seed, not by return as the paper's Algorithm 1 (docs/model.md, departure 22); in the "
        "deployment track from 40 candidates and 25 elites per round, not 80 and 50.",
        "- The deployment track's DT observes the devices (a device-set encoder) and flies under the attitude "
        "safety layer and the safety distance; the paper's DT observes neither.",
    ]
    deployment = next((st for st in studies if TRACK_SPECS["deployment"] in st.config.tracks), None)
    if deployment is not None and deployment.done(TRACK_SPECS["deployment"].stage(value_stage(0))) is not None:
        lines.append("- The goal-conditioned DT's cells read a fit of the learned value of a pose per pre-training "
                     "seed (`deploy-value`, `deploy-value-sK`): a seed is its DT and its V together.")
    for count, diff in dt_against_hovering(deployment) if deployment is not None else []:
        cell = judgement("dt-over-hover", "deployment", diff, "", "halls", "")
        lines.append(f"- With {count} devices the return-conditioned DT against hovering with optimised phases, "
                     f"over unseen halls: {cell.cell} bps/Hz (holds: above it).")
    return lines


def write_claims(outs: Sequence[Path], dest: Path, budgets: Sequence[tuple[Path, int]] = (),
                 from_scratch: Path | None = None, made_by: Sequence[str] = ()) -> Path:
    """Judge (:func:`judge_studies`) and write ``dest/claims.md`` (stamped: :mod:`.stamp`),
    ``dest/claims.json`` (its inputs and judgements) and the evidence beside them
    (:func:`write_evidence`); the markdown's path. ``made_by``: the commands that made the
    studies, listed on the page. Claims of other inputs in ``dest``: one line."""
    warn_if_unpinned("claims")  # a page meant to be compared with another machine's
    inputs = {"studies": [str(o) for o in outs], "budgets": [[str(d), b] for d, b in budgets],
              "from_scratch": str(from_scratch) if from_scratch else None}
    old = other_inputs(Path(dest) / "claims.json", inputs, "inputs")
    if old is not None:
        raise UavrisError(f"{dest} holds the claims of other studies ({', '.join(old.get('studies', []))}); give "
                          "this one another --out (nothing there is replaced)")
    studies = [Study.open(o) for o in outs]
    check_evidence(studies)  # before anything is judged or written
    halls = _from_scratch_halls(from_scratch, studies) if from_scratch is not None else ()
    evidence: dict[str, Any] = {}
    judgements = holm_corrected(judge_studies(studies, budgets, halls, evidence))
    judged = sum(math.isfinite(j.p_holm) for j in judgements)
    lines = ["# The paper's claims, judged", "", f"Judged by `uavris claims` on {machine()}. {FLOAT_PATHS}", "",
             *(["The studies, made by:", "", "```bash", *made_by, "```", ""] if made_by else []),
             "\n".join(claims_table(judgements)), "",
             "Each cell: the verdict, the mean paired difference over the units and its 95% CI (Student's t; "
             "Welch's for the comparison). A claim **holds** where the CI excludes zero the claimed way, is "
             "**refuted** where it excludes zero the other way, and is **not resolved** otherwise; then, for the "
             f"table's {judged} judged cells at once, a verdict stands only where Holm's step-down correction keeps "
             "it (its p-value from its interval, the family-wise error at most 5%; a cell resting on a censored unit "
             "counts as p = 1); one it does not keep reads **not resolved** and says so below. The intervals are the "
             "unadjusted 95% CIs. What each cell compares:", ""]
    for j in judgements:
        if j.verdict != NOT_TESTED:
            lines.append(f"- {j.track}, {j.claim}: {j.text}; {j.count} ({j.unit}).")
        else:
            lines.append(f"- {j.track}, {j.claim}: not tested: {j.text}.")
    lines += ["", f"A cell with fewer than {MIN_UNITS} units on a side is **not measured**: no verdict.", "",
              "## What the verdicts rest on", "", *rests_on(studies), "",
              "## Claims not measured here", "",
              *(f"- {what}: would cost {cost}." for what, cost in NOT_MEASURED_CLAIMS)]
    if budgets:
        zero = fig2_zero_action()
        # not "budget": docs/results/budget.md's own figure lives beside the committed claims page
        figs = budget_figure(budgets[0][0], Path(dest) / "claims-budget", zero["mean"])
        lines += ["", "## The comparison at each budget", "", f"![budget]({figs[0].name})", "",
                  *budget_table([(budgets[0][0], [b for _, b in budgets])], zero)]
    lines += ["", f"Studies: {', '.join(str(o) for o in outs)}" + (f"; comparison {budgets[0][0]}" if budgets else "")
              + (f"; from scratch: {from_scratch}" if from_scratch else "") + ".", ""]
    lines += [f"The evidence beside this page (`{EVIDENCE}/`): each study's report, the from-scratch curves, "
              f"`{UNITS}` (what every cell read: each unit's per-episode rates, curves and scores) and `claims.json` "
              "(every cell's interval and p-values), from which every cell can be computed again.", ""]
    path = Path(dest) / "claims.md"
    write_evidence(studies, Path(dest) / EVIDENCE, from_scratch, evidence)
    presets = sorted({st.config.preset for st in studies})
    command = " ".join(["uavris claims", *map(str, outs),
                        *(["--budget-comparison", str(budgets[0][0]), "--budgets", *(str(b) for _, b in budgets)]
                          if budgets else []),
                        *(["--from-scratch", str(from_scratch)] if from_scratch else []), "--out", str(dest)])
    stamp = make_stamp("claims", [*outs, *(d for d, _ in budgets[:1]), *([from_scratch] if from_scratch else [])],
                       presets[0] if len(presets) == 1 else None, command,
                       seeds=sorted({st.config.seed for st in studies}))
    atomic_write_text(path, stamped(stamp, "\n".join(lines)))
    write_json(Path(dest) / "claims.json", {"inputs": inputs, "judgements": [asdict(j) for j in judgements]})
    return path


EVIDENCE = "claims-evidence"  # the folder beside claims.md with what its cells are read from


def check_evidence(studies: Sequence[Study]) -> None:
    """Each study's report exists and has a file name of its own in the evidence folder."""
    names = [st.out.resolve().name for st in studies]
    if len(set(names)) != len(names):
        raise UavrisError(f"two studies judged here share a directory name ({', '.join(names)}): their reports "
                          "would be written to one file; give each its own name")
    for st in studies:
        if not (st.out / "report.md").is_file():
            raise UavrisError(f"{st.out}: no report.md (run `uavris reproduce --report-only --out {st.out}`)")


def write_evidence(studies: Sequence[Study], folder: Path, from_scratch: Path | None,
                   units: dict[str, Any] | None = None) -> None:
    """Each study's report (``NAME.md``, its directory's name; small text files, its figures left
    out), a copy of the from-scratch curves and what every cell read (``units``, :data:`UNITS`:
    :func:`judge_studies`'s evidence), as the folder ``folder`` (made beside it and put in its
    place whole, so it never mixes two invocations' evidence): what a reader checks the cells
    against, and computes them again from, without the studies' gigabytes."""
    folder.parent.mkdir(parents=True, exist_ok=True)
    made = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    try:
        for st in studies:
            atomic_write_text(made / f"{st.out.resolve().name}.md", (st.out / "report.md").read_text())
        if from_scratch is not None:
            atomic_write_text(made / "from-scratch.json", Path(from_scratch).read_text())
        if units is not None:  # one line: per-episode lists of many halls would be tens of thousands of lines
            atomic_write_text(made / UNITS, json.dumps(to_plain(units), separators=(",", ":")) + "\n")
        made.chmod(0o755)
        replace_folder(made, folder, folder.with_name(f".{folder.name}.old"))
    finally:
        shutil.rmtree(made, ignore_errors=True)


UNITS = "units.json"  # in the evidence folder: what every cell of the claims page read, unit by unit
