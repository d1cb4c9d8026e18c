"""Guide tables for the prototype's binary searches (the ``guided`` variant of
:mod:`benchmarks.lanes_prototype`): fewer dependent loads per sample.

A search for the interval of ``x`` in a CDF halves ``[0, n)`` step by step, each step a load
that depends on the previous one (about log2 n of them: 9 and 10 for the map's rows and
columns, 5 + 5 for the luminance warp, 7 + 7 for the VNDF warp). A guide table of ``G + 1``
entries per CDF (the "cutpoint" method, Chen & Asau 1974) holds, for each ``k``, the answer of
the search for ``x = k / G``; the search for ``x`` in ``[k / G, (k + 1) / G)`` then only runs
between entries ``k`` and ``k + 1``: one independent load and a few steps.

The ``rgl`` warps search CDFs interpolated between two theta_i slices (and, for the column, two
node rows). Normalized by its total, such a CDF is a convex combination of the normalized CDFs
it interpolates, so its answer for ``x`` lies between the smallest and the largest of theirs:
the bracket is the minimum of their ``lo`` entries ``k`` and the maximum of their ``hi``
entries ``k + 1`` (a row of no mass has no say: ``lo = n - 2``, ``hi = 0``), widened by one
cell for float rounding. The search inside the bracket is the production one (same predicate,
same result).

* NumPy: :func:`pc_guide`, :func:`interval_guides`, :func:`make_guides`;
* Warp: :class:`Guides`, :func:`make_guided_kernel` (the scalar kernel's loop and branches with
  the guided searches, the shading of :mod:`benchmarks.lanes_shading`).
"""
import numpy as np
import warp as wp

from .lanes_scene import Env, Tables, View, camera_hit, sample_key, to_local, uniform
from .lanes_shading import bsdf_light_branchy, env_light_branchy, incidence, lerp_at, pc_cell, row_setup, warp_finish

#: guide entries per CDF: the map's marginal and conditionals, the luminance and VNDF warps'
GUIDE_SIZES = {"env_marg": 512, "env_cond": 256, "lum": 32, "vndf": 32}
#: the format's uniform clamp inside its warps (2^-24)
WARP_EPS = 5.9604645e-8


def pc_guide(cdf: np.ndarray, G: int) -> np.ndarray:
    """For k = 0..G the last i in [0, n - 1] with ``cdf[i] <= k / G`` (``cdf`` has n + 1
    entries, float32 as the kernel compares them; G a power of two, so k / G is exact)."""
    cdf = np.asarray(cdf, np.float32)
    n = cdf.size - 1
    return np.clip(np.searchsorted(cdf, np.arange(G + 1, dtype=np.float32) / np.float32(G), "right") - 1,
                   0, n - 1).astype(np.int32)


def interval_guides(cdfs: np.ndarray, G: int) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` (m, G + 1) int32 of m CDFs (m, n) that start at 0: for k = 0..G the last i
    in [0, n - 2] with ``cdf[i] / cdf[n - 1] < k / G``; a CDF of no mass gets ``lo = n - 2``
    and ``hi = 0`` (no say in a bracket)."""
    c = np.asarray(cdfs, np.float64)
    n = c.shape[1]
    tot = c[:, -1:]
    norm = np.divide(c, tot, out=np.zeros_like(c), where=tot > 0)
    k = np.arange(G + 1) / G
    g = np.clip((norm[:, :, None] < k[None, None, :]).sum(1) - 1, 0, n - 2).astype(np.int32)
    lo, hi = g.copy(), g.copy()
    empty = tot[:, 0] <= 0
    lo[empty], hi[empty] = n - 2, 0
    return lo, hi


def make_guides(floats: np.ndarray, header: np.ndarray, env_marg: np.ndarray, env_cond: np.ndarray,
                env_h: int, env_w: int, R) -> "Guides":
    """The :class:`Guides` of an ``rgl`` material (its packed ``floats`` and ``header``, fields
    ``R.RGL_*``) and a map's sampling CDFs."""
    g = Guides()
    g.g_env_marg, g.g_env_cond = GUIDE_SIZES["env_marg"], GUIDE_SIZES["env_cond"]
    g.env_marg = wp.array(pc_guide(env_marg, g.g_env_marg), dtype=int)
    rows = np.asarray(env_cond).reshape(env_h, env_w + 1)
    g.env_cond = wp.array(np.concatenate([pc_guide(r, g.g_env_cond) for r in rows]), dtype=int)
    n = int(header[R.RGL_N_THETA])
    for name, fields in (("lum", (R.RGL_LUM_NY, R.RGL_LUM_NX, R.RGL_LUM_COND, R.RGL_LUM_MARG)),
                         ("vndf", (R.RGL_VNDF_NY, R.RGL_VNDF_NX, R.RGL_VNDF_COND, R.RGL_VNDF_MARG))):
        ny, nx, cond, marg = (int(header[f]) for f in fields)
        G = GUIDE_SIZES[name]
        m_lo, _ = interval_guides(floats[marg:marg + n * ny].reshape(n, ny), G)
        c_lo, c_hi = interval_guides(floats[cond:cond + n * ny * nx].reshape(n * ny, nx), G)
        setattr(g, f"g_{name}", G)
        setattr(g, f"{name}_marg", wp.array(m_lo.ravel(), dtype=int))
        setattr(g, f"{name}_lo", wp.array(c_lo.ravel(), dtype=int))
        setattr(g, f"{name}_hi", wp.array(c_hi.ravel(), dtype=int))
    return g


@wp.struct
class Guides:
    """Guide tables, ``G + 1`` ints per CDF: the map's marginal and per-row conditionals; per
    warp (luminance, VNDF) the marginal of each theta_i slice and ``lo`` / ``hi`` of each
    (slice, node row) conditional."""

    g_env_marg: int
    g_env_cond: int
    env_marg: wp.array(dtype=int)
    env_cond: wp.array(dtype=int)
    g_lum: int
    lum_marg: wp.array(dtype=int)
    lum_lo: wp.array(dtype=int)
    lum_hi: wp.array(dtype=int)
    g_vndf: int
    vndf_marg: wp.array(dtype=int)
    vndf_lo: wp.array(dtype=int)
    vndf_hi: wp.array(dtype=int)


@wp.func
def bucket(x: float, G: int) -> int:
    return wp.clamp(int(x * float(G)), 0, G - 1)


@wp.func
def pc_search(cdf: wp.array(dtype=float), off: int, n: int, guide: wp.array(dtype=int), goff: int, G: int,
              x: float, guided: int) -> int:
    """The last i in [0, n - 1] with ``cdf[off + i] <= x``, searched between the guide's
    entries (``guided`` 0: over all of them, the production search)."""
    k = bucket(x, G)
    lo = int(0)
    hi = n - 1
    if guided == 1:
        lo = guide[goff + k]
        hi = guide[goff + k + 1]
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if cdf[off + mid] <= x:
            lo = mid
        else:
            hi = mid - 1
    return lo


@wp.func
def warp_sample(tb: Tables, gd: Guides, lum: int, t0: int, w1: float, sx_in: float, sy_in: float,
                guided: int) -> wp.vec3:
    """A warp's forward sample (``lum`` 1: luminance, 0: VNDF) with guided searches (``guided``
    0: searches over every interval, the production ones): the production ``Marginal2D``
    sample, (u_x, u_y, density)."""
    ny = wp.where(lum == 1, tb.lum_ny, tb.vndf_ny)
    nx = wp.where(lum == 1, tb.lum_nx, tb.vndf_nx)
    data = wp.where(lum == 1, tb.lum_data, tb.vndf_data)
    cond = wp.where(lum == 1, tb.lum_cond, tb.vndf_cond)
    marg = wp.where(lum == 1, tb.lum_marg, tb.vndf_marg)
    G = wp.where(lum == 1, gd.g_lum, gd.g_vndf)
    sx = wp.clamp(sx_in, WARP_EPS, 1.0 - WARP_EPS)
    sy = wp.clamp(sy_in, WARP_EPS, 1.0 - WARP_EPS)
    plane = ny * nx
    mb = marg + t0 * ny
    # the row: bracket from the two slices' marginal guides
    k = bucket(sy, G)
    g0 = t0 * (G + 1) + k
    g1 = g0 + (G + 1)
    lo = int(0)
    hi = int(0)
    if lum == 1:
        lo = wp.min(gd.lum_marg[g0], gd.lum_marg[g1])
        hi = wp.max(gd.lum_marg[g0 + 1], gd.lum_marg[g1 + 1])
    else:
        lo = wp.min(gd.vndf_marg[g0], gd.vndf_marg[g1])
        hi = wp.max(gd.vndf_marg[g0 + 1], gd.vndf_marg[g1 + 1])
    lo = wp.max(lo - 1, 0)
    hi = wp.min(hi + 1, ny - 2)
    if guided == 0:
        lo = 0
        hi = ny - 2
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if lerp_at(tb.f, mb + mid, ny, w1) < sy:
            lo = mid
        else:
            hi = mid - 1
    row = lo
    cb = cond + t0 * plane + row * nx
    r = row_setup(tb.f, mb, row, ny, cb, nx, plane, w1, sx, sy)
    fy = r[0]
    xs = r[1]
    # the column: bracket from the four (slice, node row) conditional guides
    k = bucket(sx, G)
    a = (t0 * ny + row) * (G + 1) + k      # slice t0, node row `row`
    b = a + (G + 1)                         # node row `row + 1`
    c = a + ny * (G + 1)                    # slice t0 + 1
    d = c + (G + 1)
    if lum == 1:
        lo = wp.min(wp.min(gd.lum_lo[a], gd.lum_lo[b]), wp.min(gd.lum_lo[c], gd.lum_lo[d]))
        hi = wp.max(wp.max(gd.lum_hi[a + 1], gd.lum_hi[b + 1]), wp.max(gd.lum_hi[c + 1], gd.lum_hi[d + 1]))
    else:
        lo = wp.min(wp.min(gd.vndf_lo[a], gd.vndf_lo[b]), wp.min(gd.vndf_lo[c], gd.vndf_lo[d]))
        hi = wp.max(wp.max(gd.vndf_hi[a + 1], gd.vndf_hi[b + 1]), wp.max(gd.vndf_hi[c + 1], gd.vndf_hi[d + 1]))
    if lo > hi or guided == 0:   # every row without mass, or no guides
        lo = 0
        hi = nx - 2
    lo = wp.max(lo - 1, 0)
    hi = wp.min(hi + 1, nx - 2)
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if (1.0 - fy) * lerp_at(tb.f, cb + mid, plane, w1) + fy * lerp_at(tb.f, cb + nx + mid, plane, w1) < xs:
            lo = mid
        else:
            hi = mid - 1
    return warp_finish(tb.f, data + t0 * plane + row * nx + lo, cb, row, lo, ny, nx, plane, w1, fy, xs)


def make_guided_kernel(options: dict, stages: int = 3, guided: bool = True):
    """One sample per loop iteration with the guided searches (module ``options``; ``stages``
    as for :func:`benchmarks.lanes_kernels.make_scalar_kernel`); ``guided`` False: the same
    kernel with the production searches over every interval (what the guides are measured
    against)."""
    use = int(guided)

    @wp.func
    def shade(tb: Tables, gd: Guides, env: Env, view: View, px: int, py: int, key: wp.uint32) -> wp.vec3:
        hit, n, wo_w = camera_hit(view, px, py, key)
        if hit == 0.0:
            return wp.vec3(0.0)
        wo = to_local(n, wo_w)
        inc = incidence(tb, wo)
        if wp.static(stages < 2):
            return wp.vec3(inc[0], inc[1], inc[2] + inc[3])
        u = uniform(key, 2)
        v = uniform(key, 3)
        row = pc_search(env.marg, 0, env.h, gd.env_marg, 0, gd.g_env_marg, v, wp.static(use))
        col = pc_search(env.cond, row * (env.w + 1), env.w, gd.env_cond, row * (gd.g_env_cond + 1), gd.g_env_cond,
                        u, wp.static(use))
        ry = pc_cell(env.marg, 0, row, v)
        cx = pc_cell(env.cond, row * (env.w + 1), col, u)
        L = env_light_branchy(tb, env, n, wo, inc, (float(col) + cx[0]) / float(env.w),
                              (float(row) + ry[0]) / float(env.h), ry[1] * cx[1] * float(env.w * env.h))
        if wp.static(stages < 3):
            return L
        t0 = int(inc[0])
        s = warp_sample(tb, gd, 1, t0, inc[1], uniform(key, 5), uniform(key, 4), wp.static(use))
        um = warp_sample(tb, gd, 0, t0, inc[1], s[0], s[1], wp.static(use))
        return L + bsdf_light_branchy(tb, env, n, wo, inc, s, um)

    @wp.kernel(module="unique", enable_backward=False, module_options=options)
    def render_guided(tg: Tables, env: Env, view: View, x0: int, y0: int, tile_w: int,
                      out: wp.array(dtype=wp.vec3), gd: Guides):
        tid = wp.tid()
        px = x0 + tid % tile_w
        py = y0 + tid // tile_w
        if px >= view.res or py >= view.res:
            return
        pix = py * view.res + px
        acc = wp.vec3(0.0)
        for s in range(view.spp):
            acc = acc + shade(tg, gd, env, view, px, py, sample_key(view, pix, s))
        out[pix] = acc / float(view.spp)

    return render_guided
