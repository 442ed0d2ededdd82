"""The plan store (uavris.agents.oracle.store): a plan one process made is taken by another as it
was made, under a key that changes with everything the plan depends on, and a file in the store
that is not a plan (or tries to run code) is planned again."""

import os
import pickle
import shutil
import subprocess
import sys
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import GLANCE  # a planner that looks little: the store keeps any plan alike
from uavris.agents.oracle import policy as oracle_module
from uavris.agents.oracle import store
from uavris.agents.oracle.planner import PlanSettings
from uavris.agents.oracle.policy import oracle_policy
from uavris.config import SCENARIOS, SystemConfig
from uavris.experiments.study import reproduce as reproduce_module
from uavris.experiments.study.config import ReproduceConfig

START = SCENARIOS["fig2"].start


@pytest.fixture
def on(tmp_path, monkeypatch):
    """A fresh store, and no plan shared in this process."""
    monkeypatch.setenv(store.STORE_ENV, str(tmp_path / "plans"))
    monkeypatch.setattr(oracle_module, "_FRESH_PLANS", OrderedDict())
    return tmp_path / "plans"


def _no_planning(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("planned although the store holds the plan")

    monkeypatch.setattr(oracle_module, "plan_target", refuse)


def _same(a, b):
    for field in ("start", "rate", "start_rate", "travel_slots", "value", "poses_valued", "candidates", "rate_se",
                  "front_margin_deg"):
        assert getattr(a, field) == getattr(b, field), field
    np.testing.assert_array_equal(a.target, b.target)
    np.testing.assert_array_equal(a.attitude, b.attitude)


def test_a_plan_another_process_made_is_taken_as_it_was_made(on, monkeypatch):
    """A child process plans the paper's hall with the store on; this process then takes that plan
    without planning: every field equal to its own plan made from nothing (store off), and the same
    valued poses, which the learned value's labels read."""
    code = ("import uavris; from uavris.agents.oracle.planner import PlanSettings as P; "
            "from uavris.agents.oracle.policy import oracle_policy; from uavris.config import SCENARIOS, SystemConfig; "
            f"oracle_policy(settings=P(**{GLANCE.__dict__!r})).plan(SystemConfig(), SCENARIOS['fig2'].start)")
    subprocess.run([sys.executable, "-c", code], check=True, env={**os.environ, store.STORE_ENV: str(on)})
    assert len(list(on.glob("*.npz"))) == 1
    monkeypatch.delenv(store.STORE_ENV)
    alone = oracle_policy(settings=GLANCE)
    made = alone.plan(SystemConfig(), START)  # from nothing: the store is off

    monkeypatch.setenv(store.STORE_ENV, str(on))
    monkeypatch.setattr(oracle_module, "_FRESH_PLANS", OrderedDict())
    _no_planning(monkeypatch)
    taken = oracle_policy(settings=GLANCE)
    _same(taken.plan(SystemConfig(), START), made)
    for a, b in zip(taken.valued_poses(SystemConfig()), alone.valued_poses(SystemConfig())):
        np.testing.assert_array_equal(a, b)


def test_another_setting_system_or_start_is_planned_anew(on, monkeypatch):
    """A stored plan answers only the settings, system and start it was made for."""
    oracle_policy(settings=GLANCE).plan(SystemConfig(), START)
    calls = []
    real = oracle_module.plan_target
    monkeypatch.setattr(oracle_module, "plan_target", lambda *a, **k: calls.append(a[1]) or real(*a, **k))
    other_seed = PlanSettings(**{**GLANCE.__dict__, "seed": 1})
    for settings, system, start in ((other_seed, SystemConfig(), START), (GLANCE, SystemConfig(horizon=50), START),
                                    (GLANCE, SystemConfig(), (10.0, 10.0, 4.0))):
        monkeypatch.setattr(oracle_module, "_FRESH_PLANS", OrderedDict())
        oracle_policy(settings=settings).plan(system, start)
    assert calls == [START, START, (10.0, 10.0, 4.0)]
    assert len(list(on.glob("*.npz"))) == 4


class _Runs:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def test_a_file_that_is_not_a_plan_is_planned_again_and_runs_no_code(on, monkeypatch, tmp_path):
    """Garbage, a truncated plan and an archive of pickled objects under a plan's key: each is planned
    again (the same plan as from nothing), and the pickle's code never runs."""
    made = oracle_policy(settings=GLANCE).plan(SystemConfig(), START)
    (path,) = on.glob("*.npz")
    good = path.read_bytes()
    marker = tmp_path / "ran"
    evil = tmp_path / "evil.npz"
    np.savez(evil, numbers=np.array([_Runs(marker)], dtype=object))
    assert pickle.loads(pickle.dumps(_Runs(marker))) is None and marker.exists()  # the payload does run if unpickled
    marker.unlink()
    for bad in (b"not a plan", good[: len(good) // 2], evil.read_bytes()):
        path.write_bytes(bad)
        monkeypatch.setattr(oracle_module, "_FRESH_PLANS", OrderedDict())
        _same(oracle_policy(settings=GLANCE).plan(SystemConfig(), START), made)
        assert not marker.exists()
        assert path.read_bytes() == good  # planned again, and stored again


def test_the_key_changes_with_the_code_and_the_float_path(monkeypatch, tmp_path):
    """One changed byte in any source file of the package, or another kernel pinned for the
    libraries, is another fingerprint; the key is taken with the fingerprint of the code this
    process imported, and a subclass of the config classes is not stored (its code is not hashed)."""
    package = Path(store.__file__).resolve().parents[2]
    copy = tmp_path / "uavris"
    shutil.copytree(package, copy, ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    prints = [store._fingerprint(copy)]
    channel = copy / "physics" / "channel.py"
    channel.write_bytes(channel.read_bytes() + b"\n")
    prints.append(store._fingerprint(copy))
    monkeypatch.setenv("OPENBLAS_CORETYPE", "SkylakeX")
    prints.append(store._fingerprint(copy))
    monkeypatch.setenv("NUMBA_OPT", "0")
    prints.append(store._fingerprint(copy))
    assert len(set(prints)) == 4
    args = (GLANCE, SystemConfig(), START)
    first = store.key(*args)
    monkeypatch.setattr(store, "FINGERPRINT", prints[1])
    assert store.key(*args) != first

    class Mine(SystemConfig):
        pass

    assert store.key(GLANCE, Mine(), START) is None


def test_an_oracle_that_valued_poses_plans_itself_and_leaves_the_store_alone(on, monkeypatch):
    """Only a plan made from nothing is stored or taken: an oracle that has valued poses of the
    system (from another start) plans the stored start itself (its memo changes its cost and its
    valued poses), and the stored file is not replaced."""
    oracle_policy(settings=GLANCE).plan(SystemConfig(), START)
    (path,) = on.glob("*.npz")
    before = path.read_bytes()
    calls = []
    real = oracle_module.plan_target
    monkeypatch.setattr(oracle_module, "plan_target", lambda *a, **k: calls.append(a[1]) or real(*a, **k))
    monkeypatch.setattr(oracle_module, "_FRESH_PLANS", OrderedDict())
    busy = oracle_policy(settings=GLANCE)
    busy.plan(SystemConfig(), (10.0, 10.0, 4.0))
    busy.plan(SystemConfig(), START)
    assert calls == [(10.0, 10.0, 4.0), START] and path.read_bytes() == before


def test_a_plan_of_another_user_or_under_another_name_is_not_taken(on, monkeypatch):
    """The file's mark is an HMAC under this user's seal key and the file's own name: a store
    another key signed, or a plan copied under another plan's name, is planned again."""
    made = oracle_policy(settings=GLANCE).plan(SystemConfig(), START)
    other = (10.0, 10.0, 4.0)
    oracle_policy(settings=GLANCE).plan(SystemConfig(), other)
    calls = []
    real = oracle_module.plan_target
    monkeypatch.setattr(oracle_module, "plan_target", lambda *a, **k: calls.append(a[1]) or real(*a, **k))
    mine, theirs = (on / f"{store.key(GLANCE, SystemConfig(), s)}.npz" for s in (START, other))
    theirs.write_bytes(mine.read_bytes())  # START's plan under the other start's name
    monkeypatch.setattr(oracle_module, "_FRESH_PLANS", OrderedDict())
    oracle_policy(settings=GLANCE).plan(SystemConfig(), other)
    monkeypatch.setenv("UAVRIS_SEAL_KEY", "ab" * 16)  # another user: START's file is not theirs
    monkeypatch.setattr(oracle_module, "_FRESH_PLANS", OrderedDict())
    _same(oracle_policy(settings=GLANCE).plan(SystemConfig(), START), made)
    assert calls == [other, START]


def test_a_store_that_cannot_be_written_is_one_warning_and_the_plan_is_made(tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    monkeypatch.setenv(store.STORE_ENV, str(blocked / "plans"))
    monkeypatch.setattr(oracle_module, "_FRESH_PLANS", OrderedDict())
    monkeypatch.setattr(store, "_WARNED", set())
    with pytest.warns(UserWarning, match="plans are not kept in"):
        plan = oracle_policy(settings=GLANCE).plan(SystemConfig(), START)
    assert plan.target.shape == (3,)


def test_a_study_keeps_its_plans_in_its_folder_unless_a_store_is_named(monkeypatch, tmp_path):
    """reproduce's workers inherit the store its block sets (OUT/plans); after the block the environment
    is as it was, and a store the user named is the one used."""
    monkeypatch.delenv(store.STORE_ENV, raising=False)
    with store.kept_in(tmp_path / "plans") as folder:
        assert folder == tmp_path / "plans" and store.directory() == folder
    assert store.directory() is None
    monkeypatch.setenv(store.STORE_ENV, str(tmp_path / "mine"))
    with store.kept_in(tmp_path / "plans") as folder:
        assert folder == store.directory() == tmp_path / "mine"
    assert store.directory() == tmp_path / "mine"

    seen = []
    monkeypatch.delenv(store.STORE_ENV)
    monkeypatch.setattr(reproduce_module, "_run", lambda *a, **k: seen.append(store.directory()) or tmp_path)
    reproduce_module.reproduce(ReproduceConfig("smoke"), tmp_path / "study", workers=1, progress=False)
    assert seen == [(tmp_path / "study" / reproduce_module.PLANS_DIR).absolute()] and store.directory() is None
