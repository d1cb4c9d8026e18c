"""Environment-map importance sampling follows the map as it is looked up: the density is the
bilinear lookup's luminance (with the lat-long map's sin theta) normalised, the sampled
directions follow it (chi-square, on a synthetic map with a tiny bright sun and on the rooitou
map), ``env_pdf`` is the pdf ``env_sample`` returns, and Warp = NumPy. The expected
probabilities come from Gauss-Legendre quadrature of the density on the lookup's patches, not
from the sampler's own closed forms. The renderer's scheme (``hierarchical``) is tested through
its own functions, the comparison schemes of :mod:`lab.env_schemes` (``marginal``: the same
density by another warp; ``piecewise-constant``) through the lab's, and the lab's light-only
render (:mod:`lab.env_scheme_render`) against the renderer. Tests of the lab's schemes and render
are in the ``lab`` tier; the negative control (the piecewise-constant scheme rejected) stays in
the default run, as it shows the product's test can fail."""
from __future__ import annotations

import functools

import numpy as np
import pytest
from chi2 import chi2_pvalue
from conftest import data_file

from lab import env_kernels as K
from lab import env_schemes as S
from warp_rbrdf.lights.env_distribution import (build_env_distribution, env_pdf_numpy, env_sample_numpy,
                                                row_geometry, sin_integrals, solve_row_fraction_numpy)
from warp_rbrdf.lights.env_file import read_latlong
from warp_rbrdf.lights.env_map import make_env_struct
from warp_rbrdf.lights.latlong import (LUMINANCE, direction_to_uv, lookup_luminance_numpy, lookup_numpy,
                                       uv_to_direction)
from warp_rbrdf.runtime import init_warp

wp = init_warp()

#: The renderer's scheme, and the lab's comparison scheme (a test of lab code: the ``lab`` tier).
SCHEMES = ("hierarchical", pytest.param("marginal", marks=pytest.mark.lab))
P_MIN = 1e-4   # chi-square p-values below this fail (several tests, fixed seeds)


def sun_map(H=32, W=64, seed=0):
    """Smooth random background plus a one-texel sun 10 degrees above the horizon, 2000 times
    brighter (about 3/4 of the map's power); the top pole row black."""
    rng = np.random.default_rng(seed)
    img = rng.uniform(0.05, 0.3, (H, W, 3)).astype(np.float32)
    img[int(round(0.44 * (H - 1))), (5 * W) // 8] = (2000.0, 1800.0, 1500.0)
    img[0, :] = 0.0
    return img


@functools.lru_cache(maxsize=1)
def rooitou():
    """The rooitou map, read once per process (read-only: the tests share it)."""
    img = read_latlong(data_file("envmaps/rooitou_park_1k.hdr"))
    img.setflags(write=False)
    return img


def build(img, scheme="hierarchical", rot=None):
    """The renderer's distribution (``hierarchical``: an ``EnvData``) or a comparison scheme of
    the lab (a ``SchemeData``)."""
    if scheme == "hierarchical":
        return build_env_distribution(img, rot)
    return S.build_scheme(img, S.SCHEME_NAMES[scheme], rot)


def lab_scheme(env) -> bool:
    return isinstance(env, S.SchemeData)


def base(env):
    """The renderer's ``EnvData`` of ``env`` (luminance, Z, pdf scale)."""
    return env.env if lab_scheme(env) else env


def struct(env):
    return S.make_scheme_struct(env, "cpu") if lab_scheme(env) else make_env_struct(env, "cpu")


def pdf_numpy(env, d):
    return S.scheme_pdf_numpy(env, d) if lab_scheme(env) else env_pdf_numpy(env, d)


def sample_numpy(env, xi):
    return S.scheme_sample_numpy(env, xi) if lab_scheme(env) else env_sample_numpy(env, xi)


def warp_sample(env, xi):
    out = wp.zeros(len(xi), dtype=wp.vec4, device="cpu")
    kernel = S.scheme_sample_kernel if lab_scheme(env) else K.env_sample_kernel
    wp.launch(kernel, dim=len(xi), inputs=[struct(env), wp.array(np.asarray(xi, np.float32), dtype=wp.vec2)],
              outputs=[out], device="cpu")
    return out.numpy()


def warp_sample_point(env, xi):
    """(samples (n, 4): direction and pdf; (n, 3) float64 u, v and looked-up luminance of the
    sampled point)."""
    out = wp.zeros(len(xi), dtype=wp.vec4, device="cpu")
    point = wp.zeros(len(xi), dtype=wp.vec3d, device="cpu")
    kernel = S.scheme_sample_point_kernel if lab_scheme(env) else K.env_sample_point_kernel
    wp.launch(kernel, dim=len(xi), inputs=[struct(env), wp.array(np.asarray(xi, np.float32), dtype=wp.vec2)],
              outputs=[out, point], device="cpu")
    return out.numpy(), point.numpy()


def warp_pdf(env, d):
    out = wp.zeros(len(d), dtype=float, device="cpu")
    kernel = S.scheme_pdf_kernel if lab_scheme(env) else K.env_pdf_kernel
    wp.launch(kernel, dim=len(d), inputs=[struct(env), wp.array(np.asarray(d, np.float32), dtype=wp.vec3)],
              outputs=[out], device="cpu")
    return out.numpy()


def warp_eval(env, d):
    out = wp.zeros(len(d), dtype=wp.vec3, device="cpu")
    wp.launch(K.env_eval_kernel, dim=len(d),
              inputs=[make_env_struct(base(env), "cpu"), wp.array(np.asarray(d, np.float32), dtype=wp.vec3)],
              outputs=[out], device="cpu")
    return out.numpy()


def pixel_coords(d, H, W):
    """Continuous lookup coordinates of directions: x = u W - 1/2 wrapped into [0, W),
    y = v (H - 1)."""
    u, v = direction_to_uv(d)
    return np.mod(u * W - 0.5, W), v * (H - 1)


def bin_probs(env, x0, x1, y0, y1, k, nx=2, nt=4):
    """Probabilities of the (k (y1 - y0), k (x1 - x0)) bins of size 1/k pixel covering
    x in [x0, x1), y in [y0, y1) (integers: whole patches), by Gauss-Legendre quadrature of
    the scheme's NumPy pdf (nx x nt nodes per bin: exact in x, ~1e-12 in y where the density is a
    bilinear function times sin(pi v))."""
    H, W = base(env).lum.shape
    gx, wx = np.polynomial.legendre.leggauss(nx)
    gt, wt = np.polynomial.legendre.leggauss(nt)
    xe = x0 + np.arange(k * (x1 - x0)) / k
    ye = y0 + np.arange(k * (y1 - y0)) / k
    x = (xe[:, None] + 0.5 * (gx + 1) / k).ravel()
    y = (ye[:, None] + 0.5 * (gt + 1) / k).ravel()
    u = np.mod((x + 0.5) / W, 1.0)
    v = y / (H - 1)
    d = uv_to_direction(u[None, :], v[:, None]).reshape(-1, 3)
    w = (2 * np.pi ** 2 * np.sin(np.pi * v)[:, None] * np.tile(0.5 * wt, len(ye))[:, None]
         * np.tile(0.5 * wx, len(xe))[None, :]) / (W * (H - 1) * k * k)
    p = pdf_numpy(env, d).reshape(w.shape) * w
    return p.reshape(len(ye), nt, len(xe), nx).sum(axis=(1, 3))


_PATCH_PROBS = {}


def patch_probs(env):
    """(H - 1, W) probabilities of the lookup's patches (quadrature), computed once per
    distribution object (the rooitou ones: :func:`rooitou_env`)."""
    key = id(env)
    if key not in _PATCH_PROBS:
        H, W = base(env).lum.shape
        _PATCH_PROBS[key] = (env, bin_probs(env, 0, W, 0, H - 1, 1, nx=2, nt=3))
    return _PATCH_PROBS[key][1]


@functools.lru_cache(maxsize=2)
def rooitou_env(scheme="hierarchical"):
    """``build(rooitou(), scheme)``, built once per process (the tests only read it)."""
    return build(rooitou(), scheme)


def fine_chi2(env, samples, k):
    """Chi-square p-value of samples against bins of 1/k pixel over the whole map."""
    H, W = base(env).lum.shape
    x, y = pixel_coords(samples, H, W)
    bx = np.clip(np.floor(x * k).astype(int), 0, k * W - 1)
    by = np.clip(np.floor(y * k).astype(int), 0, k * (H - 1) - 1)
    counts = np.bincount(by * (k * W) + bx, minlength=k * k * W * (H - 1))
    return chi2_pvalue(counts, bin_probs(env, 0, W, 0, H - 1, k), len(samples))


# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize("shape", [(32, 64), (17, 45)])
def test_chi2_tiny_sun_synthetic_map(scheme, shape):
    """Quarter-pixel bins: the within-patch (bilinear x sin theta) shape is tested too, on the
    sun's four patches (about 3/4 of the samples) and on the background; odd sizes too (the
    hierarchy's padding)."""
    env = build(sun_map(*shape), scheme)
    n = 1_000_000
    s = warp_sample(env, np.random.default_rng(3).random((n, 2)))
    assert fine_chi2(env, s[:, :3], 4) > P_MIN


def test_chi2_detects_the_piecewise_constant_density():
    """The same test rejects the piecewise-constant scheme (a constant density per texel cell,
    :mod:`lab.env_schemes`) in favour of the lookup's density: the test can fail."""
    img = sun_map()
    pc = build(img, "piecewise-constant")
    s = warp_sample(pc, np.random.default_rng(3).random((200_000, 2)))
    assert fine_chi2(build(img), s[:, :3], 4) < 1e-12


@pytest.mark.parametrize("scheme", SCHEMES)
def test_chi2_rooitou(scheme):
    """The rooitou map (512 x 1024, a sun of a few texels with 2/3 of the power): blocks of
    8 x 8 patches over the whole map, and quarter-pixel bins on the 8 x 8 patches around the
    sun (the rest pooled into one bin)."""
    env = rooitou_env(scheme)
    H, W = base(env).lum.shape
    n = 2_000_000
    s = warp_sample(env, np.random.default_rng(4).random((n, 2)))[:, :3]
    x, y = pixel_coords(s, H, W)
    # blocks of 8 x 8 patches
    pp = patch_probs(env)
    assert abs(pp.sum() - 1) < 1e-9
    hb, wb = -(-(H - 1) // 8), W // 8
    pad = np.zeros((hb * 8, W))
    pad[:H - 1] = pp
    probs = pad.reshape(hb, 8, wb, 8).sum(axis=(1, 3))
    bx = np.clip(np.floor(x).astype(int), 0, W - 1) // 8
    by = np.clip(np.floor(y).astype(int), 0, H - 2) // 8
    assert chi2_pvalue(np.bincount(by * wb + bx, minlength=hb * wb), probs, n) > P_MIN
    # quarter-pixel bins around the sun
    j, c = np.unravel_index(np.argmax(base(env).lum), (H, W))
    x0, y0, k = c - 4, j - 4, 4
    win = bin_probs(env, x0, x0 + 8, y0, y0 + 8, k)
    assert 0.5 < win.sum() < 1
    inside = (x >= x0) & (x < x0 + 8) & (y >= y0) & (y < y0 + 8)
    bx = np.floor((x[inside] - x0) * k).astype(int)
    by = np.floor((y[inside] - y0) * k).astype(int)
    counts = np.append(np.bincount(by * 8 * k + bx, minlength=win.size), (~inside).sum())
    assert chi2_pvalue(counts, np.append(win.ravel(), 1 - win.sum()), n) > P_MIN


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize("which", ["sun", "rooitou"])
def test_env_pdf_is_the_returned_pdf_and_integrates_to_one(scheme, which):
    env = build(sun_map(), scheme) if which == "sun" else rooitou_env(scheme)
    s, pt = warp_sample_point(env, np.random.default_rng(5).random((200_000, 2)))
    d, p = s[:, :3], s[:, 3]
    assert np.all(p > 0)
    # the pdf is the looked-up luminance at the sampled point (u, v)
    at_uv = lookup_luminance_numpy(base(env).lum.astype(np.float32), pt[:, 0], pt[:, 1])
    np.testing.assert_allclose(pt[:, 2], at_uv, rtol=1e-9, atol=1e-12 * at_uv.max())
    np.testing.assert_allclose(p, pt[:, 2] * base(env).pdf_scale, rtol=2e-7)
    # and env_pdf of the returned direction: the same up to the float32 rounding of the direction
    # (about 1e-7 rad, 1.6e-5 texel of u on a 64-texel map; the sun's neighbours differ 2000x, so
    # the lookup there moves up to ~3e-2 relative per 1e-5 texel)
    pd = warp_pdf(env, d)
    np.testing.assert_allclose(pd, p, rtol=3e-2)
    assert np.median(np.abs(pd / p - 1)) < 1e-4   # most samples sit on the sun's steep footprint
    assert abs((patch_probs(env)).sum() - 1) < 1e-9      # quadrature of the NumPy pdf
    # the importance-sampled estimate of the sphere's solid angle
    est = 1 / p.astype(np.float64)
    assert abs(est.mean() - 4 * np.pi) < 4 * est.std() / np.sqrt(len(est))


@pytest.mark.parametrize("which", ["sun", "rooitou"])
def test_density_is_the_lookup_luminance(which):
    """pdf(w) = luminance(env_eval(w)) / integral of luminance(env_eval) dw at every direction
    (Warp env_pdf against Warp env_eval): a one-texel sun is sampled along its bilinear footprint,
    and an estimator of the map's luminance integral has zero variance."""
    env = build(sun_map()) if which == "sun" else rooitou_env()
    H, W = env.lum.shape
    d = uv_to_direction(*np.random.default_rng(6).random((2, 100_000)))
    # and directions on the sun's footprint, where the old density was off by up to 2x
    j, c = np.unravel_index(np.argmax(env.lum), env.lum.shape)
    g = np.random.default_rng(7).random((2, 20_000)) * 2 - 1
    d = np.concatenate([d, uv_to_direction((c + 0.5 + g[0]) / W, (j + g[1]) / (H - 1))])
    lum = warp_eval(env, d).astype(np.float64) @ LUMINANCE
    p = warp_pdf(env, d).astype(np.float64)
    ok = lum > 1e-4 * lum.max()
    ratio = lum[ok] / p[ok]
    np.testing.assert_allclose(ratio, np.median(ratio), rtol=2e-4)
    assert np.all(p[~ok] <= 1e-4 * p.max() * 1.01)
    lum_integral = 2 * np.pi ** 2 * env.total
    assert abs(np.median(ratio) / lum_integral - 1) < 1e-5


def test_lookup_luminance_integral_matches_quadrature():
    """Z (the closed-form patch integrals) against Gauss-Legendre quadrature of the bilinear
    luminance lookup itself."""
    img = sun_map()
    env = build(img)
    H, W = env.lum.shape
    gx, wx = np.polynomial.legendre.leggauss(2)
    gt, wt = np.polynomial.legendre.leggauss(8)
    x = (np.arange(W)[:, None] + 0.5 * (gx + 1)).ravel()
    y = (np.arange(H - 1)[:, None] + 0.5 * (gt + 1)).ravel()
    u, v = np.mod((x + 0.5) / W, 1.0), y / (H - 1)
    L = lookup_numpy(img, u[None, :], v[:, None]) @ LUMINANCE
    w = np.sin(np.pi * v)[:, None] * np.tile(0.5 * wt, H - 1)[:, None] * np.tile(0.5 * wx, W)[None, :]
    Z = (L * w).sum() / (W * (H - 1))
    assert abs(env.total / Z - 1) < 1e-12


@pytest.mark.parametrize("scheme", SCHEMES)
@pytest.mark.parametrize("which", ["sun", "rooitou"])
def test_warp_equals_numpy(scheme, which):
    img = sun_map() if which == "sun" else rooitou()
    rot = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    env = build(img, scheme, rot)
    xi = np.random.default_rng(8).random((20_000, 2)).astype(np.float32).astype(np.float64)
    s = warp_sample(env, xi)
    d, p = sample_numpy(env, xi)
    assert np.max(np.linalg.norm(s[:, :3] - d, axis=1)) < 5e-6
    # the pdf as a function of the direction: in float32, x = u W - 1/2 is within 1e-4 px
    # (u's resolution 6e-8 times W = 1024), and the pdf changes by at most its maximum per px
    ref = pdf_numpy(env, s[:, :3])
    np.testing.assert_allclose(s[:, 3], ref, rtol=1e-4, atol=2e-4 * ref.max())
    np.testing.assert_allclose(s[:, 3], p, rtol=3e-2)


def test_row_fraction_solver():
    """The within-patch inversion: F(t) = y F(1) for densities (A0 (1 - t) + A1 t) sin(a + b t),
    including a zero end and the two poles."""
    rng = np.random.default_rng(9)
    n = 20_000
    H = 512
    a_all, b = row_geometry(H)
    j = rng.integers(0, H - 1, n)
    j[:100], j[100:200] = 0, H - 2          # the pole intervals
    A0, A1 = rng.random(n), rng.random(n) * 10
    A0[300:400] = 0.0
    A1[400:500] = 0.0
    y = rng.random(n)
    t = solve_row_fraction_numpy(A0, A1, a_all[j], b, y)

    def F(t):
        i0, i1 = sin_integrals(a_all[j], b, t)
        return A0 * i0 + (A1 - A0) * i1

    np.testing.assert_allclose(F(t), y * F(np.ones(n)), rtol=1e-9, atol=1e-14)
    assert np.all((t >= 0) & (t <= 1))


@functools.lru_cache(maxsize=1)
def _half_sincos_kernel():
    from warp_rbrdf.lights.env_sampling import _half_sincos

    @wp.kernel(module="unique", enable_backward=False)
    def k(h: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.vec2d)):
        i = wp.tid()
        out[i] = _half_sincos(h[i])

    return k


def test_half_angle_sincos_is_float64_exact():
    """The row solver's sine and cosine of b t / 2: the series below SERIES_MAX_HALF_ANGLE
    within 2 ulp of float64 sin and cos (the first omitted term is under half an ulp), libm
    above it; a wrong or float32 factor in the series fails (1/6 rounded to float32: 2.8e6 ulp)."""
    from warp_rbrdf.lights.env_sampling import SERIES_MAX_HALF_ANGLE

    h = np.concatenate([np.linspace(0.0, SERIES_MAX_HALF_ANGLE, 20_001),
                        np.random.default_rng(3).uniform(0.0, 1e-3, 5_000),
                        np.linspace(SERIES_MAX_HALF_ANGLE, 1.6, 101)])
    out = wp.zeros(len(h), dtype=wp.vec2d, device="cpu")
    wp.launch(_half_sincos_kernel(), len(h), inputs=[wp.array(h, dtype=wp.float64, device="cpu"), out],
              device="cpu")
    sc = out.numpy()
    ulp_s = np.abs(sc[:, 0] - np.sin(h)) / np.spacing(np.maximum(np.sin(h), 1e-300))
    ulp_c = np.abs(sc[:, 1] - np.cos(h)) / np.spacing(np.cos(h))
    assert ulp_s.max() <= 2.0 and ulp_c.max() <= 2.0


def test_black_map_cannot_be_sampled():
    env = build(np.zeros((8, 16, 3), np.float32))
    assert env.total == 0 and struct(env).can_sample == 0
    s = warp_sample(env, np.full((4, 2), 0.5))
    assert np.all(s[:, 3] == 0)
    assert np.all(warp_pdf(env, np.tile([0.0, 1.0, 0.0], (4, 1))) == 0)


@pytest.mark.lab
@pytest.mark.parametrize("which", ["sun", "rooitou"])
def test_lab_hierarchical_scheme_is_the_renderer_sampler(which):
    """The lab's comparison struct and kernels, with the ``hierarchical`` scheme, sample and
    evaluate the pdf with the renderer's own functions: the same values to the bit."""
    img = sun_map() if which == "sun" else rooitou()
    rng = np.random.default_rng(10)
    xi = rng.random((20_000, 2))
    d = uv_to_direction(*rng.random((2, 20_000)))
    env, lab = build(img), S.build_scheme(img, S.SCHEME_HIERARCHICAL)
    np.testing.assert_array_equal(warp_sample(lab, xi), warp_sample(env, xi))
    np.testing.assert_array_equal(warp_pdf(lab, d), warp_pdf(env, d))
    assert not np.array_equal(warp_sample(build(img, "marginal"), xi), warp_sample(env, xi))


@pytest.mark.lab
def test_light_only_render_is_the_renderer_render():
    """The benchmark's light-only kernel (lab.env_scheme_render) renders with the ``hierarchical``
    scheme what the renderer renders (same samples, same estimator), so the schemes it compares
    differ only by their environment sample; another scheme gives another image; a scene it does
    not cover is refused."""
    import dataclasses

    from lab import env_scheme_render as ER
    from warp_rbrdf.renderer import Renderer

    path = data_file("envmaps/rooitou_park_1k.hdr")
    r = Renderer(ER.light_only_scene(path, 16, "stratified"))
    image = read_latlong(path)
    ref = r.render(spp=4, seed=3)
    hier, _ = ER.render_light_only(r, S.make_scheme_struct(S.build_scheme(image, S.SCHEME_HIERARCHICAL), r.device),
                                   4, 3)
    assert ref.max() > 0
    np.testing.assert_allclose(hier, ref, rtol=1e-6, atol=1e-7 * ref.max())
    marg, _ = ER.render_light_only(r, S.make_scheme_struct(S.build_scheme(image, S.SCHEME_MARGINAL), r.device), 4, 3)
    assert np.abs(marg - ref).max() > 1e-3 * ref.max()
    sc = r.scene
    mis = dataclasses.replace(sc, materials={"obj": dataclasses.replace(sc.materials["obj"], sampler="mis")})
    with pytest.raises(ValueError, match="sampler other than light"):
        ER.check_light_only(Renderer(mis))
