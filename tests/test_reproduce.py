"""End to end: `uavris reproduce --preset smoke` (one comparison seed, 4 evaluation episodes,
2 trajectories per expert to keep CI at a few minutes), interrupted once and resumed."""

import dataclasses
import re

import pytest

from uavris.config import SystemConfig
from uavris.experiments import dt_pipeline
from uavris.experiments.compare import train_job
from uavris.experiments.io import read_json
from uavris.experiments.jobs import Job, run_jobs
from uavris.experiments.reproduce import ReproduceConfig, _Context, build_pipeline, nearest_training_scenarios, reproduce
from uavris.experiments.stages import Pipeline, Stage
from uavris.experiments.training import preset_config

RC = ReproduceConfig("smoke", compare_seeds=1, eval_episodes=4, trajectories=2)


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    calls = []
    real_pretrain = dt_pipeline.pretrain

    def killed(*args, **kwargs):
        calls.append(1)
        raise KeyboardInterrupt("simulated kill during pre-training")

    dt_pipeline.pretrain = killed
    try:
        with pytest.raises(KeyboardInterrupt):
            reproduce(RC, out, workers=2, progress=False)
    finally:
        dt_pipeline.pretrain = real_pretrain
    assert calls
    first_done = sorted(p.parent.name.rsplit("-", 1)[0] for p in (out / "stages").glob("*/stage.json"))
    report = reproduce(RC, out, workers=2, progress=False)
    return out, report, first_done


def test_all_artefacts_exist(smoke_run):
    out, report, _ = smoke_run
    assert report == out / "report.md"
    for stem in ("fig2_learning_curves", "fig3a_unseen1", "fig3b_unseen2", "interactions_unseen1",
                 "interactions_unseen2", "trajectory_unseen1"):
        for ext in ("png", "pdf"):
            assert (out / "figures" / f"{stem}.{ext}").stat().st_size > 1000, stem
    text = report.read_text()
    assert "## The paper's claims, checked" in text
    for claim in ("DDPG is the best of the four", "zero-shot DT above transferred DDPG",
                  "fine-tuned DT within 5% of the expert"):
        assert claim in text


def test_report_numbers_come_from_evaluation_files(smoke_run):
    out, report, _ = smoke_run
    text = report.read_text()
    for scenario in ("unseen1", "unseen2"):
        stage = next((out / "stages").glob(f"evaluate-{scenario}-*"))
        result = read_json(stage / "stage.json")["result"]
        assert set(result) == {"expert", "dt-zero-shot", "dt-finetuned", "oracle"} | {
            f"transfer-{s}" for s in nearest_training_scenarios(scenario)}
        for summary in result.values():
            per_episode = [float(x) for x in re.findall(r"^\d+,([^,]+),", (stage / f"{summary['policy']}.csv")
                                                       .read_text(), re.M)]
            assert len(per_episode) == 4
            assert abs(sum(per_episode) / 4 - summary["mean"]) < 1e-9
            assert f"| {summary['label']} | {summary['mean']:.2f} |" in text
        oracle = result["oracle"]["mean"]
        assert f"| {result['expert']['mean'] / oracle:.0%} |" in text


def test_rerun_after_kill_skips_finished_stages(smoke_run):
    out, _, first_done = smoke_run
    # the kill hit pre-training: everything before it had finished and was not redone
    assert {"compare", "experts-train", "experts-unseen", "dataset"} <= set(first_done)
    assert "pretrain" not in first_done
    pipeline = build_pipeline(RC, out, _Context(1, "local", None, None))
    records = pipeline.run()
    assert all(r.status == "skipped" for r in records)


def test_changed_parameter_invalidates_exactly_its_dependents(tmp_path):
    ctx = _Context(1, "local", None, None)
    base = build_pipeline(RC, tmp_path, ctx)

    def changed(**kw):
        other = build_pipeline(dataclasses.replace(RC, **kw), tmp_path, ctx)
        return {n for n in base.stages if base.stages[n].key != other.stages[n].key}

    downstream_of_dataset = {"dataset", "pretrain", "finetune-unseen1", "finetune-unseen2", "evaluate-unseen1",
                             "evaluate-unseen2"}
    assert changed(trajectories=3) == downstream_of_dataset
    assert changed(compare_seeds=2) == {"compare"}
    assert changed(system=SystemConfig(noise_dbm=-90.0)) == set(base.stages)


def test_stage_keys_chain_through_dependencies(tmp_path):
    ran = []

    def make(name):
        return lambda d, deps: ran.append(name) or {"name": name}

    def pipe(a_cfg):
        return Pipeline(tmp_path, [Stage("a", a_cfg, make("a")), Stage("b", {"x": 1}, make("b")),
                                   Stage("c", {}, make("c"), ("a",))])

    pipe({"v": 1}).run()
    assert ran == ["a", "b", "c"]
    pipe({"v": 1}).run()
    assert ran == ["a", "b", "c"]  # nothing redone
    pipe({"v": 2}).run()
    assert ran == ["a", "b", "c", "a", "c"]  # b does not depend on a
    pipe({"v": 2}).run(force=("b",))
    assert ran[-1] == "b"


def test_ray_backend_gives_the_same_numbers_as_the_process_pool(smoke_run, tmp_path):
    pytest.importorskip("ray")
    out, _, _ = smoke_run
    cfg = preset_config("ddpg", "unseen1", RC.seed, "smoke", eval_episodes=RC.n_eval)
    local_dir = next((out / "stages").glob("experts-unseen-*")) / "runs" / "unseen1"
    jobs = [Job("ddpg-unseen1", train_job, (cfg.to_dict(), str(tmp_path / "ray" / "unseen1")),
                tmp_path / "ray.log")]
    [res] = run_jobs(jobs, 1, backend="ray")
    assert res.ok, (res.error, res.log.read_text()[-2000:])
    assert res.value["final_eval"] == read_json(local_dir / "done.json")["final_eval"]
