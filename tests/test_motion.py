import numpy as np
from scipy import integrate

from uavris import physics as ph
from uavris.config import PropulsionParams

POWER = vars(PropulsionParams())


def test_hover_power():
    np.testing.assert_allclose(ph.propulsion_power(0.0), 79.86 + 88.63)


def test_power_model_terms():
    V = 12.0
    p0, pi_, u, v0 = 79.86, 88.63, 120.0, 4.03
    expected = (p0 * (1 + 3 * V**2 / u**2) + pi_ * np.sqrt(np.sqrt(1 + V**4 / (4 * v0**4)) - V**2 / (2 * v0**2))
                + 0.5 * 0.6 * 1.225 * 0.05 * 0.503 * V**3)
    np.testing.assert_allclose(ph.propulsion_power(V), expected, rtol=1e-12)
    # the rotary-wing curve dips below hover power at moderate speed, then rises
    speeds = np.linspace(0, 30, 301)
    p = ph.propulsion_power(speeds)
    assert p.argmin() not in (0, 300) and p[-1] > p[0]


def test_feasible_acceleration_respects_both_bounds(rng):
    v = ph.limit_norm(rng.uniform(-6, 6, (5000, 3)), 5.0)
    a_cmd = rng.uniform(-4, 4, (5000, 3))
    a = ph.feasible_acceleration(v, a_cmd, 0.5, 5.0, 2.0)
    assert np.all(np.linalg.norm(a, axis=1) <= 2.0 + 1e-12)
    assert np.all(np.linalg.norm(v + a * 0.5, axis=1) <= 5.0 + 1e-12)
    # within bounds the command passes unchanged
    small = np.array([[0.1, 0.2, -0.1]])
    np.testing.assert_allclose(ph.feasible_acceleration(np.zeros((1, 3)), small, 0.5, 5, 2), small)


def test_limit_norm_scales_vector_not_axes():
    out = ph.limit_norm(np.array([3.0, 4.0, 0.0]), 1.0)
    np.testing.assert_allclose(out, [0.6, 0.8, 0.0])


def test_kinematics_closed_form_and_walls():
    q, v, a = np.array([10.0, 10.0, 4.0]), np.array([1.0, -1.0, 0.5]), np.array([0.5, 0.2, -0.4])
    q1, v1 = ph.kinematic_step(q, v, a, 0.5, [0, 0, 2], [40, 40, 8])
    np.testing.assert_allclose(q1, q + v * 0.5 + 0.5 * a * 0.25)
    np.testing.assert_allclose(v1, v + a * 0.5)
    # flying into the floor of the region: position clipped, downward velocity zeroed
    q1, v1 = ph.kinematic_step([10, 10, 2.1], [1, 0, -2], [0, 0, 0], 0.5, [0, 0, 2], [40, 40, 8])
    np.testing.assert_allclose(q1, [10.5, 10, 2.0])
    np.testing.assert_allclose(v1, [1, 0, 0])


def test_slot_energy_matches_numerical_integral(rng):
    for _ in range(20):
        v = ph.limit_norm(rng.uniform(-5, 5, 3), 5.0)
        a = ph.feasible_acceleration(v, rng.uniform(-2, 2, 3), 0.5, 5.0, 2.0)
        ref, _ = integrate.quad(lambda t, v0=v, a0=a: float(ph.propulsion_power(np.linalg.norm(v0 + a0 * t))), 0, 0.5,
                                epsabs=1e-10, epsrel=1e-12)
        np.testing.assert_allclose(ph.slot_energy(v, a, 0.5, **POWER), ref, rtol=1e-8)


def test_hover_energy_per_slot():
    np.testing.assert_allclose(ph.slot_energy(np.zeros(3), np.zeros(3), 0.5), 0.5 * 168.49, rtol=1e-12)
