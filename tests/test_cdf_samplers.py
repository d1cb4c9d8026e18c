"""Inverse-CDF samplers (issue 6): tabulated on every shared RGL material, rational (verified
fit) on a Lambert material, Warp == NumPy, unbiasedness, renders, fallback detection."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import RGL_MATERIALS, data_file
from fit.analytic import lambert
from fit.formats.angles import spherical_to_direction
from fit.formats.colour import LUMINANCE
from fit.projection.albedo import directional_albedo
from fit.sampling.cdf_file import CDFFit, fit_cdf, verify
from fit.sampling.table import tabulate
from test_cdf_table import _chi2_pvalue, _expected_cell_probs

THETA_V = [0.0, np.radians(45), np.radians(85)]


@pytest.fixture(scope="module")
def rgl():
    from fit.formats import load_measured

    out = {}
    for name in RGL_MATERIALS:
        b = load_measured(data_file(f"rgl/{name}.bsdf"))
        out[name] = (b, tabulate(b.evaluate))
    return out


@pytest.fixture(scope="module")
def lambert_fit():
    f = lambert((0.8, 0.6, 0.4))
    fit = fit_cdf(f, name="lambert", table_params=dict(n_v=8, n_t=32, n_p=32),
                  phi_kw=dict(degrees=(2, 1)), refinements=0, layout="global")
    assert not fit.fallback, fit.reason
    return f, fit


@pytest.mark.parametrize("name", RGL_MATERIALS)
def test_tabulated_chi2_and_unbiased_rgl(rgl, name):
    brdf, table = rgl[name]
    rng = np.random.default_rng(3)
    n = 60_000
    for tv in THETA_V:
        tl, pl, pdf = table.sample(tv, rng.random(n), rng.random(n))
        probs, te, pe = _expected_cell_probs(table, tv)
        counts, _, _ = np.histogram2d(tl, pl, bins=[te, pe])
        assert _chi2_pvalue(counts, probs, n) > 1e-4, (name, tv)
        _assert_albedo_matches_quadrature(brdf, tv, tl, pl, 1.0 / pdf, name)


def _assert_albedo_matches_quadrature(brdf, tv, tl, pl, weight, name):
    """Unbiasedness of ``f cos * weight`` (weight = 1/pdf or alpha) for light samples
    ``(tl, pl)`` at view ``tv``, against quadrature over the light (view fixed)."""
    wi = spherical_to_direction(tl, pl)
    wo = spherical_to_direction(tv, 0.0)
    est = (brdf.evaluate(wi, wo) @ LUMINANCE) * np.cos(tl) * weight
    m, se = est.mean(), est.std() / np.sqrt(len(est))
    # Quadrature over the light with the view fixed (full azimuth range: the resampled RGL
    # data are not mirror-symmetric in phi_l, 2.6 % apart on cc_iris_purple_gem at 45 deg).
    swap = lambda a, b: brdf.evaluate(b, a)  # noqa: E731
    q1 = directional_albedo(swap, tv) @ LUMINANCE
    q2 = directional_albedo(swap, tv, 180, 720) @ LUMINANCE
    # 3 sigma + the quadrature's own uncertainty (difference of two resolutions) + 0.5 %
    # for the clear coats' near-normal mirror peak (heavy-tailed weights, midpoint rule)
    assert abs(m - q2) < 3 * se + 2 * abs(q2 - q1) + 0.005 * q2, (name, tv, m, q2, se, q1)


def _rational_cell_probs(fit: CDFFit, tv, nb_t=7, nb_p=9, nq=64):
    """Exact cell probabilities of the rational sampler by inverting its monotone map."""
    t_edges = np.linspace(0, np.pi / 2, nb_t + 1)
    p_edges = np.linspace(-np.pi, np.pi, nb_p + 1)
    mu_e = fit.theta_cdf(tv, t_edges)
    probs = np.zeros((nb_t, nb_p))
    for a in range(nb_t):
        mu = mu_e[a] + (np.arange(nq) + 0.5) / nq * (mu_e[a + 1] - mu_e[a])
        tl = fit.sample(tv, mu, 0.75)[0]
        # P(phi in [lo, hi] | theta_l): symmetric half-range CDF C(|phi|) with mass 1/2 per side
        C = lambda p: fit.phi_cdf_half(tv, tl, p)  # noqa: E731
        for b in range(nb_p):
            lo, hi = p_edges[b], p_edges[b + 1]
            if lo >= 0:
                pr = 0.5 * (C(hi) - C(lo))
            elif hi <= 0:
                pr = 0.5 * (C(-lo) - C(-hi))
            else:
                pr = 0.5 * (C(hi) + C(-lo))
            probs[a, b] = (mu_e[a + 1] - mu_e[a]) * pr.mean()
    return probs, t_edges, p_edges


@pytest.mark.parametrize("tv", THETA_V)
def test_rational_chi2_and_derivative_estimator(lambert_fit, tv):
    f, fit = lambert_fit
    rng = np.random.default_rng(7)
    n = 40_000
    tl, pl, alpha = fit.sample(tv, rng.random(n), rng.random(n))
    probs, te, pe = _rational_cell_probs(fit, tv)
    assert probs.sum() == pytest.approx(1.0, abs=1e-6)
    counts, _, _ = np.histogram2d(tl, pl, bins=[te, pe])
    assert _chi2_pvalue(counts, probs, n) > 1e-4
    wi = spherical_to_direction(tl, pl)
    wo = spherical_to_direction(tv, 0.0)
    est = (f(wi, wo) @ LUMINANCE) * np.cos(tl) * alpha
    q = directional_albedo(f, tv) @ LUMINANCE
    assert abs(est.mean() - q) < 3 * est.std() / np.sqrt(n) + 1e-6


def test_broken_fits_trigger_fallback(lambert_fit):
    import copy

    _, fit = lambert_fit
    # non-monotone: add a large oscillation in mu to the theta numerator
    bad = copy.deepcopy(fit)
    th = bad.maps.theta
    e = np.array([[0, 5]])
    scale = 3.0 * np.abs(th.num_coef).max()
    th.num_exponents = np.vstack([th.num_exponents, e])
    th.num_coef = np.concatenate([th.num_coef, [scale]])
    verify(bad)
    assert bad.fallback and not bad.verification["theta"]["monotone_grid"]
    # a pole: denominator through zero
    bad2 = copy.deepcopy(fit)
    bad2.maps.phi.den_coef = bad2.maps.phi.den_coef.copy()
    bad2.maps.phi.den_coef[0] = -0.5
    verify(bad2)
    assert bad2.fallback and not bad2.verification["phi"]["q_certified"]
    # the renderer falls back explicitly (printed) to the tabulated sampler
    from warp_rbrdf import testing as T
    from warp_rbrdf import registry
    from warp_rbrdf.materials.build import build_material_data

    spec = T.lambert(albedo=(0.8, 0.6, 0.4), sampler="rational")
    spec.cdf = bad
    md = build_material_data(T.plane_scene(spec, [T.constant_env(1.0)]))
    assert md.strategies[0] == "tabulated" and md.cdf[0] is bad.table
    assert md.technique[0] == registry.technique("tabulated").code and not md.global_fits


def test_cdf_fit_time_limit_falls_back_explicitly():
    # no time to fit: the material falls back to the tabulated sampler and says why
    fit = fit_cdf(lambert((0.8, 0.6, 0.4)), name="lambert", table_params=dict(n_v=8, n_t=32, n_p=32),
                  refinements=0, time_limit_s=0.0, layout="global")
    assert fit.fallback and "time limit" in fit.reason
    assert fit.table is not None and fit.fit_info["time_limit_reached"]


def test_cdf_file_round_trip(lambert_fit, tmp_path):
    from fit.sampling.cdf_file import load

    _, fit = lambert_fit
    fit.save(tmp_path / "c.json")
    g = load(tmp_path / "c.json")
    assert g.fallback is False and g.verification["theta"]["ok"]
    x = np.random.default_rng(0).random((100, 3))
    np.testing.assert_allclose(g.sample(x[:, 0], x[:, 1], x[:, 2])[2], fit.sample(x[:, 0], x[:, 1], x[:, 2])[2])


def test_rows_layout_file_is_refused(lambert_fit, tmp_path):
    """Files of the removed per-view-row layout ("layout": "rows") are refused in one line."""
    import json

    from fit.errors import BRDFFileError
    from fit.sampling.cdf_file import load

    _, fit = lambert_fit
    p = tmp_path / "rows.json"
    fit.save(p)
    d = json.loads(p.read_text())
    d.update(layout="rows", rows=[None] * fit.table.n_v)
    p.write_text(json.dumps(d))
    with pytest.raises(BRDFFileError) as e:
        load(p)
    assert str(e.value) == f"{p}: layout 'rows' is no longer supported; re-run rbrdf-fit cdf"


# ---- Warp ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def warp_lambert(lambert_fit):
    from warp_rbrdf import testing as T
    from warp_rbrdf.renderer import Renderer

    _, fit = lambert_fit
    spec = T.lambert(albedo=(0.8, 0.6, 0.4), sampler="mis-rational")
    spec.cdf = fit
    r = Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=8, spp=64))
    r.compile()
    return r, fit


def test_warp_samplers_equal_numpy(warp_lambert):
    r, fit = warp_lambert
    rng = np.random.default_rng(2)
    n = 4000
    tv = rng.random(n) * np.radians(88)
    pv = rng.random(n) * 2 * np.pi
    wo = spherical_to_direction(tv, pv)
    xi = rng.random((n, 2)) * 0.998 + 0.001
    for sampler in ("rational", "rational-derivative"):
        wi, w = r.sample_material("m", wo, xi, sampler)
        tl, pl, alpha = fit.sample(tv, xi[:, 0], xi[:, 1])
        ref = spherical_to_direction(tl, pv + pl)
        np.testing.assert_allclose(wi, ref, atol=2e-4)
        np.testing.assert_allclose(w, alpha, rtol=2e-3, atol=1e-5)
    wi, w = r.sample_material("m", wo, xi, "tabulated")
    tl, pl, pdf = fit.table.sample(tv, xi[:, 0], xi[:, 1])
    np.testing.assert_allclose(wi, spherical_to_direction(tl, pv + pl), atol=2e-4)
    np.testing.assert_allclose(w, 1 / pdf, rtol=2e-3)


def test_warp_renders_agree(lambert_fit):
    """A Lambert plane under a constant sky: every pixel is the albedo, with every sampler."""
    from warp_rbrdf import testing as T
    from warp_rbrdf.renderer import Renderer

    _, fit = lambert_fit
    for sampler in ("tabulated", "rational", "rational-derivative", "mis-tabulated", "mis-rational"):
        spec = T.lambert(albedo=(0.8, 0.6, 0.4), sampler=sampler)
        spec.cdf = fit
        img = Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=6, spp=64)).render()
        img = np.asarray(img)
        np.testing.assert_allclose(img.reshape(-1, 3).mean(0), [0.8, 0.6, 0.4], rtol=0.02, err_msg=sampler)


def test_warp_measured_tabulated_matches_reference(rgl):
    """A glossy RGL material under an uneven sky: tabulated / mis-tabulated agree with a
    high-spp cosine-MIS reference within noise."""
    from warp_rbrdf import testing as T
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import MaterialSpec

    brdf, _ = rgl["satin_rosaline_rgb"]
    h, w = 32, 64
    v = (np.arange(h) + 0.5) / h
    sky = np.broadcast_to((0.2 + 2.0 * np.exp(-((v - 0.2) / 0.1) ** 2))[:, None, None], (h, w, 3)).astype(np.float32)
    imgs = {}
    for sampler, spp in (("mis", 1024), ("tabulated", 128), ("mis-tabulated", 128)):
        spec = MaterialSpec(name="m", type="measured", data=brdf, sampler=sampler)
        sc = T.plane_scene(spec, [T.image_env(sky)], resolution=4, spp=spp)
        sc.camera.origin = (0.0, 1.0, 1.0)
        imgs[sampler] = np.asarray(Renderer(sc).render()).reshape(-1, 3).mean(0)
    for s in ("tabulated", "mis-tabulated"):
        np.testing.assert_allclose(imgs[s], imgs["mis"], rtol=0.05, err_msg=s)


def test_monotone_refit_repairs_a_fold_and_stays_unbiased(lambert_fit):
    """A theta map with a fold is detected, then repaired by refitting its numerator under
    slope rows with Q fixed; the repaired map is verified and its derivative estimator agrees
    with quadrature and passes the chi-square test."""
    import copy

    from fit.formats.angles import HALF_PI
    from fit.sampling.global_layout import fit_theta, verify_axes, verify_theta
    from fit.sampling.monotone import monotone_refit

    f, fit = lambert_fit
    bad = copy.deepcopy(fit)
    th = bad.maps.theta
    th.num_exponents = np.vstack([th.num_exponents, [[0, 5]]])
    th.num_coef = np.concatenate([th.num_coef, [3.0 * np.abs(th.num_coef).max()]])
    assert not verify_theta(th)["monotone_grid"]
    _, _, (X, lo, hi) = fit_theta(fit.table)
    g, info = monotone_refit(th, 1, X, lo, hi, verify_axes("theta"), HALF_PI)
    assert g is not None and info["min_slope"] > 0
    assert np.array_equal(g.den_coef, th.den_coef)             # Q (and its certificate) kept
    bad.maps.theta = g
    verify(bad)
    assert not bad.fallback, bad.reason
    rng = np.random.default_rng(11)
    n = 40_000
    for tv in THETA_V:
        tl, pl, alpha = bad.sample(tv, rng.random(n), rng.random(n))
        probs, te, pe = _rational_cell_probs(bad, tv)
        counts, _, _ = np.histogram2d(tl, pl, bins=[te, pe])
        assert _chi2_pvalue(counts, probs, n) > 1e-4
        est = (f(spherical_to_direction(tl, pl), spherical_to_direction(tv, 0.0)) @ LUMINANCE) * np.cos(tl) * alpha
        q = directional_albedo(f, tv) @ LUMINANCE
        assert abs(est.mean() - q) < 3 * est.std() / np.sqrt(n) + 1e-6


# ---- Warp samples of a measured material (used by test_cdf_pieces) ---------------------------
def warp_rational_samples(brdf, fit, n: int = 4000):
    """Renderer (plane, measured ``brdf`` with rational inverse CDFs ``fit``) and 4000 Warp
    samples of its rational-derivative strategy: ``(renderer, theta_v, phi_v, xi, wi, alpha)``
    for view angles below 89 deg and xi away from 0 and 1."""
    from warp_rbrdf import testing as T
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import MaterialSpec

    spec = MaterialSpec(name="m", type="measured", data=brdf, sampler="rational-derivative")
    spec.cdf = fit
    r = Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=2, spp=1))
    r.compile()
    rng = np.random.default_rng(4)
    tv = rng.random(n) * np.radians(89)
    pv = rng.random(n) * 2 * np.pi
    xi = rng.random((n, 2)) * 0.998 + 0.001
    wi, w = r.sample_material("m", spherical_to_direction(tv, pv), xi, "rational-derivative")
    return r, tv, pv, xi, wi, w
