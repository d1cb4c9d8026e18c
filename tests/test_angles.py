import numpy as np
from hypothesis import given, settings, strategies as st

from fit.formats.angles import (cos_theta_i_o, direction_to_spherical, directions_to_half_diff,
                                half_diff_to_directions, spherical_to_direction)

angle = st.floats(0.0, np.pi / 2, allow_nan=False)
azimuth = st.floats(-np.pi, np.pi, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(angle, azimuth, angle, azimuth)
def test_directions_round_trip(ti, pi_, to, po):
    wi = spherical_to_direction(ti, pi_)
    wo = spherical_to_direction(to, po)
    th, ph, td, pd = directions_to_half_diff(wi, wo)
    wi2, wo2 = half_diff_to_directions(th, ph, td, pd)
    if np.linalg.norm(wi + wo) > 1e-6:  # wi == -wo has no half vector
        np.testing.assert_allclose(wi2, wi, atol=1e-9)
        np.testing.assert_allclose(wo2, wo, atol=1e-9)


@settings(max_examples=300, deadline=None)
@given(st.floats(0.0, np.pi / 2 - 1e-3), azimuth, st.floats(0.0, np.pi / 2 - 1e-3), azimuth)
def test_half_diff_round_trip(th, ph, td, pd):
    wi, wo = half_diff_to_directions(th, ph, td, pd)
    np.testing.assert_allclose(np.linalg.norm(wi), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(wo), 1.0, atol=1e-12)
    th2, ph2, td2, pd2 = directions_to_half_diff(wi, wo)
    assert abs(th2 - th) < 1e-7 and abs(td2 - td) < 1e-7
    def same_angle(a, b):
        return abs(np.angle(np.exp(1j * (a - b)))) < 1e-6

    if th > 1e-6 and td > 1e-6:  # both azimuths defined
        assert same_angle(ph2, ph) and same_angle(pd2, pd)
    elif th <= 1e-6 and td > 1e-6:  # h = n: only phi_h + phi_d is defined (phi_h := 0)
        assert same_angle(ph2 + pd2, ph + pd)


def test_degenerate_cases_are_finite():
    n = np.array([0.0, 0.0, 1.0])
    # theta_h = 0 and theta_d = 0 at once (wi = wo = n)
    th, ph, td, pd = directions_to_half_diff(n, n)
    assert th == 0 and td == 0 and ph == 0 and pd == 0
    # theta_h = 0 with theta_d > 0: mirror pair
    wi = spherical_to_direction(0.4, 1.0)
    wo = spherical_to_direction(0.4, 1.0 + np.pi)
    th, ph, td, pd = directions_to_half_diff(wi, wo)
    assert abs(th) < 1e-7 and abs(td - 0.4) < 1e-12
    wi2, wo2 = half_diff_to_directions(th, ph, td, pd)
    np.testing.assert_allclose(wi2, wi, atol=1e-7)
    # opposite directions: no half vector, still finite
    out = directions_to_half_diff(np.array([1.0, 0, 0]), np.array([-1.0, 0, 0]))
    assert all(np.isfinite(o) for o in out)


def test_closed_form_cosines_match_vectors():
    rng = np.random.default_rng(1)
    th, td = rng.uniform(0, np.pi / 2, (2, 1000))
    pd = rng.uniform(0, 2 * np.pi, 1000)
    wi, wo = half_diff_to_directions(th, rng.uniform(-np.pi, np.pi, 1000), td, pd)
    ci, co = cos_theta_i_o(th, td, pd)
    np.testing.assert_allclose(ci, wi[:, 2], atol=1e-12)
    np.testing.assert_allclose(co, wo[:, 2], atol=1e-12)


def test_spherical_round_trip():
    t, p = direction_to_spherical(spherical_to_direction(0.3, -2.0))
    assert abs(t - 0.3) < 1e-12 and abs(p + 2.0) < 1e-12
