"""Sample patterns and streams (issue 21 item 2): every 2-D dimension is stratified (padded CMJ,
or Owen-scrambled Sobol), and the same user seed with another sampler gives independent light
and BSDF samples while the camera rays (dimension 0) and, for one sampler, every material keep
common random numbers."""
from __future__ import annotations

import numpy as np
import pytest

from warp_rbrdf import registry
from warp_rbrdf import sample_patterns as P
from lab import testing as T
from warp_rbrdf.renderer import Renderer
from warp_rbrdf.runtime import init_warp

from conftest import data_file

wp = init_warp()


@wp.kernel
def _points(pattern: int, spp: int, seed: int, dim: int, out: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    out[i] = P.sample_2d(pattern, P.pixel_seed(seed, i // spp), i % spp, spp, dim)


def points(pattern: int, spp: int, pixels=64, seed=1, dim=1) -> np.ndarray:
    """(pixels, spp, 2) samples of dimension ``dim`` for ``pixels`` pixels."""
    out = wp.zeros(spp * pixels, dtype=wp.vec2, device="cpu")
    wp.launch(_points, dim=spp * pixels, inputs=[pattern, spp, seed, dim, out], device="cpu")
    return out.numpy().reshape(pixels, spp, 2).astype(np.float64)


def one_per_cell(x, nx, ny) -> bool:
    """Every pixel's points fill the nx x ny grid's cells once each."""
    cell = np.floor(x[..., 0] * nx).astype(int) * ny + np.floor(x[..., 1] * ny).astype(int)
    return all(len(np.unique(c)) == nx * ny for c in cell)


@pytest.mark.parametrize("spp", [16, 64])
def test_sobol_power_of_two_prefixes_are_nets(spp):
    m = int(np.log2(spp))
    for dim in (0, 1, 2, 5):
        x = points(P.PATTERN_SOBOL, spp, dim=dim)
        assert all(one_per_cell(x, 2 ** a, 2 ** (m - a)) for a in range(m + 1)), dim
        assert 0 <= x.min() and x.max() < 1


@pytest.mark.parametrize("dim", [0, 1, 2])
def test_cmj_is_jittered_and_latin(dim):
    x = points(P.PATTERN_STRATIFIED, 16, dim=dim)
    assert one_per_cell(x, 4, 4) and one_per_cell(x, 16, 1) and one_per_cell(x, 1, 16)


def test_independent_is_not_stratified():
    """The check above can fail: plain random points miss cells."""
    assert not one_per_cell(points(P.PATTERN_INDEPENDENT, 16), 4, 4)


@pytest.mark.parametrize("pattern", [P.PATTERN_STRATIFIED, P.PATTERN_SOBOL, P.PATTERN_INDEPENDENT])
def test_dimensions_and_pixels_are_decorrelated(pattern):
    """Padding: the light and BSDF dimensions of one sample are not correlated with each other or
    with the camera's (correlation over 4096 pixels x 16 samples)."""
    a, b, c = (points(pattern, 16, pixels=4096, dim=d).reshape(-1, 2) for d in (0, 1, 2))
    for x, y in ((a, b), (b, c), (a, c)):
        for i in range(2):
            for k in range(2):
                assert abs(np.corrcoef(x[:, i], y[:, k])[0, 1]) < 0.02


def test_stream_key():
    light = registry.combine_code(registry.strategy("light"))
    mis = registry.combine_code(registry.strategy("mis"))
    cos = registry.technique("cosine").code
    k_light = P.stream_key([light], [cos])
    assert k_light == P.stream_key([light, light], [cos, cos])       # a set of strategies
    assert P.stream_key([light, mis], [cos, cos]) == P.stream_key([mis, light], [cos, cos])
    assert len({k_light, P.stream_key([mis], [cos]), P.stream_key([light, mis], [cos, cos])}) == 3
    assert 0 <= k_light <= P.STREAM_KEY_MASK
    assert k_light == P.stream_key(np.array([light], np.int32), np.array([cos], np.int32))


def test_stream_changes_every_dimension_but_the_camera():
    base = P.PATTERN_CODES["stratified"]
    k1, k2 = base | (11 << P.STREAM_SHIFT), base | (12 << P.STREAM_SHIFT)
    np.testing.assert_array_equal(points(k1, 16, dim=0), points(k2, 16, dim=0))
    for dim in (1, 2, 3):
        assert not np.any(np.all(points(k1, 16, dim=dim) == points(k2, 16, dim=dim), axis=-1))
    # and the stream keeps the pattern's stratification
    assert one_per_cell(points(k2, 16, dim=1), 4, 4)


def _sun_plane(sampler, albedo=0.5, res=32):
    rng = np.random.default_rng(0)
    img = rng.uniform(0.05, 0.3, (32, 64, 3)).astype(np.float32)
    img[8, 40] = (2000.0, 1800.0, 1500.0)   # a sun 45 degrees above the plane
    # the common test kernel (lab.testing): its hidden materials' strategies are the same in
    # every scene, the visible material's "light" or "mis" makes the scenes' sets differ
    return Renderer(T.common_kernel(T.plane_scene(T.lambert(albedo=albedo, sampler=sampler),
                                                  [T.image_env(img)], spp=1, resolution=res)))


def _noise(r, seed):
    """One render's noise (seeds 2 seed + 1 minus 2 seed + 2), luminance per pixel."""
    a = r.render(spp=1, seed=2 * seed + 1) - r.render(spp=1, seed=2 * seed + 2)
    return (a.astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722])).ravel()


def test_another_sampler_gives_independent_noise():
    """The same seeds rendered with 'light' and with 'mis' (whose environment sample is the same
    estimator part): the renders' noise is uncorrelated (1024 pixels: |r| < 5 / 32). With one
    sampler, two materials (albedo 0.5 and 0.8) keep common random numbers: the same noise up to
    the albedo (the test's control: it sees correlation where there is some)."""
    light, mis = _sun_plane("light"), _sun_plane("mis")
    n_light, n_mis = _noise(light, 0), _noise(mis, 0)
    assert n_light.std() > 0 and n_mis.std() > 0
    assert abs(np.corrcoef(n_light, n_mis)[0, 1]) < 5 / 32
    n_bright = _noise(_sun_plane("light", albedo=0.8), 0)
    np.testing.assert_allclose(n_bright, n_light * 0.8 / 0.5, rtol=1e-4, atol=1e-6 * np.abs(n_light).max())
    assert np.corrcoef(n_light, n_bright)[0, 1] > 0.999


def _pattern_means(x):
    """Per-pixel means of test integrands over each pixel's points (pixels, spp, 2), and their
    exact integrals over the unit square."""
    u, v = x[..., 0], x[..., 1]
    f = np.stack([u, v, u * v, u * u, (u > 0.9) & (v < 0.35), v > 0.95], axis=-1).mean(axis=1)
    return f, np.array([0.5, 0.5, 0.25, 1.0 / 3.0, 0.1 * 0.35, 0.05])


@pytest.mark.parametrize("spp", [5, 8, 32, 128, 130, 512, 16, 64, 12])
@pytest.mark.parametrize("pattern", [P.PATTERN_STRATIFIED, P.PATTERN_SOBOL])
def test_patterns_are_unbiased_at_any_spp(pattern, spp):
    """Every sample of a pattern is uniform over the unit square, whatever the spp: the mean over
    4096 pixels of each pixel's estimate of a few integrals (smooth, and indicators of strips at
    the pattern's last columns and rows) equals the integral within 5 standard errors. A CMJ
    pattern that keeps the first spp cells of its m x n grid in row order (Kensler's padding for
    spp < m * n: 5, 32, 128, 130, 512 here) is off by 90 to 17000 standard errors (mean of x 0.490 at
    128 spp)."""
    f, exact = _pattern_means(points(pattern, spp, pixels=4096, seed=7, dim=1))
    se = f.std(axis=0, ddof=1) / np.sqrt(len(f))
    z = (f.mean(axis=0) - exact) / np.maximum(se, 1e-7)
    assert np.all(np.abs(z) < 5.0), (spp, np.round(z, 1))


def test_stratified_render_has_the_same_mean_at_any_spp():
    """The render-level consequence: a Lambert sphere under the tiny sun of rooitou (32 px, 4
    seeds each) has the same channel means with the default stratified pattern at 32 spp (not a
    grid product: 5 x 7 cells, 3 unused) as at 36 spp (6 x 6), within 4 standard errors of the
    difference (per-pixel sample variances: an upper bound for stratified samples). Keeping the
    first 32 cells in row order made the 32-spp image 4.3-4.5 % brighter (about 20 standard
    errors)."""
    from lab import mitsuba_reference as MR

    env = data_file("envmaps/rooitou_park_1k.hdr")
    # with the hidden materials of lab.testing.common_kernel inside the sphere: the common test kernel
    r = Renderer(T.common_kernel(MR.sphere_scene(("lambert", 0.5), env, spp=8, resolution=32,
                                                 pattern="stratified")))
    mask = MR.sphere_mask(32)
    mean, se2 = {}, {}
    for spp in (32, 36):
        runs = [r.render(spp=spp, seed=s, return_variance=True) for s in range(4)]
        mean[spp] = np.mean([np.asarray(i, np.float64)[mask].mean(axis=0) for i, _ in runs], axis=0)
        se2[spp] = np.mean([np.asarray(v, np.float64)[mask].sum(axis=0) / spp for _, v in runs], axis=0) \
            / mask.sum() ** 2 / len(runs)
    diff = mean[32] - mean[36]
    assert np.all(np.abs(diff) < 4 * np.sqrt(se2[32] + se2[36])), (diff / mean[36], np.sqrt(se2[32]) / mean[36])
