"""Warp functions over the tables of an RGL-EPFL material as the ``rgl`` kind packs them
(:mod:`warp_rbrdf.materials.rgl`): the format's interpolants, the same arithmetic as the NumPy
reference :mod:`fit.formats.rgl_interpolants` (itself a port of the reference loader's
``Marginal2D``), in float32.

A *warp* is a 2-D density on ``ny x nx`` nodes of the unit square, conditioned on theta_i: per
theta_i slice, the normalized node values ``data``, the conditional CDFs ``cond`` along x (per
row) and the marginal CDF ``marg`` along y, all in index units (a cell is 1 x 1), every looked-up
quantity interpolated linearly between the two nearest theta_i slices (``t0``, weight ``w1``
of slice ``t0 + 1``). Layouts in ``Materials.rgl_f``: ``data``/``cond`` at
``off + (slice * ny + y) * nx + x``, ``marg`` at ``off + slice * ny + y``.

* :func:`theta_interval`: the slice interval of an incidence (reference ``find_interval``);
* :func:`bilinear`: a plain bilinear table (``ndf``, ``sigma``);
* :func:`warp_invert`: unit-square point (``u``) -> warped point (``s``) and the density of the
  forward warp at ``u``;
* :func:`warp_eval`: the normalized density of a warp at a point (the luminance pdf);
* :func:`warp_sample`: the forward warp (``s`` -> ``u``) and its density, by binary searches
  over the interpolated CDFs;
* :func:`rgb_eval`: the ``rgb`` tensor, bilinear over ``s`` and linear in theta_i.
"""
from __future__ import annotations

import warp as wp

from .data import Materials


@wp.func
def theta_interval(mats: Materials, off: int, n: int, x: float) -> wp.vec2:
    """(t0, w1) of incidence ``x`` (radians) over the ``n`` sorted angles at ``rgl_f[off]``:
    ``t0`` in [0, n-2] (the last k <= n-2 with theta[k] <= x, 0 below), ``w1`` the clamped
    weight of slice ``t0 + 1``; (0, 0) for one slice. ``t0`` returned as a float."""
    if n < 2:
        return wp.vec2(0.0, 0.0)
    t0 = int(0)
    for k in range(1, n - 1):
        if mats.rgl_f[off + k] <= x:
            t0 = k
    p0 = mats.rgl_f[off + t0]
    p1 = mats.rgl_f[off + t0 + 1]
    w1 = wp.clamp((x - p0) / (p1 - p0), 0.0, 1.0)
    return wp.vec2(float(t0), w1)


@wp.func
def _cell(u: float, n: int) -> int:
    x = u * float(n - 1)
    return wp.min(int(wp.max(x, 0.0)), n - 2)


@wp.func
def _frac(u: float, n: int, i: int) -> float:
    """Position of ``u`` inside cell ``i`` of ``n`` nodes (0 at node i, 1 at node i + 1)."""
    return u * float(n - 1) - float(i)


@wp.func
def _stride(size: int, n_slices: int) -> int:
    """Floats from one theta_i slice to the next (0 with a single slice: no interpolation)."""
    if n_slices < 2:
        return 0
    return size


@wp.func
def bilinear(mats: Materials, off: int, ny: int, nx: int, ux: float, uy: float) -> float:
    """Bilinear interpolant of the ``ny x nx`` table at ``rgl_f[off]`` at (ux, uy) in the unit
    square (x along the rows' columns)."""
    ix = _cell(ux, nx)
    iy = _cell(uy, ny)
    fx = _frac(ux, nx, ix)
    fy = _frac(uy, ny, iy)
    k = off + iy * nx + ix
    v00 = mats.rgl_f[k]
    v10 = mats.rgl_f[k + 1]
    v01 = mats.rgl_f[k + nx]
    v11 = mats.rgl_f[k + nx + 1]
    a = v00 + fx * (v10 - v00)
    b = v01 + fx * (v11 - v01)
    return a + fy * (b - a)


@wp.func
def _lerp_at(mats: Materials, i: int, stride: int, w1: float) -> float:
    """``rgl_f[i]`` interpolated towards the next slice (``stride`` floats on; 0: one slice)."""
    a = mats.rgl_f[i]
    if stride == 0:
        return a
    return a + w1 * (mats.rgl_f[i + stride] - a)


@wp.func
def _corners(mats: Materials, k: int, nx: int, stride: int, w1: float) -> wp.vec4:
    """The four node values (x0 y0, x1 y0, x0 y1, x1 y1) of the cell whose first node is
    ``rgl_f[k]`` in rows of ``nx``, each interpolated towards the next slice."""
    return wp.vec4(_lerp_at(mats, k, stride, w1), _lerp_at(mats, k + 1, stride, w1),
                   _lerp_at(mats, k + nx, stride, w1), _lerp_at(mats, k + nx + 1, stride, w1))


@wp.func
def warp_invert(mats: Materials, data: int, cond: int, marg: int, ny: int, nx: int, n_slices: int,
                t0: int, w1: float, ux: float, uy: float) -> wp.vec3:
    """Inverse warp of (ux, uy): returns (sx, sy, pdf), pdf the density of the forward warp at
    (ux, uy) on the unit square."""
    ix = _cell(ux, nx)
    iy = _cell(uy, ny)
    fx = _frac(ux, nx, ix)
    fy = _frac(uy, ny, iy)
    plane = ny * nx
    stride = _stride(plane, n_slices)
    k = t0 * plane + iy * nx + ix
    v = _corners(mats, data + k, nx, stride, w1)
    cc0 = _lerp_at(mats, cond + k, stride, w1)
    cc1 = _lerp_at(mats, cond + k + nx, stride, w1)
    krow = t0 * plane + iy * nx + nx - 1
    r0 = _lerp_at(mats, cond + krow, stride, w1)
    r1 = _lerp_at(mats, cond + krow + nx, stride, w1)
    mstride = _stride(ny, n_slices)
    m0 = _lerp_at(mats, marg + t0 * ny + iy, mstride, w1)
    gy = 1.0 - fy
    c0 = gy * v[0] + fy * v[2]
    c1 = gy * v[1] + fy * v[3]
    pdf = c0 + fx * (c1 - c0)
    rr = gy * r0 + fy * r1
    sx = 0.0
    if rr > 0.0:
        sx = (fx * (c0 + 0.5 * fx * (c1 - c0)) + gy * cc0 + fy * cc1) / rr
    sy = fy * (r0 + 0.5 * fy * (r1 - r0)) + m0
    return wp.vec3(sx, sy, pdf * float((nx - 1) * (ny - 1)))


@wp.func
def warp_eval(mats: Materials, data: int, ny: int, nx: int, n_slices: int, t0: int, w1: float,
              sx: float, sy: float) -> float:
    """Normalized density of a warp at (sx, sy) of the unit square (bilinear, lerped slices)."""
    ix = _cell(sx, nx)
    iy = _cell(sy, ny)
    fx = _frac(sx, nx, ix)
    fy = _frac(sy, ny, iy)
    plane = ny * nx
    stride = _stride(plane, n_slices)
    v = _corners(mats, data + t0 * plane + iy * nx + ix, nx, stride, w1)
    a = v[0] + fx * (v[1] - v[0])
    b = v[2] + fx * (v[3] - v[2])
    return (a + fy * (b - a)) * float((nx - 1) * (ny - 1))


@wp.func
def _solve_linear_density(a: float, b: float, y: float) -> float:
    """Fraction f in a cell whose density goes linearly from ``a`` to ``b`` with integral ``y``
    up to f: the root of a f + (b - a) f^2 / 2 = y (the reference's formula)."""
    if wp.abs(a - b) < 1.0e-4 * (a + b):
        return 2.0 * y / (a + b)
    return (a - wp.sqrt(wp.max(a * a - 2.0 * y * (a - b), 0.0))) / (a - b)


@wp.func
def warp_sample(mats: Materials, data: int, cond: int, marg: int, ny: int, nx: int, n_slices: int,
                t0: int, w1: float, sx_in: float, sy_in: float) -> wp.vec3:
    """Forward warp of (sx, sy) (uniform on the unit square): returns (ux, uy, pdf)."""
    eps = 5.9604645e-8
    sx = wp.clamp(sx_in, eps, 1.0 - eps)
    sy = wp.clamp(sy_in, eps, 1.0 - eps)
    plane = ny * nx
    stride = _stride(plane, n_slices)
    mstride = _stride(ny, n_slices)
    # row: the last k in [0, ny-2] with marg(k) < sy (marg is non-decreasing, marg(0) = 0)
    mb = marg + t0 * ny
    lo = int(0)
    hi = ny - 2
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if _lerp_at(mats, mb + mid, mstride, w1) < sy:
            lo = mid
        else:
            hi = mid - 1
    row = lo
    sy = sy - _lerp_at(mats, mb + row, mstride, w1)
    cb = cond + t0 * plane + row * nx
    r0 = _lerp_at(mats, cb + nx - 1, stride, w1)
    r1 = _lerp_at(mats, cb + nx + nx - 1, stride, w1)
    fy = _solve_linear_density(r0, r1, sy)
    gy = 1.0 - fy
    sx = sx * (gy * r0 + fy * r1)
    # column: the last k in [0, nx-2] with the interpolated conditional CDF < sx
    lo = int(0)
    hi = nx - 2
    while lo < hi:
        mid = (lo + hi + 1) // 2
        c = gy * _lerp_at(mats, cb + mid, stride, w1) + fy * _lerp_at(mats, cb + nx + mid, stride, w1)
        if c < sx:
            lo = mid
        else:
            hi = mid - 1
    col = lo
    sx = sx - (gy * _lerp_at(mats, cb + col, stride, w1) + fy * _lerp_at(mats, cb + nx + col, stride, w1))
    v = _corners(mats, data + t0 * plane + row * nx + col, nx, stride, w1)
    c0 = gy * v[0] + fy * v[2]
    c1 = gy * v[1] + fy * v[3]
    fx = _solve_linear_density(c0, c1, sx)
    pdf = ((1.0 - fx) * c0 + fx * c1) * float((nx - 1) * (ny - 1))
    return wp.vec3((float(col) + fx) / float(nx - 1), (float(row) + fy) / float(ny - 1), pdf)


@wp.func
def rgb_eval(mats: Materials, off: int, ny: int, nx: int, n_slices: int, t0: int, w1: float,
             sx: float, sy: float) -> wp.vec3:
    """The (n_slices, 3, ny, nx) ``rgb`` tensor at ``rgl_f[off]``: bilinear at (sx, sy),
    linear between slices ``t0`` and ``t0 + 1``."""
    ix = _cell(sx, nx)
    iy = _cell(sy, ny)
    fx = _frac(sx, nx, ix)
    fy = _frac(sy, ny, iy)
    plane = ny * nx
    stride = _stride(3 * plane, n_slices)
    out = wp.vec3(0.0)
    for c in range(3):
        v = _corners(mats, off + (t0 * 3 + c) * plane + iy * nx + ix, nx, stride, w1)
        a = v[0] + fx * (v[1] - v[0])
        b = v[2] + fx * (v[3] - v[2])
        out[c] = a + fy * (b - a)
    return out
