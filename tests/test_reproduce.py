"""End to end: `uavris reproduce --preset smoke`, both tracks (one comparison seed, 4 evaluation
episodes, 2 trajectories per expert to keep CI at a few minutes), killed once and resumed."""

import csv
import dataclasses
import re
import shutil
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from uavris.config import SystemConfig
from uavris.errors import UavrisError
from uavris.experiments.engine.jobs import Job, JobRunner, run_jobs
from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.engine.stages import Pipeline, Stage
from uavris.experiments.study.config import ReproduceConfig
from uavris.experiments.study.pipeline import build_pipeline
from uavris.experiments.study.reproduce import reproduce
from uavris.experiments.study.tracks import nearest_training_scenarios
from uavris.experiments.training import pretrain as pretrain_module
from uavris.experiments.training.train_expert import TrainConfig, train_job
from uavris.io import read_json

RC = ReproduceConfig("smoke", compare_seeds=1, eval_episodes=4, trajectories=2, ablation=True)


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    calls = []
    real_pretrain = pretrain_module.pretrain

    def killed(*args, **kwargs):
        calls.append(1)
        raise KeyboardInterrupt("simulated kill during pre-training")

    # One worker runs the jobs in this process, where the patched function is seen; the
    # killed pre-training fails its stages and what depends on them, the rest finishes.
    pretrain_module.pretrain = killed
    try:
        with pytest.raises(UavrisError, match="stage"):
            reproduce(RC, out, workers=1, progress=False)
    finally:
        pretrain_module.pretrain = real_pretrain
    assert calls
    first_done = sorted(p.parent.name.rsplit("-", 1)[0] for p in (out / "stages").glob("*/stage.json"))
    report = reproduce(RC, out, workers=2, progress=False)
    return out, report, first_done


@pytest.mark.slow
def test_all_artefacts_exist(smoke_run):
    out, report, _ = smoke_run
    assert report == out / "report.md"
    for prefix in ("", "strong-"):
        for stem in ("fig3a_unseen1", "fig3b_unseen2", "interactions_unseen1", "interactions_unseen2",
                     "trajectory_unseen1"):
            for ext in ("png", "pdf"):
                assert (out / "figures" / f"{prefix}{stem}.{ext}").stat().st_size > 1000, prefix + stem
    assert (out / "figures" / "fig2_learning_curves.png").stat().st_size > 1000
    text = report.read_text()
    assert "## The paper's claims, judged" in text and "## Both tracks side by side" in text
    assert text.index("## The paper's claims, judged") < text.index("## Stages")  # where a reader looks first
    assert "| claim | paper | strong | deployment |" in text
    summary = read_json(next((out / "stages").glob("compare-*")) / "summary.json")
    chosen = summary["expert"]
    assert f"Expert algorithm of the paper track: **{chosen.upper()}**. {summary['expert_choice']['text']}" in text
    assert "## Stages" in text and (out / "figures" / "schedule.png").stat().st_size > 1000
    schedule = read_json(out / "schedule.json")
    assert {j["worker"] for j in schedule["jobs"]} <= {0, 1} and all(j["end"] >= j["start"] for j in schedule["jobs"])
    # the bar's ETA was recorded (the first sample at the first tick), never below zero
    assert schedule["eta"] and all(s["eta"] >= 0 and s["t"] >= 0 for s in schedule["eta"])
    for stage in (out / "stages").glob("*/stage.json"):  # the wall clock is beside the results, not in them
        assert "wall_s" not in read_json(stage) and "wall_s" in read_json(stage.parent / "timing.json")
    experts = read_json(next((out / "stages").glob("experts-train-*")) / "stage.json")["result"]
    assert experts["algo"] == chosen


@pytest.mark.slow
def test_report_numbers_come_from_evaluation_files(smoke_run):
    out, report, _ = smoke_run
    text = report.read_text()
    stages = sorted((out / "stages").glob("*evaluate-unseen*"))
    assert len(stages) == 4  # evaluate-unseen1/2, strong-evaluate-unseen1/2
    for stage in stages:
        scenario = stage.name.split("-")[-2]
        result = read_json(stage / "stage.json")["result"]
        assert set(result) == {"expert", "dt-zero-shot", "dt-finetuned", "zero-action", "hover-optimizer", "oracle"} | {
            f"transfer-{s}" for s in nearest_training_scenarios(scenario)}
        for summary in result.values():
            per_episode = [float(x) for x in re.findall(r"^\d+,([^,]+),", (stage / f"{summary['policy']}.csv")
                                                       .read_text(), re.M)]
            assert len(per_episode) == 4
            assert abs(sum(per_episode) / 4 - summary["mean"]) < 1e-9
            # the CI over episodes (what "95% CIs overlap" and "vs zero action" read) is Student's t
            assert (summary["ci_low"], summary["ci_high"]) == pytest.approx(_mean_ci(per_episode)[1:], rel=1e-9)
            assert f"| {summary['label']} | {summary['mean']:.2f} |" in text
        oracle = result["oracle"]["mean"]
        assert f"| {result['expert']['mean'] / oracle:.0%} |" in text


@pytest.mark.slow
def test_deployment_numbers_and_verdicts_come_from_evaluation_files(smoke_run):
    # The deployment track's stages are deploy-evaluate-layout-unseen-J (the glob above misses them).
    out, report, _ = smoke_run
    stages = sorted((out / "stages").glob("deploy-evaluate-layout-unseen-*"))
    assert len(stages) == 2
    for stage in stages:
        result = read_json(stage / "stage.json")["result"]
        for key in ("dt-zero-shot", "bc", "dt-flat", "dt-mixed", "bc-mixed"):  # every learned row over 2 seeds
            assert {key, f"{key}@s1"} <= set(result)
        for summary in result.values():
            per_episode = [float(x) for x in re.findall(r"^\d+,([^,]+),", (stage / f"{summary['policy']}.csv")
                                                       .read_text(), re.M)]
            assert len(per_episode) == 4 and abs(sum(per_episode) / 4 - summary["mean"]) < 1e-9
    check_deployment_report({s.name[len("deploy-evaluate-"):].rsplit("-", 1)[0]:
                             read_json(s / "stage.json")["result"] for s in stages}, report.read_text())
    # the halls of another generator: zero-shot only, their own tables and claims after the study's
    other = sorted((out / "stages").glob("deploy-evaluate-layout-other-*"))
    assert len(other) == 2 and all("dt-finetuned" not in read_json(s / "stage.json")["result"] for s in other)
    text = report.read_text()
    check_deployment_report({s.name[len("deploy-evaluate-"):].rsplit("-", 1)[0]: read_json(s / "stage.json")["result"]
                             for s in other}, text[text.index("### Halls of another generator"):],
                            "deployment track, another generator's halls")


@pytest.mark.slow
def test_paper_and_strong_verdicts_come_from_evaluation_files(smoke_run):
    out, report, _ = smoke_run
    stages = {("strong" if s.name.startswith("strong-") else "paper", s.name.split("-")[-2]): s
              for s in sorted((out / "stages").glob("*evaluate-unseen*"))}
    check_track_claims(stages, next((out / "stages").glob("compare-*")), report.read_text())
    deploy = [s for s in sorted((out / "stages").glob("deploy-evaluate-layout-unseen-*"))
              if re.fullmatch(r"deploy-evaluate-layout-unseen-\d+-[0-9a-f]{12}", s.name)]
    check_deployment_claims(deploy, report.read_text())


@pytest.mark.slow
@pytest.mark.parametrize("track, key", [("paper", "dt-finetuned"), ("strong", "expert"), ("strong", "transfer-train3")])
def test_uavris_evaluate_reproduces_a_scenario_tracks_row(smoke_run, tmp_path, track, key):
    from uavris.cli import main

    out, _, _ = smoke_run
    [stage] = (out / "stages").glob(f"{'strong-' if track == 'strong' else ''}evaluate-unseen1-*")
    want = read_json(stage / "stage.json")["result"][key]
    assert main(["evaluate", str(out), "--row", key, "--track", track, "--scenario", "unseen1", "--out",
                 str(tmp_path), "--no-progress"]) == 0
    got = read_json(next(tmp_path.glob(f"{key}-unseen1-*.json")))
    assert got["mean"] == want["mean"] and got["label"] == want["label"] and got["episodes"] == RC.eval_episodes


# ---------------------------------------------------------------------- the report against its stage files
# Recomputed here from the stages' results with SciPy, by the rules the report states, not by the
# report's own functions.
def _mean_ci(x) -> tuple[float, float, float]:
    """Mean and Student-t 95% interval of a sample (a sample without spread: a point)."""
    x = np.asarray(x, dtype=float)
    if sps.sem(x) == 0:
        return x.mean(), x.mean(), x.mean()
    lo, hi = sps.t.interval(0.95, len(x) - 1, loc=x.mean(), scale=sps.sem(x))
    return x.mean(), lo, hi


def _zero(lo: float, hi: float) -> str:
    return "above zero" if lo > 0 else "below zero" if hi < 0 else "includes zero"


def _pct3(m: tuple[float, float, float]) -> str:
    return f"{m[0]:.1%} [{m[1]:.1%}, {m[2]:.1%}]"


def _num3(m: tuple[float, float, float]) -> str:
    return f"{m[0]:+.2f} [{m[1]:+.2f}, {m[2]:+.2f}]"


def _table(text: str, header: str) -> list[list[str]]:
    """The body rows of the table whose header line starts with ``header``, as cells."""
    lines = text.splitlines()
    i = next(i for i, line in enumerate(lines) if line.startswith(header))
    rows = []
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip().strip("|").split("|")])
    return rows


# DT minus another policy, per layout (the report's paired differences)
DEPLOYMENT_PAIRS = (("dt-zero-shot", "hover-optimizer"), ("dt-zero-shot", "nearest"),
                    ("dt-ensemble", "hover-optimizer"), ("dt-ensemble", "nearest"), ("dt-zero-shot", "transfers"),
                    ("dt-zero-shot", "bc"), ("dt-zero-shot", "dt-flat"), ("dt-mixed", "bc-mixed"),
                    ("dt-finetuned", "dt-zero-shot"), ("dt-zero-shot-safe", "hover-optimizer"),
                    ("dt-zero-shot-safe", "nearest"), ("dt-zero-shot-safe", "dt-zero-shot"),
                    ("dt-ensemble-safe", "hover-optimizer"), ("dt-ensemble-safe", "nearest"),
                    ("dt-finetuned-safe", "dt-zero-shot-safe"), ("dt-zero-shot-safe", "dt-zero-shot-level"),
                    ("dt-zero-shot-safe", "bc-safe"), ("dt-goal-safe", "hover-optimizer"), ("dt-goal-safe", "nearest"),
                    ("dt-goal-safe", "dt-zero-shot-safe"), ("plan-learned", "hover-optimizer"),
                    ("dt-goal-finetuned-safe", "dt-goal-safe"))
LEARNED = ("dt-zero-shot", "dt-ensemble", "dt-finetuned", "bc", "dt-zero-shot-safe", "dt-ensemble-safe",
           "dt-finetuned-safe", "bc-safe", "dt-zero-shot-level", "dt-ensemble-level", "dt-flat", "dt-mixed", "bc-mixed",
           "dt-goal", "dt-goal-safe", "dt-goal-finetuned", "dt-goal-finetuned-safe", "plan-learned", "plan-semi")
# issue 36's targets of the rows that choose a place: (row, mean, worst hall); in zero-shot-only halls, the count's
PLACE_TARGETS = (("dt-goal-safe", 0.97, 0.92), ("plan-semi", 0.99, None), ("dt-goal-finetuned-safe", 0.985, 0.95))


def check_deployment_report(results: dict[str, dict], text: str, where: str = "deployment track") -> None:
    """The deployment track's tables and claims in ``text`` against ``{layout: stage result}``;
    ``where`` heads the claims of this group of halls."""
    scores = {}
    for layout, result in results.items():
        seeds: dict[str, list[float]] = {}
        for key, s in result.items():
            if not key.startswith("transfer-"):
                seeds.setdefault(key.split("@s")[0], []).append(s["mean"])
        row = {k: sum(v) / len(v) for k, v in seeds.items()}  # a learned row: the mean over its seeds
        [row["nearest"]] = [s["mean"] for k, s in result.items() if k.startswith("transfer-")
                            and "(nearest)" in s["label"]]
        transfers = [s["mean"] for k, s in result.items() if k.startswith("transfer-")]
        if len(transfers) > 1:
            row["transfers"], row["best-transfer"] = sum(transfers) / len(transfers), max(transfers)
        scores[layout] = row
    layouts = list(scores)
    keys = [k for k in scores[layouts[0]] if all(k in scores[lay] for lay in layouts)]
    frac = {k: [scores[lay][k] / scores[lay]["oracle"] for lay in layouts] for k in keys}
    stat = {k: _mean_ci(frac[k]) for k in keys}

    # per layout: every policy's score and fraction of the oracle (cells compared as a multiset)
    per_layout = {r[0]: r[1:] for r in _table(text, "| layout |")}
    assert set(per_layout) == set(layouts)
    for lay in layouts:
        want = [f"{scores[lay][k]:.2f} ({scores[lay][k] / scores[lay]['oracle']:.0%})" for k in keys]
        assert sorted(per_layout[lay]) == sorted(want), lay
    # over layouts: fraction of the oracle, mean [t CI], mean score, worst layout
    summary = _table(text, "| policy | fraction of oracle")
    want = [[_pct3(stat[k]), f"{np.mean([scores[lay][k] for lay in layouts]):.2f}", f"{min(frac[k]):.1%}"]
            for k in keys]
    assert sorted(r[1:] for r in summary) == sorted(want)
    # paired differences per layout, their mean [t CI] and what the CI says about zero
    diffs = {}
    for a, b in DEPLOYMENT_PAIRS:
        if a in keys and b in keys:
            d = [scores[lay][a] - scores[lay][b] for lay in layouts]
            diffs[(a, b)] = _mean_ci(d)
            diffs[(a, b)] = (*diffs[(a, b)], _zero(*diffs[(a, b)][1:]), [f"{x:+.2f}" for x in d])
    table = _table(text, "| difference |")
    assert sorted(r[1:] for r in table) == sorted([*v[4], _num3(v[:3]), v[3]] for v in diffs.values())

    claims = [line for line in text.splitlines() if line.startswith(f"- {where}: **")]
    expected = _check_score_claims(claims, where, keys, stat, diffs)
    expected += _check_place_claims(claims, where, keys, stat, diffs, frac)
    # blocking: every learned row's share of slots with a device behind the RIS, its seeds averaged per layout
    blocked = {}
    for layout, result in results.items():
        for key, s in result.items():
            blocked.setdefault(key.split("@s")[0], {}).setdefault(layout, []).append(s["behind_share"])
    share = {k: np.mean([np.mean(v) for v in by.values()]) for k, by in blocked.items() if k in LEARNED}
    expected += 1
    [claim] = [c for c in claims if c.startswith(f"- {where}: **no learned row blocks a device")]
    assert f"**: {'holds' if max(share.values()) <= 0.01 else 'does not hold'} (" in claim, claim
    assert len(claims) == expected >= 5


def _check_place_claims(claims: list[str], where: str, keys: list[str], stat: dict, diffs: dict, frac: dict) -> int:
    """Issue 36's targets against the recomputed statistics; how many claims there are."""
    if where != "deployment track":  # zero-shot halls: the count target, >= 96% and above hovering
        if "dt-goal-safe" not in keys:
            return 0
        [claim] = [c for c in claims if c.startswith(f"- {where}: **the learned planner's place flown by")]
        hover = diffs[("dt-goal-safe", "hover-optimizer")]
        holds = stat["dt-goal-safe"][0] >= 0.96 and hover[1] > 0
        assert f"**: {'holds' if holds else 'does not hold'} ({_pct3(stat['dt-goal-safe'])}; minus hovering " \
               f"{_num3(hover[:3])} bps/Hz, {hover[3]})." in claim, claim
        return 1
    count = 0
    for key, mean, worst in PLACE_TARGETS:
        if key not in keys:
            continue
        count += 1
        [claim] = [c for c in claims if f">= {mean:.1%} of the oracle" in c and c.startswith(f"- {where}: **")]
        holds = stat[key][0] >= mean and (worst is None or min(frac[key]) >= worst)
        if key == "dt-goal-safe":
            holds = holds and diffs[(key, "hover-optimizer")][1] > 0 and diffs[(key, "nearest")][1] > 0
        assert f"**: {'holds' if holds else 'does not hold'} ({_pct3(stat[key])} of the oracle, worst hall " \
               f"{min(frac[key]):.1%}" in claim, claim
    return count


def _check_score_claims(claims: list[str], where: str, keys: list[str], stat: dict, diffs: dict) -> int:
    """The deployment claims about scores (targets, fine-tuning, paired differences) against the
    recomputed statistics; how many there are."""
    expected = 0
    for key, what in (("dt-zero-shot", "zero-shot DT"), ("dt-ensemble", "zero-shot DT ensemble (one controller)"),
                      ("dt-zero-shot-safe", "zero-shot DT under the attitude safety layer"),
                      ("dt-ensemble-safe", "zero-shot DT ensemble under the attitude safety layer")):
        if key not in keys:
            continue
        expected += 1
        [claim] = [c for c in claims if c.startswith(f"- {where}: **{what} >= ")]
        target = int(re.search(r">= (\d+)% of the oracle", claim).group(1)) / 100
        hover, near = diffs[(key, "hover-optimizer")], diffs[(key, "nearest")]
        holds = stat[key][0] >= target and hover[1] > 0 and near[1] > 0
        assert f"**: {'holds' if holds else 'does not hold'} (" in claim, claim
        assert (f"({_pct3(stat[key])} of the oracle; minus hovering {_num3(hover[:3])} bps/Hz, {hover[3]}; minus "
                f"nearest {_num3(near[:3])} bps/Hz, {near[3]})." in claim), claim
    for ft, zs, what in (("dt-finetuned", "dt-zero-shot", "fine-tuned DT"),
                         ("dt-finetuned-safe", "dt-zero-shot-safe", "fine-tuned DT under the attitude safety layer")):
        if ft not in keys:
            continue
        expected += 1
        [claim] = [c for c in claims if c.startswith(f"- {where}: **{what} >= ")]
        target = int(re.search(r">= (\d+)% of the oracle", claim).group(1)) / 100
        holds = stat[ft][0] >= target and stat[ft][0] >= stat[zs][0]
        gain = diffs[(ft, zs)]
        assert f"**: {'holds' if holds else 'does not hold'} (" in claim, claim
        assert f"(fine-tuned {_pct3(stat[ft])}; fine-tuned minus zero-shot {_num3(gain[:3])} bps/Hz)." in claim, claim
    for pair, what in ((("dt-zero-shot", "bc"), "**return conditioning on demonstrations of one quality"),
                       (("dt-zero-shot-safe", "bc-safe"), "**return conditioning under the attitude safety layer"),
                       (("dt-mixed", "bc-mixed"), "**return conditioning on mixed-quality data"),
                       (("dt-zero-shot", "dt-flat"), "**the device-set encoder")):
        if pair in diffs:
            expected += 1
            [claim] = [c for c in claims if c.startswith(f"- {where}: {what}")]
            assert claim.endswith(f"**: {_num3(diffs[pair][:3])} bps/Hz per layout, {diffs[pair][3]}."), claim
    return expected


def _cell(diffs) -> str:
    """The claims table's cell for per-unit differences, by the stated rule, with SciPy's t interval."""
    diffs = np.asarray(diffs, dtype=float)
    if diffs.size < 2:
        return f"**not resolved**: {diffs.mean():+,.2f}"
    ci = sps.ttest_1samp(diffs, 0.0).confidence_interval(0.95)
    word = "holds" if ci.low > 0 else "refuted" if ci.high < 0 else "not resolved"
    return f"**{word}**: {diffs.mean():+,.2f} [{ci.low:+,.2f}, {ci.high:+,.2f}]"


def _episodes(stage: Path, row: str) -> np.ndarray:
    with open(stage / f"{row}.csv", newline="") as f:
        return np.array([float(r["avg_sum_rate"]) for r in csv.DictReader(f)])


def check_deployment_claims(stages: list[Path], text: str) -> None:
    """The claims table's deployment cell of the zero-shot claim: the return- and the
    goal-conditioned DT (safety layer, mean of the seeds per episode) minus the nearest training
    hall's plan, per unseen hall of the study's own generator and count."""
    table = _table(text, "| claim | paper | strong | deployment |")
    [row] = [r for r in table if r[0].startswith("the zero-shot DT scores above")]
    cells = []
    for variant in ("dt-zero-shot-safe", "dt-goal-safe"):
        diffs = []
        for stage in stages:
            res = read_json(stage / "stage.json")["result"]
            keys = [k for k, s in res.items() if s.get("variant") == variant]
            [near] = [k for k in res if k.startswith("transfer-")]
            diffs.append(np.mean(np.mean([_episodes(stage, k) for k in keys], axis=0) - _episodes(stage, near)))
        cells.append(_cell(diffs))
    assert row[3] == " / ".join(cells), (row[3], cells)


def check_track_claims(stages: dict[tuple[str, str], Path], compare_dir: Path, text: str) -> None:
    """The claims table's paper and strong cells in ``text`` against their evaluation stages'
    per-episode files (``{(track, scenario): stage dir}``) and the comparison's runs."""
    assert len(stages) == 4
    table = _table(text, "| claim | paper | strong |")
    rows = {r[0]: r[1:] for r in table}
    with open(compare_dir / "final_per_run.csv", newline="") as f:
        runs = list(csv.DictReader(f))
    by_algo = {}
    for r in runs:
        by_algo.setdefault(r["algo"], []).append(float(r["final_eval_mean"]))
    gaps = {a: np.mean(by_algo["ddpg"]) - np.mean(v) for a, v in by_algo.items() if a != "ddpg"}
    [ddpg] = [v for k, v in rows.items() if k.startswith("DDPG trains the best")]
    assert ddpg[0] == f"**not resolved**: {min(gaps.values()):+,.2f}"  # one seed per algorithm: no interval
    for col, track in enumerate(("paper", "strong")):
        zs, near = [], []
        for (t, _scenario), stage in sorted(stages.items()):
            if t != track:
                continue
            res = read_json(stage / "stage.json")["result"]
            top = max((k for k in res if k.startswith("transfer-")), key=lambda k: res[k]["mean"])
            zs.append(np.mean(_episodes(stage, "dt-zero-shot") - _episodes(stage, top)))
            near.append(np.mean(_episodes(stage, "dt-finetuned") - 0.95 * _episodes(stage, "expert")))
        [z] = [v for k, v in rows.items() if k.startswith("the zero-shot DT scores above")]
        [n] = [v for k, v in rows.items() if k.startswith("the fine-tuned DT is within 5%")]
        assert z[col] == _cell(zs) and n[col] == _cell(near), (track, z, n)


@pytest.mark.slow
def test_rerun_after_kill_skips_finished_stages(smoke_run):
    out, _, first_done = smoke_run
    # the kill hit pre-training: everything before it had finished and was not redone
    assert {"compare", "experts-train", "experts-unseen", "dataset", "strong-experts-train",
            "strong-dataset"} <= set(first_done)
    assert "pretrain" not in first_done and "strong-pretrain" not in first_done
    pipeline = build_pipeline(RC, out, StudyContext(1, "local", None))
    records = pipeline.run()
    assert all(r.status == "skipped" for r in records)


def test_changed_parameter_invalidates_exactly_its_dependents(tmp_path):
    ctx = StudyContext(1, "local", None)
    base = build_pipeline(RC, tmp_path, ctx)

    def changed(**kw):
        other = build_pipeline(dataclasses.replace(RC, **kw), tmp_path, ctx)
        return {n for n in base.stages if n not in other.stages or base.stages[n].key != other.stages[n].key}

    dt = {"dataset", "pretrain", "finetune-unseen1", "finetune-unseen2", "evaluate-unseen1", "evaluate-unseen2"}
    deploy = {n for n in base.stages if n.startswith("deploy-")}
    models = {"pretrain", "bc", "goal", "pretrain-n1", "flat", "mixed-dt", "mixed-bc"}  # each for 2 seeds at smoke
    evaluations = {f"deploy-evaluate-layout-{split}-{j}" for split in ("unseen", "other") for j in (0, 1)}
    places = {f"deploy-finetune-places-layout-unseen-{j}{s}" for j in (0, 1) for s in ("", "-s1")}
    assert deploy == {"deploy-dataset", "deploy-dataset-mixed", "deploy-finetune-layout-unseen-0",
                      "deploy-finetune-layout-unseen-1", "deploy-values", "deploy-value"} | evaluations | places | {
                          f"deploy-{m}{s}" for m in models for s in ("", "-s1")}
    assert changed(trajectories=3) == dt | {f"strong-{n}" for n in dt}
    # the learned value's labels come from their own halls, its fit from them and the demonstrations' plans
    assert changed(layout_trajectories=3) == deploy - {"deploy-values"}
    # the paper track's experts follow the comparison (they are its winner's)
    assert changed(compare_seeds=2) == {"compare", "experts-train", "experts-unseen"} | dt
    assert changed(expert_algo="ppo") == {"experts-train", "experts-unseen"} | dt
    assert changed(system=SystemConfig(noise_dbm=-90.0)) == set(base.stages)
    # other layouts: only the deployment track's stages
    assert changed(layout_seed=1) == deploy
    assert changed(scaling=()) == {"deploy-pretrain-n1", "deploy-pretrain-n1-s1"} | evaluations
    assert changed(dt_seeds=1) == {n for n in deploy if n.endswith("-s1")} | evaluations
    assert changed(mixed_layouts=1) == {"deploy-dataset-mixed", "deploy-mixed-dt", "deploy-mixed-dt-s1",
                                        "deploy-mixed-bc", "deploy-mixed-bc-s1"} | evaluations
    assert set(build_pipeline(dataclasses.replace(RC, track="strong"), tmp_path, ctx).stages) == {
        n for n in base.stages if n.startswith("strong-")}
    assert set(build_pipeline(dataclasses.replace(RC, track="deployment"), tmp_path, ctx).stages) == deploy
    assert "compare" not in build_pipeline(dataclasses.replace(RC, track="deployment"), tmp_path, ctx).stages


def test_stage_keys_chain_through_dependencies(tmp_path):
    ran = []

    def make(name):
        return lambda d, deps: ran.append(name) or {"name": name}

    def pipe(a_cfg):
        return Pipeline(tmp_path, [Stage("a", a_cfg, make("a")), Stage("b", {"x": 1}, make("b")),
                                   Stage("c", {}, make("c"), ("a",))])

    # sequential runs start stages in pipeline order, so the order is part of the contract
    pipe({"v": 1}).run(concurrent=False)
    assert ran == ["a", "b", "c"]
    pipe({"v": 1}).run(concurrent=False)
    assert ran == ["a", "b", "c"]  # nothing redone
    pipe({"v": 2}).run(concurrent=False)
    assert ran == ["a", "b", "c", "a", "c"]  # b does not depend on a
    pipe({"v": 2}).run(force=("b",), concurrent=False)
    assert ran[-1] == "b"


def test_concurrent_run_respects_dependencies(tmp_path):
    """Independent stages may start in any order; a dependent one only after its input."""
    ran = []

    def make(name):
        return lambda d, deps: ran.append(name) or {"name": name}

    for _ in range(20):
        ran.clear()
        shutil.rmtree(tmp_path / "stages", ignore_errors=True)
        Pipeline(tmp_path, [Stage("a", {}, make("a")), Stage("b", {}, make("b")),
                            Stage("c", {}, make("c"), ("a",))]).run()
        assert sorted(ran) == ["a", "b", "c"]
        assert ran.index("c") > ran.index("a")


@pytest.mark.slow
def test_ray_backend_gives_the_same_numbers_as_the_process_pool(smoke_run, tmp_path):
    pytest.importorskip("ray")
    out, _, _ = smoke_run
    stage = next((out / "stages").glob("experts-unseen-*"))
    algo = read_json(stage / "stage.json")["result"]["algo"]
    cfg = TrainConfig(algo=algo, scenario="unseen1", seed=RC.seed, preset="smoke", eval_episodes=RC.eval_episodes)
    local_dir = stage / "runs" / "unseen1"
    jobs = [Job(f"{algo}-unseen1", train_job, (cfg.to_dict(), str(tmp_path / "ray" / "unseen1")),
                tmp_path / "ray.log")]
    [res] = run_jobs(jobs, 1, backend="ray")
    assert res.ok, (res.error, res.log.read_text()[-2000:])
    assert res.value["final_eval"] == read_json(local_dir / "done.json")["final_eval"]


@pytest.mark.slow
def test_reproduce_on_ray_gives_the_process_pools_numbers(smoke_run, tmp_path):
    """``reproduce --backend ray`` on a local Ray instance with two workers: a whole track
    (experts in parallel, the DT chain, evaluations), every stage's result the same as the
    local pool's in the smoke run (stages are keyed by their configuration: same keys)."""
    pytest.importorskip("ray")
    out, _, _ = smoke_run
    ray_out = tmp_path / "ray"
    reproduce(dataclasses.replace(RC, track="strong"), ray_out, workers=2, backend="ray", progress=False)
    ray_stages = sorted(p.parent.name for p in (ray_out / "stages").glob("*/stage.json"))
    assert len(ray_stages) >= 8 and all(name.startswith("strong-") for name in ray_stages)
    for name in ray_stages:
        assert (read_json(ray_out / "stages" / name / "stage.json")["result"]
                == read_json(out / "stages" / name / "stage.json")["result"]), name
    schedule = read_json(ray_out / "schedule.json")
    assert len(schedule["jobs"]) > len(ray_stages)  # more than one job a stage went through Ray


def test_downstream_is_the_longest_chain_after_each_stage(tmp_path):
    noop = lambda d, deps: {}  # noqa: E731
    p = Pipeline(tmp_path, [Stage("a", {}, noop, costs=(10.0,)), Stage("b", {}, noop, ("a",), costs=(4.0, 4.0)),
                            Stage("c", {}, noop, ("b",), costs=(3.0,)), Stage("d", {}, noop, ("a",), costs=(1.0,)),
                            Stage("e", {}, noop, costs=(2.0,))])
    # b's two jobs of 4 s take 4 s on two workers, 8 s on one
    assert p.downstream(2) == {"a": 7.0, "b": 3.0, "c": 0.0, "d": 0.0, "e": 0.0}
    assert p.downstream(1) == {"a": 11.0, "b": 3.0, "c": 0.0, "d": 0.0, "e": 0.0}


def test_the_longest_chain_runs_first(tmp_path):
    """One worker; a chain of three long stages and four short independent ones. Every stage
    without unmet inputs starts at once and queues its job; the runner starts none until all
    have, then the one heading the longest remaining work: the chain's first stage runs
    before every short one. A later link is queued when its input ends, by which time the
    freed worker may have taken one short job, never more."""
    _ORDER.clear()
    ctx = StudyContext(1, "local", None)

    def stage(name, cost, deps=()):  # a job of 0.1 s per unit of cost, long enough to queue the next link
        return Stage(name, {}, lambda d, deps_: ctx.run_one(name, _record, (name, False, cost / 10), tmp_path / name,
                                                            cost), deps, costs=(cost,))

    # short jobs of 0.4 s: a loaded machine still queues the next link within one of them
    pipeline = Pipeline(tmp_path, [stage("short1", 4.0), stage("short2", 4.0), stage("long1", 10.0),
                                   stage("long2", 10.0, ("long1",)), stage("short3", 4.0),
                                   stage("long3", 10.0, ("long2",)), stage("short4", 4.0)])
    ctx.plan(pipeline)
    pipeline.run()
    ctx.close()
    assert _ORDER[0] == "long1" and sorted(_ORDER) == sorted(
        ["long1", "long2", "long3", "short1", "short2", "short3", "short4"])
    assert 1 <= _ORDER.index("long2") - _ORDER.index("long1") <= 2
    assert 1 <= _ORDER.index("long3") - _ORDER.index("long2") <= 2
    assert [s["worker"] for s in ctx.schedule(0.0)] == [0] * 7


_ORDER = []
_GATE = threading.Event()


def _record(name, wait=False, seconds=0.0):
    if wait:
        _GATE.wait(10)
    time.sleep(seconds)
    _ORDER.append(name)
    return name


def test_job_runner_starts_the_highest_priority_waiting_job_first(tmp_path):
    """One worker busy with a job; a low- and then a high-priority job wait from two other
    threads: when the worker frees, the high-priority one runs first."""
    _ORDER.clear()
    _GATE.clear()
    runner = JobRunner(1)
    log = tmp_path / "log"
    first = threading.Thread(target=runner.run, args=([Job("first", _record, ("first", True), log)],))
    first.start()
    while not runner._busy:
        time.sleep(0.01)
    low = threading.Thread(target=runner.run, args=([Job("low", _record, ("low",), log)],), kwargs={"priority": 0})
    high = threading.Thread(target=runner.run, args=([Job("high", _record, ("high",), log)],), kwargs={"priority": 2})
    low.start()
    while len(runner._waiting) < 1:
        time.sleep(0.01)
    high.start()
    while len(runner._waiting) < 2:
        time.sleep(0.01)
    _GATE.set()
    for t in (first, low, high):
        t.join(10)
    assert _ORDER == ["first", "high", "low"]


@pytest.mark.slow
def test_job_runner_pool_returns_every_result(tmp_path):
    with JobRunner(2) as runner:
        res = runner.run([Job(f"j{i}", _record, (f"j{i}",), tmp_path / f"{i}.log") for i in range(4)])
    assert sorted(r.value for r in res) == ["j0", "j1", "j2", "j3"] and all(r.ok for r in res)


def test_expected_schedule_replays_the_longest_chain_first(tmp_path: Path) -> None:
    """The estimate of `reproduce --estimate`: a chain A -> B of 10 s jobs and three 3 s stages
    on two workers end at 20 s (the chain on one worker, the rest beside it); on one worker
    the work adds up; on many the chain bounds it."""
    from uavris.experiments.engine.forecast import expected_schedule
    from uavris.experiments.engine.stages import Pipeline, Stage

    def noop(d: Path, deps: dict[str, Path]) -> None:
        return None

    stages = [Stage("a", {}, noop, costs=(10.0,)), Stage("b", {}, noop, ("a",), (10.0,)),
              *(Stage(n, {}, noop, costs=(3.0,)) for n in ("c", "d", "e"))]
    pipeline = Pipeline(tmp_path, stages)
    wall, spans = expected_schedule(pipeline, 2)
    assert wall == 20.0 and spans["a"] == (0.0, 10.0) and spans["b"] == (10.0, 20.0)
    assert max(spans[n][1] for n in "cde") == 9.0
    assert expected_schedule(pipeline, 1)[0] == 29.0
    assert expected_schedule(pipeline, 8)[0] == 20.0


def test_reproduce_estimate_runs_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    from uavris.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["reproduce", "--preset", "quick", "--estimate", "--expert-algo", "ppo"]) == 0
    out = capsys.readouterr().out
    assert "expected wall clock" in out and "| deploy-pretrain |" in out and "| compare | 12 |" in out
    assert list(tmp_path.iterdir()) == []


def test_the_progress_bar_counts_this_invocations_work(tmp_path: Path) -> None:
    """A stage finished earlier leaves the bar's total (a resumed study does not look nearly
    done at once); a stage that runs moves the bar by its expected cost; a stage's known
    jobs replace its estimate when they are submitted."""
    import io

    from tqdm import tqdm

    from uavris.experiments.engine.stages import StageRecord

    bar = tqdm(total=0, file=io.StringIO())
    ctx = StudyContext(1, "local", None, bar)
    pipeline = Pipeline(tmp_path, [Stage("old", {}, lambda d, deps: None, costs=(10.0,)),
                                   Stage("new", {}, lambda d, deps: None, costs=(30.0,), progress_s=50.0)])
    ctx.plan(pipeline)
    assert bar.total == 60.0
    ctx.stage_done(StageRecord("old", "k", tmp_path, "skipped", 1.0, None))
    assert (bar.total, bar.n) == (50.0, 0)
    ctx.submit("new", [Job("j", _record, ("j",), tmp_path / "log", 30.0)])
    assert bar.total == 30.0 and bar.n == 30.0
    ctx.stage_done(StageRecord("new", "k", tmp_path, "done", 1.0, None))
    ctx.close()
    assert (bar.total, bar.n) == (30.0, 30.0)


def test_the_ablation_runs_on_demand_only(tmp_path):
    """`make run` (no --ablation) has no ablation stage; with --ablation the data curve, the flat
    encoder and the mixed-quality rows come back, each for every pre-training seed, and the return-
    conditioned DT's fine-tuning, and
    nothing else changes but the evaluations that read them. Fine-tuning that tries places is
    the ablation's too (it ended below the zero-shot goal-conditioned DT: docs/places.md)."""
    ctx = StudyContext(1, "local", None)
    plain = build_pipeline(dataclasses.replace(RC, ablation=False), tmp_path, ctx).stages
    full = build_pipeline(RC, tmp_path, ctx).stages
    ablation = {"deploy-dataset-mixed", "deploy-evaluate-layout-other-0", "deploy-evaluate-layout-other-1",
                "deploy-finetune-layout-unseen-0", "deploy-finetune-layout-unseen-1"} | {
        f"deploy-{m}{s}" for m in ("pretrain-n1", "flat", "mixed-dt", "mixed-bc") for s in ("", "-s1")} | {
        f"deploy-finetune-places-layout-unseen-{j}{s}" for j in (0, 1) for s in ("", "-s1")}
    assert set(full) - set(plain) == ablation and set(plain) <= set(full)
    assert not any(m in n for n in plain for m in ("-flat", "-mixed", "-pretrain-n"))
    # the main rows are the same stages with the same keys: DT and BC over both seeds, fine-tuning
    main = {f"deploy-{m}{s}" for m in ("pretrain", "bc") for s in ("", "-s1")} | {"deploy-dataset"}
    assert main <= set(plain) and all(plain[n].key == full[n].key for n in main)
    evaluations = {n for n in plain if "-evaluate-layout" in n}
    assert all(plain[n].key != full[n].key for n in evaluations)
    assert {n for n in plain if plain[n].key != full[n].key} == evaluations
    assert not any("-other-" in n for n in plain)  # the other generator's halls: with the ablation only


def test_the_comparison_runs_for_the_studys_number_of_steps(tmp_path):
    """--compare-steps sets every run of the comparison (and only the comparison): its stage is
    keyed by it and its expected cost follows it; the experts of the paper track keep the
    preset's training length."""
    from uavris.experiments.training.compare import comparison_configs
    from uavris.presets import TRAIN

    ctx = StudyContext(1, "local", None)
    short = build_pipeline(dataclasses.replace(RC, compare_steps=320), tmp_path, ctx).stages
    long = build_pipeline(dataclasses.replace(RC, compare_steps=1280), tmp_path, ctx).stages
    assert short["compare"].config["steps"] == 320 and short["compare"].key != long["compare"].key
    assert sum(long["compare"].costs) > 2 * sum(short["compare"].costs)
    assert short["experts-train"].config == long["experts-train"].config  # its key follows the comparison's choice
    cfgs = comparison_configs("smoke", 2, ("sac", "ppo"), "fig2", 4, RC.system, steps=320)
    assert {c.total_steps for c in cfgs.values()} == {320} and len(cfgs) == 4
    assert {c.total_steps for c in comparison_configs("smoke", 1, ("sac",), "fig2", 4, RC.system).values()} == {
        TRAIN["smoke"]["total_steps"]}
