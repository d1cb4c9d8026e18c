"""Warp functions of the 2-D distributions on the unit square (NumPy references
:class:`.reference.PiecewiseConstant2D` and :class:`.reference.Marginal2D`).

**Piecewise constant** (``ny x nx`` cells; generic over float32 / float64 arrays): the marginal
CDF over rows at ``marg[moff .. moff + ny]`` and one conditional CDF per row, row ``r`` at
``cond[coff + r (nx + 1) ..]`` (``nx + 1`` entries). ``uy`` picks the row, ``ux`` the column;
``x`` runs along a row. :func:`pc2d_sample`, :func:`pc2d_pdf`, :func:`pc2d_invert`.

**Marginal2D** (the RGL-EPFL format's bilinear warp, Mitsuba 3 ``Marginal2D``; float32): node
values on ``ny x nx`` nodes of the unit square, normalized per slice of an interpolated
parameter, with their running integrals, all in node units (a cell is 1 x 1) in one flat
array ``vals``: slice ``t`` of the densities and of the conditional CDFs (along each row) at
``data + (t ny + y) nx + x`` and ``cond + (t ny + y) nx + x``, of the marginal CDF (down the
rows' totals) at ``marg + t ny + y``. Every looked-up value is interpolated linearly between
slices ``t0`` and ``t0 + 1`` (``w1`` the weight of the second); ``n_slices = 1`` is the warp
without a parameter. :func:`marginal2d_sample` (uniforms -> point), :func:`marginal2d_invert`
(point -> uniforms), :func:`marginal2d_pdf`; :func:`bilinear_lerp`, the interpolant they
share, serves plain tables of the same layout.
"""
from __future__ import annotations

from typing import Any

import warp as wp

from .. import fastmath as fmath
from .warp_1d import pc1d_cell, pc1d_invert, pc1d_mass, pc1d_pdf, pc1d_sample

# ---------------------------------------------------------------------------- piecewise constant


@wp.func
def pc2d_sample(marg: wp.array(dtype=Any), moff: int, cond: wp.array(dtype=Any), coff: int, ny: int,
                nx: int, ux: Any, uy: Any):
    """``(x, y, pdf)`` of uniforms (ux, uy): the row by the marginal, the column by that row's
    conditional, each continuous inside its cell."""
    r, fy, my = pc1d_sample(marg, moff, ny, uy)
    c, fx, mx = pc1d_sample(cond, coff + r * (nx + 1), nx, ux)
    return ((type(ux)(c) + fx) / type(ux)(nx), (type(ux)(r) + fy) / type(ux)(ny),
            my * mx * type(ux)(nx * ny))


@wp.func
def pc2d_pdf(marg: wp.array(dtype=Any), moff: int, cond: wp.array(dtype=Any), coff: int, ny: int,
             nx: int, x: Any, y: Any):
    """Density of :func:`pc2d_sample` at (x, y) (0 outside the unit square)."""
    py = pc1d_pdf(marg, moff, ny, y)
    if py == type(y)(0.0):
        return py
    return py * pc1d_pdf(cond, coff + pc1d_cell(y, ny) * (nx + 1), nx, x)


@wp.func
def pc2d_invert(marg: wp.array(dtype=Any), moff: int, cond: wp.array(dtype=Any), coff: int, ny: int,
                nx: int, x: Any, y: Any):
    """``(ux, uy)``: the uniforms :func:`pc2d_sample` maps to (x, y)."""
    yc = fmath.clamp(y, type(y)(0.0), type(y)(1.0))
    ux = pc1d_invert(cond, coff + pc1d_cell(yc, ny) * (nx + 1), nx, x)
    return ux, pc1d_invert(marg, moff, ny, yc)


# ----------------------------------------------------------------------------------- Marginal2D


#: :func:`marginal2d_sample` clamps its uniforms to [2^-24, 1 - 2^-24]
MARGINAL2D_EPS = wp.constant(5.9604645e-8)


@wp.func
def _node(u: float, n: int) -> int:
    """The cell in [0, n - 2] of ``n`` nodes on [0, 1] that holds ``u`` (clamped)."""
    return fmath.fmin(int(fmath.fmax(u * float(n - 1), 0.0)), n - 2)


@wp.func
def _stride(size: int, n_slices: int) -> int:
    """Entries from one slice to the next (0 with a single slice: no interpolation)."""
    if n_slices < 2:
        return 0
    return size


@wp.func
def _lerp_at(vals: wp.array(dtype=float), i: int, stride: int, w1: float) -> float:
    """``vals[i]`` interpolated towards the next slice (``stride`` entries on; 0: one slice)."""
    a = vals[i]
    if stride == 0:
        return a
    return a + w1 * (vals[i + stride] - a)


@wp.func
def _corners(vals: wp.array(dtype=float), k: int, nx: int, stride: int, w1: float) -> wp.vec4:
    """The node values (x0 y0, x1 y0, x0 y1, x1 y1) of the cell whose first node is ``vals[k]``
    in rows of ``nx``, each interpolated towards the next slice."""
    return wp.vec4(_lerp_at(vals, k, stride, w1), _lerp_at(vals, k + 1, stride, w1),
                   _lerp_at(vals, k + nx, stride, w1), _lerp_at(vals, k + nx + 1, stride, w1))


@wp.func
def _find_interval_lerped(vals: wp.array(dtype=float), off: int, row_step: int, stride: int, w1: float,
                          fy: float, size: int, x: float) -> int:
    """Marginal2D's interval search: the last ``i`` in ``[0, size - 2]`` whose CDF value,
    ``(1 - fy) L(off + i) + fy L(off + row_step + i)`` with ``L`` interpolated between slices,
    is ``< x`` (0 when none; the CDF starts at 0 and ``x > 0``). ``fy = 0``: one CDF."""
    gy = 1.0 - fy
    lo = int(0)
    hi = size - 2
    while lo < hi:
        mid = (lo + hi + 1) // 2
        c = _lerp_at(vals, off + mid, stride, w1)
        if fy != 0.0:
            c = gy * c + fy * _lerp_at(vals, off + row_step + mid, stride, w1)
        if c < x:
            lo = mid
        else:
            hi = mid - 1
    return lo


@wp.func
def format_fraction(a: float, b: float, y: float) -> float:
    """:func:`.warp_1d.linear_fraction` as the RGL-EPFL format and Mitsuba 3's ``Marginal2D``
    compute it (the warp's own arithmetic, :func:`.reference.format_fraction`): ``2 y / (a + b)``
    where ``|a - b| < 1e-4 (a + b)``, else ``(a - sqrt(a^2 - 2 y (a - b))) / (a - b)``."""
    if wp.abs(a - b) < 1.0e-4 * (a + b):
        return 2.0 * y / (a + b)
    return (a - wp.sqrt(fmath.fmax(a * a - 2.0 * y * (a - b), 0.0))) / (a - b)


@wp.func
def bilinear_lerp(vals: wp.array(dtype=float), off: int, ny: int, nx: int, stride: int, w1: float,
                  x: float, y: float) -> float:
    """The ``ny x nx`` node table at ``vals[off]`` at (x, y) of the unit square: bilinear in the
    nodes, linear towards the table ``stride`` entries on (weight ``w1``; stride 0: one table)."""
    ix = _node(x, nx)
    iy = _node(y, ny)
    fx = x * float(nx - 1) - float(ix)
    fy = y * float(ny - 1) - float(iy)
    v = _corners(vals, off + iy * nx + ix, nx, stride, w1)
    a = v[0] + fx * (v[1] - v[0])
    b = v[2] + fx * (v[3] - v[2])
    return a + fy * (b - a)


@wp.func
def marginal2d_pdf(vals: wp.array(dtype=float), data: int, ny: int, nx: int, n_slices: int, t0: int,
                   w1: float, x: float, y: float) -> float:
    """Density of the warp at (x, y) of the unit square."""
    plane = ny * nx
    d = bilinear_lerp(vals, data + t0 * plane, ny, nx, _stride(plane, n_slices), w1, x, y)
    return d * float((nx - 1) * (ny - 1))


@wp.func
def marginal2d_invert(vals: wp.array(dtype=float), data: int, cond: int, marg: int, ny: int, nx: int,
                      n_slices: int, t0: int, w1: float, x: float, y: float) -> wp.vec3:
    """``(sx, sy, pdf)``: the uniforms :func:`marginal2d_sample` maps to (x, y) (the
    conditional and marginal CDFs there) and the density at (x, y)."""
    ix = _node(x, nx)
    iy = _node(y, ny)
    fx = x * float(nx - 1) - float(ix)
    fy = y * float(ny - 1) - float(iy)
    plane = ny * nx
    stride = _stride(plane, n_slices)
    k = t0 * plane + iy * nx + ix
    v = _corners(vals, data + k, nx, stride, w1)
    cc0 = _lerp_at(vals, cond + k, stride, w1)
    cc1 = _lerp_at(vals, cond + k + nx, stride, w1)
    krow = t0 * plane + iy * nx + nx - 1
    r0 = _lerp_at(vals, cond + krow, stride, w1)
    r1 = _lerp_at(vals, cond + krow + nx, stride, w1)
    m0 = _lerp_at(vals, marg + t0 * ny + iy, _stride(ny, n_slices), w1)
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
def marginal2d_row_setup(vals: wp.array(dtype=float), mb: int, mstride: int, cb: int, nx: int, stride: int,
                         w1: float, row: int, sx: float, sy: float) -> wp.vec2:
    """The step of :func:`marginal2d_sample` between its two searches: ``(fy, sx')`` -- the
    fraction inside ``row`` by the linear density of the row totals, and ``sx`` scaled to the
    row's total (``mb``, ``cb``: the slice's marginal CDF and the row's conditional CDF)."""
    sy = sy - _lerp_at(vals, mb + row, mstride, w1)
    r0 = _lerp_at(vals, cb + nx - 1, stride, w1)
    r1 = _lerp_at(vals, cb + nx + nx - 1, stride, w1)
    fy = format_fraction(r0, r1, sy)
    gy = 1.0 - fy
    return wp.vec2(fy, sx * (gy * r0 + fy * r1))


@wp.func
def marginal2d_finish(vals: wp.array(dtype=float), data: int, cb: int, ny: int, nx: int, plane: int,
                      stride: int, t0: int, w1: float, row: int, col: int, fy: float, sx: float) -> wp.vec3:
    """The last step of :func:`marginal2d_sample` after its column search: ``(x, y, pdf)``."""
    gy = 1.0 - fy
    sx = sx - (gy * _lerp_at(vals, cb + col, stride, w1) + fy * _lerp_at(vals, cb + nx + col, stride, w1))
    v = _corners(vals, data + t0 * plane + row * nx + col, nx, stride, w1)
    c0 = gy * v[0] + fy * v[2]
    c1 = gy * v[1] + fy * v[3]
    fx = format_fraction(c0, c1, sx)
    pdf = ((1.0 - fx) * c0 + fx * c1) * float((nx - 1) * (ny - 1))
    return wp.vec3((float(col) + fx) / float(nx - 1), (float(row) + fy) / float(ny - 1), pdf)


@wp.func
def marginal2d_sample(vals: wp.array(dtype=float), data: int, cond: int, marg: int, ny: int, nx: int,
                      n_slices: int, t0: int, w1: float, sx_in: float, sy_in: float) -> wp.vec3:
    """``(x, y, pdf)`` of uniforms (sx, sy), clamped to [2^-24, 1 - 2^-24]: the row by the
    marginal CDF, the fraction inside it by the linear density of the row totals, then the
    column by the conditional CDF interpolated between the row's two node rows (fractions by
    :func:`format_fraction`). :mod:`.lanes` draws K samples at once with the same steps."""
    sx = fmath.clamp(sx_in, MARGINAL2D_EPS, 1.0 - MARGINAL2D_EPS)
    sy = fmath.clamp(sy_in, MARGINAL2D_EPS, 1.0 - MARGINAL2D_EPS)
    plane = ny * nx
    stride = _stride(plane, n_slices)
    mstride = _stride(ny, n_slices)
    mb = marg + t0 * ny
    row = _find_interval_lerped(vals, mb, 0, mstride, w1, 0.0, ny, sy)
    cb = cond + t0 * plane + row * nx
    r = marginal2d_row_setup(vals, mb, mstride, cb, nx, stride, w1, row, sx, sy)
    col = _find_interval_lerped(vals, cb, nx, stride, w1, r[0], nx, r[1])
    return marginal2d_finish(vals, data, cb, ny, nx, plane, stride, t0, w1, row, col, r[0], r[1])
