"""The environment as the render kernels see it: the Warp struct ``EnvMap``, its construction
from an :class:`~warp_rbrdf.lights.env_distribution.EnvData`, and the lookup, radiance and pdf
functions of the lat-long conventions (:mod:`warp_rbrdf.lights.latlong`, whose NumPy functions
are their references). The sample is :mod:`warp_rbrdf.lights.env_sampling`."""
from __future__ import annotations

import numpy as np
import warp as wp

from .. import fastmath as fmath
from .env_distribution import EnvData, build_env_distribution, row_geometry, sin_integrals


@wp.struct
class EnvMap:
    texels: wp.array2d(dtype=wp.vec3)    # (H, W) radiance (scale applied)
    lum: wp.array2d(dtype=float)         # (H, W) luminance of the texels (>= 0)
    pdf_scale: float                     # 1 / (2 pi^2 Z): pdf = lum(lookup) * pdf_scale
    row_trig: wp.array2d(dtype=wp.float64)  # (H - 1, 5) per row interval: sin a, cos a, sin(a + b),
                                            # I0(1), I1(1) (K1 = I1(1), K0 = I0(1) - I1(1))
    mip: wp.array(dtype=float)           # hierarchical warp: levels 1.. (2 x 2 blocks), flat, float32
    mip_offset: wp.array(dtype=int)      # start of level l in ``mip`` at [l - 1]
    mip_blocks_x: wp.array(dtype=int)    # 2 x 2 blocks per row of level l at [l - 1]
    levels: int                          # levels of the pyramid, the patches' (level 0) included
    rot: wp.mat33                        # map -> world rotation
    width: int
    height: int
    present: int                         # 0: no environment (black)
    can_sample: int                      # 0: all-black map, no importance sampling


def _block_layout(m: np.ndarray) -> np.ndarray:
    """An (h, w) level, zero-padded to even sizes, as (h/2, w/2, 4) blocks of its 2 x 2 cells
    (v00, v10, v01, v11), so that one hierarchical step reads 4 consecutive values."""
    h, w = m.shape
    p = np.zeros((h + (h & 1), w + (w & 1)))
    p[:h, :w] = m
    return p.reshape(p.shape[0] // 2, 2, p.shape[1] // 2, 2).transpose(0, 2, 1, 3).reshape(p.shape[0] // 2, p.shape[1] // 2, 4)


def make_env_struct(env: EnvData | None, device) -> EnvMap:
    """The Warp struct of ``env`` (None: no environment, a black 2 x 2 map with ``present = 0``)
    on ``device``."""
    s = EnvMap()
    if env is None:
        env = build_env_distribution(np.zeros((2, 2, 3), np.float32))
        s.present = 0
    else:
        s.present = 1
    H, W = env.image.shape[:2]
    s.texels = wp.array(env.image, dtype=wp.vec3, device=device)
    s.lum = wp.array(env.lum.astype(np.float32), dtype=float, device=device)
    s.pdf_scale = float(env.pdf_scale)
    a, b = row_geometry(H)
    i0, i1 = sin_integrals(a, b, 1.0)
    s.row_trig = wp.array(np.ascontiguousarray(np.stack([np.sin(a), np.cos(a), np.sin(a + b), i0, i1], axis=1),
                                               np.float64), dtype=wp.float64, device=device)
    # level 0 (the patch masses) is not stored: the sampler computes the 4 candidates from ``lum``
    # (which it reads for the chosen patch anyway), so the pyramid is 1/4 of the patches, float32
    blocks = [_block_layout(m) for m in env.mip[1:]] or [np.zeros((1, 1, 4))]
    sizes = np.array([b.size for b in blocks])
    s.mip = wp.array(np.concatenate([b.ravel() for b in blocks]).astype(np.float32), dtype=float, device=device)
    s.mip_offset = wp.array(np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int32), dtype=int, device=device)
    s.mip_blocks_x = wp.array(np.array([b.shape[1] for b in blocks], np.int32), dtype=int, device=device)
    s.levels = len(env.mip)
    s.rot = wp.mat33(*np.asarray(env.rotation, np.float32).ravel())
    s.width, s.height = W, H
    s.can_sample = 1 if (env.total > 0 and s.present) else 0
    return s


@wp.func
def env_dir_to_uv(env: EnvMap, d: wp.vec3) -> wp.vec2:
    """Map coordinates (u, v) of world direction ``d`` (:func:`~.latlong.direction_to_uv`)."""
    dl = wp.transpose(env.rot) * d
    u = fmath.atan2(dl[0], -dl[2]) * (0.5 / wp.pi)
    if u < 0.0:
        u = u + 1.0
    if u >= 1.0:
        u = u - 1.0
    # acos(y) as atan2(|(x, z)|, y): inline (no libm call) and accurate at the poles
    v = fmath.atan2(wp.sqrt(dl[0] * dl[0] + dl[2] * dl[2]), dl[1]) * (1.0 / wp.pi)
    return wp.vec2(u, v)


@wp.struct
class BilinearTaps:
    """The four texels and weights of the conventions' bilinear lookup at (u, v): columns
    ``x0``, ``x1`` (wrapping), rows ``y0``, ``y1`` (clamped), weights ``fx``, ``fy`` of the
    second column / row."""
    x0: int
    x1: int
    y0: int
    y1: int
    fx: float
    fy: float


@wp.func
def next_column(c: int, W: int) -> int:
    """(c + 1) mod W for c in [0, W - 1], without an integer division (a division's latency
    sits on the address of every tap)."""
    return wp.where(c + 1 >= W, 0, c + 1)


@wp.func
def bilinear_taps(env: EnvMap, u: float, v: float) -> BilinearTaps:
    """Texels of the lookup at (u, v) in [0, 1]^2 (rows are not texel-centred: v = 0 and 1 are
    the first and last rows)."""
    W = env.width
    H = env.height
    x = u * float(W) - 0.5
    y = fmath.clamp(v * float(H - 1), 0.0, float(H - 1))
    xf = wp.floor(x)
    t = BilinearTaps()
    t.fx = x - xf
    # wrap without an integer division (x0 is in [-1, W - 1] for u in [0, 1]; the clamp keeps a
    # NaN direction's index inside the map)
    x0 = int(xf)
    if x0 < 0:
        x0 = x0 + W
    if x0 >= W:
        x0 = x0 - W
    x0 = fmath.clamp(x0, 0, W - 1)
    t.x0 = x0
    t.x1 = next_column(x0, W)
    yf = wp.floor(y)
    t.fy = y - yf
    t.y0 = fmath.clamp(int(yf), 0, H - 1)
    t.y1 = fmath.fmin(t.y0 + 1, H - 1)
    return t


@wp.func
def env_lookup_uv(env: EnvMap, u: float, v: float) -> wp.vec3:
    """Bilinear lookup of the radiance texels at (u, v)."""
    t = bilinear_taps(env, u, v)
    top = env.texels[t.y0, t.x0] * (1.0 - t.fx) + env.texels[t.y0, t.x1] * t.fx
    bot = env.texels[t.y1, t.x0] * (1.0 - t.fx) + env.texels[t.y1, t.x1] * t.fx
    return top * (1.0 - t.fy) + bot * t.fy


@wp.func
def env_eval_uv(env: EnvMap, uv: wp.vec2) -> wp.vec3:
    """:func:`env_eval` at the map coordinates ``uv`` (:func:`env_dir_to_uv`) of a direction."""
    if env.present == 0:
        return wp.vec3(0.0)
    return env_lookup_uv(env, uv[0], uv[1])


@wp.func
def env_eval(env: EnvMap, d: wp.vec3) -> wp.vec3:
    """Radiance arriving from world direction ``d`` (pointing out to the environment)."""
    if env.present == 0:
        return wp.vec3(0.0)
    return env_eval_uv(env, env_dir_to_uv(env, d))


@wp.func
def env_lookup_lum(env: EnvMap, u: float, v: float) -> float:
    """Bilinear lookup of the luminance map (the same weights as :func:`env_lookup_uv`)."""
    t = bilinear_taps(env, u, v)
    top = env.lum[t.y0, t.x0] * (1.0 - t.fx) + env.lum[t.y0, t.x1] * t.fx
    bot = env.lum[t.y1, t.x0] * (1.0 - t.fx) + env.lum[t.y1, t.x1] * t.fx
    return top * (1.0 - t.fy) + bot * t.fy


@wp.func
def env_pdf_uv(env: EnvMap, uv: wp.vec2) -> float:
    """:func:`env_pdf` at the map coordinates ``uv`` (:func:`env_dir_to_uv`) of a direction."""
    if env.can_sample == 0:
        return 0.0
    return env_lookup_lum(env, uv[0], uv[1]) * env.pdf_scale


@wp.func
def env_pdf(env: EnvMap, d: wp.vec3) -> float:
    """Solid-angle density (1/sr) of the environment sample
    (:func:`warp_rbrdf.lights.env_sampling.env_sample`) for world direction ``d``."""
    if env.can_sample == 0:
        return 0.0
    return env_pdf_uv(env, env_dir_to_uv(env, d))
