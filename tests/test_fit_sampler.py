"""A fit's own inverse CDFs stored in its coefficient file (fit.sampling.embedded,
fit.sampling.model_sampler): made from the fit (2-D and 3-D), deterministic, read back
bit for bit, used by the renderer with no tabulation and no source measurement, χ² and
unbiasedness of the 3-D fit's sampler through the registry, and hostile records (one line,
exit 2)."""
from __future__ import annotations

import copy
import functools
import json
from pathlib import Path

import numpy as np
import pytest
from chi2 import assert_unbiased, chi2_pvalue, edges, histogram, map_cell_probs
from conftest import session_cached

from fit.formats.angles import direction_to_spherical, spherical_to_direction
from fit.rational.coefficient_file import load, save
from fit.sampling import binary_arrays, embedded
from fit.sampling.model_sampler import embed_sampler, fit_model_sampler, vouched_evaluate
from fit.sampling.table import tabulate

T_EDGES, P_EDGES = edges(8, 16)


def lobe3d(X):
    """A synthetic RGB BRDF (1/sr) of (theta_h, theta_d, |phi_d|) rows that depends on phi_d and
    is not reciprocal."""
    th, td, pd = X[:, 0], X[:, 1], X[:, 2]
    spec = 2.5 * np.exp(-(th / 0.3) ** 2) * (1.0 + 0.3 * np.cos(pd)) * (1.0 + 0.4 * np.sin(td) ** 2)
    base = np.array([0.1, 0.14, 0.22]) * (1.0 + 0.3 * (np.cos(pd) * np.sin(td))[:, None])
    return base + spec[:, None] * [1.0, 0.85, 0.7]


@functools.lru_cache(maxsize=1)
def _fit3d_with_sampler():
    """``(model, cdf)``: the 3-D fit of :func:`lobe3d` and its sampler, made once per test session
    for every worker (:func:`conftest.session_cached`; tests/test_sampler_contract.py samples
    it too): callers must not modify them."""
    return session_cached(Path(__file__), "fit3d-with-sampler", _make_fit3d_with_sampler)


def _make_fit3d_with_sampler():
    from fit.rational.fit3d import fit_samples, sample_grid

    tm = np.radians(80.0)
    X = sample_grid(tm, grid=(10, 9, 7), n_random=300, seed=3)
    res = fit_samples(X, lobe3d(X), name="lobe3d", theta_max=tm, degrees=(4, 2), theta_h_edges=[0.2],
                      tol=0.01, time_limit=60.0, grazing_cos=0.0, channel_floor=0.0)
    assert res.valid
    # every row rational, whatever the machine's load: no variance gate (a time limit would
    # leave the rows it has not reached to the table), 16 phi pieces
    cdf = embed_sampler(res.model, time_limit_s=None, pieces_kw=dict(max_variance_ratio=None, n_u=(16,)))
    return res.model, cdf


@pytest.fixture(scope="module")
def fit3d(tmp_path_factory):
    """``(path, model, cdf)``: a 3-D fit with its sampler, saved in a folder of its own."""
    model, cdf = _fit3d_with_sampler()
    path = tmp_path_factory.mktemp("fit3d") / "lobe3d.json"
    save(model, path)
    return path, copy.deepcopy(model), cdf


def test_3d_sampler_round_trip_bit_for_bit(fit3d):
    """The file's record reads back to the same table, bit for bit, and the same pieces; its
    table is the one the renderer tabulates from the same fit (deterministic)."""
    path, model, cdf = fit3d
    assert not cdf.fallback and cdf.layout == "pieces" and cdf.maps.row_ok.all(), cdf.reason
    back = embedded.read(load(path), path)
    np.testing.assert_array_equal(back.table.cdf_theta, cdf.table.cdf_theta)
    np.testing.assert_array_equal(back.table.cdf_phi, cdf.table.cdf_phi)
    np.testing.assert_array_equal(back.maps.row_ok, cdf.maps.row_ok)
    only = embedded.read(load(path), path, maps=False)
    np.testing.assert_array_equal(only.cdf_phi, cdf.table.cdf_phi)
    again = tabulate(vouched_evaluate(load(path)))
    np.testing.assert_array_equal(again.cdf_phi, cdf.table.cdf_phi)


def test_stored_pieces_read_without_rebuild_or_scipy(fit3d, tmp_path):
    """The record stores its pieces' knots and slopes: a load makes the pieces from them (the
    same floats as a rebuild from the table, bit for bit), with no rebuild, no sampled
    verification and no SciPy import; a record without them (as written before they were
    stored) still loads, rebuilt from the table, to the same pieces."""
    import subprocess
    import sys

    from fit.sampling import cdf_reader, pieces

    path, model, cdf = fit3d
    rec = load(path).sampler
    assert set(rec["pieces"]["knots"]) == set(cdf_reader.KNOT_KEYS)
    stored = embedded.read(load(path), path).maps
    rebuilt = pieces.build_pieces(cdf.table, cdf.maps.n_mu, cdf.maps.n_u, cdf.maps.row_ok, cdf.maps.flat_end)
    for a in ("theta", "phi", "theta_knots", "row_ok", "flat_end"):
        np.testing.assert_array_equal(getattr(stored, a), getattr(rebuilt, a), err_msg=a)
    np.testing.assert_array_equal(pieces.pieces_phi_knots(stored), pieces.pieces_phi_knots(cdf.maps))
    d = json.loads(path.read_text())
    del d["sampler"]["pieces"]["knots"]
    d["sampler"]["sha256"] = embedded.record_sha256(d["sampler"])
    old = tmp_path / "old.json"
    old.write_text(json.dumps(d))
    again = embedded.read(load(old), old).maps
    for a in ("theta", "phi", "theta_knots"):
        np.testing.assert_array_equal(getattr(again, a), getattr(stored, a), err_msg=a)
    code = ("import sys; from fit.rational.coefficient_file import load; from fit.sampling import embedded, pieces\n"
            "pieces.build_pieces = pieces._pchip_slopes = pieces.rq_eval = None\n"
            f"c = embedded.read(load({str(path)!r}))\n"
            "assert c.maps.row_ok.any() and not c.fallback\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy' or m == 'fit.rational.fitter'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", out.stdout


@pytest.fixture(scope="module")
def quadrature(fit3d):
    """``quadrature(theta_v)``: :func:`chi2.quadrature_albedo` of the 3-D fit (its vouched
    evaluation) at view ``theta_v``, cached (both strategies are checked against it)."""
    from chi2 import quadrature_albedo

    evaluate, cache = vouched_evaluate(fit3d[1]), {}

    def get(theta_v):
        if theta_v not in cache:
            cache[theta_v] = quadrature_albedo(evaluate, theta_v)
        return cache[theta_v]
    return get


def _case(path, sampler):
    from lab import testing as T
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import MaterialSpec

    spec = MaterialSpec(name="m", sampler=sampler, type="rational", file=path)
    return Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=4, spp=1))


@pytest.mark.parametrize("strategy", ["mis-rational", "rational-derivative"])
def test_3d_fit_samples_with_its_own_sampler(fit3d, quadrature, strategy, monkeypatch, tmp_path):
    """Through the registry, with the source measurement nowhere (RBRDF_DATA elsewhere): the
    fit's own sampler is used (no fallback, no build), its draws follow the map's own density
    (χ²) and f cos * weight is unbiased against quadrature at three views."""
    from warp_rbrdf.techniques import cdf_data

    path, model, cdf = fit3d
    monkeypatch.setenv("RBRDF_DATA", str(tmp_path))
    monkeypatch.setattr(cdf_data, "cached_tabulate", lambda *a, **k: pytest.fail("tabulated at load"))
    r = _case(path, strategy)
    assert r.material_data.strategies == [strategy]
    evaluate = vouched_evaluate(model)
    for tv_deg in (5.0, 45.0, 80.0):
        tv = np.radians(tv_deg)
        # the whole square: an edge cut off (xi in [0.001, 0.999]) drops the strip at the light's
        # horizon, where f cos of a fit of rho cos theta_i is finite (0.15 % low at 5 deg)
        xi = np.clip(np.random.default_rng(11).random((20_000, 2)), 1e-9, 1.0 - 1e-9)
        wo = np.broadcast_to(spherical_to_direction(tv, 0.0), (len(xi), 3))
        wi, w = r.sample_material("m", wo, xi, strategy)
        wi, w = wi.astype(float), w.astype(float)
        counts = histogram(*direction_to_spherical(wi[w > 0]), T_EDGES, P_EDGES)
        assert chi2_pvalue(counts, map_cell_probs(cdf, tv, T_EDGES, P_EDGES), len(xi)) > 1e-4, tv_deg
        assert_unbiased(evaluate, tv, wi, wo, w, (strategy, tv_deg), quadrature=quadrature(tv))


def test_mis_tabulated_uses_the_fits_table(fit3d, monkeypatch, tmp_path):
    """The default strategy of a rational fit reads the table of the fit's record: no tabulation,
    and the packed table is the record's."""
    from warp_rbrdf.techniques import cdf_data

    path, _, cdf = fit3d
    monkeypatch.setenv("RBRDF_DATA", str(tmp_path))
    monkeypatch.setattr(cdf_data, "cached_tabulate", lambda *a, **k: pytest.fail("tabulated at load"))
    r = _case(path, "mis-tabulated")
    np.testing.assert_array_equal(r.material_data.cdf[0].cdf_phi, cdf.table.cdf_phi)


def test_2d_fit_sampler_made_from_the_fit(tmp_path):
    """A shipped 2-D fit: the sampler's table is the table the renderer's load tabulates from the
    same fit (the vouched values), and the file written with it loads."""
    from warp_rbrdf.paths import PACKAGE_DATA

    model = load(PACKAGE_DATA / "paper_white_rgb.json")
    cdf = fit_model_sampler(model, time_limit_s=0.01)       # the table; rows past the limit use it
    ref = tabulate(vouched_evaluate(model))
    np.testing.assert_array_equal(cdf.table.cdf_theta, ref.cdf_theta)
    embedded.attach(model, cdf)
    save(model, tmp_path / "p.json")
    assert embedded.read(load(tmp_path / "p.json"), maps=False).n_v == 32


def test_plot_cdf_of_a_fit_carrying_its_sampler(fit3d, tmp_path, capsys):
    """rbrdf-fit plot-cdf FIT.json plots the CDFs the fit carries (two PNGs); a fit without a
    sampler is one line naming the file, exit status 2, nothing written."""
    from fit.cli import main
    from warp_rbrdf.paths import PACKAGE_DATA

    path = fit3d[0]
    assert main(["plot-cdf", str(path), "--out", str(tmp_path / "plots"), "--prefix", "own"]) == 0
    assert sorted(p.name for p in (tmp_path / "plots").iterdir()) == ["own_phi.png", "own_theta.png"]
    assert all(p.stat().st_size > 10_000 for p in (tmp_path / "plots").iterdir())
    capsys.readouterr()
    bare = PACKAGE_DATA / "paper_white_rgb.json"
    assert load(bare).sampler is None
    assert main(["plot-cdf", str(bare), "--out", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "paper_white_rgb.json" in err and "no sampler record" in err, err
    assert not (tmp_path / "none").exists() or not any((tmp_path / "none").iterdir())


# --------------------------------------------------------------------------------------------
# Hostile records: one line naming the file and the key, exit status 2
# --------------------------------------------------------------------------------------------
def _edited(fit3d, tmp_path, edit, keep_sha=False):
    path = fit3d[0]
    d = json.loads(path.read_text())
    edit(d)
    if keep_sha:   # re-sign the record, so that the check after the digest is reached
        d["sampler"]["sha256"] = embedded.record_sha256(d["sampler"])
    out = tmp_path / "bad.json"
    out.write_text(json.dumps(d))
    return out


def _truncate(d):
    data = d["sampler"]["table_data"]["cdf_phi"]["data"]
    d["sampler"]["table_data"]["cdf_phi"]["data"] = data[: len(data) // 2]


def _huge(d):
    d["sampler"]["table_data"]["cdf_phi"]["shape"] = [32, 64, 2 ** 30]


def _coefficient(d):
    d["pieces"][0]["functions"][0]["numerator"]["coefficients"][0] *= 1.0 + 1e-9


def _cdf_value(d):
    a = binary_arrays.decode(d["sampler"]["table_data"]["cdf_theta"], "x", (32, 65), 10 ** 6)
    a[3, 10] = a[3, 11]                        # a cell of no mass
    d["sampler"]["table_data"]["cdf_theta"] = binary_arrays.encode(a)


def _knots(name, change):
    """An edit of the stored knots (the record signed again): ``change(array)`` in place."""
    def edit(d):
        rec = d["sampler"]["pieces"]["knots"]
        a = binary_arrays.decode(rec[name], "x", tuple(rec[name]["shape"]), 10 ** 7)
        change(a)
        rec[name] = binary_arrays.encode(a)
    return edit


def _swap_phi_knots(a):
    a[0, 5, 3], a[0, 5, 4] = a[0, 5, 4], a[0, 5, 3]     # a decreasing map


HOSTILE = [
    ("truncated", _truncate, True, "sampler.table_data.cdf_phi.data"),
    ("huge counts", _huge, True, "sampler.table_data"),
    ("record edited, sha kept", lambda d: d["sampler"]["pieces"]["row_ok"].__setitem__(0, False), False,
     "sampler.sha256"),
    ("coefficients edited", _coefficient, False, "sampler.fit_sha256"),
    ("a CDF value", _cdf_value, True, "sampler.table_data.cdf_theta"),
    ("knots not monotone", _knots("phi", _swap_phi_knots), True, "sampler.pieces.knots"),
    ("slope beyond the bound", _knots("theta_slopes", lambda a: a.__setitem__((1, 7), 1e300)), True,
     "sampler.pieces.knots"),
    ("end not normalised", _knots("theta", lambda a: a.__setitem__((2, -1), 1.5)), True,
     "sampler.pieces.knots"),
    ("knots of the wrong shape", lambda d: d["sampler"]["pieces"]["knots"]["phi"].__setitem__("shape", [32, 64, 3]),
     True, "sampler.pieces.knots.phi"),
]


@pytest.mark.parametrize("what,edit,keep_sha,key", HOSTILE, ids=[h[0] for h in HOSTILE])
def test_hostile_sampler_record_is_one_line_exit_2(fit3d, tmp_path, capsys, what, edit, keep_sha, key):
    from warp_rbrdf.cli import main

    bad = _edited(fit3d, tmp_path, edit, keep_sha)
    scene = tmp_path / "s.toml"
    scene.write_text('[camera]\nresolution = [4, 4]\n[integrator]\nspp = 1\n'
                     '[materials.m]\ntype = "rational"\nfile = "bad.json"\nsampler = "mis-rational"\n'
                     '[[shapes]]\ntype = "sphere"\nmaterial = "m"\n[[lights]]\ntype = "constant"\n')
    rc = main(["render", str(scene), "--out", str(tmp_path / "o.exr"), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert len(err.splitlines()) == 1 and key in err and "bad.json" in err, err
