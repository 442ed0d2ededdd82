import dataclasses

import pytest

from uavris.config import SCENARIOS, ConfigError, Scenario, SystemConfig, get_scenario
from uavris.env import UavRisD2DEnv


def test_defaults_are_the_papers():
    c = SystemConfig()
    assert c.num_users == 4 and c.num_elements == 16
    assert (c.rician_factor, c.pathloss_exponent, c.tx_power_w) == (8.0, 2.4, 1.0)
    assert c.room == (40.0, 40.0, 8.0)
    assert c.action_dim == 22 and c.observation_dim == 158
    assert c.pairs_upper == 2
    assert abs(c.noise_w - 1e-11) < 1e-20


def test_scenarios():
    assert SCENARIOS["fig2"].start == (15.0, 20.0, 4.5)
    assert [SCENARIOS[f"train{i}"].start[:2] for i in range(1, 9)] == [
        (10, 10), (10, 30), (15, 20), (20, 20), (20, 30), (25, 20), (30, 10), (30, 30)]
    assert SCENARIOS["unseen1"].start == (15, 15, 4.5) and SCENARIOS["unseen2"].start == (25, 25, 4.5)


@pytest.mark.parametrize(
    "changes, field",
    [
        (dict(tx_power_w=-1.0), "tx_power_w"),
        (dict(users=((1.0, 1.0, 1.0),)), "users"),
        (dict(users=((1.0, 1.0, 1.0), (50.0, 1.0, 1.0))), "users[1] (device D2)"),
        (dict(v_max=0.0), "v_max"),
        (dict(a_max=float("nan")), "a_max"),
        (dict(horizon=0), "horizon"),
        (dict(nx=2.5), "nx"),
        (dict(z_min=5.0, z_max=3.0), "z_min/z_max"),
        (dict(energy_budget_j=-5.0), "energy_budget_j"),
        (dict(attitude_step_deg=270.0), "attitude_step_deg"),
        (dict(max_active_pairs=3), "max_active_pairs"),
        (dict(noise_dbm=float("inf")), "noise_dbm"),
    ],
)
def test_bad_config_names_the_field(changes, field):
    with pytest.raises(ConfigError) as e:
        SystemConfig(**changes).check()
    msg = str(e.value)
    assert f"SystemConfig.{field} must be" in msg
    assert "\n" not in msg


def test_a_system_is_judged_whole_once_its_hall_is_given():
    """A field's own range is judged when a system is made; its hall (the devices in the room, the
    pairs they make) once the system is whole: a smaller room (a flag) waits for the devices that fit
    it (a layout), and every way to use a system judges it."""
    small = SystemConfig(room=(20.0, 20.0, 5.0), z_max=5.0)  # the paper's D3 (30, 20) lies outside
    with pytest.raises(ConfigError, match=r"users\[2\] \(device D3\) must be a point inside the room"):
        small.check()
    with pytest.raises(ConfigError, match="device D3"):
        UavRisD2DEnv(small, scenario=[10.0, 10.0, 4.5])
    with pytest.raises(ConfigError, match="device D3"):
        SystemConfig.from_dict(small.to_dict())
    fitted = small.replace(users=((5.0, 5.0, 1.0), (15.0, 15.0, 1.0)))  # replace judges the whole system
    assert fitted.check() is fitted and fitted.num_users == 2
    with pytest.raises(ConfigError, match="max_active_pairs must be an integer in"):
        fitted.replace(max_active_pairs=2)  # two devices make one pair
    with pytest.raises(ConfigError, match="SystemConfig.v_max must be"):
        SystemConfig(v_max=-1.0)  # a field's own range: at once


def test_start_outside_region_is_rejected():
    with pytest.raises(ConfigError, match=r"start must be inside the flight region"):
        UavRisD2DEnv(scenario=[15.0, 20.0, 1.0])  # below z_min
    with pytest.raises(ConfigError, match="unknown scenario 'nope'"):
        get_scenario("nope")


def test_config_is_frozen_and_round_trips():
    c = SystemConfig(noise_dbm=-90.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.noise_dbm = 0  # type: ignore[misc]
    assert SystemConfig.from_dict(c.to_dict()) == c
    with pytest.raises(ConfigError, match="no field"):
        SystemConfig.from_dict({"bogus": 1})


def test_scenario_custom():
    s = get_scenario([20, 20, 5])
    assert isinstance(s, Scenario) and s.start == (20.0, 20.0, 5.0)


def test_a_preset_changed_by_replace_gives_its_values():
    """dataclasses.replace(cfg, preset=...) gives every field the old preset gave the new preset's
    value and keeps the fields given otherwise (at construction or in the same replace); an
    algorithm changed by replace takes its own hyperparameters; the stored form (what stage keys
    hash) knows nothing of it."""
    from uavris.agents.experts import default_hyperparams
    from uavris.experiments.training.pretrain import PretrainConfig
    from uavris.experiments.training.train_expert import TrainConfig
    from uavris.presets import PRETRAIN, TRAIN

    paper = dataclasses.replace(PretrainConfig("d"), preset="paper")
    assert (paper.steps, paper.warmup_steps) == (PRETRAIN["paper"]["steps"], PRETRAIN["paper"]["warmup_steps"])
    made = PretrainConfig("d", preset="paper")
    assert paper == made and paper.to_dict() == made.to_dict()
    kept = dataclasses.replace(PretrainConfig("d", steps=7), preset="paper")
    assert kept.steps == 7 and kept.learning_rate == PRETRAIN["paper"]["learning_rate"]
    both = dataclasses.replace(PretrainConfig("d"), preset="smoke", steps=9)
    assert both.steps == 9 and both.batch_size == PRETRAIN["smoke"]["batch_size"]
    again = dataclasses.replace(PretrainConfig("d"), preset="smoke", steps=1500)  # the quick preset's value, given
    assert PRETRAIN["quick"]["steps"] == 1500 and again.steps == 1500
    from uavris.cli.training import parse_train

    line = parse_train(["--preset", "smoke", "--total-steps", str(TRAIN["smoke"]["total_steps"])]).run
    assert dataclasses.replace(line, preset="paper").total_steps == TRAIN["smoke"]["total_steps"]  # written
    assert dataclasses.replace(line, preset="paper").eval_every == TRAIN["paper"]["eval_every"]  # the preset's
    sac = dataclasses.replace(TrainConfig(preset="smoke"), algo="sac")
    assert sac.hyperparams == default_hyperparams("sac", "smoke") and sac.total_steps == TRAIN["smoke"]["total_steps"]
    assert "_from_preset" not in sac.to_dict() and sac.to_dict() == TrainConfig(algo="sac", preset="smoke").to_dict()


def test_every_config_with_a_preset_reads_back_its_stored_form():
    """What a run directory or a job stores (to_dict) reads back (from_dict) to an equal config, for
    every config class with a preset, each in its own module."""
    from uavris.experiments.study.config import ReproduceConfig
    from uavris.experiments.training.finetune import FinetuneConfig
    from uavris.experiments.training.pretrain import PretrainConfig
    from uavris.experiments.training.train_expert import TrainConfig
    from uavris.experiments.training.values import ValueFitConfig

    for cfg in (TrainConfig(preset="smoke"), PretrainConfig("d", preset="paper"), ReproduceConfig(preset="smoke"),
                FinetuneConfig(model="m", scenario="unseen1", preset="smoke"), ValueFitConfig(preset="smoke")):
        stored = cfg.to_dict()
        assert "_from_preset" not in stored and type(cfg).from_dict(stored) == cfg, type(cfg).__name__
