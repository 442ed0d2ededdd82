"""Issue 37: the reference path gain (the regime) and the search that measures the oracle's gap."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavris import physics as ph
from uavris.agents.oracle.search import SearchSettings, episode_value, exhaustive_plan
from uavris.config import SystemConfig


def test_reference_gain_scales_every_cascaded_gain_by_its_square(rng):
    # Worked by hand for two active links: SINR_k = P beta^4 |g_kk|^2 / (P beta^4 |g_jk|^2 + sigma^2), with the
    # per-hop amplitude gain beta = 10^(g0/20) on both hops of the cascaded channel, against the simulator's
    # rate formula with the config's noise.
    g0 = -30.0
    cfg = SystemConfig(reference_gain_db=g0)
    gains = rng.uniform(1e-5, 1e-4, (4, 4))  # cascaded channel amplitude of each ordered pair, without the gain
    pairing = np.zeros((4, 4))
    pairing[0, 1] = pairing[2, 3] = 1.0
    beta2 = 10 ** (2 * g0 / 10)  # the power gain of two hops
    sigma2 = 10 ** (-80 / 10) / 1000
    p = cfg.tx_power_w
    want = sum(math.log2(1 + p * beta2 * gains[t, r] ** 2 / (p * beta2 * gains[o, r] ** 2 + sigma2))
               for (t, r), (o, _) in (((0, 1), (2, 3)), ((2, 3), (0, 1))))
    got = float(ph.sum_rate(gains, pairing, cfg.tx_power_w, cfg.noise_w))
    assert got == pytest.approx(want, rel=1e-12)


def test_the_default_is_the_papers_channel_and_keeps_the_configs_keys():
    assert SystemConfig().noise_w == pytest.approx(1e-11)
    assert "reference_gain_db" not in SystemConfig().to_dict()  # the stage keys of earlier studies hold
    assert SystemConfig(reference_gain_db=-30).to_dict()["reference_gain_db"] == -30
    with pytest.raises(Exception, match="reference_gain_db"):
        SystemConfig(reference_gain_db=3.0)


def test_a_weaker_channel_is_noise_limited():
    # Limit: as the gain falls the rates fall, and a single link's rate tends to log2(1 + SNR) with SNR
    # falling by exactly the gain: 10 dB less per hop is 20 dB less SNR.
    gains = np.full((4, 4), 1e-4)
    pairing = np.zeros((4, 4))
    pairing[0, 1] = 1.0
    snr = [1.0 * 1e-8 / SystemConfig(reference_gain_db=g).noise_w for g in (0.0, -10.0)]
    assert 10 * math.log10(snr[0] / snr[1]) == pytest.approx(20.0)
    rates = [float(ph.sum_rate(gains, pairing, 1.0, SystemConfig(reference_gain_db=g).noise_w))
             for g in (0.0, -20.0, -40.0)]
    assert rates[0] > rates[1] > rates[2]


def test_the_search_finds_a_known_optimum():
    # A made-up R with one peak at a known pose, and the start on it: the objective's maximum is there
    # (moving only loses rate), and the search must find it within its last step.
    cfg = SystemConfig()
    best_q, best_a = np.array([20.3, 17.6, 5.2]), np.radians([13.0, -7.0, 4.0])

    def valuer(q, att):
        return 50.0 - np.sum((q - best_q) ** 2, axis=-1) - 100.0 * np.sum((att - best_a) ** 2, axis=-1)

    found = exhaustive_plan(cfg, tuple(best_q), SearchSettings(grid_step=4.0, top=4, refine=2), valuer)
    assert np.linalg.norm(found.target - best_q) < 0.07
    off = (found.attitude - best_a + np.pi) % (2 * np.pi) - np.pi  # attitudes are wrapped angles
    assert np.degrees(np.abs(off)).max() < 0.7
    assert found.value == pytest.approx(50.0, abs=0.01)


def test_episode_value_counts_the_trip_at_the_lower_rate():
    cfg = SystemConfig()
    start = np.array([10.0, 10.0, 4.5])
    v = episode_value(cfg, start, 10.0, np.array([[10.0, 10.0, 4.5], [30.0, 10.0, 4.5]]), np.array([20.0, 40.0]))
    assert v[0] == pytest.approx(20.0)  # no trip
    from uavris.agents.oracle.planner import travel_slots

    t = int(travel_slots(cfg, 20.0)[0])
    assert v[1] == pytest.approx((t * 10.0 + (cfg.horizon - t) * 40.0) / cfg.horizon)
