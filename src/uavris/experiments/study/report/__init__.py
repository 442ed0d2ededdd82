"""``report.md`` of ``uavris reproduce``: both tracks side by side, every number read from stage files.

Lives here: :func:`write_report`, the report's text (tables, the paper's claims checked on
each track). Not here: its figures (:mod:`.figures`, :mod:`.schedule`), the deployment
track's section (:mod:`.deployment`) and its decomposition (:mod:`.decomposition`), and the
stage files it reads (written by
:mod:`uavris.experiments.training.compare` and :mod:`uavris.experiments.study.tracks`).
"""

from __future__ import annotations

import math
import re
import shutil
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import yaml

from uavris.agents.oracle.bound import episode_bounds
from uavris.agents.references import HOVER_OPTIMIZER, ORACLE, ZERO_ACTION
from uavris.config import UNSEEN_SCENARIOS, get_scenario
from uavris.errors import UavrisError
from uavris.experiments.display.tables import counted, fraction, interval, markdown_table, num
from uavris.experiments.engine.process import machine
from uavris.experiments.engine.stages import StageRecord
from uavris.experiments.study.claims import claims_table, judge_studies
from uavris.experiments.study.claims_tracks import episode_rates
from uavris.experiments.study.finished import Study
from uavris.experiments.study.pipeline import STAGE_KINDS
from uavris.experiments.study.report.decomposition import (
    count_label,
    counts_section,
    decomposition_section,
    value_section,
)
from uavris.experiments.study.report.deployment import (
    NEAREST,
    deployment_section,
    layout_scores,
    layouts_figure,
    row_facts,
    row_labels,
    row_order,
    scaling_figure,
    seed_scores,
)
from uavris.experiments.study.report.figures import fig3, interactions_figure, trajectory_figure
from uavris.experiments.study.report.schedule import schedule_figure, stage_table
from uavris.experiments.study.stage_names import COMPARE, evaluation_stage
from uavris.experiments.study.stamp import make_stamp, stamped
from uavris.experiments.study.tracks import Track, zero_shot_only
from uavris.experiments.training.compare import fig2_table
from uavris.io import atomic_write_bytes, atomic_write_text, read_json
from uavris.presets import EVAL_SEED
from uavris.stats import versus


class _Report:
    def __init__(self, study: Study, records: Sequence[StageRecord]) -> None:
        self.study, self.out, self.rc = study, study.out, study.config
        self.ok = {r.name for r in records if r.status in ("done", "skipped")}
        self.figs = study.out / "figures"
        self.figs.mkdir(parents=True, exist_ok=True)
        self.lines: list[str] = []
        self.claims: list[str] = []

    def add(self, *lines: str) -> None:
        self.lines.extend(lines)

    # ------------------------------------------------------------------ Fig. 2
    def fig2(self) -> None:
        self.add("", "## Algorithm comparison (paper Fig. 2, paper track)", "")
        if COMPARE not in self.ok:
            self.add("Not available: the `compare` stage did not finish." if COMPARE in self.study.pipeline.stages
                     else "Not run: the paper track was not selected.")
            return
        cdir = self.study.directory(COMPARE)
        for ext in ("png", "pdf"):
            if (cdir / f"learning_curves.{ext}").exists():
                shutil.copyfile(cdir / f"learning_curves.{ext}", self.figs / f"fig2_learning_curves.{ext}")
        summary = read_json(cdir / "summary.json")
        rows = summary["rows"]
        self.add("![Fig. 2](figures/fig2_learning_curves.png)", "",
                 "The average sum rate over training episodes, the mean over seeds; the band is the 95% Student-t "
                 "interval of that mean over the seeds, drawn from 0 (a rate is never negative).", "",
                 *fig2_table(rows))
        if any(r["kind"] == "DRL" for r in rows):
            choice = summary.get("expert_choice") or {}
            self.add("", f"Expert algorithm of the paper track: **{str(summary.get('expert')).upper()}**"
                     + (f" (overridden: {self.rc.expert_algo.upper()})" if self.rc.expert_algo != "auto" else "")
                     + ". " + choice.get("text", "The largest IQM of the final evaluations, as the paper chooses.")
                     + " Among algorithms the comparison has not separated (95% CIs of the IQM overlapping the "
                     "winner's), uavris takes the cheapest to train (docs/model.md, departures).")

    # ------------------------------------------------------------------ Fig. 3, one track
    def track(self, track: Track) -> dict[str, dict[str, Any]]:
        self.add("", f"## {track.title[0].upper() + track.title[1:]}", "")
        results = {}
        for i, scenario in enumerate(UNSEEN_SCENARIOS):
            name = track.stage(evaluation_stage(scenario))
            label = "ab"[i]
            self.add(f"### Unseen scenario {scenario} {list(get_scenario(scenario).start)} (paper Fig. 3{label})", "")
            if name not in self.ok:
                self.add(f"Not available: the `{name}` stage did not finish.", "")
                continue
            found = self.study.evaluation(track, scenario)
            assert found is not None  # a stage that finished
            edir, res = found
            stem = f"{track.prefix}fig3{label}_{scenario}"
            fig3(scenario, edir, self.figs / stem, track.name)
            results[scenario] = res
            oracle, zero = res[ORACLE]["mean"], res[ZERO_ACTION]["mean"]
            self.add(f"![Fig. 3{label}, {track.name} track](figures/{stem}.png)", "")
            self.add(*markdown_table(
                ("policy", "mean", "95% CI (t)", "IQM", "95% CI (IQM, bootstrap)", "vs zero action",
                 "fraction of oracle"),
                [(s["label"], num(s["mean"]), interval(s["ci_low"], s["ci_high"]), num(s["iqm"]),
                  interval(s["boot_iqm_ci_low"], s["boot_iqm_ci_high"]),
                  "-" if key == ZERO_ACTION else versus(s["ci_low"], s["ci_high"], zero), fraction(s["mean"], oracle))
                 for key, s in res.items()], "lrlrllr"), "")
            self._claims(track, scenario, res)
            slots = self.study.first_episode(track, scenario, "dt-finetuned")
            if i == 0 and slots is not None:
                tstem = f"{track.prefix}trajectory_{scenario}"
                trajectory_figure(scenario, slots, self.rc.system, self.figs / tstem, EVAL_SEED)
                self.add(f"![trajectory, {track.name} track](figures/{tstem}.png)", "")
        return results

    def _claims(self, track: Track, scenario: str, res: dict[str, dict[str, Any]]) -> None:
        """The figure behind the "fewer interactions" claim (judged in the claims table)."""
        fdir, xdir = self.study.finetuned(track, scenario), self.study.experts(track, unseen=True)
        if fdir is not None and xdir is not None and (fdir / "model" / "finetune.csv").exists() \
                and (xdir / "runs" / scenario / "evals.csv").exists():
            istem = f"{track.prefix}interactions_{scenario}"
            interactions_figure(scenario, fdir / "model", xdir / "runs" / scenario, self.figs / istem,
                                res["expert"]["label"])
            self.add(f"![interactions, {track.name} track](figures/{istem}.png)", "")

    # ------------------------------------------------------------------ the deployment track
    def deployment(self, track: Track) -> None:
        """Unseen layouts as the unit of generalisation (:mod:`.deployment`)."""
        self.add("", f"## {track.title[0].upper() + track.title[1:]}", "")
        _, unseen = self.rc.sites(track)
        results, edirs = {}, {}
        for w in unseen:
            name = track.stage(evaluation_stage(w.name))
            found = self.study.evaluation(track, w.name) if name in self.ok else None
            if found is not None:
                edirs[w.name], results[w.name] = found
        missing = [w.name for w in unseen if w.name not in results]
        if missing:
            self.add(f"Not available for {len(missing)} of {len(unseen)} unseen layouts (their evaluation stage did "
                     f"not finish): {', '.join(missing)}.", "")
        done = [w for w in unseen if w.name in results]
        own = self.rc.system.num_users
        study = {w.name: results[w.name] for w in done if not zero_shot_only(w, self.rc.system)}
        other = {w.name: results[w.name] for w in done if w.split == "other" and w.devices == own}
        counts: dict[tuple[int, bool], dict[str, Any]] = {}  # (devices, another generator's): halls
        for w in done:
            if w.devices != own:
                counts.setdefault((w.devices, w.split == "other"), {})[w.name] = results[w.name]
        if study:
            self._deployment_group(track, study)
        if other:
            self.add("", "### Halls of another generator", "",
                     "The same models and rows, zero-shot, in unseen halls drawn by another generator (devices further "
                     "from the walls and from each other, higher, starts anywhere over the floor: "
                     "`uavris.layouts.OTHER_SPLIT`): a result tuned to the study's generator would show here.", "")
            self._deployment_group(track, other, "deployment track, another generator's halls", "-other", True)
        if counts:
            columns = {(own, False): study, **({(own, True): other} if other else {}), **counts}
            bounds = {w.name: float(episode_bounds(w.system, EVAL_SEED + np.arange(results[w.name][ORACLE]["episodes"]))
                                    .mean()) for w in done}
            self.add(*counts_section(columns, bounds, lambda lay, row: episode_rates(edirs[lay], row)))
            for (k, o), group in sorted(counts.items()):
                drawn = "unseen halls of another generator" if o else "unseen halls"
                self.add("", f"### Halls of {count_label(k, o)}", "",
                         f"The same models and rows, zero-shot, in {drawn} of {k} devices (the DTs were "
                         f"pre-trained on halls of {own}; the learned value on halls of several counts).", "")
                self._deployment_group(track, group, f"deployment track, {count_label(k, o)}",
                                       f"-k{k}" + ("-other" if o else ""), True)

    def _deployment_group(self, track: Track, results: dict[str, dict[str, Any]],
                          where: str = "deployment track", suffix: str = "", zero_shot_only: bool = False) -> None:
        """One group of unseen halls (its figures' names end in ``suffix``; ``zero_shot_only``:
        halls the study does not fine-tune in): its tables, figures, decomposition and claims."""
        scores = layout_scores(results)
        facts, labels, order = row_facts(results), row_labels(results), row_order(results)
        curve_keys = [k for k in order if k in facts and facts[k]["training_halls"] is not None]
        stem = f"{track.prefix}layouts{suffix}"
        layouts_figure(scores, labels, [k for k in order if k not in curve_keys], self.figs / stem,
                       [k for k in order if k in facts and facts[k]["kind"] == "learned"])
        curve = {facts[k]["training_halls"]: [scores[lay][k] / scores[lay][ORACLE] for lay in scores]
                 for k in curve_keys}
        scaling = None
        if curve:
            curve[self.rc.train_layouts] = [scores[lay]["dt-zero-shot"] / scores[lay][ORACLE] for lay in scores]
            refs = {label: [scores[lay][k] / scores[lay][ORACLE] for lay in scores]
                    for k, label in ((HOVER_OPTIMIZER, "hover, optimiser's phases"), (NEAREST, labels[NEAREST]))
                    if all(k in scores[lay] for lay in scores)}
            scaling = f"{track.prefix}scaling{suffix}"
            scaling_figure(curve, refs, self.figs / scaling)
        lines, claims = deployment_section(scores, labels, order, f"figures/{stem}.png",
                                           f"figures/{scaling}.png" if scaling else None, where, self.rc.seed,
                                           seed_scores(results), zero_shot_only)
        self.add(*lines)
        self.claims += claims
        lines, claims = decomposition_section(results, labels, where)
        self.add(*lines)
        self.claims += claims
        self.add(*value_section(results, self.rc.seed))

    # ------------------------------------------------------------------ both tracks side by side
    def side_by_side(self, tracks: Sequence[Track], results: dict[str, dict[str, dict[str, Any]]]) -> None:
        cols = [(t, s) for t in tracks for s in UNSEEN_SCENARIOS if s in results.get(t.name, {})]
        if not cols:
            return
        self.add("", "## Both tracks side by side", "",
                 "Average sum rate (bps/Hz) on the same seeded episodes; in brackets, the fraction of the oracle.", "")
        rows = [("scenario's own expert", "expert"), ("zero-shot DT", "dt-zero-shot"),
                ("fine-tuned DT", "dt-finetuned"), ("best transferred expert", None),
                ("zero action (hover)", ZERO_ACTION), ("hover, optimiser's phases", HOVER_OPTIMIZER),
                ("oracle", ORACLE)]
        def cell(res: dict[str, Any], key: str | None) -> str:
            item = (max((v for v in res.values() if v["kind"] == "transfer"), key=lambda v: v["mean"])
                    if key is None else res[key])
            return f"{item['mean']:.2f} ({fraction(item['mean'], res[ORACLE]['mean'])})"

        self.add(*markdown_table(("policy", *(f"{t.name}, {s}" for t, s in cols)),
                                 [(label, *(cell(results[t.name][s], key) for t, s in cols)) for label, key in rows],
                                 "l" + "r" * len(cols)))
        learned = ("expert", "dt-zero-shot", "dt-finetuned")
        self.add("", "Against doing nothing (the zero action) and the oracle, per track and scenario:", "")
        for t, s in cols:
            res = results[t.name][s]
            zero = res[ZERO_ACTION]["mean"]
            parts = [f"{res[k]['label']} {versus(res[k]['ci_low'], res[k]['ci_high'], zero)}" for k in learned]
            zs = res["dt-zero-shot"]["mean"]
            self.add(f"- {t.name}, {s}: vs zero action ({zero:.2f}): " + "; ".join(parts)
                     + f". Zero-shot DT at {fraction(zs, res[ORACLE]['mean'])} of the oracle; "
                     + finetuning_effect(res["dt-zero-shot"], res["dt-finetuned"]) + ".")


def finetuning_effect(zero_shot: dict[str, float], finetuned: dict[str, float]) -> str:
    """What fine-tuning did, in words that do not overstate it: "raised" or "lowered" only when
    the two 95% CIs over episodes do not overlap, "unchanged" when the means agree to the
    printed digits; otherwise the change is within the CIs."""
    zs, ft = zero_shot["mean"], finetuned["mean"]
    if f"{zs:.2f}" == f"{ft:.2f}":
        return f"fine-tuning left it unchanged ({zs:.2f} -> {ft:.2f})"
    # an undefined CI (one episode; None in a stage's record) is apart from nothing
    bounds = (finetuned["ci_low"], finetuned["ci_high"], zero_shot["ci_low"], zero_shot["ci_high"])
    if None not in bounds and finetuned["ci_low"] > zero_shot["ci_high"]:
        return f"fine-tuning raised it ({zs:.2f} -> {ft:.2f}, 95% CIs apart)"
    if None not in bounds and finetuned["ci_high"] < zero_shot["ci_low"]:
        return f"fine-tuning lowered it ({zs:.2f} -> {ft:.2f}, 95% CIs apart)"
    return f"fine-tuning moved it within the 95% CIs ({zs:.2f} -> {ft:.2f}); one fine-tuning run, one seed"


def claims_section(study: Study) -> list[str]:
    """The claim x track table of this study (:mod:`uavris.experiments.study.claims`) and what each cell compares."""
    judgements = judge_studies([study])
    lines = [*claims_table(judgements), "", "A claim **holds** where the 95% CI of its paired difference over the unit "
             "(a training seed; an unseen hall) excludes zero the claimed way, is **refuted** where it excludes "
             "zero the other way, and is **not resolved** otherwise; with fewer than three units it is **not "
             "measured**. Here each cell is judged alone; `uavris claims` also corrects the verdicts for the table's "
             "many cells (Holm). One study is one seed of the paper and strong tracks: `uavris claims` pools studies "
             "run with `--seed 0` to `4`.", ""]
    return lines + [f"- {j.track}, {j.claim}: {j.text}" + (f"; {j.count} ({j.unit})." if j.n else ".")
                    for j in judgements]


def _report_only_line(study: Study, records: Sequence[StageRecord]) -> str:
    """What a report of a study in part (``--report-only``) says first: how much of it there is."""
    finished = {r.name for r in records}
    waiting = [name for name in study.pipeline.stages if name not in finished]
    named = ", ".join(waiting[:10]) + (f" and {len(waiting) - 10} more" if len(waiting) > 10 else "")
    return (f"Written by `uavris reproduce --report-only`, which runs nothing: {len(records)} of the study's "
            f"{len(study.pipeline.stages)} stages had finished" + (f" (not {named})" if waiting else "")
            + "; what the others would give is not here.")


def write_report(study: Study, records: Sequence[StageRecord], wall_s: float, origin: float = math.nan,
                 ran: bool = True) -> Path:
    """``study``'s report (``OUT/report.md``) and figures (``OUT/figures``), its stages' ``records``
    being this invocation's (run or skipped; ``ran`` False: the finished ones of a study this
    invocation ran nothing of, ``--report-only``); returns the report's path."""
    rep = _Report(study, records)
    out, rc = study.out, study.config
    rep.add(f"# uavris reproduction of the paper, preset `{rc.preset}`", "",
            f"Everything below is read from the stage files under `{out / 'stages'}`; rerunning `uavris reproduce` "
            "with the same parameters skips finished stages. Evaluation: deterministic policies on "
            f"{counted(rc.eval_episodes, 'seeded episode')} (seeds {EVAL_SEED}..{EVAL_SEED + rc.eval_episodes - 1}), "
            "the same episodes for every "
            "policy of a scenario. Every policy is read against doing nothing (the zero action: hover at the start, "
            "level, all phases equal) and the oracle (`uavris.agents.oracle`: optimised phases every slot, motion "
            "planned over the whole room; docs/model.md section 19). 'vs zero action' says whether the policy's 95% "
            "CI lies above or below the zero action's mean ('tie': not resolved).",
            "", f"Machine: {machine()}.", "",
            *([] if ran else [_report_only_line(study, records), ""]),
            "## The paper's claims, judged", "", *claims_section(study), "",
            "## Stages", "")
    # the schedule of the invocation that ran the stages (an interrupted one writes none: not another's)
    schedule = read_json(out / "schedule.json") if ran and (out / "schedule.json").exists() else \
        {"jobs": [], "workers": 1}
    groups = {name: st.group for name, st in study.pipeline.stages.items()}
    if schedule_figure(schedule["jobs"], int(schedule["workers"]), rep.figs / "schedule", groups):
        rep.add("![schedule](figures/schedule.png)", "")
    rep.add(*stage_table(records, schedule["jobs"], origin))
    rep.add("", f"Total wall clock of this invocation: {wall_s / 60:.1f} min. Stages run as soon as their inputs "
                "are ready, and a free worker takes the job whose stage heads the longest remaining chain of work "
                "(expected costs: `uavris.experiments.engine.costs`); start and end are minutes after this invocation "
                "began, workers the slots that ran the stage's jobs. A stage finished by an earlier invocation is "
                "'skipped' here, with the wall clock it took then." if ran else
            "Every stage here finished in an earlier invocation ('skipped', with the wall clock it took then).")
    rep.fig2()
    scenario_tracks = [t for t in rc.tracks if not t.layouts]
    results = {t.name: rep.track(t) for t in scenario_tracks}
    rep.side_by_side(scenario_tracks, results)
    for t in rc.tracks:
        if t.layouts:
            rep.deployment(t)
    for kind in STAGE_KINDS:  # the kinds of stage registered beside the tracks' (study.pipeline.StageKind)
        waiting = [n for n, st in study.pipeline.stages.items() if st.group == kind.name and not study.done(n)]
        rep.add("", f"## {kind.title}", "", *([f"Not run: its stages {', '.join(waiting)} did not finish."]
                                              if waiting else kind.section(study)))
    rep.add("", "## Further claims, checked", "", *(rep.claims or ["None in these tracks."]),
            "", "The paper's numbers come from its own, unstated parameters (noise power, slot length, energy budget, "
            "training length); ours are in `docs/model.md` and below. Where a claim does not hold here, that is the "
            "finding on this simulator, not a tuning target.")
    rep.add("", "## Parameters", "", "```yaml",
            yaml.safe_dump({"preset": rc.preset, "seed": rc.seed, "tracks": [t.name for t in rc.tracks],
                            "expert_algo": rc.expert_algo, "compare_seeds": rc.compare_seeds,
                            "eval_episodes": rc.eval_episodes, "trajectories_per_scenario": rc.trajectories,
                            **({"train_layouts": rc.train_layouts, "unseen_layouts": rc.unseen_layouts,
                                "layout_seed": rc.layout_seed, "ablation": rc.ablation,
                                **({"scaling": list(rc.scaling)} if rc.ablation else {})}
                               if any(t.layouts for t in rc.tracks) else {})},
                           sort_keys=False).rstrip(), "```", "",
            "Stage configurations (hyperparameters, the strong track's imitation, DT and fine-tuning settings) are in "
            "each `stages/NAME-KEY/stage.json`. System configuration:", "", "```yaml",
            yaml.safe_dump(rc.system.to_dict(), sort_keys=False).rstrip(), "```", "")
    failed = [r for r in records if r.status == "failed"]
    if failed:
        rep.add("## Failures", "", *[f"- {r.name}: {r.error}" for r in failed])
    report = out / "report.md"
    stamp = make_stamp("report", [out], rc.preset, seed=rc.seed, tracks=[t.name for t in rc.tracks])
    atomic_write_text(report, stamped(stamp, "\n".join(rep.lines) + "\n"))
    return report


FIGURE = re.compile(r"!\[[^\]]*\]\(figures/([^)]+)\)")


def page_copy(study: Path, page: Path, name: str, command: str) -> list[Path]:
    """A finished study's report as the results page ``page`` (``docs/results/FILE.md``), stamped
    as the page ``name`` made by ``command``; the figures it shows that the docs keep
    (``docs/figures/quick_NAME`` for the quick report, which the site's hooks link) are copied
    from the study. Returns the files written."""
    report = study / "report.md"
    if not report.is_file():
        raise UavrisError(f"{study}: no report.md (the study did not finish: rerun it)")
    text = report.read_text(encoding="utf-8")
    config = Study.open(study).config
    written = []
    if name == "quick-report":
        figures = page.parent.parent / "figures"
        for fig in FIGURE.findall(text):
            kept = figures / f"quick_{fig}"
            if kept.exists() and (study / "figures" / fig).is_file():
                atomic_write_bytes(kept, (study / "figures" / fig).read_bytes())
                written.append(kept)
    stamp = make_stamp(name, [study], config.preset, command, seed=config.seed,
                       tracks=[t.name for t in config.tracks])
    atomic_write_text(page, stamped(stamp, text))
    return [page, *written]
