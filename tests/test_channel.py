import numpy as np
import pytest

from tests.conftest import random_cn
from uavris import physics as ph

KW = dict(rician_factor=8.0, pathloss_exponent=2.4, nx=4, ny=4)
LEVEL = ph.ris_axes([0.0, 0.0, 0.0])


def test_array_response_is_kron_with_documented_indexing(rng):
    u, v = rng.uniform(-1, 1, 2)
    g = ph.array_response(u, v, 4, 3, 0.5)
    ax = np.exp(-2j * np.pi * 0.5 * np.arange(4) * u)
    ay = np.exp(-2j * np.pi * 0.5 * np.arange(3) * v)
    np.testing.assert_allclose(g, np.kron(ay, ax), atol=1e-14)
    assert g.shape == (12,)
    # element m*nx + i carries phase of (i, m)
    np.testing.assert_allclose(g[2 * 4 + 1], ax[1] * ay[2], atol=1e-14)


def test_array_response_batched(rng):
    u = rng.uniform(-1, 1, (3, 5))
    v = rng.uniform(-1, 1, (3, 5))
    g = ph.array_response(u, v, 4, 4)
    assert g.shape == (3, 5, 16)
    np.testing.assert_allclose(g[1, 2], ph.array_response(u[1, 2], v[1, 2], 4, 4), atol=1e-14)
    np.testing.assert_allclose(np.abs(g), 1.0, atol=1e-12)


def los_only_gain(q_ris, tx, rx, phases=None):
    users = np.array([tx, rx], dtype=float)
    u, v, c, d = ph.incidence(q_ris, users, LEVEL)
    h = ph.rician_channels(u, v, c, d, np.zeros((2, 16)), rician_factor=1e12, pathloss_exponent=2.4, nx=4, ny=4)
    r_pre = np.ones(16) if phases is None else np.exp(1j * phases)
    refl = ph.effective_reflection(r_pre, c)
    return np.abs(ph.cascaded_gains(h, refl)[0, 1])


def test_snell_mirror_receiver_has_largest_gain():
    """Level RIS, equal phases, LoS only: over receivers at equal distance from the RIS,
    the gain peaks at the specular (mirror-image) direction."""
    q = np.array([20.0, 20.0, 5.0])
    tx = np.array([14.0, 17.0, 0.0])
    d_in = (q - tx) / np.linalg.norm(q - tx)
    mirror = np.array([d_in[0], d_in[1], -d_in[2]])  # outgoing direction, reflected in the plane
    radius = 8.0
    # receivers on a ring of directions around the RIS, all at the same distance
    best_dir, best = None, -1.0
    for az in np.radians(np.arange(0, 360, 2)):
        for el in np.radians(np.arange(10, 90, 2)):
            out = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
            gain = los_only_gain(q, tx, q + radius * out)
            if gain > best:
                best, best_dir = gain, out
    mirror_gain = los_only_gain(q, tx, q + radius * mirror)
    assert mirror_gain >= best - 1e-12
    assert np.degrees(np.arccos(np.clip(best_dir @ mirror, -1, 1))) < 3.0
    # and the gain there is the coherent sum N * |h_tx| * |h_rx|
    expected = 16 * np.linalg.norm(q - tx) ** -1.2 * radius**-1.2
    np.testing.assert_allclose(mirror_gain, expected, rtol=1e-9)


def test_rician_power_split_and_pathloss(rng):
    n_draws, kappa, alpha = 20000, 8.0, 2.4
    dist = np.full(n_draws, 7.0)
    u = np.full(n_draws, 0.3)
    v = np.full(n_draws, -0.2)
    c = np.full(n_draws, 0.9)
    w = random_cn(rng, (n_draws, 16))
    h = ph.rician_channels(u, v, c, dist, w, rician_factor=kappa, pathloss_exponent=alpha, nx=4, ny=4)
    g = ph.array_response(0.3, -0.2, 4, 4)
    scale = dist[0] ** (-alpha / 2)
    los = scale * np.sqrt(kappa / (kappa + 1)) * g
    nlos = h - los
    p_los = np.mean(np.abs(los) ** 2)
    p_nlos = np.mean(np.abs(nlos) ** 2)
    # kappa = LoS / NLoS power; NLoS power estimated over 320k samples: 1% tolerance is > 5 sigma
    assert abs(p_los / p_nlos - kappa) / kappa < 0.01
    assert abs(np.mean(np.abs(h) ** 2) / dist[0] ** (-alpha) - 1.0) < 0.01
    # NLoS part is circularly symmetric: real and imaginary parts uncorrelated, equal power
    assert abs(np.mean(nlos.real**2) / np.mean(nlos.imag**2) - 1) < 0.03
    assert abs(np.mean(nlos.real * nlos.imag)) / p_nlos < 0.02


@pytest.mark.parametrize("alpha", [2.0, 2.4, 3.0])
def test_mean_power_follows_distance_law(rng, alpha):
    dists = np.array([2.0, 5.0, 10.0, 20.0])
    w = random_cn(rng, (5000, 4, 16))
    zeros = np.zeros((5000, 4))
    h = ph.rician_channels(zeros, zeros, zeros + 1, np.broadcast_to(dists, (5000, 4)), w,
                           rician_factor=8, pathloss_exponent=alpha, nx=4, ny=4)
    power = np.mean(np.abs(h) ** 2, axis=(0, 2))
    np.testing.assert_allclose(power, dists**-alpha, rtol=0.02)


def test_back_side_user_is_blocked(rng):
    users = np.array([[20.0, 20.0, 0.0], [20.0, 21.0, 7.0]])  # below and above the RIS
    u, v, c, d = ph.incidence([20.0, 20.0, 4.0], users, LEVEL)
    assert c[0] > 0 and c[1] < 0
    h = ph.rician_channels(u, v, c, d, random_cn(rng, (2, 16)), **KW)
    assert np.all(h[1] == 0) and np.all(h[0] != 0)
    # turned upside down, the other user is served
    u, v, c, d = ph.incidence([20.0, 20.0, 4.0], users, ph.ris_axes([0.0, np.pi, 0.0]))
    h = ph.rician_channels(u, v, c, d, random_cn(rng, (2, 16)), **KW)
    assert np.all(h[0] == 0) and np.all(h[1] != 0)


def single_pair_setup(rng):
    users = np.array([[15, 5, 1.0], [20, 8, 1.5], [30, 20, 0.1], [15, 35, 0.6]])
    att = np.radians([20.0, 4.0, -3.0])
    u, v, c, d = ph.incidence([18.0, 12.0, 4.5], users, ph.ris_axes(att))
    assert np.all(c > 0)  # every user in front of the RIS
    h = ph.rician_channels(u, v, c, d, random_cn(rng, (4, 16)), **KW)
    P = np.zeros((4, 4))
    P[0, 1] = 1.0
    return h, c, P


def test_closed_form_single_pair_co_phasing(rng):
    h, c, P = single_pair_setup(rng)
    power, noise = 1.0, 1e-11
    target = np.exp(-1j * np.angle(h[0] * h[1]))  # co-phase every element
    r_pre = ph.preset_for_target(target, c[0])
    refl = ph.effective_reflection(r_pre, c)
    snr = ph.pair_sinr(ph.cascaded_gains(h, refl), P, power, noise)[0, 1]
    closed = power * np.sum(np.abs(h[0]) * np.abs(refl[0]) * np.abs(h[1])) ** 2 / noise
    np.testing.assert_allclose(snr, closed, rtol=1e-9)
    np.testing.assert_allclose(np.abs(refl[0]), 1.0, atol=1e-12)
    # no random phase vector beats it
    phases = rng.uniform(0, 2 * np.pi, (2000, 16))
    rand_refl = ph.effective_reflection(np.exp(1j * phases), c)
    rand_snr = ph.pair_sinr(ph.cascaded_gains(h, rand_refl), P, power, noise)[:, 0, 1]
    assert rand_snr.max() <= snr * (1 + 1e-12)
    assert rand_snr.max() < 0.8 * snr  # and co-phasing is a real gain, not a tie


def test_rate_equals_log2_of_snr(rng):
    h, c, P = single_pair_setup(rng)
    refl = ph.effective_reflection(np.ones(16), c)
    gains = ph.cascaded_gains(h, refl)
    expected = np.log2(1 + np.abs(gains[0, 1]) ** 2 / 1e-11)
    np.testing.assert_allclose(ph.pair_rates(gains, P, 1.0, 1e-11)[0, 1], expected, rtol=1e-12)
    np.testing.assert_allclose(ph.sum_rate(gains, P, 1.0, 1e-11), expected, rtol=1e-12)


def test_interference_only_from_active_transmitters(rng):
    h, c, _ = single_pair_setup(rng)
    gains = ph.cascaded_gains(h, ph.effective_reflection(np.exp(1j * rng.uniform(0, 6, 16)), c))
    P = np.zeros((4, 4))
    P[0, 1] = P[2, 3] = 1.0
    sinr = ph.pair_sinr(gains, P, 1.0, 1e-11)
    g2 = np.abs(gains) ** 2
    np.testing.assert_allclose(sinr[0, 1], g2[0, 1] / (g2[2, 1] + 1e-11), rtol=1e-12)
    np.testing.assert_allclose(sinr[2, 3], g2[2, 3] / (g2[0, 3] + 1e-11), rtol=1e-12)
    assert np.count_nonzero(sinr) == 2
    # user 3 (idle in the first case) adds no interference
    P1 = np.zeros((4, 4))
    P1[0, 1] = 1.0
    np.testing.assert_allclose(ph.pair_sinr(gains, P1, 1.0, 1e-11)[0, 1], g2[0, 1] / 1e-11, rtol=1e-12)


def test_rates_nonnegative_and_zero_when_idle(rng):
    h = random_cn(rng, (200, 4, 16)) * 1e-2
    refl = np.exp(1j * rng.uniform(0, 6, (200, 4, 16)))
    P = ph.sample_pairing(rng, 4, 2, (200,))
    rates = ph.pair_rates(ph.cascaded_gains(h, refl), P, 1.0, 1e-11)
    assert np.all(rates >= 0)
    assert np.all(rates[P == 0] == 0)
    assert np.all(rates[P == 1] > 0)


def test_cascaded_gain_uses_transmitter_angle(rng):
    h, c, _ = single_pair_setup(rng)
    r_pre = np.exp(1j * rng.uniform(0, 6, 16))
    refl = ph.effective_reflection(r_pre, c)
    gains = ph.cascaded_gains(h, refl)
    manual = np.sum(h[2] * ph.reflection_coefficient(r_pre, c[2]) * h[0])
    np.testing.assert_allclose(gains[2, 0], manual, rtol=1e-12)
    assert not np.isclose(gains[2, 0], gains[0, 2])  # not symmetric: r depends on the transmitter
