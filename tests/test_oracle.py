"""Per-slot phase optimiser and the oracle policy."""

import numpy as np
import pytest

from uavris import physics as ph
from uavris.agents import phase_optimizer as po
from uavris.agents.baselines import hover_aligned
from uavris.agents.evaluation import evaluate
from uavris.agents.oracle import choose_moves, expected_sum_rate, link_activity, oracle_policy
from uavris.env.simulator import BatchedSimulator, decode_action


def slots(config, n, seed, max_pairs=None, tilt=0.4):
    """``n`` seeded slots at random poses (region-wide, tilts up to ``tilt`` rad):
    channels, cos(theta) and pairings (``max_pairs`` active pairs if given)."""
    sim = BatchedSimulator(config, "fig2", n)
    sim.seed(seed + np.arange(n))
    sim.reset()
    rng = np.random.default_rng(seed)
    sim.pos = np.c_[rng.uniform(0, 40, (n, 2)), rng.uniform(2, 8, n)]
    sim.att = rng.uniform(-tilt, tilt, (n, 3))
    sim._draw_slot(slice(None))
    pairing = sim.pairing
    if max_pairs is not None:
        pairing = ph.pairing_from_uniforms(np.full(n, (max_pairs - 0.5) / config.pairs_upper),
                                           rng.random((n, config.num_users)), config.pairs_upper)
    return sim.channels, sim.cos_theta, pairing


def physics_sum_rate(config, h, cos, pairing, phases, angle_dependent=True):
    refl = ph.effective_reflection_from_phases(phases, cos, angle_dependent)
    return ph.sum_rate(ph.cascaded_gains(h, refl), pairing, config.tx_power_w, config.noise_w)


def test_rate_and_gradient_match_physics_and_finite_differences(config):
    h, cos, pairing = slots(config, 12, 3)
    phi = np.random.default_rng(0).uniform(0, 2 * np.pi, (12, config.num_elements))
    rate, grad = po.sum_rate_and_gradient(phi, h, cos, pairing, config.tx_power_w, config.noise_w)
    np.testing.assert_allclose(rate, physics_sum_rate(config, h, cos, pairing, phi), rtol=1e-9, atol=1e-9)
    eps, fd = 1e-6, np.empty_like(grad)
    for n in range(config.num_elements):
        e = np.zeros(config.num_elements)
        e[n] = eps
        up, _ = po.sum_rate_and_gradient(phi + e, h, cos, pairing, config.tx_power_w, config.noise_w)
        dn, _ = po.sum_rate_and_gradient(phi - e, h, cos, pairing, config.tx_power_w, config.noise_w)
        fd[:, n] = (up - dn) / (2 * eps)
    np.testing.assert_allclose(grad, fd, atol=1e-6 * np.abs(grad).max())


def test_phase_form_of_reflection_matches_physics():
    """The optimiser's tan-based evaluation of r(theta) equals unit_reflection_coefficient,
    including phi = pi (tan infinite), phi = 0 and grazing incidence; slope = d arg r / d phi."""
    rng = np.random.default_rng(4)
    phi = np.concatenate([rng.uniform(-10, 10, 500), [0.0, np.pi, -np.pi, 2 * np.pi, np.pi / 2, 3 * np.pi]])
    cos = np.array([0.0, 1e-9, 0.3, 0.7, 1.0])
    r, slope = po._reflection_and_slope(phi, cos, True)
    np.testing.assert_allclose(r, ph.unit_reflection_coefficient(phi[None, :], cos[:, None]), atol=1e-14)
    # Slope by finite differences, except at c = 1e-9 where arg r steps by 2 pi within ~1e-9 rad.
    eps, rows = 1e-6, [0, 2, 3, 4]
    up, dn = po._reflection_and_slope(phi + eps, cos, True)[0], po._reflection_and_slope(phi - eps, cos, True)[0]
    np.testing.assert_allclose(np.angle(up / dn)[rows] / (2 * eps), slope[rows], atol=1e-6)


@pytest.mark.parametrize("angle_dependent", [True, False])
def test_one_active_pair_reaches_closed_form(config, angle_dependent):
    h, cos, pairing = slots(config, 64, 11, max_pairs=1)
    assert np.all(pairing.sum(axis=(1, 2)) == 1)
    sol = po.optimize_phases(h, cos, pairing, config.tx_power_w, config.noise_w, angle_dependent=angle_dependent)
    tx, rx = np.nonzero(pairing)[1:]
    amp = np.abs(h)
    coherent = np.sum(amp[np.arange(64), tx] * amp[np.arange(64), rx], axis=-1)
    closed = config.tx_power_w * coherent**2 / config.noise_w
    refl = ph.effective_reflection_from_phases(sol.phases, cos, angle_dependent)
    gain = ph.cascaded_gains(h, refl)[np.arange(64), tx, rx]
    snr = config.tx_power_w * np.abs(gain) ** 2 / config.noise_w
    np.testing.assert_allclose(snr, closed, rtol=1e-9)
    np.testing.assert_allclose(sol.sum_rate, np.log2(1 + closed), rtol=1e-12)
    np.testing.assert_allclose(po.single_pair_snr(h, tx, rx, config.tx_power_w, config.noise_w), closed, rtol=1e-12)
    assert np.all((sol.phases >= 0) & (sol.phases < 2 * np.pi))


def test_several_pairs_beat_random_search_and_co_phasing(config):
    """Fixed seeded instances (two active pairs, random poses and tilts): the optimiser beats
    the best of 1,000 random phase vectors and the best single-pair co-phasing, both scored
    by the physics module."""
    n, draws = 8, 1000
    h, cos, pairing = slots(config, n, 2024, max_pairs=2)
    assert np.all(pairing.sum(axis=(1, 2)) == 2)
    sol = po.optimize_phases(h, cos, pairing, config.tx_power_w, config.noise_w)
    # physics.pair_sinr forms interference as total - signal, which cancels at SINRs ~1e9:
    # agreement to ~1e-7 bps/Hz there.
    np.testing.assert_allclose(sol.sum_rate, physics_sum_rate(config, h, cos, pairing, sol.phases), atol=1e-6)
    rng = np.random.default_rng(7)
    phi = rng.uniform(0, 2 * np.pi, (n, draws, config.num_elements))
    random_best = physics_sum_rate(config, h[:, None], cos[:, None], pairing[:, None], phi).max(axis=1)
    tx, rx, _ = po.active_links(pairing, 2)
    cophase = po.co_phasing_phases(h[:, None], cos[:, None], tx, rx)
    cophase_best = physics_sum_rate(config, h[:, None], cos[:, None], pairing[:, None], cophase).max(axis=1)
    assert np.all(sol.sum_rate >= random_best)
    assert np.all(sol.sum_rate >= cophase_best - 1e-9)
    # Measured: optimiser 21.4-53.7 bps/Hz, random best 12.1-25.4, co-phasing best 4.3-26.6
    # (in two instances serving one pair is best); mean margin over random search 21.6.
    assert np.mean(sol.sum_rate - random_best) > 10.0


def test_batched_equals_slot_by_slot_and_leading_axes(config):
    h, cos, pairing = slots(config, 6, 5)
    batched = po.optimize_phases(h.reshape(2, 3, *h.shape[1:]), cos.reshape(2, 3, -1), pairing.reshape(2, 3, 4, 4),
                                 config.tx_power_w, config.noise_w)
    assert batched.phases.shape == (2, 3, config.num_elements) and batched.sum_rate.shape == (2, 3)
    # Same per-slot random starts in any batch ...
    starts = po.random_starts(h, 0, 4)
    for i in range(6):
        np.testing.assert_array_equal(po.random_starts(h[i:i + 1], 0, 4)[0], starts[i])
    # ... so slot-by-slot results agree (up to rounding paths; equal on these slots).
    for i in range(6):
        one = po.optimize_phases(h[i], cos[i], pairing[i], config.tx_power_w, config.noise_w)
        np.testing.assert_allclose(one.sum_rate, batched.sum_rate.reshape(6)[i], rtol=1e-9)


def test_no_active_pair_gives_zero_rate(config):
    h, cos, _ = slots(config, 3, 9)
    sol = po.optimize_phases(h, cos, np.zeros((3, 4, 4)), config.tx_power_w, config.noise_w)
    np.testing.assert_array_equal(sol.sum_rate, 0.0)


def test_link_activity_matches_pairing_model(config):
    rng = np.random.default_rng(1)
    p = ph.sample_pairing(rng, config.num_users, config.pairs_upper, (200_000,)).mean(axis=0)
    off = ~np.eye(config.num_users, dtype=bool)
    np.testing.assert_allclose(p[off], link_activity(config), atol=4e-3)  # 0.125 +- ~5 sigma


def test_lookahead_heads_for_better_poses_and_stops(config):
    """From rest at the fig2 start the chosen move raises the expected rate; at the best
    point of a local grid, at rest, the oracle stays (no move beats staying put)."""
    start = np.array([[15.0, 20.0, 4.5]])
    zero = np.zeros((1, 3))
    acc, datt, _ = choose_moves(config, start, zero, zero)
    assert np.linalg.norm(acc) > 0 and np.all(datt == 0)
    users, level = np.asarray(config.users), ph.ris_axes(zero[0])
    q, _ = ph.kinematic_step(start, zero, acc, config.slot_s, config.region_low, config.region_high)
    _, _, c0, d0 = ph.incidence(start[0], users, level)
    _, _, c1, d1 = ph.incidence(q[0], users, level)
    assert expected_sum_rate(config, d1, c1) > expected_sum_rate(config, d0, c0)
    # Above user 2 at the lowest altitude (the oracle's fig2 destination) it holds still.
    acc, datt, _ = choose_moves(config, np.array([[20.0, 8.0, 2.0]]), zero, zero)
    np.testing.assert_array_equal(acc, 0.0)
    np.testing.assert_array_equal(datt, 0.0)


def test_oracle_action_is_valid_and_does_not_peek_at_the_next_slot(config):
    sims = []
    for key_shift in (0, 12345):
        sim = BatchedSimulator(config, "fig2", 4)
        sim.seed(np.arange(4))
        sim.reset()
        sim.key = sim.key + np.uint64(key_shift)  # different future draws, same current slot
        sims.append(sim)
    policy = oracle_policy(seed=3)
    a0 = policy(sims[0].observe(), sims[0])
    a1 = policy(sims[1].observe(), sims[1])
    assert a0.dtype == np.float32 and a0.shape == (4, config.action_dim)
    assert np.all(np.abs(a0) <= 1.0)
    np.testing.assert_array_equal(a0, a1)
    # The decoded phases are the optimiser's (up to the float32 action resolution).
    _, phase, _, _ = decode_action(a0, config)
    sol = po.optimize_phases(sims[0].channels, sims[0].cos_theta, sims[0].pairing, config.tx_power_w,
                             config.noise_w, seed=3)
    diff = np.angle(np.exp(1j * (phase.astype(np.float64) - sol.phases)))
    assert np.max(np.abs(diff)) < 1e-6
    r0, *_ = sims[0].step(a0)
    np.testing.assert_allclose(r0, sol.sum_rate, rtol=1e-5)


def test_oracle_evaluation_reproducible_and_beats_hover_aligned(config):
    """Three fig2 episodes (seed 1_000_000). Measured: oracle 47.23, 46.60, 46.30 bps/Hz
    against hover_aligned 14.84, 15.08, 15.06: margins 32.4, 31.5, 31.2 (mean 31.7)."""
    episodes, seed = 3, 1_000_000
    first = evaluate(oracle_policy(seed=0), config, "fig2", episodes, seed)
    second = evaluate(oracle_policy(seed=0), config, "fig2", episodes, seed)
    np.testing.assert_array_equal(first.avg_sum_rate, second.avg_sum_rate)
    np.testing.assert_array_equal(first.length, second.length)
    np.testing.assert_array_equal(first.energy_used, second.energy_used)
    base = evaluate(hover_aligned(), config, "fig2", episodes, seed)
    assert np.all(first.avg_sum_rate > base.avg_sum_rate + 20.0)
    assert first.avg_sum_rate.mean() - base.avg_sum_rate.mean() > 25.0


def test_config_variants_run(config):
    """Ideal RIS and amplitude-learning actions are handled (smoke, one step)."""
    for cfg in (config.replace(angle_dependent_reflection=False), config.replace(learn_amplitudes=True)):
        sim = BatchedSimulator(cfg, "fig2", 2)
        sim.seed(np.arange(2))
        sim.reset()
        action = oracle_policy()(sim.observe(), sim)
        assert action.shape == (2, cfg.action_dim)
        sim.step(action)


def test_rejects_bad_settings():
    with pytest.raises(ValueError):
        po.optimize_phases(np.zeros((4, 16)), np.ones(4), np.zeros((4, 4)), 1.0, 1e-11, noise_levels=())
    with pytest.raises(ValueError):
        oracle_policy(braking_slots=-1)
