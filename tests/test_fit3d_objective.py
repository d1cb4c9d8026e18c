"""The second stage's objective of the 3-D fits (``Fit3DSettings.objective``).

* on a synthetic BRDF with a tall specular peak (30 /sr) over a dark base (0.02-0.05 /sr), the
  ``"relative"`` objective's fit has at most 0.6 times the median relative error of the
  ``"rho_cos_cos"`` one at fresh cosine-distributed pairs in the dark half of the values, with the
  same degrees, pieces, data and bound policy (every data point within the stated bound, Q > 0
  certified): the absolute objective of ``rho cos cos`` is dominated by the peak and leaves the
  dark region at about twice the error;
* the relative weights divide the density by the squared value floored at the floor and at the
  channel floor; the objective points of ``"relative"`` carry the cosine density alone;
* each objective's held-out selection score (:func:`fit.rational.select3d.validation_score`)
  ranks the fit made for it first: the relative score the relative fit, the relative RMSE of
  ``rho cos cos`` the default one;
* the fit records its objective; an unknown objective is refused.
"""
from __future__ import annotations

import numpy as np
import pytest

from fit.formats.angles import cos_theta_i_o
from fit.rational.fit3d import fit_samples, objective_points, sample_grid
from fit.rational.samples3d import relative_weights
from fit.rational.select3d import validation_relative, validation_score
from fit.rational.settings import Fit3DSettings
from fit.rational.variables3d import evaluate_directions, half_diff_3d

THETA_MAX = np.radians(80.0)
EDGES = [0.15]


def peak_over_dark(X):
    """Synthetic RGB BRDF (1/sr) of rows ``(theta_h, theta_d, |phi_d|)`` ``(N, 3)``: a narrow
    specular peak of 30 /sr over a dark base that varies with all three variables."""
    th, td, pd = X[:, 0], X[:, 1], X[:, 2]
    spec = 30.0 * np.exp(-(th / 0.12) ** 2) * (1.0 + 0.35 * np.cos(pd)) * (1.0 + 0.5 * np.sin(td) ** 2)
    base = np.array([0.02, 0.03, 0.05])
    dark = base[None, :] * (1.0 + 0.6 * np.cos(pd)[:, None] * np.sin(td)[:, None] + 0.5 * np.sin(th)[:, None] ** 2)
    return dark + spec[:, None] * [1.0, 0.9, 0.8]


def _cosine_dirs(rng, n):
    a, b = rng.random(n), rng.random(n)
    r, p = np.sqrt(a), 2 * np.pi * b
    return np.stack([r * np.cos(p), r * np.sin(p), np.sqrt(np.maximum(1 - a, 0))], -1)


@pytest.fixture(scope="module")
def fits():
    X = sample_grid(THETA_MAX, grid=(10, 9, 7), n_random=300, seed=3)
    rho = peak_over_dark(X)
    out = {}
    for kind in ("rho_cos_cos", "relative"):
        s = Fit3DSettings(degrees=(4, 2), theta_h_edges=EDGES, tol=0.01, time_limit=60.0, relax=2.0, objective=kind)
        Xo, wo = objective_points(THETA_MAX, [0.0, *EDGES, THETA_MAX], 1500, seed=9, objective=kind)
        out[kind] = fit_samples(X, rho, settings=s, theta_max=THETA_MAX, objective=(Xo, peak_over_dark(Xo), wo))
    return X, rho, out


def _fresh_pairs(n=40_000, seed=17):
    rng = np.random.default_rng(seed)
    wi, wo = _cosine_dirs(rng, n), _cosine_dirs(rng, n)
    keep = (wi[:, 2] >= np.cos(THETA_MAX)) & (wo[:, 2] >= np.cos(THETA_MAX))
    return wi[keep], wo[keep]


def test_relative_objective_beats_the_absolute_one_in_the_dark_region(fits):
    X, rho, out = fits
    wi, wo = _fresh_pairs()
    t = peak_over_dark(half_diff_3d(wi, wo))
    dark = t < np.median(t, axis=0)
    err = {k: np.median((np.abs(evaluate_directions(r.model, wi, wo) - t) / t)[dark]) for k, r in out.items()}
    assert err["relative"] < 0.6 * err["rho_cos_cos"], err
    for kind, r in out.items():
        assert r.valid and r.model.fit_info["objective"] == kind
        assert all(rec["stage"]["kind"] == "two-stage" for rec in r.records), kind
        for rec in r.records:          # the bound of every data point: at most relax x the tolerance met
            assert rec["tolerance"] <= rec["tolerance_met"] * (1 + 1e-9)
            assert rec["q_certificate"]["certified"]


class _Truth:
    """Stands in for an RGL file in the selection's validation: ``evaluate(wi, wo)`` (1/sr)."""

    def evaluate(self, wi, wo):
        return peak_over_dark(half_diff_3d(wi, wo))


def test_each_selection_score_prefers_the_fit_of_its_objective(fits):
    _, _, out = fits
    truth = _Truth()
    score = {(k, o): validation_score(truth, r.model, o) for k, r in out.items() for o in ("relative", "rho_cos_cos")}
    assert score[("relative", "relative")] < score[("rho_cos_cos", "relative")], score
    assert score[("rho_cos_cos", "rho_cos_cos")] < score[("relative", "rho_cos_cos")], score
    med, p95 = validation_relative(truth, out["relative"].model)
    assert 0.0 < med <= p95 and score[("relative", "relative")] == med + p95


def test_relative_weights_floor_the_value():
    rho = np.array([[2.0, 1.0, 0.0], [0.001, 0.002, 0.5]])
    w = np.array([1.0, 4.0])
    got = relative_weights(w, rho, floor=np.array([0.01, 0.01, 0.01]), channel_floor=0.05)
    unit = np.array([[2.0, 1.0, 0.1], [0.025, 0.025, 0.5]])
    np.testing.assert_allclose(got, w[:, None] / unit ** 2)


def test_relative_objective_points_carry_the_cosine_density():
    """``"relative"`` weights are the ``"rho_cos_cos"`` ones over ``(cos cos)^2`` at the same points."""
    edges = [0.0, 0.1, np.pi / 2]
    Xa, wa = objective_points(np.pi / 2, edges, 500, seed=4, objective="rho_cos_cos")
    Xr, wr = objective_points(np.pi / 2, edges, 500, seed=4, objective="relative")
    np.testing.assert_array_equal(Xa, Xr)
    ci, co = cos_theta_i_o(Xr[:, 0], Xr[:, 1], Xr[:, 2])
    np.testing.assert_allclose(wa, wr * (ci * co) ** 2, rtol=1e-12)
    with pytest.raises(ValueError, match="objective"):
        objective_points(np.pi / 2, edges, 10, objective="log")


def test_objective_setting_is_checked():
    with pytest.raises(ValueError, match="objective"):
        Fit3DSettings(objective="absolute")
    with pytest.raises(ValueError, match="relative_floor"):
        Fit3DSettings(relative_floor=-0.1)
