"""The Warp materials against the fit package's NumPy evaluation at the same directions."""
from __future__ import annotations

import numpy as np

from fit.formats.angles import half_diff_to_directions, spherical_to_direction
from fit.formats.grid import phi_d_centres, theta_d_centres, theta_h_centres
from fit.formats.measured import MeasuredBRDF
from fit.projection.project import project
from warp_rbrdf import testing as T
from warp_rbrdf.renderer import Renderer
from warp_rbrdf.scene import MaterialSpec


def synthetic_brdf():
    """A table whose every bin differs (so a wrong bin shows), with a few invalid bins."""
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


def renderer_for(spec):
    return Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=4, spp=1))


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


def test_measured_table_matches_numpy():
    b = synthetic_brdf()
    r = renderer_for(MaterialSpec(name="m", type="measured", data=b, scale=(1.0, 2.0, 0.5)))
    scale = np.array([1.0, 2.0, 0.5])
    # at bin centres the float32 Warp code must pick exactly the same bin
    wi, wo = bin_centre_pairs()
    np.testing.assert_allclose(r.eval_material("m", wi, wo), b.evaluate(wi, wo) * scale, rtol=1e-5, atol=1e-7)
    # at random directions: identical except (rarely) at a bin boundary in float32
    wi, wo = random_pairs(20000)
    got, ref = r.eval_material("m", wi, wo), b.evaluate(wi, wo) * scale
    same = np.all(np.isclose(got, ref, rtol=1e-5, atol=1e-7), axis=1)
    assert same.mean() > 0.995, same.mean()
    # below the horizon: 0
    wi[:, 2] *= -1
    assert np.all(r.eval_material("m", wi, wo) == 0)


def test_projected_table_matches_numpy():
    b = synthetic_brdf()
    pb = project(b)
    r = renderer_for(MaterialSpec(name="m", type="projected", data=pb))
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
    spec = MaterialSpec(name="m", type="measured", data=b)
    to_light = np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5])
    to_eye = np.array([-0.5, 0.7, 0.2]) / np.linalg.norm([-0.5, 0.7, 0.2])
    sc = T.plane_scene(spec, [T.directional(to_light, 2.0)], resolution=4, spp=1)
    sc.camera = CameraSpec(origin=tuple(5 * to_eye), target=(0, 0, 0), fov=0.1, resolution=(4, 4))
    img = Renderer(sc).render()
    frame = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # rows: T, B, N (T x B = N)
    wi, wo = frame @ to_light, frame @ to_eye
    ref = b.evaluate(wi, wo) * 2.0 * to_light[1]
    np.testing.assert_allclose(img.reshape(-1, 3), np.broadcast_to(ref, (16, 3)), rtol=1e-4)
