"""Environment-map importance sampling: the density is normalised, matches its lookup, and an
importance-sampled irradiance estimate matches a quadrature of the map."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import data_file
from lab import env_kernels as K
from lab import testing as T
from warp_rbrdf import transforms
from warp_rbrdf.lights.env_distribution import build_env_distribution, env_pdf_numpy
from warp_rbrdf.lights.env_file import constant_image, read_latlong
from warp_rbrdf.lights.env_map import make_env_struct
from warp_rbrdf.lights.latlong import direction_to_uv, lookup_numpy, uv_to_direction
from warp_rbrdf.renderer import Renderer
from warp_rbrdf.runtime import init_warp

wp = init_warp()


def spot_map(H=32, W=64, seed=0):
    """Smooth random background plus a one-texel 'sun' 10 degrees above the horizon."""
    rng = np.random.default_rng(seed)
    img = rng.uniform(0.05, 0.3, (H, W, 3)).astype(np.float32)
    img[int(round(0.44 * (H - 1))), (5 * W) // 8] = (2000.0, 1800.0, 1500.0)
    img[0, :] = 0.0  # a black pole row (zero-density cells)
    return img


def _env(img, rot=None):
    return build_env_distribution(img, rot)


def warp_pdf(env, dirs):
    s = make_env_struct(env, "cpu")
    out = wp.zeros(len(dirs), dtype=float, device="cpu")
    wp.launch(K.env_pdf_kernel, dim=len(dirs), inputs=[s, wp.array(dirs.astype(np.float32), dtype=wp.vec3)],
              outputs=[out], device="cpu")
    return out.numpy()


def warp_sample(env, xi):
    s = make_env_struct(env, "cpu")
    out = wp.zeros(len(xi), dtype=wp.vec4, device="cpu")
    wp.launch(K.env_sample_kernel, dim=len(xi), inputs=[s, wp.array(xi.astype(np.float32), dtype=wp.vec2)],
              outputs=[out], device="cpu")
    return out.numpy()


def sphere_grid(n_theta=1024, n_phi=2048):
    """Midpoint quadrature nodes (directions) and solid-angle weights over the sphere."""
    t = (np.arange(n_theta) + 0.5) / n_theta * np.pi
    p = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    tt, pp = np.meshgrid(t, p, indexing="ij")
    d = np.stack([np.sin(tt) * np.cos(pp), np.cos(tt), np.sin(tt) * np.sin(pp)], -1).reshape(-1, 3)
    w = (np.sin(tt) * (np.pi / n_theta) * (2 * np.pi / n_phi)).ravel()
    return d, w


def patch_quadrature(H, W, nx=2, nt=6):
    """Gauss-Legendre nodes on every lookup patch (x in [c, c+1], y in [j, j+1] in pixel
    coordinates): directions (N, 3) and solid-angle weights (N,). Exact for the bilinear lookup
    in x, and to ~1e-12 for its product with sin(theta) in y, independently of the sampler's
    closed forms."""
    gx, wx = np.polynomial.legendre.leggauss(nx)
    gt, wt = np.polynomial.legendre.leggauss(nt)
    x = (np.arange(W)[:, None] + 0.5 * (gx + 1)).ravel()
    y = (np.arange(H - 1)[:, None] + 0.5 * (gt + 1)).ravel()
    wxx = np.tile(0.5 * wx, W)
    wyy = np.tile(0.5 * wt, H - 1)
    u = np.mod((x + 0.5) / W, 1.0)
    v = y / (H - 1)
    d = uv_to_direction(u[None, :], v[:, None]).reshape(-1, 3)
    w = (2 * np.pi ** 2 * np.sin(np.pi * v)[:, None] / (W * (H - 1)) * wyy[:, None] * wxx[None, :]).ravel()
    return d, w


def test_pdf_integrates_to_one_exactly():
    env = _env(spot_map())
    d, w = patch_quadrature(*env.lum.shape)
    assert abs(w.sum() - 4 * np.pi) < 1e-10
    assert abs((env_pdf_numpy(env, d) * w).sum() - 1.0) < 1e-10


@pytest.mark.parametrize("rotated", [False, True])
def test_warp_pdf_integrates_to_one_and_matches_numpy(rotated):
    rot = transforms.rotation(37.0, (0.2, 1.0, 0.1))[:3, :3] if rotated else None
    env = _env(spot_map(), rot)
    d, w = patch_quadrature(*env.lum.shape)
    if rot is not None:
        d = d @ rot.T
    p = warp_pdf(env, d)
    assert abs((p * w).sum() - 1.0) < 2e-5
    # and at arbitrary directions the Warp density is the NumPy reference's (float32 lookups)
    d, _ = sphere_grid(256, 512)
    p = warp_pdf(env, d)
    ref = env_pdf_numpy(env, d)
    np.testing.assert_allclose(p, ref, rtol=2e-4, atol=1e-6 * ref.max())


def test_pdf_positive_exactly_where_lookup_is_positive():
    img = np.zeros((16, 32, 3), np.float32)
    img[5, 7] = 1.0  # one texel: its bilinear footprint covers the 4 patches around it
    env = _env(img)
    d, _ = sphere_grid(256, 512)
    L = lookup_numpy(img, *direction_to_uv(d))[:, 0]
    p = env_pdf_numpy(env, d)
    assert np.all(p[L > 1e-9] > 0) and np.all(p[L <= 0] == 0)
    assert (L > 1e-9).sum() > 100


def test_constant_map_is_uniform():
    env = _env(constant_image((0.3, 0.5, 0.7)))
    d, _ = sphere_grid(64, 128)
    np.testing.assert_allclose(env_pdf_numpy(env, d), 1 / (4 * np.pi), rtol=1e-12)
    np.testing.assert_allclose(warp_pdf(env, d), 1 / (4 * np.pi), rtol=1e-6)


def test_samples_follow_pdf():
    """Returned pdf equals the pdf of the returned direction; a histogram of the sampled
    directions over the lookup's patches matches the patch probabilities (quadrature)."""
    img = spot_map(16, 32, seed=2)
    img[img > 100] = 5.0  # a moderate spot so that many patches get enough samples
    env = _env(img)
    rng = np.random.default_rng(1)
    n = 400_000
    s = warp_sample(env, rng.random((n, 2)))
    d, pdf = s[:, :3], s[:, 3]
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(env_pdf_numpy(env, d), pdf, rtol=2e-4, atol=1e-6 * pdf.max())
    H, W = env.lum.shape
    u, v = direction_to_uv(d)
    c = np.floor(np.mod(u * W - 0.5, W)).astype(int) % W
    r = np.clip(np.floor(v * (H - 1)).astype(int), 0, H - 2)
    counts = np.bincount(r * W + c, minlength=(H - 1) * W).reshape(H - 1, W)
    q, w = patch_quadrature(H, W)
    expected = n * (env_pdf_numpy(env, q) * w).reshape(H - 1, -1, W, 2).sum(axis=(1, 3))
    assert counts[expected == 0].sum() == 0
    m = expected > 50
    z = (counts[m] - expected[m]) / np.sqrt(expected[m])
    k = m.sum()
    assert k > 300
    assert np.abs(z).max() < 5.5 and abs(np.mean(z ** 2) - 1) < 5 * np.sqrt(2 / k)


def upward_irradiance(img, rotation=None):
    """E = integral of L(w) max(0, w.y) dw for the bilinear lookup; exact in u (each column's
    hat integrates to one texel), Gauss-Legendre in v over each row's tent."""
    H, W = img.shape[:2]
    x, wx = np.polynomial.legendre.leggauss(16)
    Wv = np.zeros(H)
    for r in range(H):
        for a, b in ((r - 1, r), (r, r + 1)):  # the two halves of row r's tent, in y units
            lo, hi = max(a, 0), min(b, H - 1)
            if hi <= lo:
                continue
            y = 0.5 * (hi - lo) * x + 0.5 * (hi + lo)
            tent = 1 - np.abs(y - r)
            v = y / (H - 1)
            f = tent * np.maximum(np.cos(np.pi * v), 0) * np.sin(np.pi * v)
            Wv[r] += 0.5 * (hi - lo) * (wx * f).sum() / (H - 1)
    if rotation is not None:
        raise NotImplementedError
    return 2 * np.pi ** 2 / W * np.einsum("r,rwc->c", Wv, img.astype(np.float64))


def check_irradiance(img, sampler, spp=64, res=16, light=None):
    E = upward_irradiance(img)
    env = light if light is not None else T.image_env(img)
    sc = T.plane_scene(T.lambert(albedo=1.0, sampler=sampler), [env], spp=spp, resolution=res)
    # the hidden materials and spheres under the plane of lab.testing.common_kernel: the common
    # test kernel, shared with the render tests of other files
    out, var = Renderer(T.common_kernel(sc)).render(return_variance=True)
    n = res * res
    m = out.mean(axis=(0, 1)) * np.pi
    se = np.pi * np.sqrt(var.mean(axis=(0, 1)) / spp / n)
    assert np.all(np.abs(m - E) <= 4 * se + 1e-6 * E), (m, E, se)
    return m, E, se


@pytest.mark.parametrize("sampler", ["light", "mis"])
def test_irradiance_synthetic_sun(sampler):
    m, E, se = check_irradiance(spot_map(), sampler)
    assert np.all(se < 0.05 * E)  # importance sampling keeps the error small


@pytest.mark.parametrize("sampler", ["light", "mis"])
def test_irradiance_rooitou_park(sampler):
    path = data_file("envmaps/rooitou_park_1k.hdr")
    img = read_latlong(path)
    from warp_rbrdf.scene import LightSpec

    m, E, se = check_irradiance(img, sampler, spp=64, light=LightSpec(type="envmap", file=path))
    assert np.all(se < 0.05 * E)
