"""MIS compensation of the environment sample (``integrator.mis_compensation``,
:func:`warp_rbrdf.lights.env_distribution.compensated_distribution`): the distribution it
samples, when the renderer uses it, and that renders keep their expectation with it."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import data_file
from lab import testing as T
from lab.mitsuba_reference import sphere_mask, sphere_scene
from warp_rbrdf.errors import SceneError
from warp_rbrdf.lights.env_distribution import (build_env_distribution, compensated_distribution,
                                                env_pdf_numpy, mean_luminance)
from warp_rbrdf.lights.env_file import constant_image
from warp_rbrdf.lights.env_map import make_env_struct
from warp_rbrdf.lights.latlong import luminance_of
from warp_rbrdf.renderer import Renderer
from warp_rbrdf.scene import load_scene

from test_warp_envmap import patch_quadrature, spot_map


def test_mean_luminance_of_a_constant_map():
    env = build_env_distribution(constant_image((0.2, 0.5, 0.1)))
    expected = float(luminance_of(np.array([0.2, 0.5, 0.1], np.float32)))
    np.testing.assert_allclose(mean_luminance(env), expected, rtol=1e-6)


def test_compensated_distribution_samples_the_luminance_less_the_fraction_of_its_mean():
    env = build_env_distribution(spot_map())
    c = compensated_distribution(env, 0.5)
    np.testing.assert_array_equal(c.lum, np.maximum(env.lum - 0.5 * mean_luminance(env), 0.0))
    assert c.image is env.image and c.rotation is env.rotation
    assert 0 < c.total < env.total
    # a normalised density of the compensated luminance (exact quadrature of the lookup)
    d, w = patch_quadrature(*env.lum.shape)
    p = env_pdf_numpy(c, d)
    assert abs((p * w).sum() - 1.0) < 1e-10
    # zero where the map is below the cut, larger than the full density on the sun
    assert (p == 0).mean() > 0.5
    sun = np.argmax(env_pdf_numpy(env, d))
    assert p[sun] > env_pdf_numpy(env, d)[sun]


def test_compensation_leaves_what_it_cannot_use():
    env = build_env_distribution(spot_map())
    assert compensated_distribution(env, 0.0) is env
    flat = build_env_distribution(constant_image((0.3, 0.3, 0.3)))
    assert compensated_distribution(flat, 1.0) is flat          # nothing above the mean
    assert compensated_distribution(flat, 0.5).total > 0        # a constant less half of itself
    black = build_env_distribution(constant_image((0.0, 0.0, 0.0)))
    assert compensated_distribution(black, 0.5) is black
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        compensated_distribution(env, 1.5)


def _sphere(material, sampler=None, compensation=0.25, res=24):
    env = data_file("envmaps/rooitou_park_1k.hdr")
    sc = sphere_scene(material, env, spp=4, resolution=res, pattern="stratified")
    if sampler is not None:
        sc.materials["obj"].sampler = sampler
    sc.integrator.mis_compensation = compensation
    return T.common_kernel(sc)


def test_the_renderer_compensates_only_where_every_environment_sample_is_combined_by_mis():
    lam = ("lambert", 0.5)
    assert Renderer(_sphere(lam)).mis_compensated
    assert not Renderer(_sphere(lam, compensation=0.0)).mis_compensated
    r = Renderer(_sphere(lam, sampler="light"))     # beside the common kernel's hidden `mis` material
    assert not r.mis_compensated and r.env_sampling is r.env_data


def test_scene_key_is_checked(tmp_path):
    base = '[camera]\nresolution = [8, 8]\n[integrator]\nmis_compensation = {}\n' \
           '[materials.m]\ntype = "lambert"\n[[shapes]]\ntype = "sphere"\nmaterial = "m"\n'
    f = tmp_path / "s.toml"
    f.write_text(base.format("0.5"))
    assert load_scene(f).integrator.mis_compensation == 0.5
    f.write_text(base.format("1.5"))
    with pytest.raises(SceneError, match=r"integrator\.mis_compensation.*\[0\.0, 1\.0\]"):
        load_scene(f)


def _channel_means(r, spp, seeds):
    mask = sphere_mask(r.scene.camera.resolution[0])
    runs = [r.render(spp=spp, seed=s, return_variance=True) for s in seeds]
    mean = np.mean([np.asarray(i, np.float64)[mask].mean(axis=0) for i, _ in runs], axis=0)
    se2 = np.mean([np.asarray(v, np.float64)[mask].sum(axis=0) / spp for _, v in runs], axis=0) \
        / mask.sum() ** 2 / len(runs)
    return mean, se2


@pytest.mark.parametrize("material", [("lambert", 0.5), "rgl/satin_rosaline_rgb.bsdf"])
def test_compensated_renders_keep_their_expectation(material):
    """A Lambert sphere (``mis``) and an RGL film (``mis-rgl``) under rooitou's sun, with the
    compensation at 0.25 and at 1 against none: the same channel means within 4 standard
    errors of the difference. The control: the compensated distribution under the ``light``
    sampler (no BSDF sample to cover the cut-off sky) is far outside that."""
    m = material if isinstance(material, tuple) else data_file(material)
    ref = _channel_means(Renderer(_sphere(m, compensation=0.0)), 64, range(3))
    for frac in (0.25, 1.0):
        r = Renderer(_sphere(m, compensation=frac))
        assert r.mis_compensated
        got = _channel_means(r, 64, range(3, 6))
        z = (got[0] - ref[0]) / np.sqrt(got[1] + ref[1])
        assert np.all(np.abs(z) < 4.0), (frac, z)
    if isinstance(material, tuple):
        r = Renderer(_sphere(m, sampler="light", compensation=0.0))
        full = _channel_means(r, 64, range(3))
        r.env = make_env_struct(compensated_distribution(r.env_data, 1.0), "cpu")
        biased = _channel_means(r, 64, range(3, 6))
        z = (biased[0] - full[0]) / np.sqrt(biased[1] + full[1])
        assert np.all(np.abs(z) > 10.0), z
