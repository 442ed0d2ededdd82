import numpy as np

from uavris import physics as ph


def test_pairing_structure_and_distribution(rng):
    P = ph.sample_pairing(rng, 4, 2, (40000,))
    assert set(np.unique(P)) <= {0.0, 1.0}
    assert np.all(np.diagonal(P, axis1=1, axis2=2) == 0)
    # each user in at most one link, as transmitter or receiver
    assert np.all(P.sum(axis=2) + P.sum(axis=1) <= 1)
    m = P.sum(axis=(1, 2))
    assert set(np.unique(m)) == {1.0, 2.0}
    assert abs(np.mean(m == 1) - 0.5) < 0.015  # m uniform on {1, 2}
    # every ordered pair is equally likely to be active: 12 ordered pairs
    freq = P.mean(axis=0)[~np.eye(4, dtype=bool)]
    expected = np.mean(m) / 12
    np.testing.assert_allclose(freq, expected, rtol=0.05)


def test_pairing_odd_number_of_users(rng):
    P = ph.sample_pairing(rng, 5, 2, (1000,))
    assert P.shape == (1000, 5, 5)
    assert np.all(P.sum(axis=2) + P.sum(axis=1) <= 1)
    assert P.sum(axis=(1, 2)).max() == 2
