"""Environment-map sampling schemes kept for comparison, not for rendering: the benchmark
``benchmarks.bench_env_sampling`` and the tests that compare schemes use them. The renderer
samples with the hierarchical warp only (:mod:`warp_rbrdf.lights.env_sampling`).

* ``hierarchical``: the renderer's scheme itself (its ``EnvMap`` and ``env_sample_uv``), so that
  every scheme is reached through one struct and one set of kernels here;
* ``marginal``: the same density (the looked-up luminance in solid angle,
  :mod:`warp_rbrdf.lights.env_distribution`) by continuous marginal / conditional inversion, as
  Mitsuba 3's ``Marginal2D`` with continuous conditionals: ``xi[0]`` picks v from the marginal
  over the H - 1 row intervals (then the row fraction inside the interval by the renderer's
  float64 inversion), ``xi[1]`` picks u from the conditional *at that v* (the two bounding
  rows' per-column prefix sums mixed by the row fraction). Continuous too, but it stratifies
  less well than the hierarchy;
* ``piecewise-constant``: one cell per texel (rows' cells centred on the texel's
  v = r / (H - 1), half cells at the poles), weight = the exact cell mean of the lookup's
  luminance times the cell's solid angle, v drawn ~ sin(pi v) in a cell: a density constant in
  solid angle within a cell, *not* the lookup's density (a one-texel sun's lookup varies across
  its cell from 1/4 to 1 of its peak). Direction and pdf in float32.

:class:`SchemeData` is a scheme's distribution (NumPy), :class:`SchemeEnvMap` its Warp struct
(the renderer's ``EnvMap`` plus the scheme's arrays); :func:`scheme_pdf_numpy` and
:func:`scheme_sample_numpy` are float64 references of the Warp ``scheme_pdf`` /
``scheme_sample_uv`` (no NumPy sampler for ``piecewise-constant``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warp_rbrdf.distribution import find_interval, find_interval_row
from warp_rbrdf.lights.env_distribution import (EnvData, build_env_distribution, env_pdf_numpy,
                                                env_sample_numpy, linear_inverse_numpy,
                                                patch_point_direction, patch_row_moments, row_geometry,
                                                solve_row_fraction_numpy)
from warp_rbrdf.lights.env_map import EnvMap, env_dir_to_uv, env_pdf_uv, make_env_struct, next_column
from warp_rbrdf.lights.env_sampling import (env_sample_uv, linear_inverse, point_sample, sample_patch_point,
                                            solve_row_fraction)
from warp_rbrdf.lights.latlong import direction_to_uv

SCHEME_MARGINAL = 0
SCHEME_HIERARCHICAL = 1
SCHEME_PIECEWISE_CONSTANT = 2
SCHEME_NAMES = {"marginal": SCHEME_MARGINAL, "hierarchical": SCHEME_HIERARCHICAL,
                "piecewise-constant": SCHEME_PIECEWISE_CONSTANT}


# --------------------------------------------------------------------------------------------
# NumPy side
@dataclass
class SchemeData:
    """One scheme's distribution of an (H, W) map: the renderer's distribution ``env`` (image,
    rotation, luminance, Z, hierarchy) and the scheme's own arrays."""
    env: EnvData
    scheme: int
    row_cdf: np.ndarray | None = None     # marginal: (H,) CDF over the H - 1 row intervals
    col_prefix: np.ndarray | None = None  # marginal: (H, W + 1) per-row prefix sums of patch columns
    pc: dict | None = None                # piecewise-constant: pdf (H, W), marginal_cdf (H + 1,),
                                          # conditional_cdf (H, W + 1)


def build_scheme(image: np.ndarray, scheme: int, rotation=None) -> SchemeData:
    """The distribution of ``scheme`` (one of :data:`SCHEME_NAMES`' values) for an (H, W, 3)
    lat-long map under ``rotation`` (3, 3) map -> world."""
    if scheme not in SCHEME_NAMES.values():
        raise ValueError(f"unknown environment sampling scheme {scheme}")
    env = build_env_distribution(image, rotation)
    data = SchemeData(env=env, scheme=int(scheme))
    H, W = env.lum.shape
    if scheme == SCHEME_MARGINAL:
        K0, K1 = patch_row_moments(H)
        lc = 0.5 * (env.lum + np.roll(env.lum, -1, axis=1))   # (H, W) patch-column means per row
        rows = ((K0[:, None] * lc[:-1] + K1[:, None] * lc[1:]) / ((H - 1) * W)).sum(axis=1)
        if env.total > 0:
            cdf = np.concatenate([[0.0], np.cumsum(rows)]) / env.total
            cdf[-1] = 1.0
        else:
            cdf = np.linspace(0.0, 1.0, H)
        data.row_cdf = cdf
        data.col_prefix = np.concatenate([np.zeros((H, 1)), np.cumsum(lc, axis=1)], axis=1)
    elif scheme == SCHEME_PIECEWISE_CONSTANT:
        data.pc = _piecewise_constant(env.lum)
    return data


def row_bounds(H: int):
    """Piecewise-constant scheme: per-row v extent of the cells, (v0, v1) arrays of shape (H,)."""
    r = np.arange(H)
    v0 = np.clip((r - 0.5) / (H - 1), 0.0, 1.0)
    v1 = np.clip((r + 0.5) / (H - 1), 0.0, 1.0)
    return v0, v1


def cell_solid_angles(H: int, W: int) -> np.ndarray:
    """Piecewise-constant scheme: solid angle (sr) of each row's cells, shape (H,)."""
    v0, v1 = row_bounds(H)
    return 2 * np.pi / W * (np.cos(np.pi * v0) - np.cos(np.pi * v1))


def _piecewise_constant(lum: np.ndarray) -> dict:
    """The piecewise-constant scheme's tables of the (H, W) luminance ``lum``: the solid-angle
    pdf per cell, the marginal CDF over rows and the conditional CDFs over columns."""
    H, W = lum.shape
    lum_x = 0.75 * lum + 0.125 * (np.roll(lum, 1, axis=1) + np.roll(lum, -1, axis=1))
    mean = np.empty_like(lum_x)
    mean[1:-1] = 0.75 * lum_x[1:-1] + 0.125 * (lum_x[:-2] + lum_x[2:])
    mean[0] = 0.75 * lum_x[0] + 0.25 * lum_x[1]
    mean[-1] = 0.75 * lum_x[-1] + 0.25 * lum_x[-2]
    w = mean * cell_solid_angles(H, W)[:, None]
    total = float(w.sum())
    rows = w.sum(axis=1)
    if total > 0:
        pdf = mean / total
        marg = np.concatenate([[0.0], np.cumsum(rows) / total])
        cond = np.zeros((H, W + 1))
        nz = rows > 0
        cond[nz, 1:] = np.cumsum(w[nz], axis=1) / rows[nz, None]
        cond[~nz, 1:] = np.arange(1, W + 1) / W
        cond[:, -1] = 1.0
        marg[-1] = 1.0
    else:
        pdf = np.zeros((H, W))
        marg = np.linspace(0, 1, H + 1)
        cond = np.tile(np.linspace(0, 1, W + 1), (H, 1))
    return dict(pdf=pdf, marginal_cdf=marg, conditional_cdf=cond)


def scheme_pdf_numpy(data: SchemeData, d: np.ndarray) -> np.ndarray:
    """Solid-angle pdf (1/sr) of world directions ``d`` (..., 3) under ``data``'s scheme."""
    env = data.env
    if data.scheme != SCHEME_PIECEWISE_CONSTANT or env.total <= 0:
        return env_pdf_numpy(env, d)
    u, v = direction_to_uv(d, env.rotation)
    H, W = env.lum.shape
    c = np.clip(np.floor(u * W).astype(np.int64), 0, W - 1)
    r = np.clip(np.floor(v * (H - 1) + 0.5).astype(np.int64), 0, H - 1)
    return data.pc["pdf"][r, c]


def scheme_sample_numpy(data: SchemeData, xi: np.ndarray):
    """float64 reference of ``scheme_sample_uv`` for the marginal and hierarchical schemes:
    uniforms ``xi`` (N, 2) -> (world directions (N, 3), pdf (N,))."""
    if data.scheme == SCHEME_HIERARCHICAL:
        return env_sample_numpy(data.env, xi)
    if data.scheme != SCHEME_MARGINAL:
        raise NotImplementedError("scheme_sample_numpy: the piecewise-constant scheme has no NumPy sampler")
    xi = np.asarray(xi, np.float64)
    L = data.env.lum
    H, W = L.shape
    a_all, b = row_geometry(H)
    y0 = np.minimum(xi[:, 0], 1.0 - 2.0 ** -53)
    j = np.clip(np.searchsorted(data.row_cdf, y0, side="right") - 1, 0, H - 2)
    c0, c1 = data.row_cdf[j], data.row_cdf[j + 1]
    yt = np.clip((y0 - c0) / np.maximum(c1 - c0, 1e-300), 0.0, 1.0)
    P = data.col_prefix
    t = solve_row_fraction_numpy(P[j, W], P[j + 1, W], a_all[j], b, yt)
    T = np.minimum(xi[:, 1], 1.0 - 2.0 ** -53) * ((1 - t) * P[j, W] + t * P[j + 1, W])
    # the last column whose prefix, mixed by t, is <= T (the mix is monotone in the column)
    lo = np.zeros(len(xi), np.int64)
    hi = np.full(len(xi), W, np.int64)
    while np.any(hi - lo > 1):
        mid = (lo + hi) // 2
        val = (1 - t) * P[j, mid] + t * P[j + 1, mid]
        go = (val <= T) & (hi - lo > 1)
        stay = (val > T) & (hi - lo > 1)
        lo = np.where(go, mid, lo)
        hi = np.where(stay, mid, hi)
    c = lo
    rest = T - ((1 - t) * P[j, c] + t * P[j + 1, c])
    cn = (c + 1) % W
    g0 = (1 - t) * L[j, c] + t * L[j + 1, c]
    g1 = (1 - t) * L[j, cn] + t * L[j + 1, cn]
    half = 0.5 * (g0 + g1)
    s = linear_inverse_numpy(g0, g1, np.clip(rest / np.where(half > 0, half, 1.0), 0.0, 1.0))
    return patch_point_direction(data.env, j, c, t, s)


# --------------------------------------------------------------------------------------------
# Warp side
@wp.struct
class SchemeEnvMap:
    env: EnvMap                              # the renderer's struct (lookup, hierarchy, Z)
    scheme: int                              # SCHEME_*
    row_cdf: wp.array(dtype=wp.float64)      # marginal: (H,)
    col_prefix: wp.array2d(dtype=wp.float64)  # marginal: (H, W + 1)
    pc_pdf: wp.array2d(dtype=float)          # piecewise-constant: (H, W) density per cell
    pc_marginal: wp.array(dtype=float)       # (H + 1,)
    pc_conditional: wp.array2d(dtype=float)  # (H, W + 1)


def make_scheme_struct(data: SchemeData, device) -> SchemeEnvMap:
    """The Warp struct of ``data`` on ``device``; arrays its scheme does not use hold one element."""
    s = SchemeEnvMap()
    s.env = make_env_struct(data.env, device)
    s.scheme = data.scheme
    f64 = lambda a: np.ascontiguousarray(a, np.float64)   # noqa: E731
    s.row_cdf = wp.array(f64(data.row_cdf if data.row_cdf is not None else np.zeros(1)),
                         dtype=wp.float64, device=device)
    s.col_prefix = wp.array(f64(data.col_prefix if data.col_prefix is not None else np.zeros((1, 1))),
                            dtype=wp.float64, device=device)
    pc = data.pc or dict(pdf=np.zeros((1, 1)), marginal_cdf=np.zeros(1), conditional_cdf=np.zeros((1, 1)))
    s.pc_pdf = wp.array(pc["pdf"].astype(np.float32), dtype=float, device=device)
    s.pc_marginal = wp.array(pc["marginal_cdf"].astype(np.float32), dtype=float, device=device)
    s.pc_conditional = wp.array(pc["conditional_cdf"].astype(np.float32), dtype=float, device=device)
    return s


@wp.func
def marginal_sample_point(s: SchemeEnvMap, xi: wp.vec2) -> wp.vec3d:
    """(u, v, looked-up luminance) of the marginal scheme's sample of ``xi``, float64."""
    env = s.env
    H = env.height
    W = env.width
    one = wp.float64(1.0)
    zero = wp.float64(0.0)
    y0 = wp.min(wp.float64(xi[0]), wp.float64(0.9999999999999999))
    y1 = wp.min(wp.float64(xi[1]), wp.float64(0.9999999999999999))
    j = find_interval(s.row_cdf, 0, H, y0)
    c0 = s.row_cdf[j]
    c1 = s.row_cdf[j + 1]
    yt = zero
    if c1 > c0:
        yt = wp.clamp((y0 - c0) / (c1 - c0), zero, one)
    R0 = s.col_prefix[j, W]
    R1 = s.col_prefix[j + 1, W]
    t = solve_row_fraction(R0, R1, env, j, yt)
    T = y1 * ((one - t) * R0 + t * R1)
    lo = int(0)
    hi = W
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if (one - t) * s.col_prefix[j, mid] + t * s.col_prefix[j + 1, mid] <= T:
            lo = mid
        else:
            hi = mid
    c = lo
    rest = T - ((one - t) * s.col_prefix[j, c] + t * s.col_prefix[j + 1, c])
    cn = next_column(c, W)
    g0 = (one - t) * wp.float64(env.lum[j, c]) + t * wp.float64(env.lum[j + 1, c])
    g1 = (one - t) * wp.float64(env.lum[j, cn]) + t * wp.float64(env.lum[j + 1, cn])
    half = wp.float64(0.5) * (g0 + g1)
    ys = zero
    if half > zero:
        ys = wp.clamp(rest / half, zero, one)
    sc = linear_inverse(g0, g1, ys)
    lum = (one - sc) * g0 + sc * g1
    u = (wp.float64(c) + sc + wp.float64(0.5)) / wp.float64(W)
    if u >= one:
        u = u - one
    v = (wp.float64(j) + t) / wp.float64(H - 1)
    return wp.vec3d(u, v, lum)


@wp.func
def pc_sample_local(s: SchemeEnvMap, xi: wp.vec2) -> wp.vec3:
    """The piecewise-constant scheme's sample of ``xi``: a map direction (float32)."""
    H = s.env.height
    W = s.env.width
    x0 = wp.min(xi[0], 0.99999994)
    r = find_interval(s.pc_marginal, 0, H + 1, x0)
    c0 = s.pc_marginal[r]
    c1 = s.pc_marginal[r + 1]
    tv = wp.clamp((x0 - c0) / wp.max(c1 - c0, 1.0e-30), 0.0, 1.0)
    x1 = wp.min(xi[1], 0.99999994)
    c = find_interval_row(s.pc_conditional, r, W + 1, x1)
    d0 = s.pc_conditional[r, c]
    d1 = s.pc_conditional[r, c + 1]
    tu = wp.clamp((x1 - d0) / wp.max(d1 - d0, 1.0e-30), 0.0, 1.0)
    u = (float(c) + tu) / float(W)
    inv = 1.0 / float(H - 1)
    va = wp.clamp((float(r) - 0.5) * inv, 0.0, 1.0)
    vb = wp.clamp((float(r) + 0.5) * inv, 0.0, 1.0)
    ca = wp.cos(wp.pi * va)
    cb = wp.cos(wp.pi * vb)
    cos_t = wp.clamp(ca - tv * (ca - cb), -1.0, 1.0)   # v drawn with density ~ sin(pi v)
    sin_t = wp.sqrt(wp.max(0.0, 1.0 - cos_t * cos_t))
    phi = 2.0 * wp.pi * u
    return wp.vec3(wp.sin(phi) * sin_t, cos_t, -wp.cos(phi) * sin_t)


@wp.func
def scheme_pdf_uv(s: SchemeEnvMap, uv: wp.vec2) -> float:
    """Solid-angle pdf (1/sr) of the scheme's sample at map coordinates ``uv``."""
    if s.env.can_sample == 0:
        return 0.0
    if s.scheme == SCHEME_PIECEWISE_CONSTANT:
        c = wp.clamp(int(uv[0] * float(s.env.width)), 0, s.env.width - 1)
        r = wp.clamp(int(wp.floor(uv[1] * float(s.env.height - 1) + 0.5)), 0, s.env.height - 1)
        return s.pc_pdf[r, c]
    return env_pdf_uv(s.env, uv)


@wp.func
def scheme_sample_point(s: SchemeEnvMap, xi: wp.vec2) -> wp.vec3d:
    """(u, v, looked-up luminance) of the sampled point, float64 (marginal and hierarchical)."""
    if s.scheme == SCHEME_MARGINAL:
        return marginal_sample_point(s, xi)
    return sample_patch_point(s.env, xi)


@wp.func
def scheme_sample_uv(s: SchemeEnvMap, xi: wp.vec2):
    """The scheme's sample of uniforms ``xi``: ``(vec4 (dx, dy, dz, pdf), vec2 uv)`` as the
    renderer's ``env_sample_uv``."""
    if s.scheme == SCHEME_HIERARCHICAL or s.env.can_sample == 0:
        hs, huv = env_sample_uv(s.env, xi)
        return hs, huv
    if s.scheme == SCHEME_PIECEWISE_CONSTANT:
        dw = s.env.rot * pc_sample_local(s, xi)
        uvw = env_dir_to_uv(s.env, dw)
        return wp.vec4(dw[0], dw[1], dw[2], scheme_pdf_uv(s, uvw)), uvw
    ms, muv = point_sample(s.env.rot, s.env.pdf_scale, marginal_sample_point(s, xi))
    return ms, muv


# --- kernels: one value per thread ------------------------------------------------------------
@wp.kernel(enable_backward=False)
def scheme_sample_kernel(s: SchemeEnvMap, xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec4)):
    """(dx, dy, dz, pdf) of the scheme's sample of each ``xi``."""
    i = wp.tid()
    r, _uv = scheme_sample_uv(s, xi[i])
    out[i] = r


@wp.kernel(enable_backward=False)
def scheme_sample_point_kernel(s: SchemeEnvMap, xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec4),
                               point: wp.array(dtype=wp.vec3d)):
    """The sample of each ``xi`` and the float64 (u, v, looked-up luminance) of its point
    (marginal and hierarchical schemes)."""
    i = wp.tid()
    r, _uv = scheme_sample_uv(s, xi[i])
    out[i] = r
    point[i] = scheme_sample_point(s, xi[i])


@wp.kernel(enable_backward=False)
def scheme_pdf_kernel(s: SchemeEnvMap, dirs: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    """Solid-angle pdf (1/sr) of the scheme at each world direction."""
    i = wp.tid()
    out[i] = scheme_pdf_uv(s, env_dir_to_uv(s.env, dirs[i]))
