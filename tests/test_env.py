import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from scipy import integrate

import uavris  # noqa: F401  (registers the env)
from uavris import physics as ph
from uavris.config import SystemConfig
from uavris.env import ENV_ID, UavRisD2DEnv, UavRisD2DVectorEnv, observation_layout
from uavris.physics import streams


def rollout(env, actions, seed):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    rewards, dones = [], []
    for a in actions:
        obs, r, te, tr, info = env.step(a)
        out.append(obs)
        rewards.append(r)
        dones.append(te or tr)
        if te or tr:
            obs, _ = env.reset()
            out.append(obs)
    return np.array(out), np.array(rewards), np.array(dones)


def test_check_env_passes_without_warnings():
    env = gym.make(ENV_ID).unwrapped
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    assert not caught, [str(w.message) for w in caught]


def test_make_and_make_vec():
    env = gym.make(ENV_ID, scenario="unseen1")
    obs, info = env.reset(seed=0)
    assert obs.shape == (158,) and obs.dtype == np.float32
    np.testing.assert_allclose(info["position"], [15, 15, 4.5])
    venv = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point")
    assert isinstance(venv.unwrapped, UavRisD2DVectorEnv)
    obs, _ = venv.reset(seed=0)
    assert obs.shape == (3, 158)


def test_seeded_determinism():
    env = UavRisD2DEnv()
    actions = np.random.default_rng(1).uniform(-1, 1, (150, 22)).astype(np.float32)
    o1, r1, _ = rollout(env, actions, seed=7)
    o2, r2, _ = rollout(UavRisD2DEnv(), actions, seed=7)
    np.testing.assert_array_equal(o1, o2)
    np.testing.assert_array_equal(r1, r2)
    o3, r3, _ = rollout(env, actions, seed=8)
    assert not np.array_equal(r1, r3)


def test_next_episode_differs_from_first():
    env = UavRisD2DEnv()
    o1, _ = env.reset(seed=3)
    o2, _ = env.reset()
    lay = observation_layout(env.config)
    assert not np.array_equal(o1[lay["channel_real"]], o2[lay["channel_real"]])


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_batched_env_equals_single_envs(mode):
    n, steps = 4, 230  # crosses two episode boundaries
    cfg = SystemConfig()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1.2, 1.2, (steps, n, 22)).astype(np.float32)
    venv = UavRisD2DVectorEnv(n, cfg, "train4", autoreset_mode=mode)
    vobs, _ = venv.reset(seed=100)
    v_rewards, v_obs = [], [vobs]
    for t in range(steps):
        obs, r, te, tr, info = venv.step(actions[t])
        v_rewards.append(r)
        v_obs.append(obs)
    v_rewards = np.array(v_rewards)
    for i in range(n):
        env = UavRisD2DEnv(cfg, "train4")
        obs, _ = env.reset(seed=100 + i)
        np.testing.assert_array_equal(obs, vobs[i])
        needs_reset = False
        for t in range(steps):
            if needs_reset and mode == "NextStep":
                obs, _ = env.reset()
                r = 0.0
                needs_reset = False
            else:
                obs, r, te, tr, _ = env.step(actions[t, i])
                if te or tr:
                    if mode == "SameStep":
                        obs, _ = env.reset()
                    else:
                        needs_reset = True
            assert r == v_rewards[t, i], (i, t)
            np.testing.assert_array_equal(obs, v_obs[t + 1][i])


def test_same_step_final_obs():
    venv = UavRisD2DVectorEnv(2, SystemConfig(horizon=3), autoreset_mode="SameStep")
    venv.reset(seed=0)
    a = np.zeros((2, 22), dtype=np.float32)
    for _ in range(2):
        _, _, _, tr, info = venv.step(a)
        assert "final_obs" not in info and not tr.any()
    obs, _, _, tr, info = venv.step(a)
    assert tr.all() and info["_final_obs"].all()
    lay = observation_layout(venv.config)
    assert info["final_obs"][0, lay["time_fraction"]][0] == pytest.approx(1.0)
    assert obs[0, lay["time_fraction"]][0] == 0.0


def test_invariants_under_random_actions():
    cfg = SystemConfig()
    env = UavRisD2DEnv(cfg, "train1")
    obs, info = env.reset(seed=11)
    rng = np.random.default_rng(5)
    energy_prev = 0.0
    lo, hi = np.array(cfg.region_low), np.array(cfg.region_high)
    v_prev = info["velocity"]
    energy_integral = 0.0
    for _ in range(cfg.horizon):
        a = rng.uniform(-1, 1, 22).astype(np.float32)
        a[:3] = np.sign(a[:3])  # push hard to hit the speed bound and the walls
        obs, r, te, tr, info = env.step(a)
        assert np.linalg.norm(info["velocity"]) <= cfg.v_max + 1e-9
        assert np.linalg.norm(info["acceleration"]) <= cfg.a_max + 1e-9
        assert np.all(info["position"] >= lo - 1e-12) and np.all(info["position"] <= hi + 1e-12)
        assert np.all((info["attitude"] >= 0) & (info["attitude"] < 2 * np.pi))
        assert info["energy_used"] >= energy_prev
        acc = info["acceleration"]
        power = lambda s, v0=v_prev, a0=acc: float(ph.propulsion_power(np.linalg.norm(v0 + a0 * s)))  # noqa: E731
        e, _ = integrate.quad(power, 0, cfg.slot_s)
        energy_integral += e
        np.testing.assert_allclose(info["energy_used"], energy_integral, rtol=1e-8)
        assert info["energy_remaining"] == pytest.approx(max(cfg.energy_budget_j - info["energy_used"], 0.0))
        assert r >= 0 and r == pytest.approx(info["pair_rates"].sum())
        assert np.all(info["pair_rates"][info["pairing"] == 0] == 0)
        assert info["incidence_deg"].shape == (4,)
        assert np.all(np.abs(obs[:6]) <= 1 + 1e-6)
        energy_prev = info["energy_used"]
        # velocity into a wall is zeroed, so the next slot starts from the returned velocity
        v_prev = info["velocity"]
        if te or tr:
            break
    assert env.observation_space.contains(obs)


def test_energy_budget_terminates():
    cfg = SystemConfig(energy_budget_j=500.0)
    env = UavRisD2DEnv(cfg)
    env.reset(seed=0)
    hover = np.zeros(22, dtype=np.float32)
    for t in range(cfg.horizon):  # noqa: B007 - the slot at termination is asserted below
        _, _, te, tr, info = env.step(hover)
        if te:
            break
    # hovering costs 84.245 J per slot: the budget of 500 J is passed in the 6th slot
    assert te and not tr and t == 5
    assert info["energy_remaining"] == 0.0


def test_truncation_at_horizon():
    cfg = SystemConfig(horizon=7)
    env = UavRisD2DEnv(cfg)
    env.reset(seed=0)
    a = np.full(22, 0.3, dtype=np.float32)
    flags = [env.step(a)[3] for _ in range(7)]
    assert flags == [False] * 6 + [True]


def test_out_of_range_actions_are_clipped():
    env1, env2 = UavRisD2DEnv(), UavRisD2DEnv()
    env1.reset(seed=4)
    env2.reset(seed=4)
    a = np.random.default_rng(0).uniform(-3, 3, 22).astype(np.float32)
    r1 = env1.step(a)[1]
    r2 = env2.step(np.clip(a, -1, 1))[1]
    assert r1 == r2


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_or_inf_action_raises(bad):
    env = UavRisD2DEnv()
    env.reset(seed=0)
    a = np.zeros(22, dtype=np.float32)
    a[5] = bad
    with pytest.raises(ValueError, match="NaN or inf"):
        env.step(a)
    venv = UavRisD2DVectorEnv(3)
    venv.reset(seed=0)
    before = venv.sim.pos.copy()
    acts = np.zeros((3, 22), dtype=np.float32)
    acts[1, 0] = bad
    with pytest.raises(ValueError, match="NaN or inf"):
        venv.step(acts)
    np.testing.assert_array_equal(venv.sim.pos, before)  # nothing moved


def test_wrong_action_shape_raises():
    env = UavRisD2DEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(5, dtype=np.float32))


def test_step_before_reset_raises():
    with pytest.raises(RuntimeError, match="reset"):
        UavRisD2DEnv().step(np.zeros(22, dtype=np.float32))


def test_observation_scaling_is_order_one():
    venv = UavRisD2DVectorEnv(256)
    obs, _ = venv.reset(seed=0)
    rng = np.random.default_rng(0)
    all_obs = [obs]
    for _ in range(100):
        obs, *_ = venv.step(rng.uniform(-1, 1, (256, 22)).astype(np.float32))
        all_obs.append(obs)
    x = np.concatenate(all_obs)
    lay = observation_layout(venv.config)
    ch = x[:, lay["channel_real"]]
    assert 0.05 < ch.std() < 5.0
    assert np.all(np.abs(x[:, : lay["channel_real"].start]) <= 1.0 + 1e-6)


def test_stream_normals_are_standard_complex_gaussian():
    keys = streams.slot_key(streams.seed_key(np.arange(50)), 0, 3)
    w = streams.complex_normals(streams.raw_bits(keys, 4000)).ravel()
    assert abs(np.mean(np.abs(w) ** 2) - 1) < 0.015
    assert abs(np.mean(w.real**2) - 0.5) < 0.01 and abs(np.mean(w.imag**2) - 0.5) < 0.01
    assert abs(np.mean(w)) < 0.01
    u = streams.uniforms(streams.raw_bits(keys, 4000)).ravel()
    assert np.all((u > 0) & (u < 1)) and abs(u.mean() - 0.5) < 0.005
    # streams of different seeds, episodes and slots differ
    a = streams.raw_bits(streams.slot_key(streams.seed_key(1), 0, 0), 8)
    for other in [streams.slot_key(streams.seed_key(2), 0, 0), streams.slot_key(streams.seed_key(1), 1, 0),
                  streams.slot_key(streams.seed_key(1), 0, 1)]:
        assert not np.any(a == streams.raw_bits(other, 8))
