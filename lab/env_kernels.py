"""One-value-per-thread Warp kernels over the renderer's environment (``EnvMap``), for the tests
and benchmarks: the environment functions of :mod:`warp_rbrdf.lights.env_map` and
:mod:`warp_rbrdf.lights.env_sampling` evaluated at arrays of directions or uniforms. (The
comparison schemes have their own kernels in :mod:`lab.env_schemes`.)"""
from __future__ import annotations

import warp as wp

from warp_rbrdf.lights.env_map import EnvMap, env_eval, env_pdf
from warp_rbrdf.lights.env_sampling import env_sample, sample_patch_point


@wp.kernel(enable_backward=False)
def env_pdf_kernel(env: EnvMap, dirs: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    """Solid-angle pdf (1/sr) of the environment sample at each world direction."""
    i = wp.tid()
    out[i] = env_pdf(env, dirs[i])


@wp.kernel(enable_backward=False)
def env_eval_kernel(env: EnvMap, dirs: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    """Radiance arriving from each world direction."""
    i = wp.tid()
    out[i] = env_eval(env, dirs[i])


@wp.kernel(enable_backward=False)
def env_sample_kernel(env: EnvMap, xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec4)):
    """(dx, dy, dz, pdf) of the environment sample of each pair of uniforms."""
    i = wp.tid()
    out[i] = env_sample(env, xi[i])


@wp.kernel(enable_backward=False)
def env_sample_point_kernel(env: EnvMap, xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec4),
                            point: wp.array(dtype=wp.vec3d)):
    """The sample of each pair of uniforms and the float64 (u, v, looked-up luminance) of the
    sampled point."""
    i = wp.tid()
    out[i] = env_sample(env, xi[i])
    point[i] = sample_patch_point(env, xi[i])
