"""The ``Marginal2D`` warp (:func:`.warp_2d.marginal2d_sample`) drawn for ``K`` samples at once:
the CPU kernels' way to overlap the binary searches of independent samples.

One sample's searches are chains of dependent loads (each probe's address follows from the
previous compare) whose branches the CPU cannot predict, so a scalar kernel waits on every probe
in turn. Here every search is a fixed sequence of halving steps, the same for all lanes (the
step count depends on the table size only), whose inner loop runs over the ``K`` lanes with a
select in place of a branch: the ``K`` loads of a step are independent and overlap
(``docs/cpu_lanes.md``). The steps between and after the searches are
:func:`.warp_2d.marginal2d_row_setup` and :func:`.warp_2d.marginal2d_finish`, per lane, as the
scalar sample runs them: a lane's result equals the scalar sample's except where the
interpolated CDF is not monotone in float rounding and the two search orders stop on different
sides of a tie.

Lanes are Warp vectors of length ``K`` (:func:`lane_types`); all lanes read one table (the same
material), each with its own slice interval (``t0``, ``w1``) and uniforms.
"""

import functools

import warp as wp

from .. import fastmath as fmath
from .warp_2d import MARGINAL2D_EPS, _lerp_at, _stride, marginal2d_finish, marginal2d_row_setup


@functools.lru_cache(maxsize=None)
def lane_types(K: int) -> tuple:
    """``(vf, vi)``: the Warp vector types of ``K`` float32 / int32 lanes."""
    return wp.types.vector(length=K, dtype=float), wp.types.vector(length=K, dtype=int)


@functools.lru_cache(maxsize=None)
def lanes_out_type(K: int):
    """The Warp ``(8, K)`` float32 matrix of a lane BSDF sample: per lane (column) ``(wi_x, wi_y,
    wi_z, 1 / pdf, f_R, f_G, f_B, has_f)``, f_r at the sample where the technique computes it on
    the way (``has_f`` 1), else 0 (the caller evaluates the material)."""
    return wp.types.matrix(shape=(8, K), dtype=float)


@functools.lru_cache(maxsize=None)
def make_find_interval_lanes(K: int):
    """``find_interval_lanes(cdf, off, size, x) -> int lanes``: :func:`.warp_1d.find_interval` of
    every lane (its CDF at ``cdf[off[i]]``, all of ``size`` entries), by halving steps over all
    lanes. Cached: one function per ``K``."""
    vf, vi = lane_types(K)

    @wp.func
    def find_interval_lanes(cdf: wp.array(dtype=float), off: vi, size: int, x: vf) -> vi:
        base = vi()
        m = size - 1
        while m > 1:
            half = m // 2
            i = int(0)
            while i < K:
                b = base[i] + half
                base[i] = wp.where(cdf[off[i] + b] <= x[i], b, base[i])
                i += 1
            m = m - half
        return base

    return find_interval_lanes


@functools.lru_cache(maxsize=None)
def make_marginal2d_sample_lanes(K: int):
    """``marginal2d_sample_lanes(vals, data, cond, marg, ny, nx, n_slices, t0, w1, sx, sy) -> (x,
    y, pdf)``: :func:`.warp_2d.marginal2d_sample` of ``K`` lanes (``t0``: int lanes, the others
    float lanes; three float lanes out). Cached: one function per ``K``."""
    vf, vi = lane_types(K)

    @wp.func
    def search_lanes(vals: wp.array(dtype=float), off: vi, row_step: int, stride: int, w1: vf, fy: vf,
                     size: int, x: vf) -> vi:
        """Per lane ``.warp_2d._find_interval_lerped``: the last ``i`` in ``[0, size - 2]`` whose
        CDF ``(1 - fy) L(off + i) + fy L(off + row_step + i)`` is ``< x`` (``L`` interpolated
        between slices), by halving steps over all lanes (the CDF starts at 0 and ``x > 0``)."""
        base = vi()
        m = size - 1
        while m > 1:
            half = m // 2
            i = int(0)
            while i < K:
                b = base[i] + half
                c = _lerp_at(vals, off[i] + b, stride, w1[i])
                if row_step != 0:
                    c = (1.0 - fy[i]) * c + fy[i] * _lerp_at(vals, off[i] + row_step + b, stride, w1[i])
                base[i] = wp.where(c < x[i], b, base[i])
                i += 1
            m = m - half
        return base

    @wp.func
    def marginal2d_sample_lanes(vals: wp.array(dtype=float), data: int, cond: int, marg: int, ny: int, nx: int,
                                n_slices: int, t0: vi, w1: vf, sx_in: vf, sy_in: vf):
        plane = ny * nx
        stride = _stride(plane, n_slices)
        mstride = _stride(ny, n_slices)
        sx = vf()
        sy = vf()
        mb = vi()
        i = int(0)
        while i < K:
            sx[i] = fmath.clamp(sx_in[i], MARGINAL2D_EPS, 1.0 - MARGINAL2D_EPS)
            sy[i] = fmath.clamp(sy_in[i], MARGINAL2D_EPS, 1.0 - MARGINAL2D_EPS)
            mb[i] = marg + t0[i] * ny
            i += 1
        row = search_lanes(vals, mb, 0, mstride, w1, vf(), ny, sy)
        cb = vi()
        fy = vf()
        i = int(0)
        while i < K:
            cb[i] = cond + t0[i] * plane + row[i] * nx
            r = marginal2d_row_setup(vals, mb[i], mstride, cb[i], nx, stride, w1[i], row[i], sx[i], sy[i])
            fy[i] = r[0]
            sx[i] = r[1]
            i += 1
        col = search_lanes(vals, cb, nx, stride, w1, fy, nx, sx)
        x = vf()
        y = vf()
        pdf = vf()
        i = int(0)
        while i < K:
            u = marginal2d_finish(vals, data, cb[i], ny, nx, plane, stride, t0[i], w1[i], row[i], col[i], fy[i],
                                  sx[i])
            x[i] = u[0]
            y[i] = u[1]
            pdf[i] = u[2]
            i += 1
        return x, y, pdf

    return marginal2d_sample_lanes
