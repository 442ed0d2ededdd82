"""Datasets from ``collect`` under Minari's own loader: namespaced id, recoverable environment."""

import json
import re
import shutil
from pathlib import Path

import gymnasium as gym
import minari
import numpy as np
import pytest

import uavris.experiments.training.collect as collect_mod
from tests.conftest import SHORT
from uavris.agents.dt.dataset import dataset_id_for, episode_environment, load_dataset, write_dataset
from uavris.agents.dt.trajectories import record_episodes
from uavris.agents.references import reference_policy
from uavris.env import ENV_ID
from uavris.errors import DatasetError
from uavris.experiments.training.train_expert import TrainConfig
from uavris.layouts import LayoutGenerator

# The first expert's scenario is deliberately not the alphabetically first one.
EXPERTS = {"expert-a": ("train2", "hover-aligned"), "expert-b": ("train1", "hover-random-phases")}
EPISODES = 2
SEED = 2_000_000


def _fake_expert_runs(monkeypatch):
    """Training a real expert takes ~10 s; collect's own code runs, the experts are baselines."""
    cfgs = {name: TrainConfig(algo="ddpg", scenario=scen, seed=0, preset="smoke", eval_episodes=2, system=SHORT)
            for name, (scen, _) in EXPERTS.items()}
    monkeypatch.setattr(collect_mod, "load_run_config", lambda run_dir: cfgs[Path(run_dir).name])
    monkeypatch.setattr(collect_mod, "load_run_policy", lambda run_dir, trust_pickle=False: (
        cfgs[Path(run_dir).name], reference_policy(EXPERTS[Path(run_dir).name][1], SHORT)))


@pytest.fixture(scope="module")
def collected(tmp_path_factory):
    """Minari's datasets root, with one collected dataset at ``uavris/experts-tiny-v0``."""
    root = tmp_path_factory.mktemp("minari")
    runs = [root / "runs" / name for name in EXPERTS]
    for run in runs:
        run.mkdir(parents=True)
    with pytest.MonkeyPatch.context() as mp:
        _fake_expert_runs(mp)
        collect_mod.collect(runs, EPISODES, root / "uavris" / "experts-tiny-v0", seed=SEED, progress=False)
    return root


@pytest.fixture
def native(collected, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(collected))
    return minari.load_dataset("uavris/experts-tiny-v0")  # offline, Minari's own loader


def test_dataset_id_is_namespaced(collected, native):
    assert native.spec.dataset_id == "uavris/experts-tiny-v0"
    assert (native.spec.namespace, native.spec.dataset_name, native.spec.version) == ("uavris", "experts-tiny", 0)
    assert load_dataset(collected / "uavris" / "experts-tiny-v0").dataset_id == native.spec.dataset_id
    for name, want in [("experts-tiny-v0", "uavris/experts-tiny-v0"), ("Experts_Tiny", "uavris/experts-tiny-v0"),
                       ("ds.2", "uavris/ds-2-v0"), ("run 7-v12", "uavris/run-7-v12"), ("__", "uavris/experts-v0")]:
        got = dataset_id_for(Path("somewhere") / name, "uavris")
        assert got == want and re.fullmatch(r"uavris/[a-z0-9-]+-v\d+", got)
        assert minari.dataset.minari_dataset.parse_dataset_id(got)[0] == "uavris"
    assert dataset_id_for(Path("experts"), None) == "experts-v0"  # without a namespace: as before


@pytest.mark.parametrize("eval_env", [False, True])
def test_recovered_environment_is_the_registered_env_with_the_datasets_system(collected, native, eval_env):
    env = native.recover_environment(eval_env=eval_env)
    assert env.spec.id == ENV_ID
    assert env.unwrapped.config == SHORT == load_dataset(collected / "uavris" / "experts-tiny-v0").system
    assert env.unwrapped.scenario.name == "train2"  # the first expert's
    assert env.observation_space == native.observation_space and env.action_space == native.action_space
    first = next(native.iterate_episodes())
    _replay(env, first, SEED)  # the first episode's seed: the same start


def _replay(env, episode, seed):
    """Every step of a Minari episode in ``env``, from ``reset(seed)``: the same observations,
    rewards and end."""
    obs, _ = env.reset(seed=seed)
    np.testing.assert_array_equal(obs, episode.observations[0])
    assert len(episode.actions) > 1
    for t, action in enumerate(episode.actions):
        obs, reward, term, trunc, _ = env.step(action)
        np.testing.assert_array_equal(obs, episode.observations[t + 1])
        assert reward == episode.rewards[t], t
        assert (term, trunc) == (bool(episode.terminations[t]), bool(episode.truncations[t])), t


DEVICES = SHORT.replace(observe_devices=True)


@pytest.fixture(scope="module")
def devices_dataset(tmp_path_factory):
    """Two episodes of random actions in each of two generated halls, the devices observed."""
    root = tmp_path_factory.mktemp("minari-devices")
    trajs, systems = [], []
    for j in range(2):
        system, where = LayoutGenerator().layout("train", j).resolve(DEVICES)
        systems.append(system)
        trajs += record_episodes(reference_policy("random", system), system, where, [30 + 2 * j, 31 + 2 * j],
                                 expert=where.name, expert_algo="ref")
    write_dataset(root / "uavris" / "devices-v0", trajs, systems[0], namespace="uavris")
    return root, trajs


def test_minari_round_trip_with_devices_replays_every_episode(devices_dataset, monkeypatch):
    """Through Minari's own loader: the observation space holds the devices, every episode
    is the one recorded, and its hall rebuilt from its metadata replays it step by step."""
    root, trajs = devices_dataset
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    native = minari.load_dataset("uavris/devices-v0")
    assert native.total_episodes == len(trajs) == 4
    assert native.observation_space.shape == (DEVICES.observation_dim,) != (SHORT.observation_dim,)
    assert trajs[0].users != trajs[2].users  # two halls
    for i, (episode, recorded) in enumerate(zip(native.iterate_episodes(), trajs, strict=True)):
        np.testing.assert_array_equal(episode.observations, recorded.observations)
        np.testing.assert_array_equal(episode.actions, recorded.actions)
        np.testing.assert_array_equal(episode.rewards, recorded.rewards)
        env = episode_environment(native, i)
        assert env.observation_space == native.observation_space
        assert env.unwrapped.config.users == recorded.users and env.unwrapped.scenario.start == recorded.start
        _replay(env, episode, recorded.seed)


def test_env_spec_kwargs_survive_json_and_make_accepts_them(collected):
    meta = json.loads((collected / "uavris" / "experts-tiny-v0" / "data" / "metadata.json").read_text())
    for key in ("env_spec", "eval_env_spec"):
        kwargs = json.loads(meta[key])["kwargs"]
        assert kwargs == {"config": json.loads(json.dumps(SHORT.to_dict())), "scenario": "train2"}
        env = gym.make(ENV_ID, **kwargs)
        assert env.unwrapped.config == SHORT
        env.reset(seed=0)
        env.step(env.action_space.sample())


def test_episode_data_is_the_experts_rollouts(collected):
    got = load_dataset(collected / "uavris" / "experts-tiny-v0").trajectories
    want = []
    for k, (scenario, ref) in enumerate(EXPERTS.values()):
        seeds = SEED + k * EPISODES + np.arange(EPISODES)
        want += record_episodes(reference_policy(ref, SHORT), SHORT, scenario, seeds)
    assert [t.scenario for t in got] == ["train2"] * EPISODES + ["train1"] * EPISODES
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g.observations, w.observations)
        np.testing.assert_array_equal(g.actions, w.actions)
        np.testing.assert_array_equal(g.rewards, w.rewards)


def _edit_metadata(path, fn):
    meta_path = path / "data" / "metadata.json"
    meta = json.loads(meta_path.read_text())
    fn(meta)
    meta_path.write_text(json.dumps(meta))


def _as_before_env_spec(meta):
    del meta["env_spec"], meta["eval_env_spec"]
    meta["dataset_id"] = "old-v0"


def test_a_dataset_without_an_environment_spec_is_one_line(collected, tmp_path):
    """Minari cannot recover the environment of a dataset without its spec, so uavris refuses it."""
    old = shutil.copytree(collected / "uavris" / "experts-tiny-v0", tmp_path / "old-v0")
    _edit_metadata(old, _as_before_env_spec)
    with pytest.raises(DatasetError, match="no environment spec recorded") as err:
        load_dataset(old)
    assert len(str(err.value).splitlines()) == 1
    with pytest.raises(ValueError, match="env_spec is None"):  # Minari's own behaviour for such datasets
        minari.MinariDataset(old / "data").recover_environment()


def test_env_spec_with_another_system_is_rejected(collected, tmp_path):
    bad = shutil.copytree(collected / "uavris" / "experts-tiny-v0", tmp_path / "bad-v0")

    def other_system(meta):
        spec = json.loads(meta["env_spec"])
        spec["kwargs"]["config"]["horizon"] = 17
        meta["env_spec"] = json.dumps(spec)

    _edit_metadata(bad, other_system)
    with pytest.raises(DatasetError, match="another system configuration") as err:
        load_dataset(bad)
    assert len(str(err.value).splitlines()) == 1


def _crafted(collected, tmp_path, marker, keep_spaces):
    """The collected dataset with its spec's entry point replaced by ``os:system`` writing
    ``marker``; without its spaces, Minari makes the spec's environment to learn them."""
    crafted = shutil.copytree(collected / "uavris" / "experts-tiny-v0", tmp_path / "crafted-v0")

    def attack(meta):
        for key in ("env_spec", "eval_env_spec"):
            spec = json.loads(meta[key])
            spec["entry_point"], spec["kwargs"] = "os:system", {"command": f"touch {marker}"}
            meta[key] = json.dumps(spec)
        if not keep_spaces:
            del meta["observation_space"], meta["action_space"]

    _edit_metadata(crafted, attack)
    return crafted


@pytest.mark.parametrize("keep_spaces", [False, True])
def test_a_crafted_dataset_runs_no_code_and_is_one_line(collected, tmp_path, keep_spaces):
    """A metadata.json naming another entry point is refused before Minari reads it: nothing
    the file names is imported or called (load_dataset, and episode_environment on Minari's
    own reading of a dataset whose spaces are recorded)."""
    marker = tmp_path / "ran"
    crafted = _crafted(collected, tmp_path, marker, keep_spaces)
    with pytest.raises(DatasetError, match="another entry point|observation_space is missing") as err:
        load_dataset(crafted)
    assert len(str(err.value).splitlines()) == 1
    assert not marker.exists()
    if keep_spaces:  # Minari itself reads it without making the environment; ours still refuses to
        with pytest.raises(DatasetError, match="another entry point"):
            episode_environment(minari.MinariDataset(crafted / "data"), 0)
        assert not marker.exists()


@pytest.mark.parametrize("edit, message", [
    (lambda m: m.update(observation_space=json.dumps({"type": "Box", "low": 0.0, "high": 1.0, "shape": [10 ** 9],
                                                      "dtype": "float32"})), "observation_space"),
    (lambda m: m.pop("action_space"), "action_space"),
    (lambda m: m.update(data_format="arrow"), "storage format"),
    (lambda m: m.update(env_spec=json.dumps({**json.loads(m["env_spec"]), "additional_wrappers": [
        {"name": "x", "entry_point": "os:system", "kwargs": {}}]})), "another entry point"),
    (lambda m: m.update(env_spec=json.dumps({**json.loads(m["env_spec"]), "kwargs": {
        **json.loads(m["env_spec"])["kwargs"], "layout": "/etc/passwd"}})), "'config' and 'scenario'"),
    (lambda m: m.update(env_spec="not json"), "not a JSON object"),
])
def test_metadata_other_than_ours_is_refused_before_minari_reads_it(collected, tmp_path, monkeypatch, edit, message):
    bad = shutil.copytree(collected / "uavris" / "experts-tiny-v0", tmp_path / "bad-v0")
    _edit_metadata(bad, edit)
    monkeypatch.setattr(minari, "MinariDataset", lambda *a, **k: pytest.fail("Minari read an unchecked dataset"))
    with pytest.raises(DatasetError, match=message) as err:
        load_dataset(bad)
    assert len(str(err.value).splitlines()) == 1
