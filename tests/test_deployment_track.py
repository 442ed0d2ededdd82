"""The deployment track end to end at the smoke preset: demonstrations in parts, the ablation's
stages over seeds, the data curve reusing finished points, the nearest hall's plan, the report."""

from __future__ import annotations

import csv
import dataclasses
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from claims_recompute import expected_cells, mismatches
from report_check import check_deployment_report

from tests.conftest import SMOKE_SYSTEM
from uavris.agents.dt.dataset import load_dataset
from uavris.agents.oracle.bound import episode_bounds
from uavris.errors import UavrisError
from uavris.experiments.engine.scheduling import StudyContext
from uavris.experiments.engine.stages import Pipeline
from uavris.experiments.study.config import ReproduceConfig
from uavris.experiments.study.pipeline import build_pipeline
from uavris.experiments.study.report.deployment import ZERO_SHOT_TARGET
from uavris.experiments.study.reproduce import reproduce
from uavris.experiments.study.stage_names import places_stage
from uavris.experiments.study.tracks import (
    TRACK_SPECS,
    track_rows,
    trained_models,
    transfer_sources,
)
from uavris.io import read_json
from uavris.layouts import LayoutGenerator, layout_distance
from uavris.presets import EVAL_SEED

RC = ReproduceConfig("smoke", track="deployment", eval_episodes=2, dt_seeds=2, scaling=(1,), ablation=True,
                     device_counts=(3,), count_other_layouts=2, system=SMOKE_SYSTEM)


def test_the_other_generators_halls_at_each_device_count_are_sites_of_their_own():
    """--count-other-layouts N: N halls of the other generator at each of --device-counts (not at
    the study's own count, whose other-generator halls are the ablation's), what each hall is
    carried as fields; 1 hall, or no device counts, refused in one line."""
    rc = ReproduceConfig("smoke", track="deployment", device_counts=(4, 6), count_other_layouts=3)
    _, unseen = rc.sites(TRACK_SPECS["deployment"])
    other = [w for w in unseen if w.split == "other"]
    assert [(w.name, w.devices) for w in other] == [(f"layout-other-{j}-k6", 6) for j in range(3)]
    assert sum(w.devices == 6 and w.split == "unseen" for w in unseen) == rc.unseen_layouts
    for bad in (dict(device_counts=(6,), count_other_layouts=1), dict(count_other_layouts=3)):
        with pytest.raises(UavrisError, match="--count-other-layouts"):
            ReproduceConfig("smoke", track="deployment", **bad)


@pytest.fixture(scope="module")
def deployment_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("deploy")
    reproduce(RC, out, workers=1, progress=False)
    records = build_pipeline(RC, out, StudyContext(1, "local", None)).run()  # every stage skipped: their records
    return out, records


def test_the_trained_models_are_the_rows_over_seeds():
    track = TRACK_SPECS["deployment"]
    main = trained_models(track, ["a", "b", "c"], (1, 2), 3)
    assert [m.stage for m in main] == [f"{m}{s}" for m in ("pretrain", "bc", "goal", "goal-mlp", "bc-best")
                                       for s in ("", "-s1", "-s2")]
    by = {m.stage: m for m in main}
    assert by["goal-s2"].row == "dt-goal" and dict(by["goal-s2"].model) == {"goal": True, "condition_on_return": False}
    # the field's baselines: the same goal and inputs with a window of one slot; BC on the best demonstrations
    assert dict(by["goal-mlp"].model) == {"goal": True, "condition_on_return": False, "context": 1}
    assert by["bc-best-s1"].dataset == "dataset-best" and by["bc-best-s1"].row == "bc-best"
    assert dict(by["bc-best"].model) == {"condition_on_return": False}
    assert [(m.row, m.seed) for m in main[:3]] == [("dt-zero-shot", 0), ("dt-zero-shot", 1), ("dt-zero-shot", 2)]
    models = {m.stage: m for m in trained_models(track, ["a", "b", "c"], (1, 2), 3, ablation=True)}
    assert len(models) == (1 + 1 + 3 + 2 + 1 + 2) * 3  # DT, BC, goal DT/MLP/filtered BC, 2 curve points, flat,
    # mixed DT, BC; 3 seeds
    track_fields = {"learning_rate": 3e-4, "model": {"width": 64}}
    assert models["pretrain-n2-s2"].pretrain_fields(track_fields) == {**track_fields, "scenarios": ("a", "b")}
    assert models["pretrain-n2-s2"].row == "dt-zero-shot-n2" and models["pretrain-n2-s2"].seed == 2
    assert models["pretrain-n2-s2"].dataset == "dataset" and models["mixed-bc-s1"].dataset == "dataset-mixed"
    assert models["flat"].pretrain_fields(track_fields)["model"] == {"width": 64, "state_encoder": "flat"}
    assert models["bc-s1"].pretrain_fields({})["model"] == {"condition_on_return": False}
    assert models["mixed-bc-s1"].row == "bc-mixed"
    assert [m.stage for m in trained_models(TRACK_SPECS["paper"], [], (), 1, ablation=True)] == ["pretrain", "bc"]


def test_the_main_rows_are_the_controllers_under_the_safety_layer():
    """Without --ablation every learned row (the DT's seeds, their ensemble, the fine-tuned DT,
    behaviour cloning's seeds) is scored under the attitude safety layer only; the ablation adds
    the same models without the layer and held level, reading the same model files."""
    track = TRACK_SPECS["deployment"]
    train, unseen = ReproduceConfig("smoke").sites(track)
    where = unseen[0]
    models = trained_models(track, [t.name for t in train], (1,), 2)
    stages = ("pretrain", "pretrain-s1", "bc", "bc-s1", "goal", "goal-s1", "goal-mlp", "goal-mlp-s1", "bc-best",
              "bc-best-s1", "value", "value-s1", f"finetune-{where.name}",
              places_stage(where.name, 0), places_stage(where.name, 1))
    dirs = {k: Path("/models") / k for k in stages}
    sources = transfer_sources(track, where, train)
    main = {r.key: r for r in track_rows(track, where, sources, dirs, models, train)}
    full = {r.key: r for r in track_rows(track, where, sources, dirs, models, train, ablation=True)}
    baselines = ("dt-goal-mlp", "dt-goal-mlp@s1", "bc-best", "bc-best@s1")
    plain = {"dt-zero-shot", "dt-zero-shot@s1", "dt-ensemble", "dt-finetuned", "bc", "bc@s1", "dt-goal", "dt-goal@s1",
             "dt-goal-finetuned", "dt-goal-finetuned@s1", *baselines}
    safe = {"dt-zero-shot-safe", "dt-zero-shot-safe@s1", "dt-ensemble-safe", "dt-finetuned-safe", "bc-safe",
            "bc-safe@s1", "dt-goal-safe", "dt-goal-safe@s1", "dt-goal-finetuned-safe", "dt-goal-finetuned-safe@s1",
            *(b.replace("@", "-safe@") if "@" in b else f"{b}-safe" for b in baselines)}
    [transfer] = [k for k, r in main.items() if r.kind == "transfer"]
    refs = {"zero-action", "hover-optimizer", "oracle"}
    # a learned place flown by the oracle's controller, one per pre-training seed's own fit of V
    planners = {"plan-learned", "plan-deployed", "plan-learned@s1", "plan-deployed@s1"}
    assert set(main) == safe | refs | planners | {"oracle-safe", transfer}
    assert set(full) == set(main) | plain | {"dt-zero-shot-level", "dt-zero-shot-level@s1", "dt-ensemble-level"}
    assert list(main)[-3:] == ["zero-action", "hover-optimizer", "oracle"]  # the references last
    for key in ("dt-zero-shot@s1", "bc", "dt-finetuned"):
        name, _, seed = key.partition("@")
        safe_row = main[f"{name}-safe" + (f"@{seed}" if seed else "")]
        assert full[key].target == safe_row.target and safe_row.front_margin_deg == track.front_margin_deg
        assert full[key].front_margin_deg is None and not full[key].level
    assert main["bc-safe@s1"].target.path == Path("/models/bc-s1/model") and main["bc-safe@s1"].seed == 1
    ensemble = full["dt-ensemble-level"]
    assert ensemble.level and [m.path for m in ensemble.members] == [Path("/models/pretrain/model"),
                                                                     Path("/models/pretrain-s1/model")]
    assert main[transfer].plan_of == {t.name: t for t in train}[main[transfer].facts()["plan_of"]]
    assert main[transfer].rank == 0 and {r.kind for k, r in main.items() if k in refs} == {"reference"}
    assert main["dt-zero-shot-safe@s1"].label_for() == "zero-shot DT, seed 1, safety layer"
    # the goal-conditioned DT is told the deployed place (V proposes, R disposes: never worse than staying); its
    # fine-tuned form keeps its own
    value, value_s1 = Path("/models/value/value"), Path("/models/value-s1/value")
    assert main["dt-goal-safe@s1"].goal_from.path == value_s1 and main["dt-goal-safe@s1"].target.path == Path(
        "/models/goal-s1/model")
    assert main["dt-goal-safe@s1"].goal_from.deployed and not main["dt-goal-safe@s1"].goal_from.top_k
    assert main["dt-goal-safe@s1"].facts()["goal_from"].startswith("deployed place")
    assert main["dt-goal-finetuned-safe@s1"].goal_from is None
    # the goal-conditioned MLP is told the same place; filtered behaviour cloning chooses none
    assert main["dt-goal-mlp-safe@s1"].goal_from.path == value_s1 and main["dt-goal-mlp-safe@s1"].goal_from.deployed
    assert main["bc-best-safe"].goal_from is None and main["bc-best-safe"].target.path == Path("/models/bc-best/model")
    assert main["dt-goal-finetuned-safe@s1"].target.path == Path("/models") / places_stage(where.name, 1) / "model"
    assert main["plan-learned"].target.path == value and main["plan-deployed"].target.deployed
    assert main["dt-goal-safe"].goal_from.path == value and main["plan-deployed@s1"].target.path == value_s1
    assert main["plan-learned@s1"].seed == 1 and main["plan-deployed@s1"].target.deployed


def test_demonstrations_cover_every_training_hall(deployment_run):
    out, records = deployment_run
    by = {r.name: r for r in records}
    assert all(r.status == "skipped" for r in records), [(r.name, r.error) for r in records if r.status != "skipped"]
    ds = load_dataset(by["deploy-dataset"].directory / "dataset")
    halls = LayoutGenerator().layouts("train", 3, ds.system)
    assert ds.scenarios == [h.name for h in halls] and len(ds.trajectories) == 3 * 2
    assert {tr.expert for tr in ds.trajectories} == {"oracle"}
    mixed = load_dataset(by["deploy-dataset-mixed"].directory / "dataset")
    assert {tr.expert for tr in mixed.trajectories} == {"oracle", "other-plan", "hover", "noisy-oracle"}


def test_the_nearest_training_halls_plan_is_the_one_at_the_smallest_distance(deployment_run):
    out, records = deployment_run
    gen = LayoutGenerator()
    train = gen.layouts("train", 3)
    for r in records:
        if not r.name.startswith("deploy-evaluate-"):
            continue
        if r.name.endswith("-k3"):  # a hall of another device count: no training hall is "nearest", no fine-tuning
            assert not any(k.startswith(("transfer-", "dt-finetuned", "dt-goal-finetuned")) for k in r.result)
            assert {"dt-goal-safe", "plan-learned", "plan-deployed", "hover-optimizer", "oracle"} <= set(r.result)
            continue
        other = "-other-" in r.name  # the ablation's halls of another generator: zero-shot only
        unseen = gen.layout("other" if other else "unseen", int(r.name.rsplit("-", 1)[1]))
        nearest = min(train, key=lambda t: layout_distance(unseen, t))  # independent of transfer_sources
        [key] = [k for k, v in r.result.items() if v["kind"] == "transfer"]
        assert r.result[key]["plan_of"] == nearest.name and r.result[key]["rank"] == 0
        assert {"dt-zero-shot", "bc", "dt-flat", "dt-mixed", "bc-mixed", "dt-zero-shot-n1", "hover-optimizer",
                "oracle", "dt-zero-shot-safe", "bc-safe", "oracle-safe"} <= set(r.result)
        assert other != ("dt-finetuned" in r.result and "dt-finetuned-safe" in r.result)


def test_the_curve_reuses_finished_points_and_parts_on_a_rerun(deployment_run, tmp_path):
    out, _ = deployment_run
    copy = tmp_path / "run"
    shutil.copytree(out, copy)
    [dataset_dir] = [d for d in (copy / "stages").glob("deploy-dataset-*/")
                     if re.fullmatch(r"deploy-dataset-[0-9a-f]{12}", d.name)]  # not deploy-dataset-mixed
    shutil.rmtree(dataset_dir / "dataset")  # the merged dataset is rebuilt from the parts on disk
    (dataset_dir / "stage.json").unlink()
    parts = sorted(p.name for p in (dataset_dir / "parts").iterdir())
    stamp = {p: (dataset_dir / "parts" / p / "data" / "main_data.hdf5").stat().st_mtime_ns for p in parts}
    more = build_pipeline(dataclasses.replace(RC, scaling=(1, 2)), copy, StudyContext(1, "local", None))
    # the curve's stages and what they read, nothing after them (the evaluations would run again
    # for the new point's row: a row's effect on the evaluations is another test's)
    needed = {"deploy-pretrain", "deploy-pretrain-n1", "deploy-pretrain-n2", "deploy-pretrain-n2-s1"}
    todo = list(needed)
    while todo:
        for dep in more.stages[todo.pop()].deps:
            if dep not in needed:
                needed.add(dep)
                todo.append(dep)
    curve = Pipeline(copy, [st for name, st in more.stages.items() if name in needed])
    assert all(curve.stages[name].key == more.stages[name].key for name in needed)
    records = {r.name: r for r in curve.run()}
    assert records["deploy-dataset"].status == "done"
    assert {p: (dataset_dir / "parts" / p / "data" / "main_data.hdf5").stat().st_mtime_ns for p in parts} == stamp
    # the dataset's key is unchanged, so everything after it keeps its key: the old curve point is reused
    assert records["deploy-pretrain-n1"].status == "skipped" and records["deploy-pretrain"].status == "skipped"
    assert records["deploy-pretrain-n2"].status == "done" and records["deploy-pretrain-n2-s1"].status == "done"


def test_the_report_averages_seeds_and_states_the_claims(deployment_run):
    out, _ = deployment_run
    report = (out / "report.md").read_text()
    section = report[report.index("## Deployment track"):]
    assert "mean over 2 pre-training seeds" in section
    evals = sorted(p for p in (out / "stages").glob("deploy-evaluate-layout-unseen-*/stage.json")
                   if "-k3-" not in p.parent.name)  # neither the other generator's nor the 3-device halls
    per_hall = []
    for path in evals:
        res = read_json(path)["result"]
        per_hall.append((res["dt-zero-shot"]["mean"] + res["dt-zero-shot@s1"]["mean"]) / 2 / res["oracle"]["mean"])
    mean = float(np.mean(per_hall))
    row = next(line for line in section.splitlines() if line.startswith("| zero-shot DT |"))
    assert row.split("|")[2].strip().startswith(f"{mean:.1%}")  # the row is the mean over seeds, then over halls
    assert f"**zero-shot DT >= {ZERO_SHOT_TARGET:.0%} of the oracle" in report and "**the device-set encoder" in report
    # the learned value's accuracy: the table's numbers are the halls' (rank correlation, R at V's argmax / oracle's)
    results = [read_json(p)["result"] for p in evals]
    rho = [r["plan-learned"]["value_rank_correlation"] for r in results]
    share = [r["plan-learned"]["value_target_rate_level"] / r["oracle"]["plan_rate_level"] for r in results]
    assert all(-1.0 <= x <= 1.0 for x in rho)
    value = section[section.index("### The learned value of a pose"):]
    row = next(line for line in value.splitlines() if line.startswith("| V of pre-training seed 0 |"))
    cells = [c.strip() for c in row.split("|")[2:-1]]
    assert cells == [f"{np.mean(rho):.3f}", f"{np.min(rho):.3f}", f"{np.mean(share):.1%}", f"{np.min(share):.1%}"]
    # the second seed's own fit of V has a line of its own, from its own row's records; a fit's one line
    rho1 = [r["plan-learned@s1"]["value_rank_correlation"] for r in results]
    row = next(line for line in value.splitlines() if line.startswith("| V of pre-training seed 1 |"))
    assert row.split("|")[2].strip() == f"{np.mean(rho1):.3f}"
    table = value[value.index("| learned value |"):].split("\n\n")[0]  # this group's table
    assert [line.split("|")[1].strip() for line in table.splitlines() if line.startswith("| V")] == [
        "V of pre-training seed 0", "V of pre-training seed 1"]


def test_plan_learned_from_a_study_without_its_value_is_one_line(tmp_path, capsys):
    """`uavris plan HALL --learned OUT` reads the study's seed 0's V; a study without one says so in a line."""
    from uavris.cli import main
    from uavris.io import write_yaml

    for track, says in (("paper", "learns no value of a pose"), ("deployment", "no finished deploy-value stage")):
        out = tmp_path / track
        write_yaml(out / "study.yaml", dataclasses.replace(RC, track=track).to_dict())
        capsys.readouterr()
        assert main(["plan", "layout-unseen-0", "--learned", str(out), "--system.observe-devices",
                     "--no-progress"]) == 2
        err = capsys.readouterr().err.strip()
        assert says in err and "\n" not in err, err


def test_a_kept_rows_key_is_what_its_numbers_depend_on(tmp_path):
    """kept_rows.row_key: the same row in a moved copy of its model folder has the same key; another
    byte in a model file, another planner of the same learned value, another hall, another
    safety margin give another; a module's policy is not kept."""
    from uavris.experiments.study.kept_rows import row_key
    from uavris.experiments.tools.rows import Row
    from uavris.experiments.tools.targets import DTModel, LearnedValue, UserPolicy

    track = TRACK_SPECS["deployment"]
    first, second = ReproduceConfig("smoke", track="deployment").sites(track)[1][:2]
    for name in ("model", "value"):
        (tmp_path / "a" / name).mkdir(parents=True)
        (tmp_path / "a" / name / "w.safetensors").write_bytes(b"weights")
    shutil.copytree(tmp_path / "a", tmp_path / "b")

    def key(where="a", site=first, deployed=True, margin=None):
        value = LearnedValue.at(tmp_path / where / "value")
        row = Row("dt-goal", "goal DT", DTModel.at(tmp_path / where / "model"),
                  goal_from=dataclasses.replace(value, deployed=deployed), front_margin_deg=margin)
        return row_key(site, track.name, 2, row, 5)

    assert key() == key("b")  # where the files lie is not what the numbers depend on
    (tmp_path / "b" / "model" / "w.safetensors").write_bytes(b"weightz")
    assert len({key(), key("b"), key(deployed=False), key(site=second), key(margin=1.0)}) == 5
    assert row_key(first, track.name, 2, Row("mine", "mine", UserPolicy("json:loads")), 5) is None


def test_each_pre_training_seed_has_its_own_fit_of_the_learned_value(deployment_run):
    """One V per pre-training seed: two fits on the same labels with different seeds, each stage
    read by the evaluations, whose rows told a place by seed 1 are told it by seed 1's V."""
    from safetensors.numpy import load_file

    out, _ = deployment_run
    dirs = {p.parent.name.rsplit("-", 1)[0]: p for p in (out / "stages").glob("deploy-value-*/value")}
    assert set(dirs) == {"deploy-value", "deploy-value-s1"}
    configs = {k: read_json(d.parent / "stage.json")["config"] for k, d in dirs.items()}
    assert configs["deploy-value-s1"]["seed"] == configs["deploy-value"]["seed"] + 1
    assert {k: v for k, v in configs["deploy-value-s1"].items() if k != "seed"} == \
        {k: v for k, v in configs["deploy-value"].items() if k != "seed"}
    w0, w1 = (load_file(str(dirs[k] / "value.safetensors")) for k in ("deploy-value", "deploy-value-s1"))
    assert w0.keys() == w1.keys() and any(not np.array_equal(w0[k], w1[k]) for k in w0)
    for stage in (out / "stages").glob("deploy-evaluate-layout-unseen-*/stage.json"):
        record = read_json(stage)
        assert {"deploy-value", "deploy-value-s1"} <= set(record["deps"])
        res = record["result"]
        assert res["plan-learned@s1"]["seed"] == 1 and res["plan-deployed@s1"]["variant"] == "plan-deployed"


def test_the_deployment_sections_numbers_are_read_from_their_files(deployment_run):
    """Every number and verdict of the deployment section worked out again from the stage files
    (tests/report_check.py), with the ablation's rows: the study's own halls, and the ablation's
    halls of another generator (zero-shot only, their own tables and claims after the study's)."""
    out, _ = deployment_run
    own = sorted(s for s in (out / "stages").glob("deploy-evaluate-layout-unseen-*")
                 if s.is_dir() and not s.name.rsplit("-", 1)[0].endswith("-k3"))
    assert len(own) == 2 and all({"dt-flat", "dt-mixed", "bc-mixed"} <= set(read_json(s / "stage.json")["result"])
                                 for s in own)
    for stage in own:
        for summary in read_json(stage / "stage.json")["result"].values():
            per_episode = [float(x) for x in re.findall(r"^\d+,([^,]+),", (stage / f"{summary['policy']}.csv")
                                                       .read_text(), re.M)]
            assert len(per_episode) == RC.eval_episodes
            assert abs(sum(per_episode) / RC.eval_episodes - summary["mean"]) < 1e-9
    check_deployment_report({s.name[len("deploy-evaluate-"):].rsplit("-", 1)[0]: read_json(s / "stage.json")["result"]
                             for s in own}, (out / "report.md").read_text())
    other = sorted(s for s in (out / "stages").glob("deploy-evaluate-layout-other-*")
                   if s.is_dir() and "-k3-" not in s.name)  # the other generator's halls of the study's count
    assert len(other) == 2 and all("dt-finetuned" not in read_json(s / "stage.json")["result"] for s in other)
    text = (out / "report.md").read_text()
    check_deployment_report({s.name[len("deploy-evaluate-"):].rsplit("-", 1)[0]: read_json(s / "stage.json")["result"]
                             for s in other}, text[text.index("### Halls of another generator"):],
                            "deployment track, another generator's halls")


def _rates(stage: Path, row: str) -> np.ndarray:
    """A row's per-episode average sum rates in an evaluation stage, read from its CSV."""
    return np.array([float(x) for x in re.findall(r"^\d+,([^,]+),", (stage / f"{row}.csv").read_text(), re.M)])


def test_the_rows_per_device_count_are_the_halls_numbers(deployment_run):
    """--device-counts 3 --count-other-layouts 2: every row zero-shot in unseen halls of 3 devices,
    of the study's generator and of another, a column per count and generator, each cell the
    mean of the halls' fractions of the oracle (seeds averaged first); the best plan found as a
    fraction of the bound; and no episode of any row above its bound."""
    out, _ = deployment_run
    report = (out / "report.md").read_text()
    section = report[report.index("### Any number of devices"):]
    section = section[:section.index("### Halls of 3 devices")]
    header = next(line for line in section.splitlines() if line.startswith("| policy |"))
    columns = [c.strip() for c in header.strip("|").split("|")][1:]
    assert columns == ["3 devices", "3 devices, another generator", "4 devices", "4 devices, another generator"]
    for column, (split, count) in enumerate((("unseen", 3), ("other", 3), ("unseen", 4), ("other", 4)), start=1):
        dirs = sorted(p for p in (out / "stages").glob(f"deploy-evaluate-layout-{split}-*") if p.is_dir()
                      and ("-k3-" in p.name) == (count == 3))
        halls = [read_json(p / "stage.json")["result"] for p in dirs]
        assert len(halls) == RC.unseen_layouts
        share = [np.mean([r[k]["mean"] for k in ("dt-goal-safe", "dt-goal-safe@s1")]) / r["oracle"]["mean"]
                 for r in halls]
        row = next(line for line in section.splitlines() if line.startswith("| goal-conditioned DT"))
        assert row.split("|")[column + 1].strip() == f"{np.mean(share):.1%} (no CI: 2 units)"
        # the bound of each episode (uavris.agents.oracle.bound, tested against closed forms in test_bound.py)
        bounds = []
        for p, r in zip(dirs, halls):
            system = next(w.system for w in RC.sites(TRACK_SPECS["deployment"])[1]
                          if p.name.rsplit("-", 1)[0] == f"deploy-evaluate-{w.name}")
            b = episode_bounds(system, EVAL_SEED + np.arange(RC.eval_episodes))
            for summary in r.values():
                per_episode = [float(x) for x in re.findall(r"^\d+,([^,]+),", (p / f"{summary['policy']}.csv")
                                                           .read_text(), re.M)]
                assert np.all(np.array(per_episode) <= b), (p.name, summary["policy"])
            bounds.append(max(r[k]["mean"] for k in ("oracle", "plan-learned", "plan-deployed")) / b.mean())
        row = next(line for line in section.splitlines() if line.startswith("| best plan found / the bound"))
        assert row.split("|")[column + 1].strip() == f"{np.mean(bounds):.1%} (no CI: 2 units)"
        # halls where a seed's paired 95% CI over episodes lies below hovering: over 2 episodes, no verdict
        assert all(_rates(p, "hover-optimizer").size == RC.eval_episodes == 2 for p in dirs)
        row = next(line for line in section.splitlines() if line.startswith("| halls where a seed of the goal"))
        assert row.split("|")[column + 1].strip() == "not measured (2 episodes)"
    assert "above 100.5% of the oracle by their 95% CI over halls (a ceiling that gives way): none." in section
    assert "Over fewer than 3 halls, not measured, above it on average: " in section  # 2 halls a count here


@pytest.mark.parametrize("key", ["dt-ensemble-safe", "dt-zero-shot-level@s1", "dt-finetuned-safe", "bc-safe@s1",
                                 "oracle-safe", "zero-action", "transfer"])
def test_uavris_evaluate_reproduces_a_row_of_the_report_by_name(deployment_run, tmp_path, key):
    """``uavris evaluate OUT --row KEY --layout HALL``: the report's number for that row, on the
    same episodes, whatever the row is (an ensemble, held level, another hall's plan, ...)."""
    from uavris.cli import main

    out, _ = deployment_run
    [stage] = [p for p in (out / "stages").glob("deploy-evaluate-layout-unseen-0-*") if "-k3-" not in p.name]
    result = read_json(stage / "stage.json")["result"]
    if key == "transfer":
        [key] = [k for k, v in result.items() if v["kind"] == "transfer"]
    assert main(["evaluate", str(out), "--row", key, "--layout", "layout-unseen-0", "--out", str(tmp_path),
                 "--no-progress"]) == 0
    [path] = tmp_path.glob(f"{key}-layout-unseen-0-seed1000000-n2-*.json")
    got = read_json(path)
    assert got["mean"] == result[key]["mean"] and got["label"] == result[key]["label"]


def test_a_row_of_the_study_in_a_hall_of_ones_own(deployment_run, tmp_path, capsys):
    from uavris.cli import main
    from uavris.layouts import Layout, write_layout

    out, _ = deployment_run
    mine = Layout("mine", ((6.0, 6.0, 1.0), (16.0, 8.0, 1.2), (30.0, 28.0, 0.5), (10.0, 32.0, 0.8)), (20.0, 20.0, 4.5))
    hall = write_layout(tmp_path / "mine.yaml", mine)
    args = ["evaluate", str(out), "--layout", str(hall), "--episodes", "1", "--out", str(tmp_path / "e"),
            "--no-progress"]
    nearest = min(LayoutGenerator().layouts("train", 3), key=lambda t: layout_distance(mine, t))
    assert main([*args, "--row", f"transfer-{nearest.name}"]) == 0  # the nearest training hall's plan, flown here
    assert main([*args, "--row", "dt-ensemble-safe"]) == 0
    got = read_json(next((tmp_path / "e").glob("dt-ensemble-safe-mine-*.json")))
    assert got["system"]["front_margin_deg"] == 1.0 and got["system"]["users"][0] == [6.0, 6.0, 1.0]
    capsys.readouterr()
    assert main([*args, "--row", "dt-finetuned-safe"]) == 2  # fine-tuned only in the study's unseen halls
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "no such row" in err and "dt-ensemble-safe" in err


SPINNING = '''
import numpy as np


def spinning(obs):
    """Pitches the RIS 10 degrees every slot (phases by the optimiser): devices fall behind it."""
    a = np.zeros((obs.shape[0], 6), dtype=np.float32)
    a[:, 4] = 1.0
    return a


spinning.phase_control = "optimizer"
'''


def test_a_row_added_in_one_place_is_in_the_tables_the_decomposition_and_the_claims(deployment_run, tmp_path,
                                                                                     monkeypatch):
    """Adding a row to the study is one edit of tracks._learned_rows (here: a controller of one's
    own that spins the RIS): the report finds it, by what its stage results record, in the table
    of every row, the per-hall table, the decomposition and the claim that no learned row blocks
    a device, in every group of halls.

    The added row changes every evaluation's key, so each hall is evaluated again, and only the
    added row is flown: the study's own rows are copied from the rows it kept (kept_rows), the
    same files, in the copy of the study too."""
    from uavris.experiments.study import tracks, workers
    from uavris.experiments.tools.rows import Row, resolve_target

    out, _ = deployment_run
    # every row of every evaluation kept, each under its own key
    evaluated = sum(len(read_json(p)["result"]) for p in (out / "stages").glob("deploy-evaluate-*/stage.json"))
    assert len([p for p in (out / "rows").iterdir() if not p.name.startswith(".")]) == evaluated
    copy = tmp_path / "run"
    shutil.copytree(out, copy)
    (tmp_path / "spin.py").write_text(SPINNING)
    added = Row("dt-spinning", "a spinning controller", resolve_target(f"{tmp_path / 'spin.py'}:spinning"))
    learned_rows = tracks._learned_rows
    monkeypatch.setattr(tracks, "_learned_rows", lambda *a, **k: [*learned_rows(*a, **k), (added, False)])
    flown: list[tuple[str, str]] = []
    evaluate_row = workers.evaluate_row

    def counted(d, site, track, episodes, row):
        flown.append((site.name, row.key))
        return evaluate_row(d, site, track, episodes, row)

    monkeypatch.setattr(workers, "evaluate_row", counted)
    pretrained = {p.name: p.stat().st_mtime_ns for p in (copy / "stages").glob("deploy-pretrain-*/stage.json")}
    report = reproduce(RC, copy, workers=1, progress=False).read_text()
    records = {p.parent: read_json(p) for p in (copy / "stages").glob("deploy-evaluate-*/stage.json")}
    again = {d: r for d, r in records.items() if added.key in r["result"]}
    halls = {r["result"][added.key]["scenario"] for r in again.values()}
    assert halls and sorted(flown) == sorted((h, added.key) for h in halls)  # no other row flown again
    for new_stage, record in again.items():  # the others' files are the study's own
        [old_stage] = [p.parent for p in (out / "stages").glob("deploy-evaluate-*/stage.json")
                       if read_json(p)["name"] == record["name"]]
        for name in (p.name for p in old_stage.glob("*.csv")):
            assert (new_stage / name).read_bytes() == (old_stage / name).read_bytes(), name
        before = read_json(old_stage / "stage.json")["result"]
        assert {k: v for k, v in record["result"].items() if k != added.key} == before
    # only the evaluations (their rows are in their keys) and the report are made again
    assert {p.name: p.stat().st_mtime_ns for p in (copy / "stages").glob("deploy-pretrain-*/stage.json")} == pretrained
    # --force flies every row of the stage again, the kept ones too
    [(forced, record)] = [(d, r) for d, r in again.items() if r["name"] == "deploy-evaluate-layout-unseen-0"]
    flown.clear()
    reproduce(RC, copy, workers=1, progress=False, force=[record["name"]])
    assert sorted(k for h, k in flown if h == "layout-unseen-0") == sorted(record["result"])
    assert read_json(forced / "stage.json")["result"] == record["result"]
    section = report[report.index("## Deployment track"):]
    groups = section.split("\n### Halls of")  # the study's halls, the other generator's, 3 devices of both
    assert len(groups) == 4
    for group in groups:
        lines = group.splitlines()
        assert any(line.startswith("| a spinning controller |") for line in lines)  # table of every row
        header = next(line for line in lines if line.startswith("| layout |"))
        assert "a spinning controller" in header  # the per-hall table's column
        decomposition = group[group.index("### Where the gap to the oracle is"):]
        assert "\n| a spinning controller |" in decomposition
    claims = [line for line in report.splitlines() if "**no learned row blocks a device" in line]
    assert len(claims) == 4 and all("above the limit: " in c and "a spinning controller" in c for c in claims)


def test_a_study_of_three_devices_treats_its_own_halls_as_its_own(tmp_path):
    """A deployment study whose system has 3 devices: its generated halls (named ...-k3) are its
    own, fine-tuned there and reported in the main table, not as halls of another count."""
    three = dataclasses.replace(SMOKE_SYSTEM, users=((10.0, 10.0, 1.0), (30.0, 12.0, 0.5), (20.0, 30.0, 1.2)))
    rc = ReproduceConfig("smoke", track="deployment", eval_episodes=2, dt_seeds=1, train_layouts=2, scaling=(1,),
                         mixed_layouts=1, ablation=True, system=three)
    pipeline = build_pipeline(rc, tmp_path, StudyContext(1, "local", None))
    _, unseen = rc.sites(TRACK_SPECS["deployment"])
    own = [w for w in unseen if w.split == "unseen"]
    assert [w.name for w in own] == ["layout-unseen-0-k3", "layout-unseen-1-k3"] and {w.devices for w in own} == {3}
    for w in own:
        assert {f"deploy-finetune-{w.name}", f"deploy-{places_stage(w.name, 0)}"} <= set(pipeline.stages)
    report = reproduce(rc, tmp_path, workers=1, progress=False).read_text()
    assert "## Failures" not in report
    for w in own:
        result = read_json(next((tmp_path / "stages").glob(f"deploy-evaluate-{w.name}-*")) / "stage.json")["result"]
        assert {"dt-finetuned-safe", "dt-goal-finetuned-safe", "dt-flat"} <= set(result)
    assert "### Halls of 3 devices" not in report and "### Any number of devices" not in report
    main = report[report.index("## Deployment track"):report.index("### Halls of another generator")]
    table = main[main.index("\n| layout |"):].splitlines()[3:]  # the per-hall table's rows
    per_hall = [line.split("|")[1].strip() for line in table[:table.index("")]]
    assert per_hall == ["layout-unseen-0-k3", "layout-unseen-1-k3"]
    assert "- deployment track: **fine-tuned DT under the attitude safety layer >= 98%" in report


def test_the_studys_controller_leaves_the_study_in_one_directory(deployment_run, tmp_path, capsys):
    """The goal-conditioned DT with its learned planner, exported by `uavris export`: evaluate,
    benchmark and sweep take its directory and give the numbers of `evaluate OUT --row`
    in the same hall, on the same episodes; plan --controller plans with its learned value."""
    from uavris.cli import main

    out, _ = deployment_run
    ctl = tmp_path / "ctl"
    assert main(["export", str(out), "--row", "dt-goal-safe", "--out", str(ctl)]) == 0
    assert not list(ctl.rglob("*.zip")) and not list(ctl.rglob("*.pkl"))  # weights and JSON only
    common = ["--layout", "layout-unseen-0", "--episodes", "8", "--no-progress", "--no-references"]
    assert main(["evaluate", str(out), "--row", "dt-goal-safe", *common, "--out", str(tmp_path / "row")]) == 0
    assert main(["evaluate", str(ctl), *common, "--out", str(tmp_path / "ctl-e")]) == 0
    [want] = [read_json(p) for p in (tmp_path / "row").glob("*.json")]
    [got] = [read_json(p) for p in (tmp_path / "ctl-e").glob("*.json")]
    assert got["mean"] == want["mean"] and got["system"]["front_margin_deg"] == 1.0
    # benchmark (the smoke protocol's 8 episodes) of the directory and of the study's row: the same cell
    for name, target in (("b-ctl", [str(ctl)]), ("b-row", [str(out), "--row", "dt-goal-safe"])):
        assert main(["benchmark", *target, "--preset", "smoke", "--layout", "layout-unseen-0", "--out",
                     str(tmp_path / name), "--no-progress"]) == 0
        [cell] = read_json(tmp_path / name / "benchmark.json")["cells"]
        assert cell["mean"] == pytest.approx(want["mean"], abs=1e-12), name
    # a sweep of one cell in that hall (the default Rician factor): the same episodes' mean (a sweep's system
    # is its command line's, the controller's safety layer applied to it: the study's horizon given)
    assert main(["sweep", str(ctl), "--layout", "layout-unseen-0", "--param", "system.rician-factor", "8",
                 "--system.horizon", str(RC.system.horizon),
                 "--system.energy-budget-j", str(RC.system.energy_budget_j), "--episodes", "8", "--workers", "1",
                 "--out", str(tmp_path / "s"), "--no-progress"]) == 0
    [cell] = [read_json(p) for p in (tmp_path / "s" / "cells").glob("*.json")]
    assert cell["mean"] == pytest.approx(want["mean"], abs=1e-12)
    # plan --controller: the planner of its row (the deployed place), as plan --learned --deployed with the
    # study's value
    [value] = [p for p in (out / "stages").glob("deploy-value-*/value")
               if not p.parent.name.startswith("deploy-value-s")]  # seed 0's
    for name, flags in (("p-ctl", ["--controller", str(ctl)]),
                        ("p-v", ["--learned", str(value), "--deployed"]),
                        ("p-study", ["--learned", str(out), "--deployed"])):  # a study: its seed 0's V
        assert main(["plan", "layout-unseen-0", *flags, "--system.observe-devices", "--out", str(tmp_path / name),
                     "--no-progress"]) == 0
    assert read_json(tmp_path / "p-ctl.json")["target"] == read_json(tmp_path / "p-v.json")["target"] \
        == read_json(tmp_path / "p-study.json")["target"]
    [stage] = [p for p in (out / "stages").glob("deploy-evaluate-layout-unseen-0-*") if "-k3-" not in p.name]
    [transfer] = [k for k, v in read_json(stage / "stage.json")["result"].items() if v["kind"] == "transfer"]
    capsys.readouterr()
    assert main(["export", str(out), "--row", transfer, "--out", str(tmp_path / "t")]) == 2
    assert "plan of" in capsys.readouterr().err  # another hall's plan: no controller of its own


def test_fewer_interactions_in_the_halls_from_scratch_charges_both_sides_alike(deployment_run):
    """The deployment track's "fewer interactions" from a from-scratch measurement: the paper's DT's
    fine-tuning measured as the expert is (the pre-trained model and each round's, on the study's
    episodes under the safety layer: its first point is the study's own zero-shot row there, its
    interactions fine-tuning's), each side charged until it first reaches 95% of the expert's
    final evaluation (made-up expert curves here). A from-scratch.json without fine-tuning curves
    (an earlier uavris's) is "not tested"."""
    from uavris.experiments.study.claims_deployment import judge_deployment
    from uavris.experiments.study.finished import Study
    from uavris.experiments.study.from_scratch import finetune_curve_alike
    from uavris.stats import NOT_MEASURED

    out, _ = deployment_run
    study = Study.open(out)
    track = TRACK_SPECS["deployment"]
    halls = {w.name: w for w in study.sites(track)[1]}
    scratch, diffs = [], []
    for h, top in (("layout-unseen-0", 1.0), ("layout-unseen-1", 0.5)):
        fx, fy = finetune_curve_alike(study, halls[h], RC.eval_episodes)
        edir, res = study.evaluation(track, h)
        assert fy[0] == pytest.approx(res["dt-zero-shot-safe"]["mean"], abs=1e-9)  # the same model, episodes, layer
        with open(study.finetuned(track, h) / "model" / "finetune.csv", newline="") as f:
            assert fx == [float(r["env_interactions"]) for r in csv.DictReader(f)]
        final = max(fy) / top  # an expert whose final evaluation the DT reaches 95% of (or not)
        x, y = [10_000.0, 20_000.0, 30_000.0], [0.5 * final, 0.96 * final, final]  # reaches 95% at 20,000
        scratch.append({"hall": h, "expert_curve": [x, y], "finetune_curve": [fx, fy]})
        reached = [i for i, m in zip(fx, fy) if m >= 0.95 * final]
        diffs.append(20_000.0 - (reached[0] if reached else fx[-1]))
    [fewer] = [j for j in judge_deployment(study, scratch) if j.claim == "fewer"]
    assert fewer.n == 2 and fewer.mean == pytest.approx(np.mean(diffs)) and fewer.verdict == NOT_MEASURED
    old = judge_deployment(study, [{"hall": h, "expert_curve": [[1.0], [1.0]]} for h in halls])
    assert [j.verdict for j in old if j.claim.startswith("fewer")] == ["not tested"] * 3


def test_an_exported_controller_says_its_seed_and_scores_an_episode_alone_as_in_a_batch(deployment_run, tmp_path,
                                                                                       capsys):
    """`export --row dt-goal-safe` is one of the row's pre-training seeds: it says which and names the
    others. Episode k of the controller alone scores as episode k of a batch, and `plan --controller`
    reports where the controller, told its place, actually ends that episode (what `evaluate` flies)."""
    from uavris.cli import main
    from uavris.io import read_csv
    from uavris.presets import EVAL_SEED

    out, _ = deployment_run
    ctl = tmp_path / "ctl"
    capsys.readouterr()
    assert main(["export", str(out), "--row", "dt-goal-safe", "--out", str(ctl)]) == 0
    printed = capsys.readouterr().out
    assert "note: this is seed 0 of the row's 2 seeds (0, 1)" in printed and "dt-goal-safe@s1" in printed
    assert read_json(ctl / "controller.json")["seed"] == 0
    common = ["--layout", "layout-unseen-0", "--no-progress", "--no-references"]
    assert main(["evaluate", str(ctl), *common, "--episodes", "4", "--out", str(tmp_path / "batch")]) == 0
    assert main(["evaluate", str(ctl), *common, "--episodes", "1", "--seed", str(EVAL_SEED + 2),
                 "--out", str(tmp_path / "alone")]) == 0
    [batch] = [read_csv(p) for p in (tmp_path / "batch").glob("*.csv")]
    [alone] = [read_csv(p) for p in (tmp_path / "alone").glob("*.csv")]
    assert float(alone[0]["avg_sum_rate"]) == float(batch[2]["avg_sum_rate"])  # bit for bit
    assert all(float(r["avg_sum_rate"]) <= float(r["bound"]) for r in batch)  # a smoke-trained DT: below the bound
    capsys.readouterr()
    assert main(["plan", "layout-unseen-0", "--controller", str(ctl), "--system.observe-devices", "--out",
                 str(tmp_path / "p"), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    flight = read_json(tmp_path / "p.json")["controller_flight"]
    assert flight["average_sum_rate"] == float(batch[0]["avg_sum_rate"])  # the episode evaluate flies
    assert f"dt-goal-safe, told this place, ends episode seed {EVAL_SEED} at" in printed


def test_the_fine_tuning_claims_judge_the_papers_dt_in_every_hall(deployment_run):
    """With --ablation both the paper's DT fine-tuned by its Algorithm 1 and the goal-conditioned
    DT fine-tuned by trying places are run; the fine-tuning cells judge the paper's, in every hall,
    and say so; its "raises the DT" difference is the paired one of those two rows as the paper
    runs them (without the safety layer fine-tuning did not train with), computed here."""
    from uavris.experiments.study.claims_deployment import judge_deployment
    from uavris.experiments.study.finished import Study

    out, _ = deployment_run
    cells = {j.claim: j for j in judge_deployment(Study.open(out)) if j.claim in ("finetuned", "near-expert")}
    assert set(cells) == {"finetuned", "near-expert"}
    assert all("the paper's DT fine-tuned in the hall by its Algorithm 1" in j.text for j in cells.values())
    assert "under the layer, not judged" in cells["finetuned"].text
    track = TRACK_SPECS["deployment"]
    study = Study.open(out)
    gains = []
    for w in study.sites(track)[1]:
        found = study.evaluation(track, w.name)
        if found is None:
            continue
        edir, res = found
        per = {}
        for variant in ("dt-finetuned", "dt-zero-shot"):  # as the paper runs them: no safety layer
            keys = [k for k, r in res.items() if r.get("variant") == variant]
            if keys:  # each seed's per-episode average sum rates, read from its CSV here, averaged over seeds
                per[variant] = np.mean([[float(r["avg_sum_rate"]) for r in csv.DictReader((edir / f"{k}.csv").open())]
                                        for k in keys], axis=0)
        if len(per) == 2:
            gains.append(float(np.mean(per["dt-finetuned"] - per["dt-zero-shot"])))
    assert cells["finetuned"].n == len(gains) and cells["finetuned"].mean == pytest.approx(np.mean(gains))


def test_the_claims_page_names_its_machine_and_keeps_its_evidence_beside_it(deployment_run, tmp_path):
    """`uavris claims` writes, beside claims.md and claims.json, each study's report and the
    from-scratch curves (what a reader checks the cells against without the studies), names the
    machine and float path it judged on, and says what the goal-conditioned cells hold fixed; two
    studies of one directory name, whose reports would share a file, are refused in one line."""
    from uavris.experiments.engine.process import machine
    from uavris.experiments.study.claims import EVIDENCE, write_claims

    out, _ = deployment_run
    page = write_claims([out], tmp_path / "c").read_text()
    assert f"Judged by `uavris claims` on {machine()}." in page
    # every judged cell computed again from the evidence beside the page, by tests/claims_recompute.py
    claims = read_json(tmp_path / "c" / "claims.json")
    units = read_json(tmp_path / "c" / EVIDENCE / "units.json")
    assert units["deployment"]["halls"] and not mismatches(claims, units)
    assert {k for k in expected_cells(units)} >= {("deployment", c) for c in ("zero-shot", "finetuned", "near-expert",
                                                                              "fluctuates", "dt-over-bc")}
    edited = json.loads(json.dumps(units))
    edited["deployment"]["halls"][0]["transfer"][0] += 1.0  # one episode of one hall's nearest plan
    assert any("zero-shot" in m for m in mismatches(claims, edited))
    assert "a fit of the learned value of a pose per pre-training seed" in page
    assert (tmp_path / "c" / EVIDENCE / f"{out.name}.md").read_text() == (out / "report.md").read_text()
    assert {j["track"] for j in read_json(tmp_path / "c" / "claims.json")["judgements"]} == {"deployment"}
    twin = tmp_path / "twin" / out.name
    shutil.copytree(out, twin, ignore=shutil.ignore_patterns("plans"))
    with pytest.raises(UavrisError, match="share a directory name"):
        write_claims([out, twin], tmp_path / "d")
    assert not (tmp_path / "d" / "claims.md").exists()


def test_a_shipped_controller_knows_the_study_it_came_from(deployment_run, tmp_path, monkeypatch):
    """`uavris pages pretrained` ships a study's goal-conditioned DT with the stage keys it came
    from: its card is current for the study that made it and stale for one whose demonstrations
    moved; a study of another configuration is refused; the folder flies as any controller."""
    from uavris.experiments.study.pretrained import CARD, ship, stale_card, write_card_page
    from uavris.experiments.tools.evaluate import evaluate_target

    out, _ = deployment_run
    shipped = ship(out, tmp_path / "pretrained", made_by=RC)
    assert stale_card(shipped, RC) == []
    moved = dataclasses.replace(RC, layout_trajectories=RC.layout_trajectories + 1)
    assert [line.split(":")[0] for line in stale_card(shipped, moved)] == ["deploy-dataset", "deploy-value",
                                                                         "deploy-goal"]
    with pytest.raises(UavrisError, match="is not this code's make run"):
        ship(out, tmp_path / "other", made_by=moved)
    card = read_json(shipped / CARD)
    groups: dict[tuple[int, str], list[float]] = {}
    for w in ReproduceConfig.sites(RC, TRACK_SPECS["deployment"])[1]:  # each hall's stage record, read directly
        [stage] = [d for d in (out / "stages").iterdir() if d.name.rsplit("-", 1)[0] == f"deploy-evaluate-{w.name}"]
        r = read_json(stage / "stage.json")["result"]
        groups.setdefault((w.devices, w.split), []).append(r["dt-goal-safe"]["mean"] / r["oracle"]["mean"])
    by_count = sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] != "unseen"))  # each count's unseen first
    assert [(s["devices"], s["halls"], s["n"]) for s in card["scores"]] == [(*k, len(v)) for k, v in by_count]
    for s, (_, v) in zip(card["scores"], by_count):
        assert s["seed0"]["mean"] == pytest.approx(np.mean(v), rel=1e-12)
    page = write_card_page(shipped, tmp_path / "pretrained.md", "uavris pages pretrained", scored_by=["C"]).read_text()
    assert page.startswith("<!-- uavris-page") and f"| 4 devices | {len(groups[4, 'unseen'])} |" in page
    assert "scored at the other device counts by `C`" in page
    # scored in a second study of the same models (here the same study): each count and generator once, the first's
    again = ship(out, tmp_path / "again", made_by=RC, scored_in=[out])
    assert read_json(again / CARD)["scores"] == card["scores"]
    from types import SimpleNamespace

    from uavris.experiments.study import pretrained

    real = pretrained.Study.open
    stages = {name: SimpleNamespace(key="0" * 12) for name in pretrained.STAGES}
    other = SimpleNamespace(pipeline=SimpleNamespace(stages=stages))
    monkeypatch.setattr(pretrained.Study, "open", lambda d: other if Path(d).name == "other-models" else real(d))
    with pytest.raises(UavrisError, match="evaluates other models"):  # another study's models: not the shipped one's
        ship(out, tmp_path / "refused", made_by=RC, scored_in=[tmp_path / "other-models"])
    assert not (tmp_path / "refused").exists()
    # a hall of 5 devices, a count it never saw: it reads the devices as a set
    summary, _ = evaluate_target(str(shipped), None, 2, EVAL_SEED, out=tmp_path / "e", references=False,
                                 layout="layout-unseen-0-k5")
    assert len(summary["system"]["users"]) == 5 and np.isfinite(summary["mean"]) and summary["mean"] > 0
