"""The regime: the reference path gain per hop (SystemConfig.reference_gain_db), against cases
worked by hand and its limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavris import physics as ph
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
