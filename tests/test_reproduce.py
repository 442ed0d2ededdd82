"""End to end: `uavris reproduce --preset smoke`, every track (one comparison seed, 3 evaluation
episodes, the fewest with a t interval of useful width, and 2 trajectories per expert to keep
the suite short), killed once and resumed; on Ray. The deployment ablation's stages and rows are
tests/test_deployment_track.py's smoke study (here: only how they enter the stage graph)."""

import dataclasses
import re
import shutil
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from ray_cluster import can_unshare, two_node_cluster
from report_check import check_deployment_claims, check_deployment_report, check_track_claims, mean_ci

from tests.conftest import SMOKE_SYSTEM
from uavris.agents.oracle.store import STORE_ENV
from uavris.errors import UavrisError
from uavris.experiments.engine.jobs import JobRunner, run_jobs
from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.engine.stages import Pipeline, Stage
from uavris.experiments.engine.worker import Job
from uavris.experiments.study.config import ReproduceConfig
from uavris.experiments.study.pipeline import build_pipeline
from uavris.experiments.study.reproduce import reproduce
from uavris.experiments.study.tracks import nearest_training_scenarios
from uavris.experiments.training import pretrain as pretrain_module
from uavris.experiments.training.train_expert import TrainConfig, train_job
from uavris.io import read_json

RC = ReproduceConfig("smoke", compare_seeds=1, eval_episodes=3, trajectories=2, system=SMOKE_SYSTEM)
# The stage graph with the deployment ablation (tests/test_deployment_track.py runs its smoke study)
ABLATION = dataclasses.replace(RC, ablation=True)


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    calls = []
    real_pretrain = pretrain_module.pretrain

    def killed(*args, **kwargs):
        calls.append(1)
        raise RuntimeError("simulated crash during pre-training")

    # One worker runs the jobs in this process, where the patched function is seen; the
    # crashed pre-training fails its stages and what depends on them, the rest finishes.
    # (Not a KeyboardInterrupt: in the command's own process that is Ctrl-C, which stops it.)
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
        # behaviour cloning on the same dataset beside the DT, in every track
        assert set(result) == {"expert", "dt-zero-shot", "dt-finetuned", "bc", "zero-action", "hover-optimizer",
                               "oracle"} | {f"transfer-{s}" for s in nearest_training_scenarios(scenario)}
        for summary in result.values():
            per_episode = [float(x) for x in re.findall(r"^\d+,([^,]+),", (stage / f"{summary['policy']}.csv")
                                                       .read_text(), re.M)]
            assert len(per_episode) == RC.eval_episodes
            assert abs(sum(per_episode) / RC.eval_episodes - summary["mean"]) < 1e-9
            # the CI over episodes (what "95% CIs overlap" and "vs zero action" read) is Student's t
            assert (summary["ci_low"], summary["ci_high"]) == pytest.approx(mean_ci(per_episode)[1:3], rel=1e-9)
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
        for key in ("dt-zero-shot-safe", "bc-safe", "dt-goal-safe"):  # every learned row over 2 seeds
            assert {key, f"{key}@s1"} <= set(result)
        for summary in result.values():
            per_episode = [float(x) for x in re.findall(r"^\d+,([^,]+),", (stage / f"{summary['policy']}.csv")
                                                       .read_text(), re.M)]
            assert len(per_episode) == RC.eval_episodes
            assert abs(sum(per_episode) / RC.eval_episodes - summary["mean"]) < 1e-9
    check_deployment_report({s.name[len("deploy-evaluate-"):].rsplit("-", 1)[0]:
                             read_json(s / "stage.json")["result"] for s in stages}, report.read_text())
    # the halls of another generator are the ablation's (tests/test_deployment_track.py checks them)
    assert not list((out / "stages").glob("deploy-evaluate-layout-other-*"))


@pytest.mark.slow
def test_the_claims_of_every_track_compute_again_from_their_evidence_and_the_pages_are_stamped(
        smoke_run, tmp_path, monkeypatch):
    """The claims page of the smoke study: every judged cell of the comparison, the paper and strong
    tracks and the deployment track computed again from the evidence beside it (tests/claims_recompute.py,
    no uavris judging code), an edited episode caught. The report, its copy as the quick run's page
    and the budget page are stamped with this code's versions and what made them."""
    import json

    from claims_recompute import expected_cells, mismatches

    from uavris.experiments.study import claims_comparison
    from uavris.experiments.study.claims import EVIDENCE, UNITS, write_claims
    from uavris.experiments.study.report import page_copy
    from uavris.experiments.study.stamp import read_stamp, stale

    out, report, _ = smoke_run
    write_claims([out], tmp_path / "c")
    claims, units = read_json(tmp_path / "c" / "claims.json"), read_json(tmp_path / "c" / EVIDENCE / UNITS)
    assert not mismatches(claims, units)
    cells = expected_cells(units)
    assert {("paper", "ddpg-best"), ("paper", "zero-shot"), ("strong", "fewer"), ("deployment", "zero-shot")} <= set(
        cells)
    edited = json.loads(json.dumps(units))
    edited["scenario"]["strong"][0]["rows"]["dt-zero-shot"][0] -= 1.0
    assert any("('strong', 'zero-shot')" in m for m in mismatches(claims, edited))
    stamp = read_stamp(report.read_text())
    assert stamp.page == "report" and stale(stamp) == [] and stamp.studies == (str(out),) and stamp.preset == "smoke"
    (tmp_path / "docs" / "figures").mkdir(parents=True)
    (tmp_path / "docs" / "figures" / "quick_fig2_learning_curves.png").write_bytes(b"old")
    written = page_copy(out, tmp_path / "docs" / "results" / "quick-report.md", "quick-report", "uavris reproduce x")
    page = read_stamp(written[0].read_text())
    assert page.page == "quick-report" and page.command == "uavris reproduce x" and stale(page) == []
    assert written[0].read_text().split("-->\n", 1)[1] == report.read_text().split("-->\n", 1)[1]
    kept = tmp_path / "docs" / "figures" / "quick_fig2_learning_curves.png"  # the figure the docs keep, refreshed
    assert kept in written and kept.read_bytes() == (out / "figures" / "fig2_learning_curves.png").read_bytes()
    fixed = {"mean": 12.0, "ci_low": 11.5, "ci_high": 12.5}
    monkeypatch.setattr(claims_comparison, "fig2_zero_action", lambda: fixed)
    monkeypatch.setattr(claims_comparison, "fig2_references", lambda: {"hover-optimizer": fixed, "oracle": fixed})
    cdir = next((out / "stages").glob("compare-*"))
    [budget, *figures] = claims_comparison.write_budget_page([(cdir, (RC.compare_steps,))], tmp_path / "budget.md",
                                                             "smoke", ["uavris compare-algorithms ..."])
    text = budget.read_text()
    assert read_stamp(text).page == "budget" and f"| {RC.compare_steps:,} | PPO |" in text
    assert all(f.is_file() for f in figures) and "holds" not in text and "refuted" not in text


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
    base = build_pipeline(ABLATION, tmp_path, ctx)

    def changed(**kw):
        other = build_pipeline(dataclasses.replace(ABLATION, **kw), tmp_path, ctx)
        return {n for n in base.stages if n not in other.stages or base.stages[n].key != other.stages[n].key}

    dt = {"dataset", "pretrain", "bc", "finetune-unseen1", "finetune-unseen2", "evaluate-unseen1",
          "evaluate-unseen2"}
    deploy = {n for n in base.stages if n.startswith("deploy-")}
    models = {"pretrain", "bc", "goal", "goal-mlp", "bc-best", "pretrain-n1", "flat", "mixed-dt", "mixed-bc"}  # 2 seeds
    evaluations = {f"deploy-evaluate-layout-{split}-{j}" for split in ("unseen", "other") for j in (0, 1)}
    places = {f"deploy-finetune-places-layout-unseen-{j}{s}" for j in (0, 1) for s in ("", "-s1")}
    assert deploy == {"deploy-dataset", "deploy-dataset-best", "deploy-dataset-mixed",
                      "deploy-finetune-layout-unseen-0", "deploy-finetune-layout-unseen-1", "deploy-value-labels",
                      "deploy-value", "deploy-value-s1"} \
        | evaluations | places | {f"deploy-{m}{s}" for m in models for s in ("", "-s1")}
    assert changed(trajectories=3) == dt | {f"strong-{n}" for n in dt}
    # the learned value's labels come from their own halls, its fit from them and the demonstrations' plans
    assert changed(layout_trajectories=3) == deploy - {"deploy-value-labels"}
    # the paper track's experts follow the comparison (they are its winner's)
    assert changed(compare_seeds=2) == {"compare", "experts-train", "experts-unseen"} | dt
    assert changed(expert_algo="ppo") == {"experts-train", "experts-unseen"} | dt
    assert changed(system=ABLATION.system.replace(noise_dbm=-90.0)) == set(base.stages)
    # other layouts: only the deployment track's stages
    assert changed(layout_seed=1) == deploy
    assert changed(scaling=()) == {"deploy-pretrain-n1", "deploy-pretrain-n1-s1"} | evaluations
    assert changed(dt_seeds=1) == {n for n in deploy if n.endswith("-s1")} | evaluations
    assert changed(mixed_layouts=1) == {"deploy-dataset-mixed", "deploy-mixed-dt", "deploy-mixed-dt-s1",
                                        "deploy-mixed-bc", "deploy-mixed-bc-s1"} | evaluations
    assert set(build_pipeline(dataclasses.replace(ABLATION, track="strong"), tmp_path, ctx).stages) == {
        n for n in base.stages if n.startswith("strong-")}
    assert set(build_pipeline(dataclasses.replace(ABLATION, track="deployment"), tmp_path, ctx).stages) == deploy
    assert "compare" not in build_pipeline(dataclasses.replace(ABLATION, track="deployment"), tmp_path, ctx).stages


def test_a_new_oracle_reruns_what_follows_from_its_plans_and_flights(tmp_path, monkeypatch):
    """The oracle's version (uavris.agents.oracle.planner.ORACLE_VERSION) is in the keys of the stages
    whose results follow from its plans and flights: the strong experts imitate its flight, the
    demonstrations fly the planner's plans, the evaluations score it, the learned value's labels are its
    screen and its rate of poses; and so in every stage that learns from them. The paper track's experts
    and DT and the comparison stay."""
    from uavris.agents.oracle import planner

    ctx = StudyContext(1, "local", None)
    base = build_pipeline(ABLATION, tmp_path, ctx)
    monkeypatch.setattr(planner, "ORACLE_VERSION", planner.ORACLE_VERSION + 1)
    other = build_pipeline(ABLATION, tmp_path, ctx)
    kept = {n for n in base.stages if base.stages[n].key == other.stages[n].key}
    assert kept == {"compare", "experts-train", "experts-unseen", "dataset", "pretrain", "bc", "finetune-unseen1",
                    "finetune-unseen2"}


def test_an_evaluation_reruns_when_its_hall_changes_under_the_same_name(tmp_path, monkeypatch):
    """A stage's key covers the hall it reads, not only its name: one device of an unseen hall
    moved (its name kept) changes that hall's stages' keys and no other (every other is reused);
    halls of one count no longer share a key."""
    from uavris.layouts import LayoutGenerator

    rc = dataclasses.replace(RC, track="deployment", ablation=False, device_counts=(3,))
    ctx = StudyContext(1, "local", None)
    before = build_pipeline(rc, tmp_path, ctx)
    evaluations = [n for n in before.stages if n.startswith("deploy-evaluate-")]
    assert len({before.stages[n].key for n in evaluations}) == len(evaluations) == 4
    generated = LayoutGenerator.layout

    def moved(self, split, index, base=None):
        layout = generated(self, split, index, base)
        if (split, index, self.devices) == ("unseen", 1, 4):
            x, y, z = layout.users[0]
            layout = dataclasses.replace(layout, users=((x + 0.25, y, z), *layout.users[1:]))
        return layout

    monkeypatch.setattr(LayoutGenerator, "layout", moved)
    after = build_pipeline(rc, tmp_path, ctx)
    assert after.stages.keys() == before.stages.keys()
    assert {n for n in before.stages if before.stages[n].key != after.stages[n].key} == {
        "deploy-evaluate-layout-unseen-1"}


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
    pipe({"v": 2}).run(force=("a",), concurrent=False)
    assert ran[-2:] == ["a", "c"]  # forcing a stage runs what depends on it again (c read a's old result)


def test_a_pipeline_refuses_two_stages_of_one_name(tmp_path):
    """A stage's name is its folder and what --force names: a second stage of that name (a stage
    kind registered beside a study under one of its names) is one error, not a silent replacement."""
    def run(d, deps):
        return {}

    with pytest.raises(UavrisError, match="two stages named 'a'"):
        Pipeline(tmp_path, [Stage("a", {"v": 1}, run), Stage("b", {}, run), Stage("a", {"v": 2}, run)])


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


def _no_nan(name: str) -> None:
    raise ValueError(f"{name} in a stage record: not JSON")


def test_a_stage_record_is_the_same_json_for_the_same_inputs(tmp_path):
    """Two runs of the same stages (a fit of the learned value, which is timed; a comparison's
    rows, one seed each: undefined intervals) write stage.json byte for byte the same, strict
    JSON (NaN as null); the wall clocks are in timing.json beside it."""
    import json

    from uavris.experiments.study.pipeline import compare_record
    from uavris.experiments.study.workers import value_fit_job
    from uavris.experiments.training.values import ValueFitConfig, write_label_part
    from uavris.stats import summarize

    rng = np.random.default_rng(0)
    part = write_label_part(tmp_path / "labels.npz", users=rng.uniform(0, 40, (32, 3, 3)),
                            position=rng.uniform(0, 40, (32, 3)), rate=rng.uniform(0, 30, 32),
                            hall=np.array(["h"] * 32))
    fit = ValueFitConfig(preset="smoke").to_dict()
    rows = [{"policy": "PPO", "kind": "DRL", **summarize([7.5]), "s_per_step": 1e-3 * time.perf_counter()}]
    summary = {"rows": rows, "expert": "ppo", "expert_choice": {"expert": "ppo", "text": f"{time.time()} ms"}}

    def stages():
        return [Stage("value", fit, lambda d, deps: value_fit_job(fit, [str(part)], str(d / "value"))),
                Stage("compare", {}, lambda d, deps: compare_record(summary))]

    records, dirs = {}, {}
    for out in (tmp_path / "one", tmp_path / "two"):
        pipeline = Pipeline(out, stages())
        assert all(r.status == "done" for r in pipeline.run(concurrent=False))
        dirs[out.name] = {name: pipeline.directory(name) for name in ("value", "compare")}
        records[out.name] = {name: (d / "stage.json").read_bytes() for name, d in dirs[out.name].items()}
        summary["rows"][0]["s_per_step"] *= 2  # another machine's, another run's times
        summary["expert_choice"]["text"] += " later"
    assert records["one"] == records["two"]
    for d in dirs["one"].values():
        timing = read_json(d / "timing.json")
        assert timing["wall_s"] >= 0 and timing["end"] >= timing["start"]
    assert read_json(dirs["one"]["value"] / "value" / "timing.json")["wall_clock_s"] > 0
    compare = json.loads(records["one"]["compare"], parse_constant=_no_nan)
    assert compare["result"]["rows"][0]["mean_ci_low"] is None and compare["result"]["rows"][0]["mean"] == 7.5
    assert "s_per_step" not in compare["result"]["rows"][0] and compare["result"]["expert"] == "ppo"
    json.loads(records["one"]["value"], parse_constant=_no_nan)


def test_the_report_reads_an_undefined_number_of_a_stage_record():
    """What a stage record stores as null (an interval over one episode, a rank correlation
    over too few poses) the report prints as undefined, as it did the NaN it stood for."""
    from uavris.experiments.study.report import finetuning_effect
    from uavris.experiments.study.report.decomposition import value_section

    one = {"mean": 5.0, "ci_low": None, "ci_high": None}
    assert "within the 95% CIs" in finetuning_effect(one, dict(one, mean=9.0))
    results = {lay: {"v": {"value_rank_correlation": rho, "value_target_rate_level": 1.0},
                     "oracle": {"plan_rate_level": 2.0}} for lay, rho in (("a", None), ("b", 0.5))}
    assert "| V | nan | nan | 50.0% | 50.0% |" in value_section(results)


@pytest.mark.slow
def test_ray_backend_gives_the_same_numbers_as_the_process_pool(smoke_run, tmp_path):
    pytest.importorskip("ray")
    out, _, _ = smoke_run
    stage = next((out / "stages").glob("experts-unseen-*"))
    algo = read_json(stage / "stage.json")["result"]["algo"]
    cfg = TrainConfig(algo=algo, scenario="unseen1", seed=RC.seed, preset="smoke", eval_episodes=RC.eval_episodes,
                      system=RC.system)
    local_dir = stage / "runs" / "unseen1"
    jobs = [Job(f"{algo}-unseen1", train_job, (cfg.to_dict(), str(tmp_path / "ray" / "unseen1")),
                tmp_path / "ray.log")]
    [res] = run_jobs(jobs, 1, backend="ray")
    assert res.ok, (res.error, res.log.read_text()[-2000:])
    assert res.value["final_eval"] == read_json(local_dir / "done.json")["final_eval"]


@pytest.mark.slow
def test_reproduce_on_ray_gives_the_process_pools_numbers(smoke_run, tmp_path, monkeypatch):
    """``reproduce --backend ray`` on a local Ray instance with two workers: a whole track
    (experts in parallel, the DT chain, evaluations), every stage's result the same as the
    local pool's in the smoke run (stages are keyed by their configuration: same keys). Where a
    node with a file system of its own can be made, the cluster test below runs a track through
    Ray (on a cluster, a node killed) with the same comparison, and this one is left out: the
    suite's time (a Ray instance started without an address is tested through run_jobs above)."""
    pytest.importorskip("ray")
    if can_unshare() is None:
        pytest.skip("test_a_study_on_ray_nodes_that_share_no_file_system runs a track through Ray here")
    out, _, _ = smoke_run
    ray_out = tmp_path / "ray"
    monkeypatch.delenv(STORE_ENV, raising=False)  # the study's own store: its workers make every plan
    reproduce(dataclasses.replace(RC, track="strong"), ray_out, workers=2, backend="ray", progress=False)
    ray_stages = sorted(p.parent.name for p in (ray_out / "stages").glob("*/stage.json"))
    assert len(ray_stages) >= 8 and all(name.startswith("strong-") for name in ray_stages)
    for name in ray_stages:
        assert (read_json(ray_out / "stages" / name / "stage.json")["result"]
                == read_json(out / "stages" / name / "stage.json")["result"]), name
    schedule = read_json(ray_out / "schedule.json")
    assert len(schedule["jobs"]) > len(ray_stages)  # more than one job a stage went through Ray
    assert list((ray_out / "plans").glob("*.npz"))  # the workers shared their plans in the study's folder


def _without_times(obj):
    """A stage's record without its wall clocks (keys ending in ``_s``), which no two runs share."""
    if isinstance(obj, dict):
        return {k: _without_times(v) for k, v in obj.items() if not k.endswith("_s")}
    if isinstance(obj, list):
        return [_without_times(v) for v in obj]
    return obj


def _stage_files(root: Path) -> set[Path]:
    """A stage's files but its logs and wall clock; a TensorBoard file by its kind (its name
    holds the time, machine and process that wrote it)."""
    return {p.relative_to(root).with_name("events.out.tfevents") if p.name.startswith("events.out.tfevents.")
            else p.relative_to(root) for p in root.rglob("*")
            if p.is_file() and p.suffix != ".log" and p.name != "timing.json"}


@pytest.mark.slow
def test_a_study_on_ray_nodes_that_share_no_file_system(smoke_run, tmp_path, monkeypatch):
    """The deployment track on a two-node Ray cluster whose far node sees an empty
    file system at OUT, that node killed while it evaluates a hall. The study completes, and
    OUT holds what the local run's holds: every stage's record, the same files, the same
    models, datasets' labels and evaluation tables bit for bit."""
    pytest.importorskip("ray")
    why = can_unshare()
    if why:
        pytest.skip(f"a node with a file system of its own cannot be made here: {why}")
    local, _, _ = smoke_run
    out = tmp_path / "study"
    monkeypatch.delenv(STORE_ENV, raising=False)  # the nodes plan for themselves: no plan read from the local run's
    killed: list[tuple[str, bool]] = []
    with two_node_cluster(out, tmp_path / "cluster-logs") as cluster:
        stop = threading.Event()

        def kill_while_evaluating() -> None:
            first_seen: dict[str, float] = {}
            while not stop.wait(0.5):
                for log in cluster.far_view(out / "stages").glob("deploy-evaluate-*/job.log"):
                    stage = log.parent.name
                    if (out / "stages" / stage / "stage.json").exists():
                        continue
                    if time.monotonic() - first_seen.setdefault(stage, time.monotonic()) >= 2.0:
                        # the driver's study.yaml is not on the far node: no shared file system
                        killed.append((stage, (cluster.far_view(out) / "study.yaml").exists()))
                        cluster.kill_far_node()
                        return

        watcher = threading.Thread(target=kill_while_evaluating, daemon=True)
        watcher.start()
        try:
            reproduce(dataclasses.replace(RC, track="deployment"), out, workers=2, backend="ray",
                      ray_address=cluster.address, progress=False)
        finally:
            stop.set()
            watcher.join()
    assert killed, "the far node evaluated no hall, so it was never killed"
    assert killed[0][1] is False and (out / "study.yaml").exists()
    stages = sorted(p.name for p in (out / "stages").iterdir())
    assert len(stages) >= 10 and all(name.startswith("deploy-") for name in stages) and killed[0][0] in stages
    for name in stages:
        mine, theirs = out / "stages" / name, local / "stages" / name
        assert _without_times(read_json(mine / "stage.json")) == _without_times(read_json(theirs / "stage.json")), name
        assert _stage_files(mine) == _stage_files(theirs), name
        for rel in _stage_files(mine):
            if rel.suffix in (".csv", ".npz", ".safetensors"):
                assert (mine / rel).read_bytes() == (theirs / rel).read_bytes(), (name, rel)


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
    assert "paper-track experts: ppo" in out.splitlines()[0]
    assert main(["reproduce", "--preset", "quick", "--track", "deployment", "--estimate"]) == 0
    first = capsys.readouterr().out.splitlines()[0]  # a study without the paper track trains no experts of it
    assert first.startswith("expected wall clock") and "experts" not in first
    assert list(tmp_path.iterdir()) == []


def test_the_estimate_of_a_study_in_part_is_that_of_what_is_left(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A stage the output directory holds is "done" in the estimate, and the clock and work are
    those of the rest (the replay of the stages left, worked out here with the forecast's own
    replay over the same costs)."""
    from uavris.cli import main
    from uavris.experiments.engine.forecast import replay

    flags = ["reproduce", "--preset", "quick", "--estimate", "--expert-algo", "ppo", "--track", "paper",
             "--out", str(tmp_path)]
    assert main(flags) == 0
    whole = capsys.readouterr().out
    rc = ReproduceConfig("quick", expert_algo="ppo", track="paper")
    pipeline = build_pipeline(rc, tmp_path, StudyContext(2, "local", None))
    (pipeline.directory("compare")).mkdir(parents=True)
    (pipeline.directory("compare") / "stage.json").write_text("{}")
    assert main(flags) == 0
    part = capsys.readouterr().out
    assert "| compare | 12 | done |" in part and "| compare | 12 | " in whole and "1 of" in part
    left = {n: (st.deps, st.costs) for n, st in pipeline.stages.items() if n != "compare"}
    wall = replay(left, pipeline.downstream(2), 2, {"compare"})[0]
    assert f"{wall / 60:.0f} min)" in part.splitlines()[0]
    work = sum(sum(c) for _, c in left.values())
    assert f"work left {work / 3600:.1f} core-hours" in part
    assert wall < float(re.search(r"\((\d+) min\)", whole).group(1)) * 60
    assert main([*flags, "--force", "compare"]) == 0  # a stage --force runs again is not done
    assert capsys.readouterr().out == whole


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
    full = build_pipeline(ABLATION, tmp_path, ctx).stages
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


@pytest.mark.slow
def test_a_stage_kind_registered_in_a_test_module_runs_and_is_reported(smoke_run, tmp_path, request, capsys):
    """A new kind of stage is one object in the user's own module (study.pipeline.StageKind):
    the command line schedules it (--estimate, --force) and the report has its section; the
    study's own stages, unchanged, are skipped."""
    from uavris.cli import main
    from uavris.experiments.study import pipeline as pipeline_module
    from uavris.experiments.study.pipeline import StageKind, register_stage_kind

    out = tmp_path / "study"
    shutil.copytree(smoke_run[0], out)

    def count_rows(d: Path, deps: dict[str, Path]) -> dict:
        rows = read_json(deps["evaluate-unseen1"] / "stage.json")["result"]
        (d / "rows.txt").write_text("\n".join(sorted(rows)))
        return {"rows": len(rows)}

    def stages(rc: ReproduceConfig, ctx: StudyContext) -> list[Stage]:
        return [Stage("rows-counted", {"episodes": rc.eval_episodes}, count_rows, ("evaluate-unseen1",))]

    saved = list(pipeline_module.STAGE_KINDS)  # the registry as it was, restored after
    request.addfinalizer(lambda: pipeline_module.STAGE_KINDS.__setitem__(slice(None), saved))
    register_stage_kind(StageKind("rows-counted", "Rows counted", stages,
                                  lambda study: [f"{study.result('rows-counted')['rows']} rows in unseen1."]))
    flags = ["reproduce", "--preset", "smoke", "--compare-seeds", "1", "--eval-episodes", "3", "--trajectories",
             "2", "--system.horizon", str(RC.system.horizon), "--system.energy-budget-j",
             str(RC.system.energy_budget_j), "--out", str(out), "--no-progress"]
    assert main([*flags, "--estimate"]) == 0
    assert "| rows-counted |" in capsys.readouterr().out
    # a finished stage's timing.json is written when it runs: the study's own are not run again
    before = {p.parent.name: p.read_text() for p in (out / "stages").glob("*/timing.json")}
    assert main(flags) == 0
    after = {p.parent.name: p.read_text() for p in (out / "stages").glob("*/timing.json")}
    [new] = set(after) - set(before)
    assert new.startswith("rows-counted-") and all(after[k] == v for k, v in before.items())
    unseen1 = read_json(next((out / "stages").glob("evaluate-unseen1-*")) / "stage.json")["result"]
    text = (out / "report.md").read_text()
    assert f"## Rows counted\n\n{len(unseen1)} rows in unseen1." in text
    (out / "stages" / new / "rows.txt").unlink()
    assert main([*flags, "--force", "rows-counted"]) == 0  # --force knows it, and runs it again
    assert (out / "stages" / new / "rows.txt").read_text().splitlines() == sorted(unseen1)
    assert read_json(out / "stages" / new / "stage.json")["result"] == {"rows": len(unseen1)}


@pytest.mark.slow
def test_report_only_writes_the_report_of_a_study_in_part_and_runs_nothing(smoke_run, tmp_path, capsys):
    """A study stopped part-way: its report so far, from the stages it holds, nothing run (the
    stage removed here stays removed); while another invocation writes the study, one line."""
    from uavris.cli import main
    from uavris.runs.lock import locked

    out = tmp_path / "study"
    shutil.copytree(smoke_run[0], out)
    (out / "report.md").unlink()
    [gone] = (out / "stages").glob("evaluate-unseen2-*")
    shutil.rmtree(gone)
    total = len(build_pipeline(RC, out, StudyContext(1, "local", None)).stages)

    def others() -> dict[str, float]:  # every file but the report and its figures, with its time of change
        return {str(p): p.stat().st_mtime_ns for p in out.rglob("*")
                if p.is_file() and p.name not in ("report.md", ".uavris.lock") and "figures" not in p.parts}

    before = others()
    # the study's own parameters (study.yaml), whatever the study flags say
    assert main(["reproduce", "--preset", "quick", "--out", str(out), "--no-progress", "--report-only"]) == 0
    assert not gone.exists() and others() == before
    text = (out / "report.md").read_text()
    assert f"{total - 1} of the study's {total} stages had finished (not evaluate-unseen2)" in text
    unseen1 = read_json(next((out / "stages").glob("evaluate-unseen1-*")) / "stage.json")["result"]
    assert f"| {unseen1['dt-zero-shot']['label']} | {unseen1['dt-zero-shot']['mean']:.2f} |" in text
    capsys.readouterr()
    flags = ["reproduce", "--out", str(out), "--no-progress", "--report-only"]
    with locked(out, "another reproduce"):
        assert main(flags) == 2
    assert "is being written by" in capsys.readouterr().err
    assert main([*flags, "--force", "pretrain"]) == 2  # it runs nothing: no stage to force
    assert "neither --estimate nor --force" in capsys.readouterr().err


def test_report_only_of_a_folder_without_a_study_is_one_line(tmp_path, capsys):
    from uavris.cli import main

    assert main(["reproduce", "--preset", "smoke", "--out", str(tmp_path), "--report-only", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "holds no study" in err and "\n" not in err
