"""The banded Decision Transformer: exact key/value-cached deployment and whole-episode training."""

import json

import numpy as np
import pytest
import torch
from scipy import stats

from tests.conftest import SHORT
from tests.test_dt import random_inputs, tiny_model
from uavris.agents.dt.checkpoint import load_dt, save_dt
from uavris.agents.dt.config import DTConfig
from uavris.agents.dt.model import DecisionTransformer
from uavris.agents.dt.policy import DTBatchPolicy
from uavris.agents.dt.training import TrainingWindows
from uavris.agents.dt.trajectories import Trajectory, record_episodes
from uavris.agents.evaluation import evaluate
from uavris.config import ConfigError
from uavris.experiments.training.finetune import FinetuneConfig, finetune
from uavris.experiments.training.pretrain import PretrainConfig, pretrain

torch.set_num_threads(1)


def model_pair(context=3, depth=2, heads=2, width=32, state_dim=6, act_dim=3, seed=0):
    """A banded model and a window model with the same weights."""
    torch.manual_seed(seed)
    kw = dict(context=context, width=width, depth=depth, heads=heads, dropout=0.0, max_timestep=40)
    banded = DecisionTransformer(DTConfig(state_dim, act_dim, attention="banded", **kw)).eval()
    window = DecisionTransformer(DTConfig(state_dim, act_dim, **kw)).eval()
    window.load_state_dict(banded.state_dict())
    return banded, window


def test_attention_layout_is_validated():
    with pytest.raises(ConfigError, match="attention"):
        DTConfig(4, 2, attention="sliding")
    assert DTConfig(4, 2, context=20).band is None
    assert DTConfig(4, 2, context=20, attention="banded").band == 59


@pytest.mark.parametrize("context,depth", [(1, 1), (3, 2), (4, 3)])
def test_cached_steps_equal_the_full_forward_pass_at_every_slot(context, depth):
    """Beyond the context the band slides; the cache must still reproduce the uncached model."""
    model, _ = model_pair(context=context, depth=depth)
    r, s, a, t = random_inputs(model, length=4 * context + 5)
    full = model(r, s, a, t)  # every slot's prediction, reading the episode from slot 0
    cache = model.new_cache(r.shape[0])
    with torch.inference_mode():
        for i in range(r.shape[1]):
            prev = a[:, i - 1] if i else torch.zeros_like(a[:, 0])
            out = model.step(cache, r[:, i], s[:, i], prev, t[:, i])
            torch.testing.assert_close(out, full[:, i], rtol=0, atol=1e-5)


def test_rows_reset_at_different_slots_keep_separate_histories():
    model, _ = model_pair()
    r, s, a, t = random_inputs(model, batch=2, length=14)
    cache = model.new_cache(2)
    restart = 5  # row 1 starts a new episode (its slot 0 = input slot 5) while row 0 goes on
    with torch.inference_mode():
        for i in range(r.shape[1]):
            if i == restart:
                cache.reset(np.array([1]))
            t_row = torch.tensor([i, i - restart if i >= restart else i])
            prev = a[:, i - 1] if i else torch.zeros_like(a[:, 0])
            out = model.step(cache, r[:, i], s[:, i], prev, t_row)
            if i >= restart:
                sl = slice(restart, i + 1)
                ref = model(r[1:, sl], s[1:, sl], a[1:, sl], t[1:, : i + 1 - restart], last_only=True)
                torch.testing.assert_close(out[1], ref[0], rtol=0, atol=1e-5)
            ref0 = model(r[:1, : i + 1], s[:1, : i + 1], a[:1, : i + 1], t[:1, : i + 1], last_only=True)
            torch.testing.assert_close(out[0], ref0[0], rtol=0, atol=1e-5)


def test_banded_equals_window_while_the_history_fits_the_context():
    banded, window = model_pair(context=4)
    r, s, a, t = random_inputs(banded, length=4)
    torch.testing.assert_close(banded(r, s, a, t), window(r, s, a, t), rtol=0, atol=1e-6)
    r, s, a, t = random_inputs(banded, length=9)  # longer: the window model re-reads, the banded one does not
    assert not torch.allclose(banded(r, s, a, t, last_only=True), window(r[:, -4:], s[:, -4:], a[:, -4:], t[:, -4:],
                                                                          last_only=True))


@pytest.mark.parametrize("depth", [1, 2])
def test_receptive_field_is_depth_bands(depth):
    """S_t's prediction depends on the token p positions back iff p <= depth * (band - 1)."""
    model, _ = model_pair(context=2, depth=depth)  # band = 5 tokens
    reach = depth * (model.cfg.band - 1)
    r, s, a, t = random_inputs(model, batch=1, length=10)
    last = 3 * (r.shape[1] - 1) + 1  # token index of the last S
    base = model(r, s, a, t, last_only=True)
    for slot in range(r.shape[1] - 1):
        s2 = s.clone()
        s2[:, slot] += 3.0  # the state token of `slot` sits at 3 slot + 1
        changed = not torch.allclose(model(r, s2, a, t, last_only=True), base, rtol=0, atol=1e-7)
        assert changed == (last - (3 * slot + 1) <= reach), slot


def test_whole_episode_samples_and_epoch_size():
    def traj(n, scale):
        obs = scale * np.arange(2 * (n + 1), dtype=np.float32).reshape(n + 1, 2)
        return Trajectory(obs, np.ones((n, 1), np.float32), np.arange(1.0, n + 1), False, True, "train1", 0)

    windows = TrainingWindows([traj(3, 1.0), traj(5, -1.0)], context=2, whole_episodes=True)
    assert windows.context == 5 and windows.samples_per_epoch == 2 * 2
    batch = windows.sample(20, np.random.default_rng(0))
    for i in range(20):
        n = int(batch["valid"][i].sum())
        assert n in (3, 5)
        np.testing.assert_array_equal(batch["timesteps"][i, 5 - n:].numpy(), np.arange(n))  # from slot 0
        np.testing.assert_array_equal(batch["returns_to_go"][i, 5 - n:].numpy(),
                                      np.cumsum(np.arange(n, 0, -1.0))[::-1])


def test_policy_actions_equal_the_models_prediction_on_the_whole_episode():
    model = tiny_model(context=3, attention="banded")
    target = 300.0
    trajs = record_episodes(DTBatchPolicy(model, target), SHORT, "unseen1", [5, 6, 7])
    for tr in trajs:
        n = tr.length
        rtg = target - np.concatenate([[0.0], np.cumsum(tr.rewards)[:-1]])
        pred = model(torch.tensor(rtg[None], dtype=torch.float32), torch.from_numpy(tr.observations[None, :n]),
                     torch.from_numpy(tr.actions[None]), torch.arange(n)[None])[0].detach().numpy()
        np.testing.assert_allclose(tr.actions, np.clip(pred, -1, 1), rtol=0, atol=1e-4)
    for s, b in zip([5, 6, 7], trajs):  # batched == one by one
        (one,) = record_episodes(DTBatchPolicy(model, target), SHORT, "unseen1", [s])
        np.testing.assert_allclose(one.actions, b.actions, rtol=0, atol=1e-4)


def test_banded_pipeline_pretrains_finetunes_and_round_trips(dataset_dir, tmp_path):
    pre = pretrain(PretrainConfig(dataset=dataset_dir, preset="smoke", model={"attention": "banded"}), tmp_path / "pre",
                   progress=False)
    model, meta = load_dt(pre)
    assert model.cfg.attention == "banded"
    cfg = FinetuneConfig(model=pre, scenario="unseen1", preset="smoke")
    ft = finetune(cfg, tmp_path / "ft", progress=False)
    tuned, tuned_meta = load_dt(ft)
    assert tuned.cfg.attention == "banded"
    assert not all(torch.equal(p, q) for p, q in zip(model.parameters(), tuned.parameters()))
    # the evaluation's numbers from the episodes themselves: each episode's average sum rate
    # is its rewards' mean (recorded one episode at a time, away from the batch of 3), and
    # the summary is their mean with SciPy's Student-t interval
    results = evaluate(DTBatchPolicy(tuned, meta["target_return"]), SHORT, "unseen1", 3, 0)
    one_by_one = [record_episodes(DTBatchPolicy(tuned, meta["target_return"]), SHORT, "unseen1", [s])[0].rewards
                  for s in range(3)]
    np.testing.assert_allclose(results.avg_sum_rate, [r.mean() for r in one_by_one], rtol=1e-6)
    res = results.summary()
    x = results.avg_sum_rate
    assert res["episodes"] == 3 and res["mean"] == pytest.approx(np.mean(x), rel=1e-12)
    want = stats.t.interval(0.95, 2, loc=np.mean(x), scale=stats.sem(x))
    assert (res["ci_low"], res["ci_high"]) == pytest.approx(want, rel=1e-12) and want[1] - want[0] > 0
    # the saved banded model is the one fine-tuning evaluated last: same score on the same episodes
    final = json.loads((ft / "done.json").read_text())["final_eval"]
    again = evaluate(DTBatchPolicy(tuned, tuned_meta["target_return"]), SHORT, "unseen1", cfg.eval_episodes,
                     cfg.eval_seed).summary()
    assert again["mean"] == pytest.approx(final["mean"], abs=1e-9), (again, final)
    # Save/load keeps the layout; a checkpoint written before the field existed reads as "window".
    save_dt(tuned, tmp_path / "copy")
    assert load_dt(tmp_path / "copy")[0].cfg.attention == "banded"
    meta_path = tmp_path / "copy" / "model.json"
    old = json.loads(meta_path.read_text())
    del old["config"]["attention"]
    meta_path.write_text(json.dumps(old))
    assert load_dt(tmp_path / "copy")[0].cfg.attention == "window"


def test_unknown_attention_layout_on_the_cli_is_one_line_exit_2(tmp_path, capsys):
    from uavris.cli import main as cli_main

    code = cli_main(["pretrain-dt", "--dataset", str(tmp_path), "--model.attention", "sliding", "--out",
                     str(tmp_path / "run"), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "attention" in err and "sliding" in err
    assert not (tmp_path / "run").exists()
