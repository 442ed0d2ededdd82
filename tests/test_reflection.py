import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from uavris import physics as ph

cosines = st.floats(0.0, 1.0, allow_subnormal=False)  # subnormals are not physical inputs
phases = st.floats(0.0, 2 * np.pi, allow_subnormal=False)


def test_normal_incidence_returns_preset(rng):
    r_pre = rng.uniform(0, 1, 50) * np.exp(1j * rng.uniform(0, 2 * np.pi, 50))
    np.testing.assert_allclose(ph.reflection_coefficient(r_pre, 1.0), r_pre, atol=1e-14)


@given(phases, cosines)
def test_unit_preset_stays_unit(phi, c):
    assert abs(abs(ph.reflection_coefficient(np.exp(1j * phi), c)) - 1.0) < 1e-12


@given(phases, st.floats(0.0, 1.0, allow_subnormal=False))
def test_grazing_incidence_is_minus_one(phi, amp):
    assert abs(ph.reflection_coefficient(amp * np.exp(1j * phi), 0.0) - (-1.0)) < 1e-12


@given(st.floats(0.0, 1.0, allow_subnormal=False), phases, cosines)
def test_passive(amp, phi, c):
    assert abs(ph.reflection_coefficient(amp * np.exp(1j * phi), c)) <= 1.0 + 1e-12


def test_presets_plus_and_minus_one_exact():
    c = np.linspace(0, 1, 11)
    np.testing.assert_array_equal(ph.reflection_coefficient(-1.0, c), -1.0)
    r = ph.reflection_coefficient(1.0, c)
    np.testing.assert_array_equal(r[1:], 1.0)
    assert r[0] == -1.0  # documented grazing-incidence limit
    assert np.all(np.isfinite(r))


def test_reduced_form_matches_literal_eq5(rng):
    r_pre = rng.uniform(0.05, 0.95, 200) * np.exp(1j * rng.uniform(0, 2 * np.pi, 200))
    c = rng.uniform(0.01, 1.0, 200)
    np.testing.assert_allclose(ph.reflection_coefficient(r_pre, c), ph.reflection_coefficient_eq5(r_pre, c),
                               rtol=1e-9, atol=1e-12)


def test_unit_fast_path_matches_general_form(rng):
    phi = rng.uniform(0, 2 * np.pi, (30, 1, 16))
    c = rng.uniform(-0.2, 1.0, (30, 4, 1))
    ref = ph.reflection_coefficient(np.exp(1j * phi), c)
    np.testing.assert_allclose(ph.unit_reflection_coefficient(phi, c), ref, atol=1e-12)
    assert ph.unit_reflection_coefficient(0.0, 0.0) == -1.0


@given(phases, st.floats(0.01, 1.0, allow_subnormal=False))
def test_preset_for_target_inverts(phi, c):
    # Defined for every unit target but exactly -1, which no float phase gives (sin(pi) != 0 in
    # floats): no guard, so an implementation returning NaN or inf fails here.
    target = np.exp(1j * phi)
    r_pre = ph.preset_for_target(target, c)
    assert np.isfinite(r_pre)
    assert abs(abs(r_pre) - 1.0) < 1e-9
    assert abs(ph.reflection_coefficient(r_pre, c) - target) < 1e-9


def test_preset_for_target_worked_by_hand():
    # target j at cos(theta) = 0.5: (1 - j)/(1 + j) = -j, a = -0.5j, r_pre = (1 + 0.5j)/(1 - 0.5j) = 0.6 + 0.8j;
    # back through eq. (5): (0.5 (1.6 + 0.8j) - (0.4 - 0.8j)) / (0.5 (1.6 + 0.8j) + (0.4 - 0.8j)) = j
    assert ph.preset_for_target(1j, 0.5) == pytest.approx(0.6 + 0.8j, abs=1e-15)
    assert ph.reflection_coefficient(0.6 + 0.8j, 0.5) == pytest.approx(1j, abs=1e-15)
    assert ph.preset_for_target(1j, 1.0) == pytest.approx(1j, abs=1e-15)  # normal incidence: the target itself


def test_angle_dependence_is_real():
    # A preset of +j at normal incidence rotates towards -1 as the wave tilts.
    r = ph.reflection_coefficient(1j, np.cos(np.radians([0, 30, 60, 80])))
    angles = np.angle(r)
    assert np.all(np.diff(angles) > 0) and angles[-1] > np.pi / 2


def test_lambda_typo_fix_gives_r0_equal_rpre():
    r_pre = 0.3 + 0.4j
    lam1, lam2 = ph.lambda_coefficients(r_pre)
    np.testing.assert_allclose(lam1 * lam2, 4.0)  # corrected units: lambda1 * lambda2 = 4
    assert abs(ph.reflection_coefficient_eq5(r_pre, 1.0) - r_pre) < 1e-12
    # With the paper's printed lambda2 = (2/eta)(1 + r)/(1 - r), r(0) != r_pre.
    eta = 120 * np.pi
    lam2_typo = (2 / eta) * (1 + r_pre) / (1 - r_pre)
    r0_typo = -eta * lam1 / (2 + eta * lam1) + lam2_typo / (lam2_typo + 2 * eta)
    assert abs(r0_typo - r_pre) > 0.1
