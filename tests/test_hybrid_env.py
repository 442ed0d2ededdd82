"""The hybrid controller and halls of one's own through `gymnasium.make`: `phase_control="optimizer"`
(6 motion entries, the optimiser's phases) and `layout=` (a name, a file or a Layout), single and
vector environments alike."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import uavris  # noqa: F401  (registers the environment)
from uavris import physics as ph
from uavris.config import SystemConfig
from uavris.errors import ActionError
from uavris.layouts import Layout, LayoutGenerator
from uavris.physics.co_phasing import co_phasing_phases
from uavris.physics.phase_opt import optimize_slot_phases

ID = "uavris/UavRisD2D-v1"


def test_hybrid_env_passes_gymnasiums_checker_with_six_action_entries():
    env = gym.make(ID, phase_control="optimizer")
    assert env.action_space.shape == (6,) and env.observation_space.shape == (SystemConfig().observation_dim,)
    check_env(env.unwrapped, skip_render_check=True)


def test_hybrid_step_is_the_full_env_given_the_optimisers_phases():
    """Same seed, same motion: the hybrid env's reward is the full env's with the phases the
    optimiser gives for the slot's channels, and never below co-phasing the best lone link."""
    hybrid, full = gym.make(ID, phase_control="optimizer"), gym.make(ID)
    hybrid.reset(seed=3)
    full.reset(seed=3)
    c = SystemConfig()
    motion = np.array([0.5, -0.2, 0.0, 0.1, 0.0, -0.1], dtype=np.float32)
    for _ in range(6):
        sim = full.unwrapped.sim
        sol = optimize_slot_phases(c, sim.channels, sim.cos_theta, sim.pairing)
        action = np.concatenate([motion[:3], ph.wrap_angle(sol.phases[0]) / np.pi - 1.0, motion[3:]])
        # the best single link co-phased, valued by the simulator's own rate function
        links = np.argwhere(sim.pairing[0] > 0)
        lone = max(ph.sum_rate(ph.cascaded_gains(sim.channels[0], ph.effective_reflection(
            np.exp(1j * co_phasing_phases(sim.channels[0], sim.cos_theta[0], tx, rx)), sim.cos_theta[0])),
            sim.pairing[0], c.tx_power_w, c.noise_w) for tx, rx in links)
        _, r_full, *_ = full.step(action.astype(np.float32))
        _, r_hybrid, *_ = hybrid.step(motion)
        assert r_hybrid == pytest.approx(r_full, rel=1e-6, abs=1e-9)
        assert r_hybrid >= lone - 1e-6


def test_layout_kwarg_sets_the_devices_and_the_start():
    gen = LayoutGenerator()
    lay = gen.layout("unseen", 2, SystemConfig())
    env = gym.make(ID, layout="layout-unseen-2").unwrapped
    assert env.config.users == lay.users and env.scenario.start == lay.start
    env = gym.make(ID, layout=lay, scenario="fig2").unwrapped  # a Layout object; a named start wins
    assert env.config.users == lay.users and env.scenario.name == "fig2"
    mine = Layout("mine", ((5.0, 5.0, 1.0), (15.0, 5.0, 1.0), (5.0, 15.0, 1.0), (30.0, 30.0, 1.0)), (20.0, 20.0, 4.0))
    env = gym.make(ID, layout=mine, phase_control="optimizer").unwrapped
    assert env.config.users == mine.users and env.scenario.start == (20.0, 20.0, 4.0)


def test_vector_hybrid_env_row_i_is_the_single_env_seeded_s_plus_i():
    vec = gym.make_vec(ID, num_envs=3, vectorization_mode="vector_entry_point", phase_control="optimizer",
                       layout="layout-train-1")
    assert vec.single_action_space.shape == (6,)
    obs, _ = vec.reset(seed=10)
    rng = np.random.default_rng(0)
    moves = rng.uniform(-1, 1, (4, 3, 6)).astype(np.float32)
    rewards = [vec.step(m)[1] for m in moves]
    for i in range(3):
        env = gym.make(ID, phase_control="optimizer", layout="layout-train-1")
        o, _ = env.reset(seed=10 + i)
        assert np.array_equal(o, obs[i])
        for t in range(4):
            assert env.step(moves[t, i])[1] == rewards[t][i]


def test_a_full_action_in_the_hybrid_env_is_one_line():
    env = gym.make(ID, phase_control="optimizer")
    env.reset(seed=0)
    with pytest.raises(ActionError, match="takes 6 motion entries"):
        env.step(np.zeros(22, dtype=np.float32))
    with pytest.raises(ActionError, match="finite"):
        env.step(np.full(6, np.nan, dtype=np.float32))
    with pytest.raises(Exception, match="phase control"):
        gym.make(ID, phase_control="wings")


def test_stable_baselines3_trains_on_the_hybrid_env_unchanged():
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", gym.make(ID, phase_control="optimizer", layout="layout-unseen-0"), n_steps=32,
                batch_size=16, n_epochs=1, seed=0, verbose=0)
    model.learn(64)
    action, _ = model.predict(np.zeros(SystemConfig().observation_dim, dtype=np.float32), deterministic=True)
    assert action.shape == (6,)
