"""The cost model of the study's jobs: each expected cost worked by hand
from the unit costs the module documents, and the scalings it claims (a DT step grows with
the slots it reads times width squared times depth, on top of a fixed overhead)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from uavris.experiments.engine import costs


def _train(**over):
    cfg = dict(preset="quick", algo="sac", total_steps=10_000, eval_every=2_500, eval_episodes=4,
               system=SimpleNamespace(horizon=50), phase_control="agent", imitation=None)
    cfg.update(over)
    return SimpleNamespace(**cfg)


def test_an_expert_run_costs_its_env_steps_and_its_evaluations():
    sac = costs.SB3_STEP_S["quick"]["sac"]
    # 10,000 steps; evaluations at 0, 2,500, 5,000, 7,500 and 10,000: 5 x 4 episodes x 50 slots
    assert costs.train_cost(_train()) == pytest.approx(10_000 * sac + 5 * 4 * 50 * costs.SLOT_S["agent"])
    # the smoke preset is priced at quick's rates; the paper preset at its bigger networks'
    assert costs.train_cost(_train(preset="smoke")) == costs.train_cost(_train())
    assert costs.train_cost(_train(preset="paper")) > costs.train_cost(_train())
    # imitation of the oracle: a plan, then per round its episodes of labelled slots
    imitation = SimpleNamespace(rounds=3, episodes=2, evaluate_rounds=False)
    extra = costs.PLAN_S + 3 * 2 * 50 * costs.IMITATION_SLOT_S
    assert costs.train_cost(_train(imitation=imitation)) - costs.train_cost(_train()) == pytest.approx(extra)
    # evaluated after every round: 3 more evaluations of 4 episodes
    curve = SimpleNamespace(rounds=3, episodes=2, evaluate_rounds=True)
    assert costs.train_cost(_train(imitation=curve)) - costs.train_cost(_train(imitation=imitation)) == pytest.approx(
        3 * 4 * 50 * costs.SLOT_S["agent"])
    # the optimiser's phases make every evaluation slot dearer, nothing else
    diff = 5 * 4 * 50 * (costs.SLOT_S["optimizer"] - costs.SLOT_S["agent"])
    assert costs.train_cost(_train(phase_control="optimizer")) - costs.train_cost(_train()) == pytest.approx(diff)


def test_the_algorithms_are_priced_in_the_order_the_comparison_measured():
    rates = costs.SB3_STEP_S["quick"]
    # measured in the quick comparison (25,000 steps, AMD EPYC of family 26): SAC about 3.2 ms a step, PPO 0.13
    assert rates["ppo"] < rates["ddpg"] <= rates["td3"] < rates["sac"]
    assert rates["sac"] / rates["ppo"] > 20


def test_data_costs_are_their_slots_and_plans():
    slot = costs.SLOT_S["optimizer"]
    # a collected slot: its share of an evaluated one (one batch, no slot records)
    assert costs.dataset_cost(10, 50, "optimizer") == pytest.approx(10 * 50 * slot * costs.COLLECT_SHARE["optimizer"])
    # 64 halls, 2 episodes each of 100 slots: a plan per hall and 128 episodes with the optimiser
    assert costs.demonstration_cost(64, 2, 100, exact_plans=True) == pytest.approx(64 * costs.PLAN_S + 128 * 100 * slot)
    # the teacher: the same episodes, each plan 4.1x cheaper (its pattern search on the cheap estimate)
    assert costs.demonstration_cost(64, 2, 100) == pytest.approx(64 * costs.PLAN_S / 4.1 + 128 * 100 * slot)


def _pretrain(**over):
    model = dict(context=20, width=128, depth=3, state_encoder="flat")
    model.update(over)
    return SimpleNamespace(steps=1_000, batch_size=64, model=SimpleNamespace(**model))


def test_a_dt_step_is_an_overhead_plus_its_matrix_products():
    overhead, reference = costs.DT_STEP_OVERHEAD_S, costs.DT_STEP_S
    # the reference size (batch 64 x 20 slots, width 128, 3 layers) costs DT_STEP_S a step
    assert costs.pretrain_cost(_pretrain()) == pytest.approx(1_000 * (overhead + reference))
    # half the width: a quarter of the products; half the context: half; two layers of three
    assert costs.pretrain_cost(_pretrain(width=64)) == pytest.approx(1_000 * (overhead + reference / 4))
    assert costs.pretrain_cost(_pretrain(context=10, depth=2)) == pytest.approx(1_000 * (overhead + reference / 3))
    # the device-set encoder reads every state of the batch once more
    devices = costs.pretrain_cost(_pretrain(state_encoder="devices")) - costs.pretrain_cost(_pretrain())
    assert devices == pytest.approx(1_000 * 64 * 20 * costs.DEVICE_ENCODER_STATE_S)


def test_finetuning_and_evaluation_worked_by_hand():
    slot = costs.SLOT_S["optimizer"]
    ft = SimpleNamespace(candidates=10, eval_episodes=4, epochs_per_round=2, elites=3, batch_size=64, rounds=2)
    horizon, context, width, depth = 50, 20, 128, 3
    step = costs.DT_STEP_S  # the reference size at batch 64
    act = costs.DT_STEP_S / 64 / 4  # one state's forward pass: a quarter of its share of a training step
    # per round: 14 episodes of 50 slots acting; 2 epochs over ceil(3 x 50 / 64) = 3 batches
    per_round = 14 * 50 * (slot + act) + 2 * 3 * step
    expected = 4 * 50 * slot + 2 * per_round
    model = SimpleNamespace(context=context, width=width, depth=depth)
    assert costs.finetune_cost(ft, horizon, "optimizer", model) == pytest.approx(expected)
    # evaluation: the learned policies' episodes, and the references (a plan; hovering and the
    # oracle with the optimiser)
    assert costs.evaluate_cost(3, 8, 50, "agent") == pytest.approx(
        3 * 8 * 50 * costs.SLOT_S["agent"] + costs.PLAN_S + 2 * 8 * 50 * slot)
    # a generated hall of 8 devices: an optimised slot as dear as R of a pose there against 4 devices
    # (0.0455 / 0.0105 s), the oracle's global stage with and without the safety layer, and the
    # transferred plan's hall planned
    dear = 0.0455 / 0.0105
    assert costs.evaluate_cost(3, 8, 50, "optimizer", 8, 2, True, 1) == pytest.approx(
        3 * 8 * 50 * slot * dear + 2 * costs.ORACLE_PLAN_S[8] + costs.PLAN_S + 2 * 8 * 50 * slot * dear)
    # a hall of 3 (one pair, the closed form) or 4 devices: a slot as in the make run's halls; more
    # devices, dearer slots, faster than the pairs grow
    assert costs.optimiser_scale(3) == costs.optimiser_scale(4) == 1.0
    grows = [costs.optimiser_scale(k) for k in (6, 8, 10, 12)]
    assert grows == sorted(grows) and all(g > k / 4 for g, k in zip(grows, (6, 8, 10, 12)))
    # two DT rows of the DT paper's size read their 20-slot window every slot: a quarter of a
    # one-window gradient step each (the DT step's reference is a batch of 64 such windows)
    paper = SimpleNamespace(context=20, width=128, depth=3)
    assert costs.evaluate_cost(3, 8, 50, "agent", dt_forwards=2, model=paper) == pytest.approx(
        costs.evaluate_cost(3, 8, 50, "agent") + 2 * 8 * 50 * costs.DT_STEP_S / 64 / 4)
