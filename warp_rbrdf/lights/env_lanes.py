"""The environment sample (:func:`.env_sampling.env_sample_uv`) of ``K`` samples at once: the
render kernel's lanes (:mod:`warp_rbrdf.lanes`). The hierarchical descent is a chain of
dependent loads and float64 divisions per sample; here each level is taken for all lanes
before the next (:func:`.env_sampling.descend_level` per lane), so the lanes' loads and
divisions overlap; so is the last level, over the four patches under each lane's block
(:func:`.env_sampling.patch_select`, with their texel loads). The inversion inside the patch
runs lane by lane (:func:`.env_sampling.patch_invert`). Every lane's sample is the
one-at-a-time sample, bit for bit (the same functions on the same values).

No ``from __future__ import annotations``: Warp reads the lane function's argument types from
annotations that name closure types.
"""
import functools

import warp as wp

from .. import fastmath as fmath
from ..distribution.lanes import lane_types
from .env_map import EnvMap
from .env_sampling import descend_level, patch_invert, patch_select, point_sample


@functools.lru_cache(maxsize=None)
def env_lanes_out_type(K: int):
    """The Warp ``(6, K)`` float32 matrix of lane environment samples: per lane (column) ``(dx, dy,
    dz, pdf, u, v)``, :func:`.env_sampling.env_sample_uv`'s direction and pdf, and map
    coordinates."""
    return wp.types.matrix(shape=(6, K), dtype=float)


@functools.lru_cache(maxsize=None)
def make_env_sample_lanes(K: int):
    """``env_sample_uv_lanes(env, xi0, xi1, on) -> (6, K)``: :func:`.env_sampling.env_sample_uv`
    of the uniforms ``(xi0[i], xi1[i])`` of every lane ``i`` with ``on[i] != 0`` (the others: a
    zero column). Cached: one function per ``K``."""
    vf, vi = lane_types(K)
    vd = wp.types.vector(length=K, dtype=wp.float64)
    out_t = env_lanes_out_type(K)

    @wp.func
    def env_sample_uv_lanes(env: EnvMap, xi0: vf, xi1: vf, on: vi) -> out_t:
        out = out_t()
        if env.can_sample == 0:        # env_sample_uv's (0, 1, 0, 0) and uv (0, 0)
            i = int(0)
            while i < K:
                out[1, i] = 1.0
                i += 1
            return out
        x = vi()
        y = vi()
        sx = vd()
        sy = vd()
        i = int(0)
        while i < K:
            sy[i] = fmath.fmin(wp.float64(xi0[i]), wp.float64(0.9999999999999999))
            sx[i] = fmath.fmin(wp.float64(xi1[i]), wp.float64(0.9999999999999999))
            i += 1
        level = env.levels - 2
        while level >= 1:
            i = int(0)
            while i < K:
                a, b, c, d = descend_level(env, level, x[i], y[i], sx[i], sy[i])
                x[i] = a
                y[i] = b
                sx[i] = c
                sy[i] = d
                i += 1
            level = level - 1
        i = int(0)
        while i < K:
            a, b, c, d = patch_select(env, x[i], y[i], sx[i], sy[i])
            x[i] = b          # the patch: column, row interval, rescaled uniforms
            y[i] = a
            sx[i] = c
            sy[i] = d
            i += 1
        i = int(0)
        while i < K:
            if on[i] != 0:
                ds, uv = point_sample(env.rot, env.pdf_scale, patch_invert(env, y[i], x[i], sx[i], sy[i]))
                for r in range(4):
                    out[r, i] = ds[r]
                out[4, i] = uv[0]
                out[5, i] = uv[1]
            i += 1
        return out

    return env_sample_uv_lanes
