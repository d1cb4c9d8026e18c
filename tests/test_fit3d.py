"""3-D rational BRDF fits (issue 25): :mod:`fit.rational.fit3d`, coefficient file version 3 and
the renderer's evaluation of it.

* on a small synthetic lobe that is not reciprocal and depends on phi_d, the fit meets its
  stated bound at every data point, Q > 0 is certified on every piece, and the bound is below
  what ANY function of (theta_h, theta_d) alone can reach on the same data (the half relative
  spread of each (theta_h, theta_d) column over phi_d);
* the fit's functions give rho cos theta_i by default (value factor "1/cos_theta_i": the model
  divides by cos theta_i of the unclamped angles, step 8), and the stated bound holds in that unit;
* a version-4 file (a factor) and a version-3 file (none) round-trip exactly; versions 1/2 and
  3/4 do not accept each other's variables, nor 3 and 4 each other's value factors;
* the Warp evaluation of the packed fit equals its NumPy evaluation (|phi_d| fold, pieces, log
  values, clamps).
"""
from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from fit.errors import BRDFFileError
from fit.formats.angles import half_diff_to_directions, spherical_to_direction
from fit.rational.coefficient_file import VERSION_3D, VERSION_3D_FACTOR, from_dict, load, save
from fit.rational.model import COS_FLOOR, cos_theta_i_of, value_factor_weights
from fit.rational.fit3d import fit_samples, grazing_weight, sample_grid
from fit.rational.variables3d import evaluate_directions, half_diff_3d

THETA_MAX = np.radians(80.0)


def lobe(X):
    """A synthetic RGB BRDF (1/sr) of (theta_h, theta_d, |phi_d|) rows: a diffuse base and a
    specular lobe whose height depends on phi_d through cos(phi_d), which changes sign under
    phi_d -> phi_d + pi (light and view swapped): not reciprocal, not a function of theta_h,
    theta_d alone."""
    th, td, pd = X[:, 0], X[:, 1], X[:, 2]
    spec = 3.0 * np.exp(-(th / 0.25) ** 2) * (1.0 + 0.35 * np.cos(pd)) * (1.0 + 0.5 * np.sin(td) ** 2)
    base = np.array([0.08, 0.12, 0.2])
    return base[None, :] * (1.0 + 0.3 * np.cos(pd)[:, None] * np.sin(td)[:, None]) + spec[:, None] * [1.0, 0.9, 0.8]


@pytest.fixture(scope="module")
def synthetic_fit():
    X = sample_grid(THETA_MAX, grid=(10, 9, 7), n_random=300, seed=3)
    rho = lobe(X)
    res = fit_samples(X, rho, name="lobe3d", theta_max=THETA_MAX, degrees=(4, 2), theta_h_edges=[0.2],
                      tol=0.01, time_limit=30.0, grazing_cos=0.0, channel_floor=0.0)
    return X, rho, res


def _two_d_lower_bound(X, rho, noise):
    """The smallest max relative error (over max(rho, noise)) any function of (theta_h, theta_d)
    alone can reach on the data: per (theta_h, theta_d) column of the grid, one value v must
    serve every phi_d, so max |v - y| / s >= (ymax - ymin) / (s_max + s_min) at its extremes."""
    keys = np.round(X[:, :2], 12)
    _, inv = np.unique(keys, axis=0, return_inverse=True)
    best = 0.0
    for c in range(3):
        s = np.maximum(rho[:, c], noise[c])
        for g in np.unique(inv):
            m = inv == g
            if m.sum() < 2:
                continue
            i, j = np.argmax(rho[m, c]), np.argmin(rho[m, c])
            best = max(best, (rho[m, c][i] - rho[m, c][j]) / (s[m][i] + s[m][j]))
    return best


def test_3d_fit_meets_its_bound_everywhere_and_beats_any_2d_fit(synthetic_fit):
    X, rho, res = synthetic_fit
    assert res.valid and res.n_coefficients == 2 * 3 * (35 + 10)   # total degrees 4 and 2 in 3 variables
    assert res.model.value_factor == "1/cos_theta_i"            # the default: the functions give rho cos theta_i
    noise = np.array(res.noise)                                # (in the functions' unit, as the bound)
    rho_f = rho / value_factor_weights(X, res.model.value_factor)[:, None]
    fit = res.model.values(X)
    np.testing.assert_allclose(res.model(X), fit / np.maximum(cos_theta_i_of(X), COS_FLOOR)[:, None], rtol=1e-12)
    rho = rho_f
    err = np.abs(fit - rho) / np.maximum(rho, noise)
    assert np.all(err <= res.tolerance * (1 + 1e-9))          # the stated bound, at every data point
    for leaf in res.model.pieces:                              # per piece and channel: its own bound
        lo, hi = leaf.variables[0].domain
        sel = (X[:, 0] >= lo) & (X[:, 0] <= hi)
        for c, info in enumerate(leaf.function_info):
            assert info["valid"] and info["q_certificate"]["certified"]
            assert leaf.functions[c].certify_denominator().certified
            e = np.abs(leaf(X[sel])[:, c] - rho[sel, c]) / np.maximum(rho[sel, c], noise[c])
            assert np.max(e) <= info["tolerance"] * (1 + 1e-9)
    bound_2d = _two_d_lower_bound(X, rho, noise)                # in the same unit: any 2-D function of it
    assert bound_2d > 0.2                                      # the data really depend on phi_d
    assert res.tolerance < 0.5 * bound_2d, (res.tolerance, bound_2d)


def test_grazing_weight():
    """g = 1 (a relative bound) while cos(theta_i) cos(theta_o) >= grazing_cos, then the bound is
    on rho cos(theta_i) cos(theta_o): g cos(theta_i) cos(theta_o) = grazing_cos."""
    X = np.array([[0.0, 0.0, 0.0], [0.0, np.radians(60.0), 0.0], [0.0, np.radians(75.0), 1.0]])
    g = grazing_weight(X, 0.25)
    c = np.cos(X[:, 1]) ** 2     # theta_h = 0: theta_i = theta_o = theta_d
    np.testing.assert_allclose(g, [1.0, 1.0, 0.25 / c[2]])
    assert np.all(grazing_weight(X, 0.0) == 1.0)


def test_directions_use_mirror_fold_and_keep_roles(synthetic_fit):
    """rho(wi, wo) of the fit is the model at (theta_h, theta_d, |phi_d|); swapping light and
    view changes it (the lobe is not reciprocal); mirroring the pair (y -> -y) does not."""
    _, _, res = synthetic_fit
    rng = np.random.default_rng(1)
    X = np.stack([rng.uniform(0, 0.3, 500), rng.uniform(0.2, 0.8, 500), rng.uniform(0.2, 2.9, 500)], 1)
    wi, wo = half_diff_to_directions(X[:, 0], rng.uniform(-3, 3, 500), X[:, 1], X[:, 2])
    np.testing.assert_allclose(half_diff_3d(wi, wo), X, atol=1e-9)
    a = evaluate_directions(res.model, wi, wo)
    np.testing.assert_allclose(a, res.model(X), rtol=1e-9)
    mirror = np.array([1.0, -1.0, 1.0])
    np.testing.assert_allclose(evaluate_directions(res.model, wi * mirror, wo * mirror), a, rtol=1e-9)
    swapped = evaluate_directions(res.model, wo, wi)
    assert np.median(np.abs(swapped - a) / a) > 0.05
    assert np.all(evaluate_directions(res.model, wi * [1, 1, -1], wo) == 0)


def test_version_3_and_4_file_round_trip(synthetic_fit, tmp_path):
    X, _, res = synthetic_fit
    p = tmp_path / "lobe3d.json"
    save(res.model, p)
    d = json.loads(p.read_text())
    assert d["version"] == VERSION_3D_FACTOR and [v["name"] for v in d["variables"]] == ["theta_h", "theta_d", "phi_d"]
    assert d["value"]["factor"] == "1/cos_theta_i"
    back = load(p)
    np.testing.assert_array_equal(back(X), res.model(X))
    assert back.value_factor == "1/cos_theta_i" and all(q.value_factor == "none" for q in back.pieces)
    assert back.pieces[1].function_info[2]["tolerance"] == res.model.pieces[1].function_info[2]["tolerance"]
    # without the factor: version 3, the functions' values themselves
    none = copy.deepcopy(res.model)
    none.value_factor = "none"
    p3 = tmp_path / "lobe3d_v3.json"
    save(none, p3)
    d3 = json.loads(p3.read_text())
    assert d3["version"] == VERSION_3D and "factor" not in d3["value"]
    np.testing.assert_array_equal(load(p3)(X), res.model.values(X))
    assert not np.allclose(load(p3)(X), back(X))
    # a factor needs version 4 and version 4 needs one; an unknown factor is refused
    with pytest.raises(BRDFFileError, match="value.factor"):
        from_dict(dict(d, version=3), "x.json")
    with pytest.raises(BRDFFileError, match="value.factor"):
        from_dict(dict(d3, version=4), "x.json")
    with pytest.raises(BRDFFileError, match="value.factor"):
        from_dict(dict(d, value=dict(d["value"], factor="cos")), "x.json")
    # a version-2 reader's body with 3 variables is refused, and so is a version-3 file of 2
    d2 = dict(d, version=2)
    with pytest.raises(BRDFFileError, match="variables are theta_h, theta_d, not theta_h, theta_d, phi_d"):
        from_dict(d2, "x.json")
    bad = json.loads(p.read_text())
    bad["variables"][2]["domain"] = [0.0, 4.0]
    with pytest.raises(BRDFFileError, match=r"variables\[2\].domain.*not inside \[0, pi\]"):
        from_dict(bad, "x.json")


def test_warp_eval_equals_numpy_eval(synthetic_fit):
    from lab import testing as T
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import MaterialSpec

    _, _, res = synthetic_fit
    r = Renderer(T.plane_scene(MaterialSpec(name="m", type="rational", data=res.model), [T.constant_env(1.0)],
                               resolution=4, spp=1))
    rng = np.random.default_rng(4)
    n = 6000
    wi = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    wo = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    # near-specular pairs (the peak piece and the theta_h split) and pairs beyond theta_max (clamps)
    wi[: n // 3] = wo[: n // 3] * [-1, -1, 1] + rng.normal(scale=0.05, size=(n // 3, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    got = r.eval_material("m", wi, wo)
    ref = evaluate_directions(res.model, wi, wo)
    assert np.mean(half_diff_3d(wi, wo)[:, 0] <= 0.2) > 0.2
    np.testing.assert_allclose(got, ref, rtol=2e-4, atol=1e-6)


def test_3d_fit_converts_to_rgl_with_roles_kept(synthetic_fit, tmp_path, capsys):
    """``rbrdf-fit convert`` of a version-3 file (before 2026-11-24 a traceback: the 2-D
    recipe was applied to a 3-D model): the source is the fit's own direction evaluation, not
    reciprocal, and an RGL output (which keeps the roles) reproduces it where the format is
    accurate (both directions within 70 deg), the swapped pair included."""
    from fit.cli import main
    from fit.convert.sources import load_source
    from fit.convert.summary import compare

    _, _, res = synthetic_fit
    src = tmp_path / "lobe3d.json"
    save(res.model, src)
    s = load_source(src)
    assert not s.reciprocal and s.evaluate_angles is None and "3-D rational fit" in s.notes[0]
    rng = np.random.default_rng(4)
    wi = spherical_to_direction(np.arccos(rng.random(300)), rng.random(300) * 2 * np.pi)
    wo = spherical_to_direction(np.arccos(rng.random(300)), rng.random(300) * 2 * np.pi)
    np.testing.assert_array_equal(s.evaluate(wi, wo), evaluate_directions(res.model, wi, wo))
    out = tmp_path / "lobe3d.bsdf"
    assert main(["convert", str(src), str(out), "--theta-i", "8", "--n-vndf", "64", "--n-rgb", "32",
                 "--pairs", "2000"]) == 0
    assert "not reciprocal" in capsys.readouterr().out
    back = load_source(out).evaluate
    core = compare(back, s.evaluate, 4000, 0, 70.0)
    swapped = compare(lambda a, b: back(b, a), lambda a, b: s.evaluate(b, a), 4000, 1, 70.0)
    assert core.rel_rms < 0.05 and swapped.rel_rms < 0.05, (core.describe(), swapped.describe())
