"""Radiometric checks of the Warp integrator: white furnace, directional closed form, shadows,
determinism, camera and environment-map conventions."""
from __future__ import annotations

import numpy as np
import pytest

from lab import testing as T
from warp_rbrdf import registry
from warp_rbrdf.renderer import Renderer
from warp_rbrdf.scene import CameraSpec, IntegratorSpec, Scene, ShapeSpec

N_SIGMA = 4.0


def mean_and_se(img, var, spp):
    """Mean over all pixels and channels and its standard error (pixels are independent)."""
    n = img.shape[0] * img.shape[1]
    m = img.mean(axis=(0, 1))
    se = np.sqrt(var.mean(axis=(0, 1)) / spp / n)
    return m, se


#: every registered strategy that needs no inverse-CDF data and no material of its own (a
#: strategy added to the registry joins the furnaces below; the table strategies run theirs in
#: test_cdf_samplers.py, the rgl ones in test_sampler_contract.py)
FURNACE_STRATEGIES = registry.BASE_STRATEGIES


def hidden(sc: Scene) -> Scene:
    """``sc`` with the hidden materials and shapes of :func:`lab.testing.common_kernel`: the
    scenes of this module (Lambert materials, the techniques of :data:`FURNACE_STRATEGIES`)
    share the common test kernel with the render tests of other files."""
    return T.common_kernel(sc)


@pytest.mark.parametrize("sampler", FURNACE_STRATEGIES)
@pytest.mark.parametrize("pattern", ["stratified", "independent"])
def test_white_furnace_plane(sampler, pattern):
    L = 0.7
    sc = T.plane_scene(T.lambert(albedo=1.0, sampler=sampler), [T.constant_env(L)], spp=16,
                       pattern=pattern)
    img, var = Renderer(hidden(sc)).render(return_variance=True)
    m, se = mean_and_se(img, var, 16)
    assert np.all(np.abs(m - L) <= N_SIGMA * se + 1e-5), (m, se)
    if sampler == "cosine":  # zero-variance estimator
        np.testing.assert_allclose(img, L, rtol=1e-5)


@pytest.mark.parametrize("sampler", FURNACE_STRATEGIES)
def test_white_furnace_sphere(sampler):
    """White furnace on the (analytic) unit sphere: every sampler returns the environment's
    radiance (the bound below also held for the former subdivision-5 icosphere, whose light loss
    where the shading hemisphere dips below the facets is O(facet angle^2), < 0.1 %)."""
    L = 1.0
    sc = Scene(camera=CameraSpec(origin=(0, 0, 3.0), target=(0, 0, 0), fov=30, resolution=(16, 16)),
               integrator=IntegratorSpec(spp=16, hide_environment=True, tile_size=8),
               materials={"m": T.lambert(albedo=1.0, sampler=sampler)},
               shapes=[ShapeSpec(type="sphere", material="m", radius=1.0)],
               lights=[T.constant_env(L)])
    img, var = Renderer(hidden(sc)).render(return_variance=True)
    # pixels fully inside the sphere's silhouette (radius 1 at distance 3, fov 30 deg)
    W = 16
    px = (np.arange(W) + 0.5) / W * 2 - 1
    tx = np.tan(np.radians(15))
    r_img = np.hypot(px[None, :], px[:, None]) * tx * 3.0
    inside = r_img < 0.75
    m = img[inside].mean(axis=0)
    se = np.sqrt(var[inside].mean(axis=0) / 16 / inside.sum())
    assert np.all(np.abs(m - L) <= N_SIGMA * se + 2e-3), (m, se)


def test_max_depth_furnace_plane():
    sc = T.plane_scene(T.lambert(albedo=1.0), [T.constant_env(0.5)], spp=8, max_depth=3)
    img, var = Renderer(hidden(sc)).render(return_variance=True)
    m, se = mean_and_se(img, var, 8)
    assert np.all(np.abs(m - 0.5) <= N_SIGMA * se + 1e-5)


def test_directional_closed_form():
    albedo, E, theta = 0.6, 2.5, np.radians(30)
    to_light = (np.sin(theta), np.cos(theta), 0.0)
    sc = T.plane_scene(T.lambert(albedo=albedo), [T.directional(to_light, E)], spp=2)
    img = Renderer(hidden(sc)).render()
    np.testing.assert_allclose(img, albedo / np.pi * E * np.cos(theta), rtol=1e-5)


def test_colinear_with_view_light():
    from warp_rbrdf.scene import LightSpec

    sc = T.plane_scene(T.lambert(albedo=0.5), [LightSpec(type="directional", irradiance=(1, 1, 1),
                                                          colinear_with_view=True)], spp=1)
    img = Renderer(hidden(sc)).render()  # the camera looks straight down: cos = 1
    np.testing.assert_allclose(img, 0.5 / np.pi, rtol=1e-5)


def test_shadow_of_sphere():
    cam = CameraSpec(origin=(0, 4, 4), target=(0, 0, 0), fov=50, resolution=(32, 32))
    sc = Scene(camera=cam, integrator=IntegratorSpec(spp=4, tile_size=16),
               materials={"m": T.lambert(albedo=0.8)},
               shapes=[ShapeSpec(type="plane", material="m", size=(20, 20)),
                       ShapeSpec(type="sphere", material="m", center=(0, 1.5, -1.0), radius=0.5)],
               lights=[T.directional((0, 1, 0), 3.0)])
    img = Renderer(hidden(sc)).render()
    lit = 0.8 / np.pi * 3.0
    # the plane point under the sphere centre (shadowed) and one far from it (lit)
    (sx, sy), (lx, ly) = T.project_to_film(cam, [(0, 0, -1.0), (1.5, 0, 1.5)])
    shadow = img[int(sy), int(sx)]
    assert np.all(shadow == 0.0), shadow
    np.testing.assert_allclose(img[int(ly), int(lx)], lit, rtol=1e-5)


def test_same_seed_same_image_and_threads():
    sc = hidden(T.plane_scene(T.lambert(albedo=0.9), [T.constant_env(1.0)], spp=4, resolution=24))
    r = Renderer(sc)
    a = r.render(seed=3, threads=2)
    b = r.render(seed=3, threads=1)
    c = r.render(seed=4, threads=2)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    sc.integrator.tile_size = 5  # a different tiling gives the same pixels
    assert np.array_equal(Renderer(sc).render(seed=3), a)


def test_camera_orientation():
    """World +X is image right and +Y is image up for a camera on +Z looking at -Z."""
    cam = CameraSpec(origin=(0, 0, 5), target=(0, 0, 0), fov=40, resolution=(32, 32))
    sc = Scene(camera=cam, integrator=IntegratorSpec(spp=1, hide_environment=True),
               materials={"m": T.lambert(albedo=1.0)},
               shapes=[ShapeSpec(type="sphere", material="m", center=(1.0, 0.5, 0), radius=0.3)],
               lights=[T.directional((0, 0, 1), 1.0)])
    img = Renderer(hidden(sc)).render()[..., 0]
    ys, xs = np.nonzero(img > 0)
    assert xs.mean() > 16 and ys.mean() < 16
    px, py = T.project_to_film(cam, [(1.0, 0.5, 0)])[0]
    assert abs(xs.mean() + 0.5 - px) < 1.0 and abs(ys.mean() + 0.5 - py) < 1.0


def test_environment_seen_by_camera_matches_numpy_lookup():
    """Camera rays that miss return the map with the conventions' lookup (u, v and rows)."""
    from warp_rbrdf.camera import camera_rays_numpy
    from warp_rbrdf.lights.latlong import direction_to_uv, lookup_numpy

    H, W = 32, 64
    v = np.arange(H)[:, None] / (H - 1)
    u = (np.arange(W)[None, :] + 0.5) / W
    img = np.stack([1 + np.cos(2 * np.pi * u) + 0 * v, 1 + np.cos(np.pi * v) + 0 * u,
                    1 + np.sin(2 * np.pi * u) * np.sin(np.pi * v)], -1).astype(np.float32)
    rot = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], float)  # 90 deg about +Y
    for target, R in [((0, 0, -1), None), ((1, 0.3, 0), rot), ((0, -1, 0.01), None)]:
        cam = CameraSpec(origin=(0, 0, 0), target=target, fov=60, resolution=(16, 16))
        sc = Scene(camera=cam, integrator=IntegratorSpec(spp=64), lights=[T.image_env(img, R)])
        out = Renderer(sc).render()
        # box-filtered reference: mean of the lookup over 8x8 points in each pixel
        sub = (np.arange(8) + 0.5) / 8
        px = (np.arange(16)[:, None] + sub[None, :]).ravel()
        d = camera_rays_numpy(cam, px[None, :], px[:, None])
        ref = lookup_numpy(img, *direction_to_uv(d, R)).reshape(16, 8, 16, 8, 3).mean(axis=(1, 3))
        np.testing.assert_allclose(out, ref, atol=0.02)


def test_hide_environment():
    sc = Scene(camera=CameraSpec(resolution=(8, 8)), integrator=IntegratorSpec(spp=1, hide_environment=True),
               lights=[T.constant_env(2.0)])
    assert np.all(Renderer(sc).render() == 0)
    sc.integrator.hide_environment = False
    np.testing.assert_allclose(Renderer(sc).render(), 2.0, rtol=1e-6)
