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


def test_the_device_slice_is_each_device_seen_from_the_uav_in_the_layouts_order():
    env = UavRisD2DEnv(HALL, WHERE)
    obs, info = env.reset(seed=3)
    lay = observation_layout(HALL)
    assert list(lay)[-1] == "devices" and lay["devices"].stop == HALL.observation_dim == 158 + 12
    for _ in range(3):
        # one length for the three axes: 20 m, half the 40 m floor (the flight region's largest half-extent)
        want = (np.asarray(HALL.users) - info["position"]) / 20.0
        np.testing.assert_allclose(obs[lay["devices"]].reshape(4, 3), want, rtol=1e-6, atol=1e-6)
        obs, _, _, _, info = env.step(np.full(22, 0.8, dtype=np.float32))
    # everything before the slice is the observation without it
    plain = UavRisD2DEnv(HALL.replace(observe_devices=False), WHERE)
    np.testing.assert_array_equal(plain.reset(seed=3)[0], env.reset(seed=3)[0][:158])


def test_device_rows_are_in_metres_a_far_low_device_is_farther_than_a_near_high_one():
    # From [20, 20, 4.5]: a far, low device (10.4 m away, 3 m below) and a near one 4.9 m away
    # whose 4.5 m drop dominated the norm when each axis was scaled by its own half-extent
    # (20 m across the floor, 3 m in height): the far one then looked nearer.
    far, near = (30.0, 20.0, 1.5), (20.0, 22.0, 0.0)
    hall, where = Layout("case", (far, near, (5.0, 5.0, 1.0), (35.0, 35.0, 1.0)), (20.0, 20.0, 4.5)).resolve(SEEN)
    obs, _ = UavRisD2DEnv(hall, where).reset(seed=0)
    rows = obs[observation_layout(hall)["devices"]].reshape(4, 3)
    metres = np.linalg.norm(np.asarray(hall.users) - (20.0, 20.0, 4.5), axis=1)
    assert metres[0] == pytest.approx(np.hypot(10.0, 3.0)) and metres[1] == pytest.approx(np.hypot(2.0, 4.5))
    norms = np.linalg.norm(rows, axis=1)
    assert norms[1] < norms[0]  # the near device is nearer in the observation too
    np.testing.assert_allclose(norms / norms[0], metres / metres[0], rtol=1e-6)  # proportional to metres


def test_the_device_slice_keeps_the_layouts_order_with_channels_and_pairing():
    # Device k of the devices slice is device k of the channels: listing the devices in another
    # order permutes the slice the same way (order-free reading is the encoder's job).
    lay = observation_layout(HALL)
    perm = [3, 1, 0, 2]
    shuffled = Layout("shuffled", [HALL.users[i] for i in perm], WHERE.start).system(HALL)
    a, _ = UavRisD2DEnv(HALL, WHERE).reset(seed=1)
    b, _ = UavRisD2DEnv(shuffled, WHERE).reset(seed=1)
    np.testing.assert_array_equal(a[lay["devices"]].reshape(4, 3)[perm], b[lay["devices"]].reshape(4, 3))


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
    assert SystemConfig.from_dict(cfg.to_dict()) == cfg
