"""Pieces layout of the rational inverse CDFs (fit.sampling.pieces, issue 6): the construction's
guarantees, tampered pieces detected, chi-square and unbiasedness on every shared RGL material,
the variance gate, file round trip, Warp == NumPy, and a render that agrees with the table's."""
from __future__ import annotations

import copy

import numpy as np
import pytest
from chi2 import assert_unbiased, chi2_pvalue, edges, histogram, map_cell_probs
from conftest import RGL_MATERIALS, rgl_measured

from lab.analytic import lambert
from fit.formats.angles import spherical_to_direction
from fit.formats.colour import LUMINANCE
from fit.sampling.cdf_file import fit_cdf, load, verify
from fit.sampling.pieces import (
    _piece,
    build_pieces,
    rq_eval,
    sample_pieces,
    verify_pieces,
)
from fit.sampling.table import tabulate

THETA_V = [0.0, np.radians(45), np.radians(85)]


@pytest.fixture(scope="module")
def paint():
    """colodur_napoli_4f, 8 view rows: every row rational with 16 phi pieces (each with the flat
    end piece: its f cos(theta_l) stays finite at grazing light). satin_rosaline, the fixture
    before the weighted tables, now keeps 6 of 8 rows (two over the gate either way)."""
    b = rgl_measured("colodur_napoli_4f_rgb")
    fit = fit_cdf(b.evaluate, name="paint", table_params=dict(n_v=8), layout="pieces")
    assert fit.layout == "pieces" and not fit.fallback, fit.reason
    return b, fit


def test_pieces_interpolate_the_table_and_are_monotone():
    """Knots are the table's inverse CDF at k / n (exact ends), pieces meet, derivatives are
    the derivatives of the values (finite differences) and never negative; the Lambertian's
    end pieces in y = sin^2 theta follow theta_l = asin(sqrt(mu)) (infinite slope at 0)."""
    table = tabulate(lambert((0.8, 0.6, 0.4)), n_v=4, n_t=32, n_p=32)
    pm = build_pieces(table, n_mu=16, n_u=8)
    assert verify_pieces(pm)["ok"]
    edges = np.linspace(0, np.pi / 2, table.n_t + 1)
    for v in range(table.n_v):
        mu = np.linspace(0, 1, 17)
        t, _ = pm.row_theta_map(np.full(mu.shape, v), mu)
        np.testing.assert_allclose(t, np.interp(mu, table.cdf_theta[v], edges), atol=1e-12)
        mu = np.linspace(1e-4, 1 - 1e-4, 4001)
        t, d = pm.row_theta_map(np.full(mu.shape, v), mu)
        assert np.all(np.diff(t) >= 0) and np.all(d > 0)
        fd = np.gradient(t, mu)
        inner = (mu > 1.5 / 16) & (mu < 14.5 / 16) & (np.abs(mu * 16 - np.round(mu * 16)) > 0.01)
        np.testing.assert_allclose(d[inner], fd[inner], rtol=2e-3)
        # Lambert + 2 % cosine mixture = cosine: CDF(theta) = sin^2(theta), up to the table's
        # piecewise-constant density (0.23 % here); a theta-space piece misses sqrt(mu) by far more
        end = mu < 1 / 16
        np.testing.assert_allclose(t[end], np.arcsin(np.sqrt(mu[end])), rtol=3e-3)
    k, x = _piece(np.array([0.0, 0.5, 1.0]), 8)
    assert k.tolist() == [0, 4, 7] and x.tolist() == [0.0, 0.0, 1.0]
    v, dv = rq_eval(pm.phi[0, 3, 2], np.array([0.0, 1.0]))
    assert v[0] == pm.phi[0, 3, 2, 0] and v[1] == pytest.approx(pm.phi[0, 3, 2, 0] + pm.phi[0, 3, 2, 1])


def test_tampered_pieces_are_detected_and_their_rows_go_to_the_table(paint):
    """A folded piece (negative slope), a gap between pieces (not covering) and a pole
    (denominator through zero) each fail verification; verify() sends that row to the table
    and the sampler then uses the table's density there (alpha = 1 / pdf)."""
    _, fit = paint
    cases = {}
    bad = copy.deepcopy(fit)
    bad.maps.theta[2, 10, 2] = -3.0          # a0 < 0: decreasing near the piece's start
    cases["fold"] = (bad, 2)
    bad = copy.deepcopy(fit)
    bad.maps.phi[5, 7, 3, 0] += 0.05          # jumps past the previous piece's end: a gap
    cases["gap"] = (bad, 5)
    bad = copy.deepcopy(fit)
    bad.maps.phi[1, 0, 0, 2:] = -4.0          # 1 + (a0 + a1 - 2) x(1 - x) = 0 at x = 1/2
    cases["pole"] = (bad, 1)
    for what, (b, row) in cases.items():
        assert not verify_pieces(b.maps)["rows"][row], what
        verify(b)
        assert not b.maps.row_ok[row] and b.maps.row_ok.sum() == fit.table.n_v - 1, what
        tv = np.full(64, b.table.theta_v[row])
        rng = np.random.default_rng(0)
        mu, tau = rng.random(64), rng.random(64)
        tl, pl, a = b.sample(tv, mu, tau)
        t2, p2, pdf = b.table.sample(tv, mu, tau)
        np.testing.assert_array_equal(tl, t2)
        np.testing.assert_allclose(a, 1.0 / pdf)


@pytest.mark.parametrize("name", [m if m == "cc_ibiza_sunset_rgb" else pytest.param(m, marks=pytest.mark.extended)
                                  for m in RGL_MATERIALS])
def test_pieces_sampler_chi2_and_unbiased_on_rgl(name):
    """Every shared material (in the default run the clear coat cc_ibiza_sunset, whose narrow
    peak and heavy-tailed weights are the hard case; the others ``extended``): chi-square of
    the pieces sampler against its own density (cell probabilities from the inverse of its
    monotone map) and the derivative estimator of the luminance albedo against quadrature
    (3 sigma), theta_v 0/45/85 deg; gate off so every row's maps are tested."""
    brdf = rgl_measured(name)
    fit = fit_cdf(brdf.evaluate, name=name, table_params=dict(n_v=16), layout="pieces",
                  pieces_kw=dict(max_variance_ratio=None))
    assert not fit.fallback and fit.maps.row_ok.all(), fit.reason
    rng = np.random.default_rng(5)
    n = 60_000
    te, pe = edges(7, 9)
    for tv in THETA_V:
        tl, pl, alpha = fit.sample(tv, rng.random(n), rng.random(n))
        probs = map_cell_probs(fit, tv, te, pe)
        assert probs.sum() == pytest.approx(1.0, abs=1e-6)
        assert chi2_pvalue(histogram(tl, pl, te, pe), probs, n) > 1e-4, (name, tv)
        # + 0.5 %: the clear coats' near-normal mirror peak (heavy-tailed weights, midpoint rule)
        assert_unbiased(brdf.evaluate, tv, spherical_to_direction(tl, pl), spherical_to_direction(tv, 0.0),
                        alpha, name, rel=0.005)


def _direct_ratio(b, fit, v, n):
    """Variance ratio pieces / table at row v on n pairs of seed 0, measured here."""
    rng = np.random.default_rng(0)
    mu, tau = rng.random(n), rng.random(n)
    tv = np.full(n, fit.table.theta_v[v])
    wo = spherical_to_direction(tv[0], 0.0)
    ungated = copy.deepcopy(fit.maps)
    ungated.row_ok[:] = True
    tl, pl, a = sample_pieces(fit.table, ungated, tv, mu, tau)
    e_r = (b.evaluate(spherical_to_direction(tl, pl), wo) @ LUMINANCE) * np.cos(tl) * a
    tl, pl, pdf = fit.table.sample(tv, mu, tau)
    e_t = (b.evaluate(spherical_to_direction(tl, pl), wo) @ LUMINANCE) * np.cos(tl) / pdf
    return np.var(e_r) / np.var(e_t)


@pytest.mark.heavy
def test_pieces_variance_gate(paint):
    """The gate's per-row ratio is the ratio of the two samplers' variances on the same
    (mu, tau); rows measured from limit / 1.25 to twice the limit are measured again on 8x the
    pairs and that decides (default limit and a limit at the median); rows above go to the
    table, with the reason."""
    b, fit = paint
    infos = fit.fit_info["rows"]
    ratios = np.array([i["variance"]["ratio"] for i in infos])
    n = fit.fit_info["gate_samples"]
    first = np.array([i.get("variance_first", i["variance"])["ratio"] for i in infos])
    assert [i for i, r in enumerate(first) if 1.2 / 1.25 < r <= 2.4] == \
        [i for i, g in enumerate(infos) if "variance_first" in g]       # re-measured near 1.2
    v = int(np.argmin(first))
    assert "variance_first" not in infos[v] and ratios[v] == pytest.approx(_direct_ratio(b, fit, v, n), rel=1e-9)
    lim = float(np.median(ratios))
    gated = fit_cdf(b.evaluate, name="paint", table=fit.table, layout="pieces",         # the same maps
                    pieces_kw=dict(max_variance_ratio=lim, n_u=fit.maps.n_u, flat_end=fit.maps.flat_end))
    ginfo = gated.fit_info["rows"]
    again = [i for i, r in enumerate(first) if lim / 1.25 < r <= 2 * lim]
    assert again and [i for i, g in enumerate(ginfo) if "variance_first" in g] == again
    w = again[0]
    assert ginfo[w]["variance"]["n"] == 8 * n
    assert ginfo[w]["variance"]["ratio"] == pytest.approx(_direct_ratio(b, fit, w, 8 * n), rel=1e-9)
    final = np.array([g["variance"]["ratio"] for g in ginfo])
    ok = gated.maps.row_ok
    assert ok.tolist() == (final <= lim).tolist() and 0 < ok.sum() < len(ok)
    assert all(i["reason"] == f"variance > {lim:g} x the table's" for i, o in zip(ginfo, ok) if not o)
    assert "sampled with the table" in gated.reason


def test_flat_end_pieces_are_tried_on_rows_over_the_gate(paint):
    """A row over the gate with PCHIP's end slope is built again with slope 0 at mu = 1 in
    y = sin^2(theta_l); it keeps that end only if it then passes (recorded per row and in the
    file); its pieces differ from PCHIP's in the last theta piece only and still verify; the
    flat end reaches theta_l = pi/2 with dy/dmu = 0."""
    from fit.sampling.pieces import build_pieces
    from fit.sampling.variance_gate import _fit_pieces_once

    b, fit = paint
    pm, info = fit.maps, fit.fit_info
    lim = info["max_variance_ratio"]
    assert pm.flat_end.any() and info["flat_end_rows"] == int(pm.flat_end.sum())
    for v, r in enumerate(info["rows"]):
        if pm.flat_end[v]:
            assert r["ok"] and r["variance_pchip_end"]["ratio"] > lim >= r["variance"]["ratio"]
        else:
            assert "variance_pchip_end" not in r
    plain = build_pieces(fit.table, pm.n_mu, pm.n_u)
    f = pm.flat_end
    np.testing.assert_array_equal(pm.theta[:, :-1], plain.theta[:, :-1])
    np.testing.assert_array_equal(pm.theta[:, -1, :3], plain.theta[:, -1, :3])
    np.testing.assert_array_equal(pm.theta[~f, -1], plain.theta[~f, -1])
    assert np.all(plain.theta[f, -1, 3] > 0) and pm.theta[f, -1, 3].tolist() == [0.0] * int(f.sum())  # a1 = 0
    assert verify_pieces(pm)["ok"]
    t, _ = pm.row_theta_map(np.flatnonzero(f), np.ones(int(f.sum())))
    np.testing.assert_allclose(t, np.pi / 2)
    # no retry without a gate, and a gate nothing passes keeps every row on the table
    pm0, info0 = _fit_pieces_once(fit.table, b.evaluate, 64, pm.n_u, None, 4096)
    assert not pm0.flat_end.any()
    pm1, info1 = _fit_pieces_once(fit.table, b.evaluate, 64, pm.n_u, 1e-6, 4096)
    assert not pm1.row_ok.any() and not pm1.flat_end.any()
    assert all("variance_pchip_end" in r for r in info1["rows"])


@pytest.mark.parametrize("gate_samples,gate_recheck", [
    (4096, None),                                            # the rule, on a small gate
    pytest.param(32768, 8, marks=pytest.mark.slow),          # the default gate (20 s)
])
def test_pieces_phi_count_is_the_fewest_that_keeps_rows_within_the_gate(paint, gate_samples, gate_recheck):
    """n_u candidates: the first count whose rows all pass the gate ends the search; else the
    count with the most rational rows, the smallest on ties (checked against each count built
    alone with the same gate). The paint passes the default gate with the fewest pieces."""
    from fit.sampling.variance_gate import _fit_pieces_once, fit_pieces

    b, fit = paint
    assert fit.maps.n_u == 16 and fit.fit_info["n_u_tried"] == {16: fit.table.n_v}
    ratios = np.array([i["variance"]["ratio"] for i in fit.fit_info["rows"]])
    lim = float(np.sort(ratios)[-3])          # strict enough that 16 pieces leave rows behind
    alone = {nu: _fit_pieces_once(fit.table, b.evaluate, 64, nu, lim, gate_samples, gate_recheck)[1]["verified_rows"]
             for nu in (16, 32, 64)}
    pm, info = fit_pieces(fit.table, b.evaluate, n_u=(64, 16, 32), max_variance_ratio=lim,
                          gate_samples=gate_samples, gate_recheck=gate_recheck)
    assert alone[16] < fit.table.n_v
    expect, tried = None, {}
    for nu in (16, 32, 64):
        tried[nu] = alone[nu]
        if expect is None or alone[nu] > alone[expect]:
            expect = nu
        if alone[nu] == fit.table.n_v:
            break
    assert info["n_u_tried"] == tried and pm.n_u == expect == info["n_u"]
    assert int(pm.row_ok.sum()) == alone[expect]


def test_warp_phi_knots_share_values_and_slopes(paint):
    """The Warp array stores the phi maps as knots (value, slope): they reproduce every piece's
    ends; a verified row whose pieces do not share a knot cannot be packed (ValueError), a
    table row can."""
    from fit.sampling.pieces import pieces_phi_knots

    _, fit = paint
    pm = fit.maps
    kn = pieces_phi_knots(pm)
    assert kn.shape == pm.phi.shape[:-2] + (pm.n_u + 1, 2)
    np.testing.assert_allclose(kn[..., :-1, 0], pm.phi[..., 0])
    np.testing.assert_allclose(kn[..., 1:, 0], pm.phi[..., 0] + pm.phi[..., 1], atol=1e-12)
    np.testing.assert_allclose(kn[..., :-1, 1], pm.phi[..., 2] * pm.phi[..., 1])
    np.testing.assert_allclose(kn[..., 1:, 1], pm.phi[..., 3] * pm.phi[..., 1], rtol=1e-9, atol=1e-15)
    bad = copy.deepcopy(pm)
    bad.phi[3, 5, 2, 3] *= 1.5                # slope at the end of a piece != next piece's start
    with pytest.raises(ValueError, match=r"rows \[3\]"):
        pieces_phi_knots(bad)
    bad.row_ok[3] = False
    pieces_phi_knots(bad)


def test_pieces_file_round_trip(paint, tmp_path):
    """The file stores the table, n_mu, n_u and the row flags; loading rebuilds identical
    pieces and the same samples; a row flag list of the wrong length is an error."""
    _, fit = paint
    fit = copy.deepcopy(fit)
    fit.maps.row_ok[3] = False
    p = tmp_path / "paint_cdf.json"
    fit.save(p)
    g = load(p)
    assert g.layout == "pieces" and g.maps.row_ok.tolist() == fit.maps.row_ok.tolist()
    assert fit.maps.flat_end.any() and g.maps.flat_end.tolist() == fit.maps.flat_end.tolist()
    np.testing.assert_array_equal(g.maps.theta, fit.maps.theta)
    np.testing.assert_array_equal(g.maps.phi, fit.maps.phi)
    rng = np.random.default_rng(1)
    tv, mu, tau = rng.random(500) * 1.5, rng.random(500), rng.random(500)
    for a, b in zip(fit.sample(tv, mu, tau), g.sample(tv, mu, tau)):
        np.testing.assert_array_equal(a, b)
    import json

    d = json.loads(p.read_text())
    d["pieces"]["row_ok"] = d["pieces"]["row_ok"][:-1]
    p.write_text(json.dumps(d))
    from fit.errors import BRDFFileError

    with pytest.raises(BRDFFileError, match="row flags"):
        load(p)


def warp_rational_samples(brdf, fit, n: int = 4000):
    """Renderer (plane, measured ``brdf`` with rational inverse CDFs ``fit``) and ``n`` Warp
    samples of its rational-derivative strategy: ``(renderer, theta_v, phi_v, xi, wi, alpha)``
    for view angles below 89 deg and xi away from 0 and 1."""
    from lab import testing as T
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import MaterialSpec

    spec = MaterialSpec(name="m", type="measured", data=brdf, sampler="rational-derivative")
    spec.cdf = fit
    r = Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=2, spp=1))
    rng = np.random.default_rng(4)
    tv = rng.random(n) * np.radians(89)
    pv = rng.random(n) * 2 * np.pi
    xi = rng.random((n, 2)) * 0.998 + 0.001
    wi, w = r.sample_material("m", spherical_to_direction(tv, pv), xi, "rational-derivative")
    return r, tv, pv, xi, wi, w


def test_pieces_warp_equals_numpy_and_renders_agree(paint):
    """The Warp sampler (constant-time pieces, table rows through the table) gives NumPy's
    directions and alphas; the standard estimator's weight 1 / pdf equals alpha; a render of
    the paint plane under a constant sky with the pieces sampler agrees with the tabulated
    sampler's within 4 sigma per channel of the image mean. The two render scenes also hold
    Lambert materials no path reaches (cosine MIS, the rational maps and the table of
    test_cdf_samplers's Lambert fit): both use one render kernel, the one of
    test_cdf_samplers's renders (compiled once per session where the runs share the cache)."""
    from test_cdf_samplers import _renderer, lambert_global_fit

    from lab import testing as T
    from warp_rbrdf.scene import MaterialSpec

    b, fit = paint
    fit = copy.deepcopy(fit)
    fit.maps.row_ok[2] = False                # one table row: the Warp code must branch to it
    r, tv, pv, xi, wi, w = warp_rational_samples(b, fit)
    wo = spherical_to_direction(tv, pv)
    tl, pl, alpha = fit.sample(tv, xi[:, 0], xi[:, 1])
    assert (fit.table.row(tv) == 2).sum() > 100
    np.testing.assert_allclose(wi, spherical_to_direction(tl, pv + pl), atol=5e-4)
    np.testing.assert_allclose(w, alpha, rtol=3e-3, atol=1e-5)
    wi2, w2 = r.sample_material("m", wo, xi, "rational")
    np.testing.assert_allclose(wi2, wi, atol=1e-6)
    np.testing.assert_allclose(w2, w, rtol=1e-5, atol=1e-7)
    hidden = []
    for sampler in ("mis", "rational", "tabulated"):
        spec = T.lambert(name=f"hidden-{sampler}", albedo=(0.8, 0.6, 0.4), sampler=sampler)
        spec.cdf = None if sampler == "mis" else lambert_global_fit(8)
        hidden.append(spec)
    means = {}
    for s in ("rational-derivative", "tabulated"):
        spec = MaterialSpec(name="m", type="measured", data=b, sampler=s)
        spec.cdf = fit
        rr = _renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=8, spp=256), hidden)
        assert rr.material_data.strategies[rr.material_index("m")] == s
        img, var = rr.render(seed=3, return_variance=True)
        means[s] = (img.reshape(-1, 3).mean(0), np.sqrt(var.reshape(-1, 3).sum(0) / 256) / img[..., 0].size)
    (m1, s1), (m2, s2) = means.values()
    assert np.all(np.abs(m1 - m2) < 4 * np.hypot(s1, s2)), means


def test_pieces_inverse_maps_and_plot_cdf(paint, tmp_path):
    """inverse_theta / inverse_phi are the maps fit.sample uses on rational rows and NaN on
    table rows; plot-cdf draws the pieces layout (two PNGs)."""
    from fit.sampling.plots import plot_cdf

    _, fit = paint
    fit = copy.deepcopy(fit)
    fit.maps.row_ok[2] = False                # one table row
    n_v = fit.table.n_v
    rng = np.random.default_rng(2)
    mu, tau = rng.random(400), rng.random(400)
    for v in range(n_v):
        tv = (v + 0.5) * (np.pi / 2) / n_v
        th = fit.inverse_theta(tv, mu)
        ph = fit.inverse_phi(tv, th, np.abs(2 * tau - 1))
        if not fit.maps.row_ok[v]:
            assert np.isnan(th).all() and np.isnan(ph).all()
            continue
        tl, pl, _ = fit.sample(tv, mu, tau)
        np.testing.assert_allclose(th, tl, atol=1e-12)
        np.testing.assert_allclose(ph, np.abs(pl), atol=1e-12)
    files = plot_cdf(fit, tmp_path, prefix="paint")
    assert [f.name for f in files] == ["paint_theta.png", "paint_phi.png"]
    assert all(f.stat().st_size > 10_000 for f in files)
