"""The render kernel's lanes (``warp_rbrdf.lanes``): K samples of a pixel whose first BSDF samples
are drawn together. A lane draws the one-at-a-time sample, so the lanes change no estimate:
the ``Marginal2D`` warp over lanes equals the scalar warp, and renders with and without lanes
are the same image up to float rounding (a search stopping on the other side of a rounding tie).
"""
from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from conftest import data_file
from fit.formats.rgl import read_rgl
from warp_rbrdf import lanes as L
from warp_rbrdf.distribution import marginal2d_sample
from warp_rbrdf.distribution.lanes import lane_types, make_marginal2d_sample_lanes
from warp_rbrdf.materials import rgl as R
from warp_rbrdf.renderer import Renderer
from warp_rbrdf.runtime import init_warp
from warp_rbrdf.scene import CameraSpec, IntegratorSpec, LightSpec, MaterialSpec, Scene, ShapeSpec

K = 16
vf, vi = lane_types(K)
_sample_lanes = make_marginal2d_sample_lanes(K)


@wp.kernel
def _warp_both(vals: wp.array(dtype=float), data: int, cond: int, marg: int, ny: int, nx: int, n_slices: int,
               t0: wp.array(dtype=int), w1: wp.array(dtype=float), u: wp.array(dtype=wp.vec2),
               scalar: wp.array(dtype=wp.vec3), lanes: wp.array(dtype=wp.vec3)):
    """Group ``g`` of K uniforms: each drawn by the scalar warp and all K by the lane warp."""
    g = wp.tid()
    tv = vi()
    wv = vf()
    sx = vf()
    sy = vf()
    for i in range(K):
        k = g * K + i
        scalar[k] = marginal2d_sample(vals, data, cond, marg, ny, nx, n_slices, t0[k], w1[k], u[k][0], u[k][1])
        tv[i] = t0[k]
        wv[i] = w1[k]
        sx[i] = u[k][0]
        sy[i] = u[k][1]
    x, y, pdf = _sample_lanes(vals, data, cond, marg, ny, nx, n_slices, tv, wv, sx, sy)
    for i in range(K):
        lanes[g * K + i] = wp.vec3(x[i], y[i], pdf[i])


@pytest.mark.parametrize("material", ["cc_ibiza_sunset_rgb", "paper_white_rgb"])
def test_marginal2d_lanes_equal_the_scalar_warp(material):
    """Both warps of a measured file (luminance and VNDF), every theta_i slice interval, uniforms
    over the whole square with its edges: the lane warp's points and densities are the scalar
    warp's on every lane but rounding ties."""
    init_warp()
    b = read_rgl(data_file(f"rgl/{material}.bsdf"))
    floats, header = R.pack(b)
    h = header(0)
    vals = wp.array(floats, dtype=float, device="cpu")
    rng = np.random.default_rng(4)
    n = 64 * K
    n_theta = int(h[R.RGL_N_THETA])
    t0 = rng.integers(0, max(n_theta - 1, 1), n).astype(np.int32)
    w1 = rng.random(n).astype(np.float32)
    u = rng.random((n, 2)).astype(np.float32)
    u[:8] = [[0, 0], [1, 1], [0, 1], [1, 0], [1e-9, 0.5], [0.5, 1 - 1e-9], [0.5, 0.5], [0.999999, 1e-7]]
    for fields in ((R.RGL_LUM_DATA, R.RGL_LUM_COND, R.RGL_LUM_MARG, R.RGL_LUM_NY, R.RGL_LUM_NX),
                   (R.RGL_VNDF_DATA, R.RGL_VNDF_COND, R.RGL_VNDF_MARG, R.RGL_VNDF_NY, R.RGL_VNDF_NX)):
        scalar = wp.zeros(n, dtype=wp.vec3, device="cpu")
        lanes = wp.zeros(n, dtype=wp.vec3, device="cpu")
        wp.launch(_warp_both, dim=n // K, inputs=[vals, *(int(h[f]) for f in fields), n_theta,
                                                  wp.array(t0, dtype=int), wp.array(w1, dtype=float),
                                                  wp.array(u, dtype=wp.vec2)],
                  outputs=[scalar, lanes], device="cpu")
        a, c = scalar.numpy(), lanes.numpy()
        assert np.isfinite(c).all() and (c[:, 2] >= 0).all()
        same = np.all(np.abs(a - c) <= 1e-6 * np.maximum(1.0, np.abs(a)), axis=1)
        assert same.mean() >= 0.995, f"{material}: {np.count_nonzero(~same)} of {n} lanes differ"
        assert np.abs(a[:, :2] - c[:, :2]).max() < 1e-3       # a tie moves a point by rounding only


def _scene(materials: dict, shapes, spp: int, max_depth: int = 1, resolution: int = 24) -> Scene:
    envmap = data_file("envmaps/studio_small_03_1k.hdr")
    cam = CameraSpec(origin=(0.0, 0.0, 4.0), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=30.0,
                     resolution=(resolution, resolution))
    return Scene(camera=cam, integrator=IntegratorSpec(spp=spp, seed=7, max_depth=max_depth, hide_environment=True,
                                                       pattern="independent"),
                 materials=materials, shapes=list(shapes), lights=[LightSpec(type="envmap", file=envmap)],
                 path="<test lanes>")


def _render(scene: Scene, lanes: int, monkeypatch) -> np.ndarray:
    monkeypatch.setattr(L, "LANES", lanes)
    return Renderer(scene, device="cpu").render(threads=1)


def _same_image(a: np.ndarray, b: np.ndarray):
    scale = float(np.abs(a).mean())
    d = np.abs(a - b).max(-1) / scale
    assert scale > 0
    assert d.mean() < 1e-5, d.mean()
    assert np.mean(d > 1e-3) <= 0.002, np.count_nonzero(d > 1e-3)


def test_lanes_render_the_one_at_a_time_image(monkeypatch):
    """An rgl sphere with its own sampler (``mis-rgl``), 20 spp: one full group of 16 lanes and one
    group with 12 idle lanes; then the same with a path of two vertices (the lanes give the first
    vertex's sample only)."""
    mat = MaterialSpec(name="m", type="rgl", file=data_file("rgl/cc_ibiza_sunset_rgb.bsdf"), sampler="mis-rgl")
    for depth in (1, 2):
        sc = _scene({"m": mat}, [ShapeSpec(type="sphere", material="m")], spp=20, max_depth=depth)
        one = _render(sc, 0, monkeypatch)
        _same_image(one, _render(sc, K, monkeypatch))
    other_seed = _scene({"m": mat}, [ShapeSpec(type="sphere", material="m")], spp=20, max_depth=2)
    other_seed.integrator.seed = 8
    with pytest.raises(AssertionError):      # the comparison tells another estimate apart
        _same_image(one, _render(other_seed, K, monkeypatch))


def test_lanes_with_several_materials_and_a_mesh(monkeypatch):
    """Two rgl materials, a Lambert one and a triangle mesh (a quad behind the spheres), rgl and
    mis samplers: the lanes of a pixel that sees two materials are drawn one at a time (the lane
    form takes one material), the others together; the image is the one-at-a-time image."""
    mats = {"a": MaterialSpec(name="a", type="rgl", file=data_file("rgl/cc_ibiza_sunset_rgb.bsdf"), sampler="mis-rgl"),
            "b": MaterialSpec(name="b", type="rgl", file=data_file("rgl/paper_white_rgb.bsdf"), sampler="rgl"),
            "c": MaterialSpec(name="c", type="lambert", albedo=(0.5, 0.4, 0.3), sampler="mis")}
    shapes = [ShapeSpec(type="sphere", material="a", center=(-0.45, 0.0, 0.0), radius=0.5),
              ShapeSpec(type="sphere", material="b", center=(0.45, 0.0, 0.0), radius=0.5),
              ShapeSpec(type="plane", material="c", size=(3.0, 3.0),     # normal +Y turned to +Z, at z = -1
                        transform=np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, -1], [0, 0, 0, 1]], float))]
    sc = _scene(mats, shapes, spp=16, resolution=32)
    _same_image(_render(sc, 0, monkeypatch), _render(sc, K, monkeypatch))


def test_lanes_for_every_material_and_strategy(monkeypatch):
    """The environment samples of the lanes serve every material with an environment sample:
    Lambert with ``mis`` and ``light``, a rational fit with its default sampler, beside a
    directional light (its shadow rays come before the environment sample); and ``cosine`` (no
    environment sample, only the first hits given). Same image with and without lanes."""
    from warp_rbrdf.paths import PACKAGE_DATA

    mats = {"l": MaterialSpec(name="l", type="lambert", albedo=(0.6, 0.5, 0.4), sampler="mis"),
            "g": MaterialSpec(name="g", type="lambert", albedo=(0.3, 0.5, 0.7), sampler="light"),
            "k": MaterialSpec(name="k", type="lambert", albedo=(0.5, 0.5, 0.5), sampler="cosine"),
            "r": MaterialSpec(name="r", type="rational", file=PACKAGE_DATA / "paper_white_rgb.json")}
    shapes = [ShapeSpec(type="sphere", material=n, center=(-0.9 + 0.6 * k, 0.0, 0.0), radius=0.3)
              for k, n in enumerate(mats)]
    sc = _scene(mats, shapes, spp=19, resolution=32)
    sc.lights.append(LightSpec(type="directional", direction=(0.3, -1.0, -0.4), irradiance=(2.0, 2.0, 2.0)))
    _same_image(_render(sc, 0, monkeypatch), _render(sc, K, monkeypatch))


def test_a_gpu_renderer_takes_one_sample_at_a_time(monkeypatch):
    """The lanes are a CPU form: a renderer on a CUDA device builds the kernel of one sample at a
    time (the same module as ``LANES = 0`` on the CPU), whatever ``LANES`` says."""
    from types import SimpleNamespace

    from warp_rbrdf.shipped_kernels import module_hash

    sc = _scene({"m": MaterialSpec(name="m", type="rgl", file=data_file("rgl/paper_white_rgb.bsdf"),
                                   sampler="mis-rgl")}, [ShapeSpec(type="sphere", material="m")], spp=4)
    r = Renderer(sc, device="cpu")
    monkeypatch.setattr(L, "LANES", 0)
    one = module_hash(r._make_kernels().render_tile.module)
    monkeypatch.setattr(L, "LANES", K)
    lanes = module_hash(r._make_kernels().render_tile.module)
    r.device = SimpleNamespace(is_cpu=False)       # the one attribute _make_kernels reads
    gpu = module_hash(r._make_kernels().render_tile.module)
    assert lanes != one and gpu == one
