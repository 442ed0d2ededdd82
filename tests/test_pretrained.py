"""The controller shipped with the package (src/uavris/pretrained/deployment, docs/results/pretrained.md):
made by this code's make run, and flying where a user would take it first, a hall of its own."""

import numpy as np

from uavris.agents.references import ORACLE, ZERO_ACTION
from uavris.experiments.study.pretrained import stale_card
from uavris.experiments.tools.evaluate import evaluate_target
from uavris.experiments.tools.rows import PRETRAINED
from uavris.presets import EVAL_SEED


def test_the_shipped_controller_is_this_codes_make_runs():
    """Its card's stage keys (demonstrations, V's labels, V, the goal-conditioned DT) are the ones
    this code's make run makes: a change that moves them leaves a stale shipped model, and this
    fails until `uavris pages pretrained` ships it again."""
    assert stale_card(PRETRAINED) == []


def test_the_shipped_controller_flies_a_hall_of_five_devices(tmp_path):
    """`uavris evaluate pretrained --layout layout-unseen-0-k5`: a hall of a count the DT never
    trained on, well above the zero action's on the same draws and within reach of
    the oracle's."""
    summary, _ = evaluate_target("pretrained", None, 4, EVAL_SEED, out=tmp_path, layout="layout-unseen-0-k5")
    assert len(summary["system"]["users"]) == 5
    refs = summary["references"]
    paired = summary["paired"][ZERO_ACTION]
    assert paired["ci_low"] > 0 and summary["mean"] > 1.2 * refs[ZERO_ACTION]["mean"]  # by its paired CI
    assert 0.9 < summary["mean"] / refs[ORACLE]["mean"] <= 1.01 and np.isfinite(summary["mean"])


def test_plan_takes_the_shipped_controllers_place_and_says_how_to_fly_it(tmp_path, capsys):
    """`uavris plan HALL --learned pretrained`: the deployed place of the shipped value, and the
    shipped controller flown there, named as the user named it."""
    from uavris.cli import main

    assert main(["plan", "layout-unseen-0-k5", "--learned", "pretrained", "--no-progress", "--out",
                 str(tmp_path / "plan")]) == 0
    printed = capsys.readouterr().out
    assert "planned by the deployed (V proposes, R disposes) planner" in printed
    assert "uavris evaluate pretrained --layout layout-unseen-0-k5" in printed
