"""The Warp materials against the fit package's NumPy evaluation at the same directions."""
from __future__ import annotations

import functools

import numpy as np
import pytest
from conftest import data_file, rgl_measured

from fit.formats.angles import half_diff_to_directions, spherical_to_direction
from fit.formats.grid import phi_d_centres, theta_d_centres, theta_h_centres
from fit.formats.measured import MeasuredBRDF
from fit.projection.project import project
from lab import testing as T
from warp_rbrdf.renderer import Renderer
from warp_rbrdf.scene import MaterialSpec


@functools.lru_cache(maxsize=1)
def synthetic_brdf():
    """A table whose every bin differs (so a wrong bin shows), with a few invalid bins (made
    once per module: callers must not modify it)."""
    def f(wi, wo):
        th = np.arccos(np.clip(wi[..., 2], -1, 1))
        to = np.arccos(np.clip(wo[..., 2], -1, 1))
        h = wi + wo
        h = h / np.linalg.norm(h, axis=-1, keepdims=True)
        spec = np.exp(-((1 - h[..., 2]) / 0.02))
        base = 0.2 + 0.1 * np.cos(3 * th) * np.sin(2 * to) + 0.05 * wi[..., 0] * wo[..., 1]
        return np.stack([base + spec, base + 0.5 * spec, 0.5 * base + 2 * spec], -1)
    b = MeasuredBRDF.from_function(f, name="synthetic")
    rng = np.random.default_rng(0)
    b.values = b.values * (1 + 0.3 * rng.random(b.values.shape))  # break any symmetry
    return b


@functools.lru_cache(maxsize=1)
def synthetic_projected():
    """:func:`synthetic_brdf` projected (once per module: callers must not modify it)."""
    return project(synthetic_brdf())


def renderer_for(spec):
    """A scene of ``spec`` (with the other kinds beside it: :func:`_multi_scene`)."""
    return _multi_scene([spec])


def random_pairs(n, seed=1):
    rng = np.random.default_rng(seed)
    t = np.arccos(rng.random((2, n)))  # upper hemisphere, cos-uniform
    p = rng.random((2, n)) * 2 * np.pi
    return spherical_to_direction(t[0], p[0]), spherical_to_direction(t[1], p[1])


def bin_centre_pairs(step=(7, 5, 11), phi_h=0.7):
    th, td, pd = np.meshgrid(theta_h_centres()[::step[0]], theta_d_centres()[::step[1]],
                             phi_d_centres()[::step[2]], indexing="ij")
    # phi_d and phi_d + pi are the same bin; test both halves
    pd = np.concatenate([pd.ravel(), pd.ravel() + np.pi])
    th = np.concatenate([th.ravel()] * 2)
    td = np.concatenate([td.ravel()] * 2)
    wi, wo = half_diff_to_directions(th, phi_h, td, pd)
    ok = (wi[:, 2] > 1e-3) & (wo[:, 2] > 1e-3)
    return wi[ok], wo[ok]


def test_lambert_matches_closed_form():
    r = renderer_for(T.lambert(albedo=(0.2, 0.5, 0.9)))
    wi, wo = random_pairs(1000)
    wi[:10, 2] *= -1
    got = r.eval_material("m", wi, wo)
    ref = np.where(wi[:, 2:3] > 0, np.array([0.2, 0.5, 0.9]) / np.pi, 0.0)
    np.testing.assert_allclose(got, ref, rtol=1e-6)


def test_measured_table_matches_numpy_nearest():
    b = synthetic_brdf()
    r = renderer_for(MaterialSpec(name="m", type="measured", data=b, scale=(1.0, 2.0, 0.5),
                                  interpolation="nearest", sampler="mis"))
    scale = np.array([1.0, 2.0, 0.5])
    # at bin centres the float32 Warp code must pick exactly the same bin
    wi, wo = bin_centre_pairs()
    np.testing.assert_allclose(r.eval_material("m", wi, wo), b.evaluate(wi, wo, "nearest") * scale,
                               rtol=1e-5, atol=1e-7)
    # at random directions: identical except (rarely) at a bin boundary in float32
    wi, wo = random_pairs(20000)
    got, ref = r.eval_material("m", wi, wo), b.evaluate(wi, wo, "nearest") * scale
    same = np.all(np.isclose(got, ref, rtol=1e-5, atol=1e-7), axis=1)
    assert same.mean() > 0.995, same.mean()
    # below the horizon: 0
    wi[:, 2] *= -1
    assert np.all(r.eval_material("m", wi, wo) == 0)


def assert_linear_lookup_matches(got, ref, wi, wo):
    """The kernel's trilinear lookup against NumPy's. Where theta_h >= 1 deg: 99.9 % within
    2e-4 relative and all within 1 % (float32 coordinates on a steep lobe). Below, the float32
    half vector's azimuth is ill-conditioned and moves the phi_d coordinate by up to ~0.1 bin
    (the synthetic tables jump up to 30 % from bin to bin): within 10 %."""
    from fit.formats.angles import directions_to_half_diff
    th = directions_to_half_diff(wi, wo)[0]
    far = th >= np.radians(1.0)
    close = np.all(np.isclose(got[far], ref[far], rtol=2e-4, atol=1e-7), axis=1)
    assert close.mean() > 0.999, close.mean()
    np.testing.assert_allclose(got[far], ref[far], rtol=0.01, atol=1e-7)
    np.testing.assert_allclose(got[~far], ref[~far], rtol=0.1, atol=1e-7)


def test_measured_table_matches_numpy_linear():
    """The default (trilinear) lookup: the kernel equals MeasuredBRDF.evaluate, bins without a
    sample left out in both; at a bin centre it is that bin's value."""
    b = synthetic_brdf()
    r = renderer_for(MaterialSpec(name="m", type="measured", data=b, scale=(1.0, 2.0, 0.5), sampler="mis"))
    scale = np.array([1.0, 2.0, 0.5])
    wi, wo = bin_centre_pairs()
    ref = b.evaluate(wi, wo) * scale
    assert_linear_lookup_matches(r.eval_material("m", wi, wo), ref, wi, wo)
    np.testing.assert_allclose(ref, b.evaluate(wi, wo, "nearest") * scale, rtol=1e-9)
    wi, wo = random_pairs(20000)
    assert_linear_lookup_matches(r.eval_material("m", wi, wo), b.evaluate(wi, wo) * scale, wi, wo)
    wi[:, 2] *= -1
    assert np.all(r.eval_material("m", wi, wo) == 0)


def test_projected_table_matches_numpy():
    pb = synthetic_projected()
    r = renderer_for(MaterialSpec(name="m", type="projected", data=pb, sampler="mis"))
    wi, wo = bin_centre_pairs()
    np.testing.assert_allclose(r.eval_material("m", wi, wo), pb.evaluate(wi, wo), rtol=1e-5, atol=1e-7)
    wi, wo = random_pairs(20000, seed=3)
    same = np.all(np.isclose(r.eval_material("m", wi, wo), pb.evaluate(wi, wo), rtol=1e-5, atol=1e-7), axis=1)
    assert same.mean() > 0.995


def test_measured_material_renders_under_directional_light():
    """A plane (normal +Y) under a directional light seen by a narrow camera: the pixel is
    rho(wi, wo) E cos(theta_i) with rho from the NumPy table in a right-handed frame about +Y."""
    from warp_rbrdf.scene import CameraSpec

    b = synthetic_brdf()
    # nearest bin: constant over the pixels' few 0.01 deg (the frame is what is tested here);
    # mis: no inverse CDFs to tabulate (the directional light is all the image holds)
    spec = MaterialSpec(name="m", type="measured", data=b, interpolation="nearest", sampler="mis")
    to_light = np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5])
    to_eye = np.array([-0.5, 0.7, 0.2]) / np.linalg.norm([-0.5, 0.7, 0.2])
    sc = T.plane_scene(spec, [T.directional(to_light, 2.0)], resolution=4, spp=1)
    sc.camera = CameraSpec(origin=tuple(5 * to_eye), target=(0, 0, 0), fov=0.1, resolution=(4, 4))
    img = Renderer(T.common_kernel(sc)).render()   # the common test kernel (lab.testing)
    frame = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # rows: T, B, N (T x B = N)
    wi, wo = frame @ to_light, frame @ to_eye
    ref = b.evaluate(wi, wo, "nearest") * 2.0 * to_light[1]
    np.testing.assert_allclose(img.reshape(-1, 3), np.broadcast_to(ref, (16, 3)), rtol=1e-4)


# ------------------------------------------------------------------------------------------
# phi_d fold (issue 20, "roles"): Materials.param = 180 (MERL, folded) or 360 (full circle)
# ------------------------------------------------------------------------------------------
def synthetic_full_circle_brdf():
    """A non-reciprocal table over the full phi_d circle (360 bins) whose every bin differs."""
    def f(wi, wo):
        base = 0.2 + 0.15 * wi[..., 2] ** 2 - 0.05 * wo[..., 0] + 0.03 * wi[..., 1] * wo[..., 2]
        return np.stack([base, 1.5 * base, 0.5 + 0 * base], -1)
    b = MeasuredBRDF.from_function(f, name="synthetic360", reciprocal=False)
    rng = np.random.default_rng(2)
    b.values = b.values * (1 + 0.3 * rng.random(b.values.shape))
    return b


def _rgl_file():
    from conftest import data_file
    return data_file("rgl/cc_ibiza_sunset_rgb.bsdf")   # a glossy film, reciprocal to 10-27 % only


def _multi_scene(specs):
    """One scene using every spec (a plane, then spheres), so the kernels see them together,
    and a material of each other kind this module evaluates (lambert, measured, projected) on
    further spheres: every scene's evaluation kernel is then the same one (each set of kinds
    is a kernel of its own, seconds of compiling on a cold cache). The tables of this module
    sample with the cosine technique of ``mis``: their kinds' default, ``mis-tabulated``, would
    tabulate each table's inverse CDFs at load, and only their evaluation is tested here."""
    from warp_rbrdf.scene import ShapeSpec

    others = {"lambert": T.lambert(name="other-lambert"),
              "measured": MaterialSpec(name="other-measured", type="measured", data=synthetic_brdf(), sampler="mis"),
              "projected": MaterialSpec(name="other-projected", type="projected", data=synthetic_projected(),
                                        sampler="mis")}
    specs = list(specs) + [o for kind, o in others.items() if kind not in {s.type for s in specs}]
    sc = T.plane_scene(specs[0], [T.constant_env(1.0)], resolution=4, spp=1)
    for n, s in enumerate(specs[1:]):
        sc.materials[s.name] = s
        sc.shapes.append(ShapeSpec(type="sphere", material=s.name, center=(0.0, 0.0, -10.0 - 3 * n)))
    return Renderer(sc)


@pytest.fixture(scope="module")
def fold_renderer():
    """A MERL-like (folded, 180) table, a synthetic full-circle one and an RGL-derived one
    (360) in one scene; the RGL file's own evaluation as the reference."""
    from fit.formats.rgl import read_rgl

    rgl = read_rgl(_rgl_file())
    tables = {"merl": synthetic_brdf(), "full": synthetic_full_circle_brdf(),
              "rgl": rgl_measured("cc_ibiza_sunset_rgb")}   # rgl.to_measured(), once per session
    specs = [MaterialSpec(name=k, type="measured", data=b, sampler="mis") for k, b in tables.items()]
    specs += [MaterialSpec(name=k + "-nearest", type="measured", data=b, interpolation="nearest",
                           sampler="mis") for k, b in tables.items()]
    return _multi_scene(specs), tables, rgl


def test_measured_param_is_the_number_of_phi_d_bins(fold_renderer):
    """param = phi_d bins + 1000 x the direction whose cosine divides the table: 0 for rho
    tables, 1 (the light) for an RGL-derived table of the default roles (f cos(theta_light));
    + 10000 for the nearest-bin lookup."""
    r, tables, _ = fold_renderer
    md = r.material_data
    assert [int(md.param[md.names.index(k)]) for k in ("merl", "full", "rgl")] == [180, 360, 1360]
    assert ([int(md.param[md.names.index(k + "-nearest")]) for k in ("merl", "full", "rgl")]
            == [10180, 10360, 11360])
    assert tables["merl"].reciprocal and not tables["full"].reciprocal and not tables["rgl"].reciprocal


def test_rgl_derived_table_has_no_terminator_line():
    """The pairs whose light grazes (85-89.9 deg, the terminator of a bright light): with the
    table of rho at bin centres, rho(bin) * cos(actual light) is 0.85 of the file's f cos there
    (the centre's 1/cos and bins straddling the horizon read 0: a dark line along each bright
    light's terminator); the weighted table gives the nearest bin's f cos exactly, within
    nearest-bin error (mean within 3 %: 1.005), in NumPy and in the kernel. The matte paper,
    whose table other tests of the default run resample too (the green metallic film
    cm_toxic_green: 0.87 and 1.02)."""
    from fit.formats.colour import LUMINANCE
    from fit.formats.rgl import read_rgl

    b = read_rgl(data_file("rgl/paper_white_rgb.bsdf"))
    m = rgl_measured("paper_white_rgb")   # b.to_measured(), once per session
    rng = np.random.default_rng(4)
    n = 20000
    ct = np.cos(np.radians(85.0)) - rng.random(n) * (np.cos(np.radians(85.0)) - np.cos(np.radians(89.9)))
    wl = spherical_to_direction(np.arccos(ct), rng.random(n) * 2 * np.pi)
    wv = spherical_to_direction(np.arccos(1 - rng.random(n) * (1 - np.cos(np.radians(80)))), rng.random(n) * 2 * np.pi)
    exact = (b.evaluate(wl, wv) @ LUMINANCE) * wl[:, 2]
    old = MeasuredBRDF(values=m.values, valid=m.valid)                 # rho at the centres only
    assert ((old.evaluate(wl, wv, "nearest") @ LUMINANCE) * wl[:, 2]).mean() / exact.mean() < 0.9   # 0.85
    new = (m.evaluate(wl, wv) @ LUMINANCE) * wl[:, 2]
    assert new.mean() / exact.mean() == pytest.approx(1.0, abs=0.03)
    r = _multi_scene([MaterialSpec(name="rgl", type="measured", data=m, sampler="mis")])
    got = (r.eval_material("rgl", wl, wv).astype(float) @ LUMINANCE) * wl[:, 2]
    close = np.isclose(got, new, rtol=2e-4, atol=1e-6 * new.max())
    assert close.mean() > 0.999   # float32 angles: a pair on a bin boundary may read the next bin


@pytest.mark.parametrize("short, grazing, nearest_above, linear_below", [
    # near-mirror lobe between the bins: 0.118 -> 0.035 (-m extended: its RGL file is resampled
    # by no other test of the default run, seconds of the suite)
    pytest.param("chm_mint", False, 0.1, 0.05, marks=pytest.mark.extended),
    ("paper_white", True, 0.05, 0.03),    # light within 5 deg of the horizon: 0.074 -> 0.023
])
def test_trilinear_table_is_closer_to_the_file(short, grazing, nearest_above, linear_below):
    """The MERL-grid table of an RGL file against the file's own evaluation, relative RMSE of
    rho cos cos over 40,000 cosine-distributed pairs (light within 5 deg of the horizon where
    ``grazing``): the nearest bin (the lookup until 2026-11-24: rings where a narrow lobe
    falls between bins, steps along a light's terminator) is 2.5-10x further from the file
    than the trilinear default, in NumPy and (same values) in the kernel."""
    from fit.formats.rgl import read_rgl

    b = read_rgl(data_file(f"rgl/{short}_rgb.bsdf"))
    m = rgl_measured(f"{short}_rgb")   # b.to_measured(), once per session
    rng = np.random.default_rng(5)
    n = 40000

    def cosine(n):
        u = rng.random((2, n))
        return spherical_to_direction(np.arccos(np.sqrt(1 - u[0])), 2 * np.pi * u[1])
    wl, wv = cosine(n), cosine(n)
    if grazing:
        wl = spherical_to_direction(np.radians(90 - 5 * rng.random(n)), 2 * np.pi * rng.random(n))
    w = (wl[:, 2] * wv[:, 2])[:, None]
    exact = b.evaluate(wl, wv) * w

    def rel_rmse(x):
        return np.sqrt(np.mean((x * w - exact) ** 2) / np.mean(exact ** 2))
    nearest, linear = rel_rmse(m.evaluate(wl, wv, "nearest")), rel_rmse(m.evaluate(wl, wv))
    assert nearest > nearest_above and linear < linear_below and linear < 0.4 * nearest, (nearest, linear)
    r = _multi_scene([MaterialSpec(name="t", type="measured", data=m, sampler="mis")])
    assert rel_rmse(r.eval_material("t", wl, wv).astype(float)) == pytest.approx(linear, rel=0.02)


@pytest.mark.parametrize("name", ["merl", "full", "rgl"])
def test_measured_lookup_matches_numpy_folded_and_full_circle(name, fold_renderer):
    """The Warp lookup equals MeasuredBRDF.evaluate for a folded (MERL-like) and a full-circle
    (RGL-derived) table in the same scene, over the whole circle and both orders. Nearest bin:
    exactly at bin centres, and at random pairs except (rarely) at a bin boundary in float32.
    Trilinear (default): :func:`assert_linear_lookup_matches`."""
    r, tables, _ = fold_renderer
    b = tables[name]
    wi, wo = bin_centre_pairs()
    np.testing.assert_allclose(r.eval_material(name + "-nearest", wi, wo), b.evaluate(wi, wo, "nearest"),
                               rtol=1e-5, atol=1e-7)
    assert_linear_lookup_matches(r.eval_material(name, wi, wo), b.evaluate(wi, wo), wi, wo)
    wi, wo = random_pairs(20000, seed=4)
    for a, c in ((wi, wo), (wo, wi)):
        got, ref = r.eval_material(name + "-nearest", a, c), b.evaluate(a, c, "nearest")
        same = np.all(np.isclose(got, ref, rtol=1e-5, atol=1e-7), axis=1)
        assert same.mean() > 0.995, same.mean()
        assert_linear_lookup_matches(r.eval_material(name, a, c), b.evaluate(a, c), a, c)


def test_rgl_measured_has_no_seam(fold_renderer):
    """The seam of issue 20: for an RGL file the kernel's values at (light, view) and
    (view, light) differ as the file's own evaluation does (a folded table gives both pairs
    one value)."""
    r, _, rgl = fold_renderer
    rng = np.random.default_rng(8)
    n = 3000
    wl, wv = half_diff_to_directions(theta_h_centres()[rng.integers(0, 90, n)], rng.uniform(0, 2 * np.pi, n),
                                     theta_d_centres()[rng.integers(0, 90, n)],
                                     phi_d_centres(360)[rng.integers(0, 360, n)])
    ok = (wl[:, 2] > 0.02) & (wv[:, 2] > 0.02)
    wl, wv = wl[ok], wv[ok]
    lv, vl = r.eval_material("rgl", wl, wv), r.eval_material("rgl", wv, wl)
    src_lv, src_vl = rgl.evaluate(wl, wv), rgl.evaluate(wv, wl)
    luma = np.array([0.2126, 0.7152, 0.0722])
    y_src = np.stack([src_lv @ luma, src_vl @ luma])
    differ = np.abs(y_src[0] - y_src[1]) > 0.1 * y_src.max(axis=0)
    assert differ.mean() > 0.05, differ.mean()
    # any phi_h (the table holds phi_h = 0; the file is isotropic to 1e-12), float32 table;
    # at bin centres the trilinear lookup is the centre's value, up to float32 coordinates
    np.testing.assert_allclose(lv, src_lv, rtol=2e-4, atol=1e-7)
    np.testing.assert_allclose(vl, src_vl, rtol=2e-4, atol=1e-7)
    y = np.stack([lv @ luma, vl @ luma])
    np.testing.assert_allclose((y[0] - y[1])[differ], (y_src[0] - y_src[1])[differ], rtol=1e-4)
