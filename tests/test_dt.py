"""Decision Transformer: model invariants, dataset round trip, checkpoints, rollouts, pipeline."""

import csv
import json
import math

import h5py
import numpy as np
import pytest
import torch

from tests.conftest import SHORT, killed_after_round
from uavris.agents.dt.checkpoint import load_dt, save_dt
from uavris.agents.dt.config import DTConfig
from uavris.agents.dt.dataset import load_dataset, write_dataset
from uavris.agents.dt.model import DecisionTransformer
from uavris.agents.dt.policy import DTBatchPolicy
from uavris.agents.dt.training import TrainingWindows, masked_action_loss
from uavris.agents.dt.trajectories import Trajectory, record_episodes, returns_to_go, select_elites
from uavris.agents.evaluation import evaluate
from uavris.cli import main as cli_main
from uavris.errors import CheckpointError, DatasetError, UavrisError
from uavris.experiments.training.finetune import FinetuneConfig, finetune
from uavris.experiments.training.pretrain import PretrainConfig, pretrain

torch.set_num_threads(1)


def tiny_model(system=SHORT, context=5, width=32, depth=2, heads=2, dropout=0.0, seed=0, attention="window", **norm):
    torch.manual_seed(seed)
    cfg = DTConfig(system.observation_dim, system.action_dim, context=context, width=width, depth=depth, heads=heads,
                   dropout=dropout, max_timestep=system.horizon, attention=attention)
    return DecisionTransformer(cfg, **norm).eval()


def random_inputs(model, batch=3, length=5, seed=1):
    g = torch.Generator().manual_seed(seed)
    c = model.cfg
    return (torch.rand(batch, length, generator=g) * 100, torch.randn(batch, length, c.state_dim, generator=g),
            torch.rand(batch, length, c.act_dim, generator=g) * 2 - 1, torch.arange(length).repeat(batch, 1))


# ------------------------------------------------------------------------------ hand-checked pieces
def test_returns_to_go_hand_checked():
    np.testing.assert_array_equal(returns_to_go([1.0, 2.0, 3.0]), [6.0, 5.0, 3.0])
    np.testing.assert_array_equal(returns_to_go([4.0]), [4.0])


def _traj(ret, seed):
    return Trajectory(np.zeros((2, 3), np.float32), np.zeros((1, 2), np.float32), np.array([ret]), False, True,
                      "train1", seed)


def test_elite_selection_hand_checked():
    trajs = [_traj(r, i) for i, r in enumerate([3.0, 7.0, 5.0, 7.0, 1.0])]
    assert [t.seed for t in select_elites(trajs, 2)] == [1, 3]  # tie at 7 keeps collection order
    assert [t.seed for t in select_elites(trajs, 3)] == [1, 3, 2]
    assert [t.seed for t in select_elites(trajs, 5)] == [1, 3, 2, 0, 4]
    with pytest.raises(ValueError, match=r"k must be in \[1, 5\], got 6"):
        select_elites(trajs, 6)
    with pytest.raises(ValueError, match=r"k must be in \[1, 5\], got 0"):
        select_elites(trajs, 0)


def test_target_return_update_hand_checked():
    policy = DTBatchPolicy(tiny_model(), target_return=10.0)
    policy.begin(2)
    policy(np.zeros((2, SHORT.observation_dim), np.float32))
    policy.record(np.zeros((2, SHORT.action_dim), np.float32), np.array([1.5, 4.0]))
    np.testing.assert_array_equal(policy.remaining, [8.5, 6.0])
    policy(np.zeros((2, SHORT.observation_dim), np.float32))
    policy.record(np.zeros((2, SHORT.action_dim), np.float32), np.array([2.5, 0.0]))
    np.testing.assert_array_equal(policy.remaining, [6.0, 6.0])


def test_return_to_go_fed_to_the_model_subtracts_the_simulators_rewards():
    seen = []

    class Spy(DTBatchPolicy):
        def __call__(self, obs):
            seen.append(self.remaining.copy())
            return super().__call__(obs)

    (tr,) = record_episodes(Spy(tiny_model(), 500.0), SHORT, "fig2", [3])
    expected = 500.0 - np.concatenate([[0.0], np.cumsum(tr.rewards)[:-1]])
    np.testing.assert_allclose(np.concatenate(seen)[:tr.length], expected, rtol=0, atol=1e-9)


def test_training_windows_are_left_padded_like_deployment():
    obs = np.arange(8, dtype=np.float32).reshape(4, 2)
    tr = Trajectory(obs, np.ones((3, 1), np.float32), np.array([1.0, 2.0, 3.0]), False, True, "train1", 0)
    batch = TrainingWindows([tr], context=4).sample(30, np.random.default_rng(0))
    ends = batch["timesteps"][:, -1].numpy()
    assert set(ends) == {0, 1, 2}
    for i, end in enumerate(ends):  # the window of the slot `end`: pads first, then slots 0..end
        real = slice(3 - end, 4)
        np.testing.assert_array_equal(batch["valid"][i].numpy(), np.arange(4) >= 3 - end)
        np.testing.assert_array_equal(batch["returns_to_go"][i, real].numpy(), [6.0, 5.0, 3.0][: end + 1])
        np.testing.assert_array_equal(batch["states"][i, real].numpy(), obs[: end + 1])
        np.testing.assert_array_equal(batch["timesteps"][i, real].numpy(), np.arange(end + 1))
        assert not batch["states"][i, : 3 - end].any()


# ------------------------------------------------------------------------------ model invariants
def test_causality_later_tokens_never_change_earlier_predictions():
    model = tiny_model()
    r, s, a, t = random_inputs(model)
    base = model(r, s, a, t)
    for i in range(r.shape[1]):
        r2, s2, a2 = r.clone(), s.clone(), a.clone()
        r2[:, i + 1:] += 50.0
        s2[:, i + 1:] = torch.randn_like(s2[:, i + 1:])
        a2[:, i:] = -a2[:, i:]  # A_i itself comes after S_i
        out = model(r2, s2, a2, t)
        torch.testing.assert_close(out[:, : i + 1], base[:, : i + 1], rtol=0, atol=1e-6)
        if i + 1 < r.shape[1]:
            assert not torch.allclose(out[:, i + 1:], base[:, i + 1:])


def test_padding_does_not_change_predictions_of_real_slots():
    model = tiny_model()
    r, s, a, t = random_inputs(model, length=3)
    real = model(r, s, a, t)
    for fill in (0.0, 7.0):
        pad = 2
        rp = torch.cat([torch.full((3, pad), fill), r], 1)
        sp = torch.cat([torch.full((3, pad, s.shape[-1]), fill), s], 1)
        ap = torch.cat([torch.full((3, pad, a.shape[-1]), fill), a], 1)
        tp = torch.cat([torch.zeros(3, pad, dtype=torch.long), t], 1)
        valid = torch.cat([torch.zeros(3, pad, dtype=torch.bool), torch.ones(3, 3, dtype=torch.bool)], 1)
        out = model(rp, sp, ap, tp, valid)
        torch.testing.assert_close(out[:, pad:], real, rtol=0, atol=1e-5)
        torch.testing.assert_close(model(rp, sp, ap, tp, valid, last_only=True), real[:, -1], rtol=0, atol=1e-5)


@pytest.mark.slow
def test_small_model_overfits_a_tiny_dataset(expert_trajectories):
    data = expert_trajectories[:2]
    model = tiny_model(context=4, width=64, depth=2, heads=1).train()
    windows = TrainingWindows(data, context=4)
    opt = torch.optim.Adam(model.parameters(), lr=2e-3)
    rng = np.random.default_rng(0)
    for _ in range(200):
        b = windows.sample(32, rng)
        loss = masked_action_loss(model(b["returns_to_go"], b["states"], b["actions"], b["timesteps"], b["valid"]),
                                  b["actions"], b["valid"])
        opt.zero_grad()
        loss.backward()
        opt.step()
    model.eval()
    with torch.no_grad():
        b = windows.sample(256, rng)
        final = masked_action_loss(model(b["returns_to_go"], b["states"], b["actions"], b["timesteps"], b["valid"]),
                                   b["actions"], b["valid"])
    assert float(final) < 2e-3, float(final)  # predicting zeros scores about 0.4


# ------------------------------------------------------------------------------ dataset
def test_minari_round_trip(dataset_dir, expert_trajectories, monkeypatch):
    ds = load_dataset(dataset_dir)
    assert ds.system == SHORT and ds.scenarios == ["train1", "train2"] and ds.dataset_id == "experts-v0"
    for got, want in zip(ds.trajectories, expert_trajectories, strict=True):
        np.testing.assert_array_equal(got.observations, want.observations)
        np.testing.assert_array_equal(got.actions, want.actions)
        np.testing.assert_array_equal(got.rewards, want.rewards)
        assert (got.scenario, got.seed, got.expert, got.terminated, got.truncated) == \
               (want.scenario, want.seed, want.expert, want.terminated, want.truncated)
    import minari

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(dataset_dir.parent))
    native = minari.load_dataset("experts-v0")  # offline, through Minari's own loader
    assert native.total_episodes == len(expert_trajectories)
    ep = next(native.iterate_episodes())
    assert ep.observations.shape == (len(ep.rewards) + 1, SHORT.observation_dim)


def _copy(src, dst):
    import shutil

    shutil.copytree(src, dst)
    return dst


def _edit_metadata(path, fn):
    meta_path = path / "data" / "metadata.json"
    meta = json.loads(meta_path.read_text())
    fn(meta)
    meta_path.write_text(json.dumps(meta))


def _edit_hdf5(path, fn):
    with h5py.File(path / "data" / "main_data.hdf5", "a") as f:
        fn(f)


def _shorter_actions(f):
    acts = f["episode_1/actions"][()]
    del f["episode_1/actions"]
    f["episode_1"].create_dataset("actions", data=acts[:, :-1])


TAMPERINGS = {
    "no rewards": (lambda p: _edit_hdf5(p, lambda f: f.__delitem__("episode_1/rewards")),
                   "episode data is unreadable"),
    "wrong action shape": (lambda p: _edit_hdf5(p, _shorter_actions), "actions have shape"),
    "no scenario": (lambda p: _edit_hdf5(p, lambda f: f["episode_2"].attrs.__delitem__("scenario")),
                    "missing the metadata field 'scenario'"),
    "other layout": (lambda p: _edit_metadata(p, lambda m: m["uavris"]["observation_layout"].update(pairing=[0, 16])),
                     "observation layout"),
    "no uavris metadata": (lambda p: _edit_metadata(p, lambda m: m.pop("uavris")), "not written by uavris collect"),
    "bad system": (lambda p: _edit_metadata(p, lambda m: m["uavris"]["system"].update(v_max=-1)),
                   "system configuration is invalid"),
    "not a dataset": (lambda p: (p / "data" / "metadata.json").unlink(), "is not a Minari dataset"),
    "broken hdf5": (lambda p: (p / "data" / "main_data.hdf5").write_bytes(b"junk"), "unreadable"),
}


@pytest.mark.parametrize("name", sorted(TAMPERINGS))
def test_tampered_dataset_gives_one_clear_error(name, dataset_dir, tmp_path):
    tamper, message = TAMPERINGS[name]
    bad = _copy(dataset_dir, tmp_path / "bad-v0")
    tamper(bad)
    with pytest.raises(DatasetError, match=message) as err:
        load_dataset(bad)
    assert len(str(err.value).splitlines()) == 1


def test_tampered_dataset_on_the_cli_is_one_line_exit_2(dataset_dir, tmp_path, capsys):
    bad = _copy(dataset_dir, tmp_path / "bad-v0")
    TAMPERINGS["wrong action shape"][0](bad)
    code = cli_main(["pretrain-dt", "--dataset", str(bad), "--preset", "smoke", "--out", str(tmp_path / "r"),
                     "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("uavris: error:") and "actions have shape" in err
    assert len(err.splitlines()) == 1 and not (tmp_path / "r").exists()


def test_existing_dataset_is_not_overwritten_without_force(dataset_dir, expert_trajectories):
    with pytest.raises(DatasetError, match="--force"):
        write_dataset(dataset_dir, expert_trajectories, SHORT)


# ------------------------------------------------------------------------------ checkpoints
def test_safetensors_round_trip_gives_identical_predictions(tmp_path):
    dim = SHORT.observation_dim
    model = tiny_model(state_mean=np.linspace(-1, 1, dim), state_std=np.full(dim, 0.5), return_scale=321.0)
    save_dt(model, tmp_path / "m", {"target_return": 12.5})
    loaded, meta = load_dt(tmp_path / "m")
    assert meta["target_return"] == 12.5 and float(loaded.return_scale) == 321.0
    inputs = random_inputs(model)
    assert torch.equal(model(*inputs), loaded(*inputs))
    assert not any(p.suffix == ".pkl" for p in (tmp_path / "m").iterdir())
    (tmp_path / "m" / "model.safetensors").write_bytes(b"garbage")
    with pytest.raises(CheckpointError, match="corrupt"):
        load_dt(tmp_path / "m")
    save_dt(tiny_model(width=16), tmp_path / "m2")
    meta2 = json.loads((tmp_path / "m2" / "model.json").read_text())
    meta2["config"]["width"] = 32
    (tmp_path / "m2" / "model.json").write_text(json.dumps(meta2))
    with pytest.raises(CheckpointError, match="shape"):
        load_dt(tmp_path / "m2")


def _weights(run_dir):
    return load_dt(run_dir)[0].state_dict()


def test_pretrain_resume_continues_to_the_same_model(dataset_dir, tmp_path):
    cfg = PretrainConfig(dataset=dataset_dir, preset="smoke", seed=3)
    straight = pretrain(cfg, tmp_path / "a", progress=False)
    with pytest.raises(KeyboardInterrupt):
        pretrain(cfg, tmp_path / "b", progress=False, interrupt_at=13)  # checkpoint at 10, killed at 13
    assert json.loads((tmp_path / "b" / "checkpoints" / "latest.json").read_text())["step"] == 10
    with pytest.raises(UavrisError, match="--resume"):
        pretrain(cfg, tmp_path / "b", progress=False)
    with pytest.raises(UavrisError, match="different configuration"):
        pretrain(PretrainConfig(dataset=dataset_dir, preset="smoke", seed=4), tmp_path / "b", resume=True,
                 progress=False)
    resumed = pretrain(cfg, tmp_path / "b", resume=True, progress=False)
    a, b = _weights(straight), _weights(resumed)
    assert all(torch.equal(a[k], b[k]) for k in a)
    log_a = (tmp_path / "a" / "train_log.csv").read_text().splitlines()
    log_b = (tmp_path / "b" / "train_log.csv").read_text().splitlines()
    assert [r.split(",")[:3] for r in log_a] == [r.split(",")[:3] for r in log_b]  # step, loss, lr
    assert any((tmp_path / "b" / "tb").iterdir())
    with pytest.raises(UavrisError, match="finished run"):
        pretrain(cfg, tmp_path / "b", resume=True, progress=False)
    meta = json.loads((tmp_path / "b" / "model.json").read_text())
    returns = sorted(tr.episode_return for tr in load_dataset(dataset_dir).trajectories)
    assert meta["target_return"] == pytest.approx(np.quantile(returns, 0.9))


# ------------------------------------------------------------------------------ rollouts
def test_batched_rollout_equals_sequential_rollout():
    """Same episodes, same actions and rewards up to float32 rounding: the matrix kernels
    block a batch of 3 differently from a batch of 1, which moves the last bits."""
    model = tiny_model(context=4)
    seeds = [5, 6, 7]
    batched = record_episodes(DTBatchPolicy(model, 300.0), SHORT, "unseen1", seeds)
    for s, b in zip(seeds, batched):
        (one,) = record_episodes(DTBatchPolicy(model, 300.0), SHORT, "unseen1", [s])
        assert one.length == b.length
        np.testing.assert_allclose(one.actions, b.actions, rtol=0, atol=1e-4)
        np.testing.assert_allclose(one.rewards, b.rewards, rtol=1e-4)


def test_dt_policy_is_scored_by_evaluate_on_the_same_episodes():
    model = tiny_model(context=4)
    res = evaluate(DTBatchPolicy(model, 300.0), SHORT, "unseen2", 3, 40)
    trajs = record_episodes(DTBatchPolicy(model, 300.0), SHORT, "unseen2", [40, 41, 42])
    np.testing.assert_allclose(res.episode_return, [t.episode_return for t in trajs], rtol=1e-12)  # summation order
    np.testing.assert_array_equal(res.length, [t.length for t in trajs])


def test_exploration_noise_is_seeded_and_bounded():
    model = tiny_model(context=4)
    a = record_episodes(DTBatchPolicy(model, 300.0, noise_sigma=0.5, seed=1), SHORT, "fig2", [1, 2])
    b = record_episodes(DTBatchPolicy(model, 300.0, noise_sigma=0.5, seed=1), SHORT, "fig2", [1, 2])
    c = record_episodes(DTBatchPolicy(model, 300.0), SHORT, "fig2", [1, 2])
    np.testing.assert_array_equal(a[0].actions, b[0].actions)
    assert np.abs(a[0].actions).max() <= 1.0 and not np.allclose(a[0].actions, c[0].actions[: a[0].length])


# ------------------------------------------------------------------------------ fine-tuning and the CLI
def test_finetune_counts_interactions_and_resumes(dataset_dir, tmp_path, monkeypatch):
    pre = pretrain(PretrainConfig(dataset=dataset_dir, preset="smoke"), tmp_path / "pre", progress=False)
    cfg = FinetuneConfig(model=pre, scenario="unseen1", preset="smoke", rounds=2)
    with pytest.raises(KeyboardInterrupt), killed_after_round(monkeypatch, 1):
        finetune(cfg, tmp_path / "ft", progress=False)
    finetune(cfg, tmp_path / "ft", resume=True, progress=False)
    straight = finetune(cfg, tmp_path / "ft2", progress=False)
    a, b = _weights(tmp_path / "ft"), _weights(straight)
    assert all(torch.equal(a[k], b[k]) for k in a)
    done = json.loads((tmp_path / "ft" / "done.json").read_text())
    rows = (tmp_path / "ft" / "finetune.csv").read_text().splitlines()
    assert len(rows) == 1 + 3  # header, zero-shot, two rounds
    assert 0 < done["env_interactions"] <= 2 * cfg.candidates * SHORT.horizon
    assert done["env_interactions"] == int(rows[-1].split(",")[1])
    zero_shot = evaluate(DTBatchPolicy(load_dt(pre)[0], json.loads((pre / "model.json").read_text())["target_return"]),
                         SHORT, "unseen1", cfg.eval_episodes, cfg.eval_seed).summary()["mean"]
    assert math.isclose(done["zero_shot_eval"]["mean"], zero_shot)
    assert json.loads((tmp_path / "ft" / "model.json").read_text())["scenario"] == "unseen1"


@pytest.mark.slow
def test_cli_collect_pretrain_evaluate_finetune(tmp_path, capsys):
    from uavris.experiments.training.train_expert import TrainConfig, train

    expert = tmp_path / "expert"
    train(TrainConfig(algo="ddpg", scenario="train4", seed=0, preset="smoke", eval_episodes=2, system=SHORT), expert,
          progress=False)
    ds, pre, ft = tmp_path / "ds-v0", tmp_path / "pre", tmp_path / "ft"
    assert cli_main(["collect", "--experts", str(expert), "--trajectories", "4", "--out", str(ds),
                     "--no-progress"]) == 0
    data = load_dataset(ds)
    assert {(t.scenario, t.expert) for t in data.trajectories} == {("train4", str(expert))}
    assert [t.seed for t in data.trajectories] == [2_000_000 + i for i in range(4)]
    assert cli_main(["collect", "--experts", str(expert), "--trajectories", "4", "--out", str(ds)]) == 2
    assert cli_main(["pretrain-dt", "--dataset", str(ds), "--preset", "smoke", "--out", str(pre),
                     "--no-progress"]) == 0
    assert cli_main(["evaluate", str(pre), "--scenario", "unseen2", "--episodes", "2"]) == 0
    assert cli_main(["finetune-dt", "--model", str(pre), "--scenario", "unseen2", "--preset", "smoke", "--out",
                     str(ft), "--no-progress"]) == 0
    assert cli_main(["evaluate", str(ft), "--episodes", "2"]) == 0  # its own scenario by default
    out = capsys.readouterr().out
    assert "pre-trained" in out and "fine-tuned" in out and "environment interactions" in out
    (stem,) = (p.with_suffix("") for p in (ft / "eval").glob(f"{ft.name}-unseen2-seed1000000-n2-*.json"))
    summary = json.loads(stem.with_suffix(".json").read_text())
    with open(stem.with_suffix(".csv"), newline="") as f:
        episodes = list(csv.DictReader(f))
    rates = [float(e["avg_sum_rate"]) for e in episodes]
    assert [int(e["seed"]) for e in episodes] == [1_000_000, 1_000_001]
    assert summary["episodes"] == len(rates) == 2 and summary["scenario"] == "unseen2"
    assert summary["mean"] == pytest.approx(np.mean(rates), rel=1e-12) and summary["mean"] > 0
    assert summary["ci_low"] <= summary["mean"] <= summary["ci_high"]
    assert summary["mean_length"] == pytest.approx(np.mean([int(e["length"]) for e in episodes]))
    for e in episodes:
        assert float(e["avg_sum_rate"]) == pytest.approx(float(e["return"]) / int(e["length"]), rel=1e-12)
    # the smoke fine-tuning evaluates on these same 2 episodes: `evaluate` reproduces its final score
    final = json.loads((ft / "done.json").read_text())["final_eval"]
    assert (final["episodes"], final["seed"]) == (2, 1_000_000)
    assert summary["mean"] == pytest.approx(final["mean"], abs=1e-9)
    assert cli_main(["finetune-dt", "--model", str(tmp_path), "--scenario", "unseen2", "--preset", "smoke"]) == 2
