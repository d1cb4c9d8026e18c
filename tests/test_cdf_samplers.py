"""Inverse-CDF samplers: the tabulated sampler on every shared RGL material (two in the default
run, the others ``extended``), the paper's global layout (verification, fallback, file round
trip, monotone refit), renders with every sampler. The Warp samplers' own contract
(chi-square, unbiasedness, Warp == NumPy, pdf) is tests/test_sampler_contract.py."""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
from chi2 import (
    assert_unbiased,
    chi2_pvalue,
    edges,
    histogram,
    map_cell_probs,
    table_cell_probs,
)
from conftest import rgl_measured, rgl_params, session_cached

from lab.analytic import lambert
from fit.formats.angles import spherical_to_direction
from fit.sampling.cdf_file import fit_cdf, verify
from fit.sampling.table import tabulate

THETA_V = [0.0, np.radians(45), np.radians(85)]


@pytest.fixture(scope="module")
def rgl():
    """``rgl(name)``: the shared RGL material on the MERL grid and its table (made on first use)."""
    tables = {}

    def get(name):
        b = rgl_measured(name)
        if name not in tables:
            tables[name] = tabulate(b.evaluate)
        return b, tables[name]
    return get


@functools.lru_cache(maxsize=2)
def lambert_global_fit(n_v: int = 8):
    """The global-layout inverse CDFs of a Lambert material on a table of ``n_v`` view rows,
    made once per test session for every worker (:func:`conftest.session_cached`;
    tests/test_sampler_contract.py and tests/test_compile_once.py take them too): callers must
    not modify them."""
    def make():
        return fit_cdf(lambert((0.8, 0.6, 0.4)), name="lambert", table_params=dict(n_v=n_v, n_t=32, n_p=32),
                       phi_kw=dict(degrees=(2, 1)), refinements=0, layout="global")

    return session_cached(Path(__file__), f"lambert-global-{n_v}", make)


@pytest.fixture(scope="module")
def lambert_fit():
    fit = lambert_global_fit(8)
    assert fit.layout == "global" and not fit.fallback, fit.reason
    return lambert((0.8, 0.6, 0.4)), fit


@pytest.mark.parametrize("name", rgl_params())
def test_tabulated_chi2_and_unbiased_rgl(rgl, name):
    brdf, table = rgl(name)
    rng = np.random.default_rng(3)
    n = 60_000
    te, pe = edges(7, 9)
    for tv in THETA_V:
        tl, pl, pdf = table.sample(tv, rng.random(n), rng.random(n))
        assert chi2_pvalue(histogram(tl, pl, te, pe), table_cell_probs(table, tv, te, pe), n) > 1e-4, (name, tv)
        # + 0.5 %: the clear coats' near-normal mirror peak (heavy-tailed weights, midpoint rule)
        assert_unbiased(brdf.evaluate, tv, spherical_to_direction(tl, pl), spherical_to_direction(tv, 0.0),
                        1.0 / pdf, name, rel=0.005)


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
    from warp_rbrdf import registry
    from lab import testing as T
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
def hidden(lambert_fit, rgl):
    """Materials that no path reaches, added to every render of this module (:func:`_renderer`)
    so that the renders share one render kernel (a kernel per set of material kinds and
    techniques, compiled on first use): a Lambert material sampled with the rational maps and
    with the table of ``lambert_fit``, and the satin measured material with cosine MIS."""
    from lab import testing as T
    from warp_rbrdf.scene import MaterialSpec

    _, fit = lambert_fit
    specs = []
    for sampler in ("rational", "tabulated"):
        spec = T.lambert(name=f"hidden-{sampler}", albedo=(0.8, 0.6, 0.4), sampler=sampler)
        spec.cdf = fit
        specs.append(spec)
    specs.append(MaterialSpec(name="hidden-measured", type="measured", data=rgl("satin_rosaline_rgb")[0],
                              sampler="mis"))
    return specs


def _renderer(scene, hidden):
    """A renderer of ``scene`` (a plane at y = 0 lit from above) with the ``hidden`` materials on
    small planes 10 units below it, where no path from the camera reaches."""
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import ShapeSpec

    for k, spec in enumerate(hidden):
        scene.materials[spec.name] = spec
        scene.shapes.append(ShapeSpec(type="plane", material=spec.name, center=(3.0 * k, -10.0, 0.0), size=(1.0, 1.0)))
    r = Renderer(scene)
    assert [r.material_data.strategies[r.material_index(s.name)] for s in hidden] == [s.sampler for s in hidden]
    return r


def test_warp_renders_agree(lambert_fit, hidden):
    """A Lambert plane under a constant sky: every pixel is the albedo, with every sampler."""
    from lab import testing as T
    from warp_rbrdf import registry

    _, fit = lambert_fit
    # every registered strategy that samples the material's inverse-CDF data
    for sampler in registry.TABLE_STRATEGIES:
        spec = T.lambert(albedo=(0.8, 0.6, 0.4), sampler=sampler)
        spec.cdf = fit
        r = _renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=6, spp=64), hidden)
        assert r.material_data.strategies[r.material_index("m")] == sampler
        img = r.render()
        img = np.asarray(img)
        np.testing.assert_allclose(img.reshape(-1, 3).mean(0), [0.8, 0.6, 0.4], rtol=0.02, err_msg=sampler)


def test_warp_measured_tabulated_matches_reference(rgl, hidden):
    """A glossy RGL material under an uneven sky: tabulated / mis-tabulated agree with a
    high-spp cosine-MIS reference within noise."""
    from lab import testing as T
    from warp_rbrdf.scene import MaterialSpec

    brdf, _ = rgl("satin_rosaline_rgb")
    h, w = 32, 64
    v = (np.arange(h) + 0.5) / h
    sky = np.broadcast_to((0.2 + 2.0 * np.exp(-((v - 0.2) / 0.1) ** 2))[:, None, None], (h, w, 3)).astype(np.float32)
    imgs = {}
    for sampler, spp in (("mis", 1024), ("tabulated", 128), ("mis-tabulated", 128)):
        spec = MaterialSpec(name="m", type="measured", data=brdf, sampler=sampler)
        sc = T.plane_scene(spec, [T.image_env(sky)], resolution=4, spp=spp)
        sc.camera.origin = (0.0, 1.0, 1.0)
        imgs[sampler] = np.asarray(_renderer(sc, hidden).render()).reshape(-1, 3).mean(0)
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
    te, pe = edges(7, 9)
    for tv in THETA_V:
        tl, pl, alpha = bad.sample(tv, rng.random(n), rng.random(n))
        assert chi2_pvalue(histogram(tl, pl, te, pe), map_cell_probs(bad, tv, te, pe), n) > 1e-4
        assert_unbiased(f, tv, spherical_to_direction(tl, pl), spherical_to_direction(tv, 0.0), alpha, tv)
