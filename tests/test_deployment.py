"""The deployment track's pieces: datasets, checkpoints and fine-tuning over layouts, the
command line in a user's hall, and every bad layout as one line."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import minari
import numpy as np
import pytest
import torch

from tests.conftest import killed_after_round
from uavris.agents.dt.checkpoint import load_dt
from uavris.agents.dt.dataset import load_dataset, write_dataset
from uavris.agents.dt.policy import load_dt_policy
from uavris.agents.dt.trajectories import record_episodes
from uavris.agents.evaluation import evaluate
from uavris.agents.references import reference_policy
from uavris.cli import main as cli_main
from uavris.config import SystemConfig
from uavris.experiments.training.finetune import FinetuneConfig, finetune
from uavris.experiments.training.pretrain import PretrainConfig, pretrain
from uavris.layouts import LayoutGenerator, write_layout

BASE = SystemConfig(observe_devices=True, horizon=12)
GEN = LayoutGenerator()
TRAIN = [GEN.layout("train", j).resolve(BASE) for j in range(2)]
UNSEEN_LAYOUT = GEN.layout("unseen", 0)
UNSEEN = UNSEEN_LAYOUT.resolve(BASE)


@pytest.fixture(scope="module")
def layouts_dataset(tmp_path_factory):
    """Two training layouts, two episodes each of hovering with the optimiser's phases (the
    deployment track's action layout: the 6 motion entries)."""
    root = tmp_path_factory.mktemp("minari")
    trajs = []
    for k, (system, where) in enumerate(TRAIN):
        trajs += record_episodes(reference_policy("hover-optimizer", system), system, where, [10 + 2 * k, 11 + 2 * k],
                                 expert=where.name, expert_algo="ref")
    path = write_dataset(root / "uavris" / "layouts-v0", trajs, TRAIN[0][0], phase_control="optimizer",
                         namespace="uavris")
    return root, path, trajs


def test_a_dataset_over_layouts_keeps_each_episodes_hall(layouts_dataset):
    _, path, trajs = layouts_dataset
    ds = load_dataset(path)
    assert ds.system == TRAIN[0][0] and ds.phase_control == "optimizer"
    assert ds.scenarios == ["layout-train-0", "layout-train-1"]
    for got, want, (system, where) in zip(ds.trajectories, trajs, [TRAIN[0]] * 2 + [TRAIN[1]] * 2):
        assert got.users == system.users and got.start == where.start
        np.testing.assert_array_equal(got.observations, want.observations)
        np.testing.assert_array_equal(got.actions, want.actions)


def test_minari_recovers_the_first_layout(layouts_dataset, monkeypatch):
    root, _, trajs = layouts_dataset
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    native = minari.load_dataset("uavris/layouts-v0")
    env = native.recover_environment()
    system, where = TRAIN[0]
    assert env.unwrapped.config == system and env.unwrapped.scenario == where
    first = next(native.iterate_episodes())
    obs, _ = env.reset(seed=trajs[0].seed)
    np.testing.assert_array_equal(obs, first.observations[0])
    # the whole episode replays in the recovered hall: every observation, reward and end (the
    # dataset's actions are the 6 motion entries; the environment takes full actions, the
    # phases being the optimiser's, as the dataset's docstring says)
    from uavris.env.wrappers import optimised_action

    for t, motion in enumerate(first.actions):
        action = optimised_action(env.unwrapped.sim, motion[None])[0] if motion.size == 6 else motion
        obs, reward, terminated, truncated, _ = env.step(action)
        np.testing.assert_array_equal(obs, first.observations[t + 1])
        assert reward == first.rewards[t] and terminated == first.terminations[t] and truncated == first.truncations[t]
    assert terminated or truncated


def test_checkpoint_round_trip_keeps_the_observation(layouts_dataset, tmp_path):
    _, path, _ = layouts_dataset
    pre = pretrain(PretrainConfig(dataset=path, preset="smoke"), tmp_path / "pre", progress=False)
    model, meta = load_dt(pre)
    assert model.cfg.state_dim == BASE.observation_dim == 170 and model.cfg.act_dim == 6
    loaded = load_dt_policy(pre)
    policy = loaded.policy
    assert loaded.system == TRAIN[0][0] and loaded.scenario is None and policy.observation_dim == 170
    # the same weights give the same actions after a reload
    again = load_dt_policy(pre).policy
    a = evaluate(policy, *UNSEEN, 2, 5).episode_return
    b = evaluate(again, *UNSEEN, 2, 5).episode_return
    np.testing.assert_array_equal(a, b)
    bc = pretrain(PretrainConfig(dataset=path, preset="smoke", model={"condition_on_return": False}), tmp_path / "bc",
                  progress=False)
    assert load_dt(bc)[0].cfg.condition_on_return is False
    only = pretrain(PretrainConfig(dataset=path, preset="smoke", scenarios=("layout-train-1",)), tmp_path / "one",
                    progress=False)
    assert json.loads((only / "model.json").read_text())["scenarios"] == ["layout-train-1"]


def test_finetuning_in_an_unseen_layout_resumes_and_matches_evaluate(layouts_dataset, tmp_path, capsys, monkeypatch):
    """A killed fine-tuning in an unseen layout resumes to the same files as an uninterrupted
    one, and `uavris evaluate` of the same checkpoints in the same layout and episodes gives
    the scores its rounds recorded."""
    _, path, _ = layouts_dataset
    pre = pretrain(PretrainConfig(dataset=path, preset="smoke"), tmp_path / "pre", progress=False)
    system, where = UNSEEN
    cfg = FinetuneConfig(model=pre, scenario=where.name, preset="smoke", rounds=2, system=system, start=where.start)
    with pytest.raises(KeyboardInterrupt), killed_after_round(monkeypatch, 1):
        finetune(cfg, tmp_path / "killed", progress=False)
    finetune(cfg, tmp_path / "killed", resume=True, progress=False)
    straight = finetune(cfg, tmp_path / "straight", progress=False)
    assert (straight / "finetune.csv").read_text() == (tmp_path / "killed" / "finetune.csv").read_text()
    a, b = load_dt(straight)[0].state_dict(), load_dt(tmp_path / "killed")[0].state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    with open(straight / "finetune.csv", newline="") as f:
        rounds = list(csv.DictReader(f))
    layout_file = write_layout(tmp_path / "hall.yaml", UNSEEN_LAYOUT)
    episodes = ["--episodes", str(cfg.eval_episodes), "--seed", str(cfg.eval_seed), "--no-progress"]
    for target, extra, row in ((pre, ["--layout", str(layout_file)], rounds[0]), (straight, [], rounds[-1])):
        out = tmp_path / "eval" / Path(target).name
        assert cli_main(["evaluate", str(target), *extra, *episodes, "--out", str(out)]) == 0
        summary = json.loads(next(out.glob("*.json")).read_text())
        assert summary["scenario"] == where.name and summary["start"] == list(where.start)
        assert summary["mean"] == pytest.approx(float(row["eval_mean"]), abs=1e-9)
    assert json.loads((straight / "model.json").read_text())["system"] == system.to_dict()


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _bad_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    return path


BAD = {
    "outside the room": ("devices: [[45, 5, 1], [20, 20, 1]]", "users[0] (device D1) must be a point inside the room"),
    "too close": ("devices: [[10, 10, 1], [13, 10, 1]]", "min_device_spacing"),
    "above z_min": ("devices: [[10, 10, 6], [30, 30, 1]]", "below the UAV's floor"),
    "start in a safety ball": ("devices: [[20, 20, 1.5], [5, 5, 1]]\nstart: [20, 21, 4]", "safety_distance"),
    "NaN": ("devices: [[10, 10, .nan], [30, 30, 1]]", "users[0]"),
    "inf": ("devices: [[10, .inf, 1], [30, 30, 1]]", "users[0]"),
    "two coordinates": ("devices: [[10, 10], [30, 30, 1]]", "device D1 of"),
    "empty": ("devices: []", "non-empty list"),
    "does not parse": ("devices: [[10, 10, 1]\n  oops: {", "not valid YAML"),
}


@pytest.mark.parametrize("case", list(BAD))
@pytest.mark.parametrize("command", ["evaluate", "plan", "train"])
def test_a_bad_layout_is_one_line_exit_2_and_nothing_changes(case, command, tmp_path, capsys):
    text, message = BAD[case]
    path = _bad_file(tmp_path, text)
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("untouched")
    before = _tree(tmp_path)
    args = {"evaluate": ["evaluate", "zero-action", "--layout", str(path), "--episodes", "1", "--out", str(out)],
            "plan": ["plan", str(path), "--out", str(out / "plan")],
            "train": ["train", "--preset", "smoke", "--layout", str(path), "--out", str(out / "run")]}[command]
    assert cli_main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("uavris: error:") and "\n" not in err and message in err, err
    assert _tree(tmp_path) == before


def test_system_users_on_the_command_line_give_a_hall(tmp_path, capsys):
    users = ["--system.users", "6", "8", "1", "12", "8", "1", "34", "36", "0.5", "34", "20", "0.5"]
    assert cli_main(["evaluate", "hover-optimizer", *users, "--scenario", "fig2", "--episodes", "2", "--out",
                     str(tmp_path / "a"), "--no-progress"]) == 0
    (path,) = (tmp_path / "a").glob("hover-optimizer-fig2-seed1000000-n2-*.json")
    got = json.loads(path.read_text())
    hall = SystemConfig(users=((6, 8, 1), (12, 8, 1), (34, 36, 0.5), (34, 20, 0.5)))
    assert got["system"]["users"] == [list(u) for u in hall.users]
    want = evaluate(reference_policy("hover-optimizer", hall), hall, "fig2", 2, 1_000_000).summary()["mean"]
    assert got["mean"] == pytest.approx(want, abs=1e-12)
    capsys.readouterr()
    assert cli_main(["evaluate", "zero-action", *users, "--layout", "layout-unseen-0"]) == 2
    assert "--layout and --system.users" in capsys.readouterr().err
    assert cli_main(["evaluate", "zero-action", "--layout", "layout-unseen-0", "--scenario", "fig2"]) == 2
    err = capsys.readouterr().err  # a hall's own start and a named one: one line too
    assert len(err.splitlines()) == 1 and "--scenario fig2" in err and "--layout layout-unseen-0" in err


def test_a_dt_in_a_hall_with_another_number_of_devices_is_one_line(layouts_dataset, tmp_path, capsys):
    _, path, _ = layouts_dataset
    pre = pretrain(PretrainConfig(dataset=path, preset="smoke"), tmp_path / "pre", progress=False)
    hall = _bad_file(tmp_path, "devices: [[5, 5, 1], [20, 5, 1], [35, 5, 1], [5, 35, 1], [35, 35, 1]]\n")
    before = _tree(tmp_path)
    assert cli_main(["evaluate", str(pre), "--layout", str(hall), "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "reads observations of 170 entries" in err and "5 devices" in err and "\n" not in err
    assert _tree(tmp_path) == before


def test_plan_draws_any_hall(tmp_path, capsys):
    """`uavris plan` for a generated layout and for a user's file: the plan is the oracle's,
    the map is drawn, and the JSON says what was printed."""
    from uavris.agents.oracle import plan_target

    hall = write_layout(tmp_path / "hall.yaml", UNSEEN_LAYOUT)
    for ref in ("layout-unseen-0", str(hall)):
        out = tmp_path / Path(ref).stem
        assert cli_main(["plan", ref, "--out", str(out), "--grid-step", "8", "--no-progress"]) == 0
        plan = json.loads(out.with_suffix(".json").read_text())
        system, where = UNSEEN_LAYOUT.resolve(SystemConfig())
        want = plan_target(system, where.start)
        assert plan["target"] == pytest.approx(want.target.tolist()) and plan["travel_slots"] == want.travel_slots
        assert plan["expected_sum_rate"] == pytest.approx(want.rate)
        for ext in ("png", "pdf"):
            assert out.with_suffix(f".{ext}").stat().st_size > 5000
        printed = capsys.readouterr().out
        assert f"{plan['expected_sum_rate']:.2f} +- " in printed and f"{plan['travel_s']:.1f} s" in printed


def test_plan_refuses_a_hall_beyond_its_device_limit_in_one_line(tmp_path, capsys):
    """A hall of 17 devices would plan for minutes without a word: one line with the limit and
    the expected time, nothing written."""
    from uavris.cli import main
    from uavris.experiments.tools.plan import MAX_PLAN_DEVICES
    from uavris.layouts import LayoutGenerator, write_layout

    many = write_layout(tmp_path / "many.yaml", LayoutGenerator(devices=MAX_PLAN_DEVICES + 1).layout("unseen", 0))
    assert main(["plan", str(many), "--out", str(tmp_path / "p"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"at most {MAX_PLAN_DEVICES} devices" in err and "min" in err, err
    assert not list(tmp_path.glob("p*"))


def test_the_ceiling_over_the_oracle_is_read_by_each_rows_interval_not_its_mean():
    """"Above 100.5% of the oracle" names a row only where its 95% CI over halls lies above it; a
    row whose mean is above but whose CI reaches below is "not resolved", one below is neither."""
    from uavris.experiments.study.report.decomposition import counts_section

    def hall(plan: float, semi: float) -> dict:
        row = {"kind": "learned", "seed": None, "training_halls": None, "plan_of": None}
        return {"oracle": {**row, "kind": "reference", "variant": "oracle", "label": "oracle", "mean": 40.0},
                "plan-learned": {**row, "variant": "plan-learned", "label": "learned place", "mean": plan},
                "plan-deployed": {**row, "variant": "plan-deployed", "label": "semi place", "mean": semi}}

    clear = {f"h{i}": hall(40.0 * 1.03 + 0.01 * i, 40.0 * (1.0 + 0.02 * (-1) ** i)) for i in range(4)}
    below = {f"k{i}": hall(39.0 + 0.1 * i, 39.5) for i in range(4)}
    lines = "\n".join(counts_section({(4, False): clear, (8, False): below}, {}))
    assert "by their 95% CI over halls (a ceiling that gives way): learned place with 4 devices (103.0%" in lines
    assert "Not resolved (the CI reaches above 100.5%): semi place with 4 devices (100.0% [" in lines
    assert "8 devices (9" not in lines.split("a ceiling that gives way")[1]  # below it: named nowhere
