"""The observation with device positions (``SystemConfig.observe_devices``): what it holds,
that single and batched environments agree on it, and that files keep it."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import uavris  # noqa: F401  (registers the env)
from uavris.config import SystemConfig
from uavris.env import ENV_ID, UavRisD2DEnv, UavRisD2DVectorEnv, observation_layout
from uavris.layouts import Layout, LayoutGenerator

SEEN = SystemConfig(observe_devices=True, horizon=40)
HALL, WHERE = LayoutGenerator().layout("unseen", 1).resolve(SEEN)


def test_the_device_slice_is_the_devices_seen_from_the_uav_nearest_first():
    env = UavRisD2DEnv(HALL, WHERE)
    obs, info = env.reset(seed=3)
    lay = observation_layout(HALL)
    assert list(lay)[-1] == "devices" and lay["devices"].stop == HALL.observation_dim == 158 + 12
    half = 0.5 * (np.asarray(HALL.region_high) - np.asarray(HALL.region_low))
    for _ in range(3):
        rel = (np.asarray(HALL.users) - info["position"]) / half
        want = rel[np.argsort(np.linalg.norm(rel, axis=1))]
        np.testing.assert_allclose(obs[lay["devices"]].reshape(4, 3), want, rtol=1e-6, atol=1e-6)
        obs, _, _, _, info = env.step(np.full(22, 0.8, dtype=np.float32))
    # everything before the slice is the observation without it
    plain = UavRisD2DEnv(HALL.replace(observe_devices=False), WHERE)
    np.testing.assert_array_equal(plain.reset(seed=3)[0], env.reset(seed=3)[0][:158])


def test_the_order_in_which_a_layout_lists_its_devices_does_not_change_the_device_slice():
    lay = observation_layout(HALL)
    shuffled = Layout("shuffled", HALL.users[::-1], WHERE.start).system(HALL)
    a, _ = UavRisD2DEnv(HALL, WHERE).reset(seed=1)
    b, _ = UavRisD2DEnv(shuffled, WHERE).reset(seed=1)
    np.testing.assert_array_equal(a[lay["devices"]], b[lay["devices"]])
    assert not np.array_equal(a[lay["channel_real"]], b[lay["channel_real"]])  # channels keep the listed order


def test_single_equals_batched_with_device_positions():
    n, steps = 3, 90  # crosses two episode boundaries of 40 slots
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, n, 22)).astype(np.float32)
    venv = UavRisD2DVectorEnv(n, HALL, WHERE, autoreset_mode="SameStep")
    vobs = [venv.reset(seed=50)[0]]
    for t in range(steps):
        vobs.append(venv.step(actions[t])[0])
    for i in range(n):
        env = UavRisD2DEnv(HALL, WHERE)
        obs, _ = env.reset(seed=50 + i)
        np.testing.assert_array_equal(obs, vobs[0][i])
        for t in range(steps):
            obs, _, te, tr, _ = env.step(actions[t, i])
            if te or tr:
                obs, _ = env.reset()
            np.testing.assert_array_equal(obs, vobs[t + 1][i])


def test_observations_stay_in_the_space_and_the_env_checks_clean():
    env = UavRisD2DEnv(HALL, WHERE)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    assert not caught, [str(w.message) for w in caught]
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(1)
    for _ in range(SEEN.horizon):
        a = np.sign(rng.uniform(-1, 1, 22)).astype(np.float32)  # to the walls and the floor
        obs, *_ = env.step(a)
        assert env.observation_space.contains(obs)


def test_the_env_spec_rebuilds_the_layout():
    env = gym.make(ENV_ID, config=HALL.to_dict(), scenario=WHERE.to_dict())
    spec_env = gym.make(gym.spec(ENV_ID).id, **env.spec.kwargs)
    assert spec_env.unwrapped.config == HALL and spec_env.unwrapped.scenario == WHERE
    a, _ = env.reset(seed=7)
    b, _ = spec_env.reset(seed=7)
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("flag", [True, False])
def test_stored_configs_keep_the_flag(flag):
    cfg = HALL.replace(observe_devices=flag)
    assert SystemConfig.from_stored(cfg.to_dict()) == cfg
    old = {k: v for k, v in SystemConfig().to_dict().items() if k not in ("observe_devices", "min_device_spacing")}
    assert SystemConfig.from_stored(old).observe_devices is False  # files from before the field: as they were
