"""Renders of the reference sphere under each environment sampling scheme of
:mod:`lab.env_schemes`, for ``benchmarks.bench_env_sampling``.

The renderer's kernel samples the environment with the hierarchical warp only, so the schemes
are compared with the kernel here: the renderer's estimator for a scene of analytic spheres with
Lambert materials, sampler ``light``, direct lighting (``max_depth = 1``) and no directional
light, written out for that case -- the same camera rays, sample dimensions and streams
(:mod:`warp_rbrdf.sample_patterns`), shading frame, ray offset, shadow ray and estimator
``f cos L / pdf`` -- with the environment sample of :func:`lab.env_schemes.scheme_sample_uv`. With
the ``hierarchical`` scheme it renders what :class:`warp_rbrdf.renderer.Renderer` renders
(``tests/test_env_sampling.py`` checks it to float rounding)."""
from __future__ import annotations

import dataclasses
import os
import time

import numpy as np
import warp as wp

from warp_rbrdf import camera as C
from warp_rbrdf import geometry as G
from warp_rbrdf import integrator, registry, sample_patterns
from warp_rbrdf.lights.env_map import env_dir_to_uv, env_eval_uv
from warp_rbrdf.materials.data import Materials
from warp_rbrdf.materials.lambert import lambert_eval
from warp_rbrdf.shipped_kernels import load_module, render_module_options

from .env_schemes import SchemeEnvMap, scheme_sample_uv

_closest_hit, _any_hit = G.make_tracer(has_mesh=False, has_spheres=True)


def light_only_scene(path, res: int, pattern: str, albedo: float = 0.5):
    """The reference sphere scene (:func:`lab.mitsuba_reference.sphere_scene`) with a Lambert
    sphere of ``albedo`` and sampler ``light``: one environment sample and its shadow ray per
    camera sample, no BSDF sample."""
    from lab import mitsuba_reference as MR

    sc = MR.sphere_scene(("lambert", albedo), path, 1, res, pattern=pattern)
    mat = dataclasses.replace(sc.materials["obj"], sampler="light")
    return dataclasses.replace(sc, materials={"obj": mat},
                               integrator=dataclasses.replace(sc.integrator, sampler="light"))


@wp.kernel(module="unique", enable_backward=False, module_options=render_module_options())
def light_only_tile(geo: G.SceneGeometry, cam: C.Camera, env: SchemeEnvMap, mats: Materials,
                    spp: int, seed: int, pattern: int, hide_env: int, eps: float,
                    x0: int, y0: int, tile_w: int, out_mean: wp.array(dtype=wp.vec3)):
    tid = wp.tid()
    px = x0 + tid % tile_w
    py = y0 + tid // tile_w
    if px >= cam.width or py >= cam.height:
        return
    pix = py * cam.width + px
    pseed = sample_patterns.pixel_seed(seed, pix)
    acc = wp.vec3(0.0)
    for s in range(spp):
        Lsum = wp.vec3(0.0)
        j = sample_patterns.sample_2d(pattern, pseed, s, spp, 0)
        d = C.camera_ray(cam, float(px) + j[0], float(py) + j[1])
        o = cam.origin
        hit, t, ng, ns, m = _closest_hit(geo, o, d)
        if hit == 0:
            if hide_env == 0:
                Lsum = env_eval_uv(env.env, env_dir_to_uv(env.env, d))
        elif env.env.can_sample == 1:
            p = o + d * t
            wo_w = -d
            if wp.dot(ns, wo_w) <= 1.0e-6:
                ns = ng
            T = integrator.onb_tangent(ns)
            B = integrator.onb_bitangent(ns)
            wo = wp.vec3(wp.dot(wo_w, T), wp.dot(wo_w, B), wp.dot(wo_w, ns))
            org = p + ng * (eps * (1.0 + wp.max(wp.abs(p[0]), wp.max(wp.abs(p[1]), wp.abs(p[2])))))
            ls, luv = scheme_sample_uv(env, sample_patterns.sample_2d(pattern, pseed, s, spp, 1))
            wl = wp.vec3(ls[0], ls[1], ls[2])
            pl = ls[3]
            if pl > 0.0 and wp.dot(wl, ng) > 0.0:
                wi = wp.vec3(wp.dot(wl, T), wp.dot(wl, B), wp.dot(wl, ns))
                if wi[2] > 0.0:
                    fv = lambert_eval(mats, m, wi, wo)
                    if integrator.max3(fv) > 0.0:  # noqa: SIM102 - Warp evaluates both sides of `and`
                        if not _any_hit(geo, org, wl, 1.0e30):
                            # the renderer's expression with throughput 1 and MIS weight 1
                            Lsum = (wp.cw_mul(wp.vec3(1.0), wp.cw_mul(fv, env_eval_uv(env.env, luv)))
                                    * (wi[2] * 1.0 / pl))
        acc = acc + Lsum
    out_mean[pix] = acc * (1.0 / float(spp))


def check_light_only(renderer) -> None:
    """ValueError unless ``renderer``'s scene is what :func:`light_only_tile` renders: analytic
    spheres only, Lambert materials with sampler ``light``, ``max_depth = 1``, no directional
    light."""
    sc, g, md = renderer.scene, renderer.geometry, renderer.material_data
    problems = []
    if g.num_triangles > 0:
        problems.append("triangles")
    if sc.directional_lights:
        problems.append("directional lights")
    if sc.integrator.max_depth != 1:
        problems.append(f"max_depth {sc.integrator.max_depth}")
    if list(md.kinds_used()) != [registry.material("lambert").code]:
        problems.append("a material other than lambert")
    if np.any(np.asarray(md.combine) != registry.COMBINE_LIGHT):
        problems.append("a sampler other than light")
    if problems:
        raise ValueError("not a light-only Lambert sphere scene: " + ", ".join(problems))


def compile_light_only(device) -> str:
    """Load (or compile) :func:`light_only_tile` for ``device`` as the renderer loads its kernel;
    returns where it came from (``"cache"`` or ``"compiled"``)."""
    return load_module(light_only_tile.module, device)


def render_light_only(renderer, env: SchemeEnvMap, spp: int, seed: int, threads: int | None = None):
    """(image (H, W, 3) float32, render seconds) of ``renderer``'s scene
    (:func:`check_light_only`) with the environment sampled by ``env``'s scheme; tiles and
    threads as :meth:`warp_rbrdf.renderer.Renderer.render`."""
    check_light_only(renderer)
    sc = renderer.scene
    W, H = sc.camera.resolution
    dev = renderer.device
    mean = wp.zeros(W * H, dtype=wp.vec3, device=dev)
    pattern = sample_patterns.kernel_pattern(sc.integrator.pattern, renderer.material_data)
    fixed = [renderer.scene_geometry, renderer.camera, env, renderer.materials, int(spp), int(seed), pattern,
             1 if sc.integrator.hide_environment else 0, renderer.ray_epsilon]

    def one(tile):
        x0, y0, tw, th = tile
        wp.launch(light_only_tile, dim=tw * th, inputs=fixed + [x0, y0, tw], outputs=[mean], device=dev)

    tl = integrator.tiles(W, H, sc.integrator.tile_size)
    t0 = time.perf_counter()
    integrator.launch_tiles(one, tl, int(threads or os.cpu_count() or 1))
    wp.synchronize_device(dev)
    seconds = time.perf_counter() - t0
    return mean.numpy().reshape(H, W, 3).astype(np.float32), seconds
