"""Rusinkiewicz half / difference angles (fit.formats.angles): round trips over many random
angles and every combination of the domain's edge values (0, pi/2, +-pi, just inside them, the
smallest doubles), all in one vectorised call each."""
import itertools

import numpy as np

from fit.formats.angles import (cos_theta_i_o, direction_to_spherical, directions_to_half_diff,
                                half_diff_to_directions, spherical_to_direction)

HALF_PI = np.pi / 2


def _cases(polar_max, n_random=20000, seed=0):
    """(theta_1, phi_1, theta_2, phi_2) arrays: ``n_random`` uniform draws over [0, polar_max] x
    [-pi, pi] twice, then every combination of the edge values of each range."""
    rng = np.random.default_rng(seed)
    polar_edges = [0.0, 5e-324, 1e-300, 1e-12, 1e-7, 0.5, polar_max - 1e-9, polar_max]
    az_edges = [-np.pi, -np.pi + 1e-12, -1e-300, 0.0, 5e-324, 1.0, np.pi - 1e-12, np.pi]
    edges = np.array(list(itertools.product(polar_edges, az_edges, polar_edges, az_edges)), float).T
    rand = np.stack([rng.uniform(0, polar_max, n_random), rng.uniform(-np.pi, np.pi, n_random),
                     rng.uniform(0, polar_max, n_random), rng.uniform(-np.pi, np.pi, n_random)])
    return np.concatenate([rand, edges], axis=1)


def test_directions_round_trip():
    ti, pi_, to, po = _cases(HALF_PI)
    wi = spherical_to_direction(ti, pi_)
    wo = spherical_to_direction(to, po)
    th, ph, td, pd = directions_to_half_diff(wi, wo)
    wi2, wo2 = half_diff_to_directions(th, ph, td, pd)
    ok = np.linalg.norm(wi + wo, axis=-1) > 1e-6      # wi == -wo has no half vector
    assert ok.sum() > 20000
    np.testing.assert_allclose(wi2[ok], wi[ok], atol=1e-9)
    np.testing.assert_allclose(wo2[ok], wo[ok], atol=1e-9)


def test_half_diff_round_trip():
    th, ph, td, pd = _cases(HALF_PI - 1e-3, seed=1)
    wi, wo = half_diff_to_directions(th, ph, td, pd)
    np.testing.assert_allclose(np.linalg.norm(wi, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(wo, axis=-1), 1.0, atol=1e-12)
    th2, ph2, td2, pd2 = directions_to_half_diff(wi, wo)
    assert np.abs(th2 - th).max() < 1e-7 and np.abs(td2 - td).max() < 1e-7

    def same_angle(a, b):
        return np.abs(np.angle(np.exp(1j * (a - b)))) < 1e-6

    both = (th > 1e-6) & (td > 1e-6)                 # both azimuths defined
    assert both.sum() > 10000 and np.all(same_angle(ph2, ph)[both]) and np.all(same_angle(pd2, pd)[both])
    pole = (th <= 1e-6) & (td > 1e-6)                # h = n: only phi_h + phi_d is defined (phi_h := 0)
    assert pole.sum() > 100 and np.all(same_angle(ph2 + pd2, ph + pd)[pole])


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
