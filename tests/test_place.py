"""The learned value of a pose, the learned planner, the goal-conditioned controller and
fine-tuning that tries places (docs/places.md)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from uavris.agents.dt.checkpoint import save_dt
from uavris.agents.dt.config import DTConfig
from uavris.agents.dt.goals import FixedGoals
from uavris.agents.dt.policy import DTBatchPolicy
from uavris.agents.dt.training import TrainingWindows, make_optimizer, model_for_data, train_steps
from uavris.agents.dt.trajectories import record_episodes
from uavris.agents.oracle.objective import expected_optimised_rate, feasible
from uavris.agents.oracle.planner import Plan
from uavris.agents.oracle.policy import PlannedFlight
from uavris.agents.place.checkpoint import load_value, save_value
from uavris.agents.place.labels import hall_labels
from uavris.agents.place.planner import learned_plan, place_grid, places_to_try
from uavris.agents.place.value import PoseValue, ValueConfig, ValueLabels, fit_value, predict
from uavris.agents.policy import Privileged
from uavris.config import SystemConfig
from uavris.env.rollout import rollout
from uavris.env.simulator import layout_as_lists, uav_position
from uavris.errors import CheckpointError
from uavris.layouts import LayoutGenerator

torch.set_num_threads(1)
BASE = SystemConfig(observe_devices=True)
GEN = LayoutGenerator(devices=4, seed=7)


def random_hall(k: int, rng: np.random.Generator) -> np.ndarray:
    return np.column_stack([rng.uniform(0, 40, (k, 2)), rng.uniform(0, 2, k)])


# ------------------------------------------------------------------------------ V's symmetry
@pytest.mark.parametrize("k", [3, 8])
def test_v_gives_the_same_value_in_any_order_of_the_devices(k):
    """To 4 float32 ulps of the value: the sorted means make the sum order-free, but a CPU's
    matrix kernels may round a device's row by its place in the batch (AVX2 kernels: 1-2 ulps
    at 8 devices; AVX-512: none). A model that read the order would be off by far more."""
    torch.manual_seed(0)
    model = PoseValue(ValueConfig(32)).eval()
    rng = np.random.default_rng(k)
    users = random_hall(k, rng)
    poses = rng.uniform([0, 0, 2], [40, 40, 8], (64, 3))
    v = predict(model, users, poses)
    for _ in range(4):
        np.testing.assert_allclose(predict(model, users[rng.permutation(k)], poses), v,
                                   rtol=4 * np.finfo(np.float32).eps, atol=0)


def test_one_set_of_weights_reads_halls_of_3_and_8_devices_and_reads_the_devices():
    torch.manual_seed(0)
    model = PoseValue(ValueConfig(32)).eval()
    rng = np.random.default_rng(1)
    users = random_hall(8, rng)
    pose = np.array([[20.0, 20.0, 4.0]])
    three, eight = predict(model, users[:3], pose), predict(model, users, pose)
    assert np.isfinite(three).all() and np.isfinite(eight).all() and three[0] != eight[0]
    moved = users.copy()
    moved[0, :2] += 5.0
    assert predict(model, moved, pose)[0] != eight[0]  # it reads where the devices are


# ------------------------------------------------------------------------------ V learns
@pytest.fixture(scope="module")
def value_model() -> PoseValue:
    users, positions, rates, halls = [], [], [], []
    for j in range(6):
        system, _ = GEN.layout("train", j).resolve(BASE)
        q, _, r = hall_labels(system, 48, j)
        users.append(np.broadcast_to(np.asarray(system.users), (len(q), 4, 3)))
        positions.append(q)
        rates.append(r)
        halls.append(np.array([f"train-{j}"] * len(q)))
    labels = ValueLabels({4: np.concatenate(users)}, {4: np.concatenate(positions)}, {4: np.concatenate(rates)},
                         {4: np.concatenate(halls)})
    return fit_value(labels, ValueConfig(32), steps=400, seed=0)


def test_vs_argmax_is_worth_more_than_hovering_at_the_start_in_halls_it_never_saw(value_model):
    """A learning test against the baseline: after 400 steps on 6 halls' labels, the learned
    planner's place is worth more than the start, by the exact R on draws of its own, in each
    of 6 held-out halls; an untrained V's place is worth less (the test can fail)."""
    torch.manual_seed(1)
    untrained = PoseValue(ValueConfig(32)).eval()
    gains, blind = [], []
    for j in range(6):
        system, where = GEN.layout("unseen", j).resolve(BASE)
        chosen = learned_plan(value_model, system, where.start).target
        guess = learned_plan(untrained, system, where.start).target
        assert feasible(system, np.stack([chosen, guess])).all()
        r = expected_optimised_rate(system, np.stack([np.asarray(where.start), chosen, guess]), np.zeros(3), seed=99)
        gains.append(r[1] - r[0])
        blind.append(r[2] - r[0])
    assert min(gains) > 0 and np.mean(gains) > 1.0, gains
    assert np.mean(blind) < np.mean(gains) - 3.0, (blind, gains)


def test_a_value_checkpoint_round_trips_and_a_corrupt_one_is_one_line(value_model, tmp_path):
    save_value(value_model, tmp_path / "v", {"labels": 288})
    again, meta = load_value(tmp_path / "v")
    poses = place_grid(GEN.layout("unseen", 0).resolve(BASE)[0], 4.0)
    users = np.asarray(GEN.layout("unseen", 0).resolve(BASE)[0].users)
    assert np.array_equal(predict(again, users, poses), predict(value_model, users, poses)) and meta["labels"] == 288
    (tmp_path / "v" / "value.safetensors").write_bytes(b"not a tensor file")
    with pytest.raises(CheckpointError, match="missing, corrupt or of another size"):
        load_value(tmp_path / "v")


def test_uavris_plan_learned_writes_the_learned_planners_target(value_model, tmp_path, capsys):
    from uavris.cli import main as cli_main

    save_value(value_model, tmp_path / "v")
    out = tmp_path / "plan"
    assert cli_main(["plan", "layout-unseen-2", "--learned", str(tmp_path / "v"), "--out", str(out),
                     "--no-progress"]) == 0
    plan = json.loads(out.with_suffix(".json").read_text())
    system, where = LayoutGenerator().layout("unseen", 2).resolve(SystemConfig())
    learned = learned_plan(value_model, system, where.start)
    assert plan["planner"] == "learned" and plan["target"] == pytest.approx(learned.target.tolist())
    # V's numbers under V's keys: nothing was valued by R, so the R keys say so
    assert plan["expected_sum_rate"] is None and plan["expected_sum_rate_se"] is None
    users = np.asarray(system.users)
    assert plan["learned_value"] == pytest.approx(float(predict(value_model, users, learned.target[None])[0]))
    printed = capsys.readouterr().out
    assert "learned value V there" in printed and "expected sum rate there" not in printed
    assert "planned by the learned planner in" in printed
    assert cli_main(["plan", "layout-unseen-2", "--top-k", "2", "--out", str(out)]) == 2  # needs --learned


def test_plan_learned_top_k_states_r_and_draws_v(value_model, tmp_path, monkeypatch):
    """With --top-k the plan's numbers are R's (and say so), V at the target beside them, and the
    map of V marks V at the target on its colour bar, never R (R could stretch V's scale)."""
    from uavris.cli import main as cli_main
    from uavris.experiments.tools import plan as plan_module

    marked = []
    limits = plan_module.colour_limits
    monkeypatch.setattr(plan_module, "colour_limits", lambda rates, v: marked.append((rates, v)) or limits(rates, v))
    save_value(value_model, tmp_path / "v")
    out = tmp_path / "plan"
    assert cli_main(["plan", "layout-unseen-2", "--learned", str(tmp_path / "v"), "--top-k", "2", "--out", str(out),
                     "--no-progress"]) == 0
    plan = json.loads(out.with_suffix(".json").read_text())
    system, _ = LayoutGenerator().layout("unseen", 2).resolve(SystemConfig())
    v_target = float(predict(value_model, np.asarray(system.users), np.asarray(plan["target"])[None])[0])
    assert plan["learned_value"] == pytest.approx(v_target) and plan["expected_sum_rate_se"] > 0
    assert plan["expected_sum_rate"] != pytest.approx(v_target)  # R, on fresh draws: not V
    [(rates, value)] = marked
    assert value == pytest.approx(v_target)


# ------------------------------------------------------------------------------ the goal-conditioned controller
def feasible_point(system: SystemConfig, rng: np.random.Generator) -> np.ndarray:
    lo, hi = np.asarray(system.region_low), np.asarray(system.region_high)
    while True:
        q = rng.uniform(lo, hi, (1, 3))
        if feasible(system, q)[0]:
            return q[0]


@pytest.fixture(scope="module")
def goal_model(tmp_path_factory):
    """A goal-conditioned DT trained 1,000 steps on the oracle's controller flying to random
    goals in 4 training halls (8 episodes each) and on hovering at the start told the start."""
    gen = LayoutGenerator(devices=4, seed=3)
    rng = np.random.default_rng(0)
    demos = []
    for j in range(4):
        system, where = gen.layout("train", j).resolve(BASE)
        for e in range(8):
            goal = feasible_point(system, rng)
            plan = Plan(where.start, goal, np.zeros(3), 0.0, 0.0, 0, 0.0, 0, ())
            demos += record_episodes(PlannedFlight(plan), system, where, [100 * j + e], phase_control="optimizer",
                                     goal=goal)
        # told to stay, it hovers (as the study's demonstrations: hovering at the start has the start as its goal)
        demos += record_episodes(Privileged(lambda obs, sim: np.zeros((sim.num_envs, 6), dtype=np.float32)), system,
                                 where, [100 * j + 50, 100 * j + 51], phase_control="optimizer", goal=where.start)
    torch.manual_seed(0)
    cfg = DTConfig(BASE.observation_dim, 6, context=4, width=32, depth=1, heads=1, dropout=0.0,
                   max_timestep=BASE.horizon, state_encoder="devices", devices=4, elements=BASE.num_elements,
                   goal=True, condition_on_return=False)
    model = model_for_data(cfg, demos)
    train_steps(model, make_optimizer(model, 1e-3, 0.0), TrainingWindows.for_model(demos, cfg, system),
                np.random.default_rng(0), 0, 1000, 32, 1e-3, 20, 1.0)
    directory = tmp_path_factory.mktemp("goal") / "model"
    save_dt(model.eval(), directory, {"target_return": 0.0, "system": system.to_dict(), "phase_control": "optimizer",
                                      "observation_layout": layout_as_lists(system)})
    return model, directory


REACH_M = 3.0  # the stated distance: a goal-conditioned controller ends this close to its goal


def test_the_goal_conditioned_controller_flies_where_it_is_told_in_halls_it_never_saw(goal_model):
    model, _ = goal_model
    gen, rng = LayoutGenerator(devices=4, seed=3), np.random.default_rng(5)
    for j in range(4):
        system, where = gen.layout("unseen", j).resolve(BASE)
        goal = feasible_point(system, rng)
        policy = DTBatchPolicy(model, 0.0, 0.0, None, "optimizer", FixedGoals(goal), system)
        b = rollout(policy, system, where, [7], record=True)
        end = uav_position(b.observations[0, b.lengths[0]], system)  # the last pose (an episode may end early)
        assert np.linalg.norm(end - goal) < REACH_M < np.linalg.norm(np.asarray(where.start) - goal), (j, end, goal)


# ------------------------------------------------------------------------------ fine-tuning that tries places
def flown_returns(system: SystemConfig, where, places: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """The mean return of the oracle's controller flying to each place (an independent valuation)."""
    return np.array([rollout(PlannedFlight(Plan(where.start, q, np.zeros(3), 0.0, 0.0, 0, 0.0, 0, ())), system,
                             where, seeds).returns.mean() for q in places])


def test_the_place_rule_scores_each_place_paired_within_its_episode_seeds():
    """The rule of fine-tuning that tries places, on returns made up by hand: each episode's
    score is its return minus its seed's mean, credited to the place nearest its goal, and the
    place of the highest mean score over all rounds is kept. Seed 1 is a lucky draw (every
    return 100 higher): with unequal counts per place the raw mean would pick place 2, which
    seed 1 alone tried twice; paired, place 1 wins."""
    from types import SimpleNamespace

    from uavris.experiments.training.finetune import Places, paired_place_scores

    places = np.array([[10.0, 10.0, 4.5], [20.0, 30.0, 4.5], [35.0, 5.0, 6.0]])
    ep = [(1, 0, 110.0), (1, 1, 113.0), (1, 2, 112.0), (1, 2, 112.0),  # (seed, place, return)
          (2, 0, 10.0), (2, 1, 16.0), (2, 2, 10.0)]
    goals = places[[p for _, p, _ in ep]] + 0.2  # a goal near its place, not on it
    place, score = paired_place_scores(places, goals, np.array([s for s, _, _ in ep]), np.array([r for *_, r in ep]))
    assert place.tolist() == [0, 1, 2, 2, 0, 1, 2]
    # seed 1's mean 111.75, seed 2's 12: worked by hand
    assert score == pytest.approx([-1.75, 1.25, 0.25, 0.25, -2.0, 4.0, -2.0])
    raw = [np.mean([r for _, p, r in ep if p == k]) for k in range(3)]
    assert int(np.argmax(raw)) == 2  # the unpaired mean is fooled by the lucky seed
    rule = Places(places[0], places)
    rule.update([SimpleNamespace(seed=s, goal=places[p], episode_return=r) for s, p, r in ep])
    assert rule.count.tolist() == [2, 2, 3] and rule.total == pytest.approx([-3.75, 5.25, -1.5])
    assert rule.chosen.tolist() == places[1].tolist()
    # a second round in which place 2 does far better moves the choice there (totals over rounds)
    rule.update([SimpleNamespace(seed=3, goal=places[p], episode_return=r) for p, r in ((0, 0.0), (1, 0.0),
                                                                                         (2, 30.0))])
    assert rule.total == pytest.approx([-13.75, -4.75, 18.5]) and rule.chosen.tolist() == places[2].tolist()
    again = Places(places[0], places)
    again.restore(rule.state())  # what a resumed run reads back
    assert again.chosen.tolist() == rule.chosen.tolist() and again.total.tolist() == rule.total.tolist()
    assert Places(places[1], None).state()["goal"] == places[1].tolist()  # no places to try: the planner's


def test_fine_tuning_that_tries_places_keeps_the_place_its_paired_scores_favour(goal_model, tmp_path):
    """In a held-out hall, fine-tuning that tries places flies every place on every episode
    seed, keeps the one of the highest mean paired score, and the fine-tuned model flies there.
    (Which place that is rests on the DT's own flights, whose bits vary with the CPU; the rule
    itself is tested on made-up returns above.)"""
    from uavris.agents.dt.policy import load_dt_policy
    from uavris.experiments.training.finetune import FinetuneConfig, finetune

    _, model_dir = goal_model
    torch.manual_seed(2)
    value_model = PoseValue(ValueConfig(32)).eval()
    save_value(value_model, tmp_path / "v")
    system, where = GEN.layout("unseen", 0).resolve(BASE)
    places = places_to_try(value_model, system, where.start, 3)
    assert len({tuple(q) for q in places.tolist()}) == 4 and places[0].tolist() == list(where.start)
    cfg = FinetuneConfig(str(model_dir), "layout-unseen-0", start=where.start, system=system, preset="smoke",
                         rounds=2, candidates=16, elites=4, rollouts_per_seed=4, value=str(tmp_path / "v"), places=3,
                         eval_episodes=2)
    out = finetune(cfg, tmp_path / "ft", progress=False)
    meta = json.loads((out / "model.json").read_text())
    assert meta["place_count"] == [8.0] * 4  # every place tried by every episode seed of both rounds
    assert abs(sum(meta["place_total"])) < 1e-6 * sum(abs(t) for t in meta["place_total"])  # paired: they sum to 0
    mean = np.asarray(meta["place_total"]) / np.asarray(meta["place_count"])
    assert np.allclose(meta["goal"], places[int(np.argmax(mean))]), (meta["goal"], places, mean)
    flown = load_dt_policy(out)
    assert flown.policy.goals is not None and np.allclose(flown.policy.goals.goals, meta["goal"])


class _CornerValue(PoseValue):
    """A misleading learned value: the farther into the room's far corner, the better. Its argmax
    is a place worse than staying in a hall whose devices sit around the start."""

    def forward(self, users: torch.Tensor, position: torch.Tensor) -> torch.Tensor:
        return position.sum(dim=-1)


def test_where_vs_argmax_is_worse_than_staying_the_deployed_place_is_not() -> None:
    """The headline controller is told the semi-amortised place: V's top places and the start,
    valued by R on fresh draws, a move only where it beats staying by more than its standard
    error. Built here: a hall whose best place is by the start and a V that points to the far
    corner. V's argmax loses to staying; the deployed place does not."""
    from uavris.agents.oracle.objective import assessed_rate, episode_value, trip_slots
    from uavris.agents.place.planner import PlaceSettings

    system = SystemConfig(users=((4.0, 4.0, 1.0), (9.0, 4.0, 1.0), (4.0, 9.0, 0.5), (9.0, 9.0, 0.5)))
    start = (6.5, 6.5, 4.0)
    model = _CornerValue(ValueConfig(width=8))
    argmax = learned_plan(model, system, start, PlaceSettings(top_k=0))
    deployed = learned_plan(model, system, start, PlaceSettings(top_k=3))
    poses = np.stack([np.asarray(start), argmax.target, deployed.target])
    rate, _ = assessed_rate(system, poses, np.zeros_like(poses))
    worth = episode_value(system.horizon, trip_slots(system, np.asarray(start), poses), rate[0], rate)
    assert argmax.target[0] > 30 and worth[1] < worth[0] - 1.0  # V's argmax: the far corner, well below staying
    assert worth[2] >= worth[0]  # the deployed place: never worse than staying


@pytest.mark.slow
@pytest.mark.parametrize("devices", [3, 8])
def test_the_learned_planners_top_places_never_beat_the_oracle_beyond_their_error(value_model, devices):
    """The yardstick holds at 3 and 8 devices: in a generated hall of each (test scale), none of
    V's top 3 places (level, as the learned planner flies them) is worth more than the oracle's
    plan beyond twice the standard error of their paired difference, both valued on the same fresh
    draws (:func:`plan_gap`). Before the oracle's global stage, the learned places beat it by 5.4%
    on average with 8 devices (docs/results/oracle-gap.md). It fails if the oracle misses a place
    V finds: with 3 devices V's places come within 0.07-0.5 bps/Hz of the oracle's, and with
    staying put in the oracle's place they beat it by about 3 bps/Hz (SE 0.05-0.08). With 8
    devices this V, trained on 4-device halls, is about 7 bps/Hz below the oracle, so that case
    catches only a gross failure; the gap benchmark is the measure there."""
    from uavris.agents.oracle.planner import plan_target
    from uavris.agents.oracle.search import Found, plan_gap

    system, where = LayoutGenerator(devices=devices, seed=7).layout("unseen", 0).resolve(BASE)
    oracle = plan_target(system, where.start)
    places = places_to_try(value_model, system, where.start, 3)[1:]
    assert len(places) == 3
    for place in places:
        gap = plan_gap(system, where.start, oracle, Found(place, np.zeros(3), float("nan"), 0))
        assert gap.difference <= 2.0 * gap.difference_se, (place, gap)  # the learned place minus the oracle's


# ------------------------------------------------------------------------------ the deployed place
def test_a_tilted_pose_is_read_as_the_level_pose_of_the_devices_seen_from_the_surface():
    """R is the same for a tilted surface and for a level one whose devices are turned by the
    inverse rotation about it (the physics sees the devices in the surface's frame), to the
    optimiser's draws; V reads a tilted pose that way (in_ris_frame), and level poses as before,
    bit for bit."""
    import copy

    from uavris.agents.place.value import in_ris_frame

    system, _ = GEN.layout("unseen", 2).resolve(BASE)
    q, att = np.array([[24.8, 24.1, 3.0]]), np.radians([[7.0, 15.0, -20.0]])
    seen = in_ris_frame(system.users, q, att)[0]
    level = copy.copy(system)
    object.__setattr__(level, "users", tuple(map(tuple, seen)))  # devices where the surface sees them
    tilted = expected_optimised_rate(system, q, att, seed=3)
    assert expected_optimised_rate(level, q, np.zeros((1, 3)), seed=3) == pytest.approx(tilted, rel=2e-3)
    torch.manual_seed(0)
    model = PoseValue(ValueConfig(16)).eval()
    users = np.asarray(system.users)
    assert predict(model, users, q, att)[0] == predict(model, seen, q)[0]
    assert predict(model, users, q, np.zeros((1, 3)))[0] == predict(model, users, q)[0]


@pytest.fixture(scope="module")
def tilted_value() -> PoseValue:
    """V fitted on tilted labels of 12 training halls of 3 and of 8 devices (test scale)."""
    users, positions, attitudes, rates = {}, {}, {}, {}
    for k in (3, 8):
        gen = LayoutGenerator(devices=k, seed=7)
        parts = []
        for j in range(12):
            system, _ = gen.layout("train", j).resolve(BASE)
            q, att, r = hall_labels(system, 24, 100 * k + j, tilted=True)
            parts.append((np.broadcast_to(np.asarray(system.users), (len(q), k, 3)), q, att, r))
        users[k], positions[k], attitudes[k], rates[k] = (np.concatenate(x) for x in zip(*parts))
    labels = ValueLabels(users, positions, rates, {k: np.array(["h"] * len(r)) for k, r in rates.items()}, attitudes)
    assert all(np.any(attitudes[k] != 0) for k in attitudes)  # tilted poses among the labels
    return fit_value(labels, ValueConfig(32), steps=1500, seed=0)


@pytest.mark.slow
@pytest.mark.parametrize("devices", [3, 8])
def test_the_deployed_place_is_the_oracles_within_the_paired_error_and_never_below_staying(tilted_value, devices):
    """In a generated hall of 3 and one of 8 devices (test scale), the deployed place (V proposes,
    R disposes) is worth the oracle's plan within 3% (or twice the standard error of their paired
    difference), and never less than staying, all valued on the same fresh draws (plan_gap); it
    keeps the oracle's margin (every device 1 degree in front of the RIS). A V of this scale (12
    halls a count) came within 0.8% and 1.9%; the quick study's V is measured against the 99%
    target by benchmarks/findings/place_planner.py. An untrained V's decision stays (R disposes:
    never below staying) and so is not within 3% of the oracle here: the check can fail."""
    from uavris import physics as ph
    from uavris.agents.oracle.planner import plan_target
    from uavris.agents.oracle.search import Found, plan_gap
    from uavris.agents.place.planner import decided_plan

    system, where = LayoutGenerator(devices=devices, seed=7).layout("unseen", 1).resolve(BASE)
    oracle = plan_target(system, where.start)
    torch.manual_seed(3)
    for model, near in ((tilted_value, True), (PoseValue(ValueConfig(32)).eval(), False)):
        plan = decided_plan(model, system, where.start)
        gap = plan_gap(system, where.start, oracle, Found(plan.target, plan.attitude, float("nan"), 0))
        close = gap.difference >= -max(2.0 * gap.difference_se, 0.03 * gap.oracle_value)
        assert close == near, (devices, near, gap)  # the untrained V's decision stays: well below the oracle
        assert gap.search_value >= gap.stay_value - 2.0 * gap.difference_se, (devices, gap)
        elevation = ph.worst_elevation(plan.attitude, plan.target, np.asarray(system.users))
        assert elevation >= np.sin(np.radians(1.0)) - 1e-12
