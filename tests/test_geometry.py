import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from uavris import physics as ph

angles = st.floats(-10.0, 10.0, allow_nan=False)


@given(angles, angles, angles)
def test_rotation_matrix_is_proper_orthonormal(y, p, r):
    R = ph.rotation_matrix(y, p, r)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert abs(np.linalg.det(R) - 1.0) < 1e-12


def test_rotation_matrix_equals_product_of_paper_matrices(rng):
    y, p, r = rng.uniform(-np.pi, np.pi, 3)
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    np.testing.assert_allclose(ph.rotation_matrix(y, p, r), Rz @ Ry @ Rx, atol=1e-14)


def test_rotation_matrix_is_batched(rng):
    a = rng.uniform(0, 2 * np.pi, (5, 7, 3))
    R = ph.rotation_matrix(a[..., 0], a[..., 1], a[..., 2])
    assert R.shape == (5, 7, 3, 3)
    np.testing.assert_allclose(R[2, 3], ph.rotation_matrix(*a[2, 3]), atol=1e-15)


def test_level_ris_axes_are_reference_axes():
    np.testing.assert_allclose(ph.ris_axes([0.0, 0.0, 0.0]), np.eye(3), atol=1e-15)


def test_pitch_of_pi_turns_the_normal_over():
    axes = ph.ris_axes([0.0, np.pi, 0.0])
    np.testing.assert_allclose(axes[:, 2], [0, 0, -1], atol=1e-12)


def test_attitude_accumulates_and_wraps():
    att = np.zeros(3)
    step = np.radians([10.0, -10.0, 7.0])
    for _ in range(40):
        att = ph.accumulate_attitude(att, step)
        assert np.all((att >= 0) & (att < 2 * np.pi))
    np.testing.assert_allclose(att, np.mod(40 * step, 2 * np.pi), atol=1e-12)
    # axes come from the absolute attitude, not from compounding per-slot rotations
    np.testing.assert_allclose(ph.ris_axes(att), ph.rotation_matrix(*(40 * step)), atol=1e-12)


def test_wrap_angle_edge_cases():
    w = ph.wrap_angle([-1e-20, 2 * np.pi, -2 * np.pi, 7.0])
    assert np.all((w >= 0) & (w < 2 * np.pi))
    np.testing.assert_allclose(w[1:3], 0.0, atol=1e-15)


def test_incidence_level_ris():
    users = np.array([[10.0, 20.0, 0.0], [13.0, 24.0, 1.0]])
    u, v, c, d = ph.incidence([10.0, 20.0, 5.0], users, ph.ris_axes([0, 0, 0]))
    np.testing.assert_allclose(d, [5.0, np.sqrt(9 + 16 + 16)])
    np.testing.assert_allclose(c, [1.0, 4.0 / d[1]])
    np.testing.assert_allclose(u, [0.0, -3.0 / d[1]])
    np.testing.assert_allclose(v, [0.0, -4.0 / d[1]])
    # direction cosines on an orthonormal frame
    np.testing.assert_allclose(u**2 + v**2 + c**2, 1.0)


def test_incidence_follows_attitude(rng):
    q = np.array([20.0, 20.0, 4.5])
    users = rng.uniform([0, 0, 0], [40, 40, 2], (6, 3))
    att = rng.uniform(0, 2 * np.pi, 3)
    axes = ph.ris_axes(att)
    u, v, c, d = ph.incidence(q, users, axes)
    dirs = (q - users) / d[:, None]
    np.testing.assert_allclose(c, dirs @ axes[:, 2], atol=1e-12)
    np.testing.assert_allclose(u, dirs @ axes[:, 0], atol=1e-12)
    np.testing.assert_allclose(u**2 + v**2 + c**2, 1.0, atol=1e-12)
