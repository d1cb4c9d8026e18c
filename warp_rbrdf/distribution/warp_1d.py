"""Warp functions of the 1-D distributions (NumPy references in :mod:`.reference`): the interval
search over a sorted array, piecewise-constant and piecewise-linear sampling, density and
inversion on [0, 1].

Arrays are flat: a distribution is ``size`` consecutive entries of an array starting at ``off``,
so that many distributions share one array (one row of a table each). The searches and the
piecewise-constant functions are generic over the array's float type (float32 or float64:
``x``, ``u`` and the array have the same type); the piecewise-linear ones are float32.

* :func:`find_interval`, :func:`find_interval_row`: the last ``i`` in ``[0, size - 2]`` with
  ``cdf[off + i] <= x``, 0 when there is none (Mitsuba's ``find_interval``, pbrt-v4's
  ``FindInterval``): the interval ``[cdf[i], cdf[i + 1])`` that holds ``x``, clamped to the
  array's intervals; 0 for ``size < 2``;
* :func:`pc1d_sample`, :func:`pc1d_mass`, :func:`pc1d_pdf`, :func:`pc1d_invert`: ``n`` cells
  of constant density, the CDF as ``n + 1`` entries (``cdf[0] = 0``, ``cdf[n] = 1``);
* :func:`linear_fraction`: where the integral of a linear density over a cell reaches a value
  (the quadratic solved without cancellation; the ``Marginal2D`` warp keeps the RGL format's
  own arithmetic, :func:`.warp_2d.format_fraction`);
* :func:`pl1d_sample`, :func:`pl1d_pdf`, :func:`pl1d_invert`: ``n`` nodes, the density
  linear between them, node densities and CDF as ``n`` entries each.
"""
from __future__ import annotations

from typing import Any

import warp as wp

from .. import fastmath as fmath


@wp.func
def find_interval(cdf: wp.array(dtype=Any), off: int, size: int, x: Any) -> int:
    """The last ``i`` in ``[0, size - 2]`` with ``cdf[off + i] <= x`` (0 when none; 0 for
    ``size < 2``); ``cdf[off .. off + size - 1]`` non-decreasing."""
    lo = int(0)
    hi = size
    while lo < hi:
        mid = (lo + hi) // 2
        if cdf[off + mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    return fmath.fmax(fmath.fmin(lo - 1, size - 2), 0)


@wp.func
def find_interval_row(cdf: wp.array2d(dtype=Any), row: int, size: int, x: Any) -> int:
    """:func:`find_interval` over the first ``size`` entries of row ``row`` of a 2-D array."""
    lo = int(0)
    hi = size
    while lo < hi:
        mid = (lo + hi) // 2
        if cdf[row, mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    return fmath.fmax(fmath.fmin(lo - 1, size - 2), 0)


@wp.func
def pc1d_mass(cdf: wp.array(dtype=Any), off: int, i: int):
    """Probability of cell ``i``: ``cdf[off + i + 1] - cdf[off + i]``."""
    return cdf[off + i + 1] - cdf[off + i]


@wp.func
def pc1d_sample(cdf: wp.array(dtype=Any), off: int, n: int, u: Any):
    """Piecewise-constant sample of ``u`` in [0, 1) over the ``n`` cells whose CDF is
    ``cdf[off .. off + n]``: ``(i, frac, mass)``, the cell, the position inside it (the
    remainder of ``u`` rescaled to the cell, in [0, 1]; 1/2 in a cell of no mass, reached only
    past the last cell of mass) and the cell's probability. The point is ``(i + frac) / n``,
    its density ``mass * n``."""
    i = find_interval(cdf, off, n + 1, u)
    frac, m = pc1d_in_cell(cdf, off, i, u)
    return i, frac, m


@wp.func
def pc1d_in_cell(cdf: wp.array(dtype=Any), off: int, i: int, u: Any):
    """:func:`pc1d_sample` in its cell ``i``: ``(frac, mass)``."""
    c0 = cdf[off + i]
    m = cdf[off + i + 1] - c0
    frac = type(u)(0.5)
    if m > type(u)(0.0):
        frac = fmath.clamp((u - c0) / m, type(u)(0.0), type(u)(1.0))
    return frac, m


@wp.func
def pc1d_cell(x: Any, n: int) -> int:
    """The cell of ``n`` on [0, 1] that holds ``x`` (clamped)."""
    return fmath.clamp(int(wp.floor(x * type(x)(n))), 0, n - 1)


@wp.func
def pc1d_pdf(cdf: wp.array(dtype=Any), off: int, n: int, x: Any):
    """Density on [0, 1] of :func:`pc1d_sample` at ``x`` (0 outside [0, 1])."""
    if x < type(x)(0.0) or x > type(x)(1.0):
        return type(x)(0.0)
    return pc1d_mass(cdf, off, pc1d_cell(x, n)) * type(x)(n)


@wp.func
def pc1d_invert(cdf: wp.array(dtype=Any), off: int, n: int, x: Any):
    """The ``u`` that :func:`pc1d_sample` maps to ``x`` in [0, 1] (the CDF at ``x``)."""
    xc = fmath.clamp(x, type(x)(0.0), type(x)(1.0))
    i = pc1d_cell(xc, n)
    return cdf[off + i] + (xc * type(x)(n) - type(x)(i)) * pc1d_mass(cdf, off, i)


@wp.func
def linear_fraction(a: float, b: float, y: float) -> float:
    """Fraction ``t`` in [0, 1] of a unit cell whose density goes linearly from ``a`` to ``b``
    where its integral from 0 reaches ``y``: the root of ``a t + (b - a) t^2 / 2 = y`` without
    cancellation, ``2 y / (a + sqrt(a^2 + 2 y (b - a)))`` (0 where the cell has no density)."""
    den = a + wp.sqrt(fmath.fmax(a * a + 2.0 * y * (b - a), 0.0))
    t = float(0.0)
    if den > 0.0:
        t = 2.0 * y / den
    return fmath.clamp(t, 0.0, 1.0)


@wp.func
def pl1d_sample(cdf: wp.array(dtype=float), pdf: wp.array(dtype=float), off: int, n: int, u: float):
    """Piecewise-linear sample of ``u`` in [0, 1) over ``n`` nodes (node densities
    ``pdf[off ..]``, CDF ``cdf[off ..]``, ``n`` entries each): ``(i, frac, density)``, the node
    interval, the position inside it and the density there. The point is
    ``(i + frac) / (n - 1)``."""
    i = find_interval(cdf, off, n, u)
    a = pdf[off + i]
    b = pdf[off + i + 1]
    t = linear_fraction(a, b, (u - cdf[off + i]) * float(n - 1))
    return i, t, a + t * (b - a)


@wp.func
def _pl1d_at(x: float, n: int) -> wp.vec2:
    """(node interval, position inside it) of ``x`` clamped to [0, 1]; the interval as a float."""
    s = fmath.clamp(x, 0.0, 1.0) * float(n - 1)
    i = fmath.fmin(int(s), n - 2)
    return wp.vec2(float(i), s - float(i))


@wp.func
def pl1d_pdf(pdf: wp.array(dtype=float), off: int, n: int, x: float) -> float:
    """Density of :func:`pl1d_sample` at ``x`` (0 outside [0, 1])."""
    if x < 0.0 or x > 1.0:
        return 0.0
    it = _pl1d_at(x, n)
    i = int(it[0])
    a = pdf[off + i]
    return a + it[1] * (pdf[off + i + 1] - a)


@wp.func
def pl1d_invert(cdf: wp.array(dtype=float), pdf: wp.array(dtype=float), off: int, n: int, x: float) -> float:
    """The ``u`` that :func:`pl1d_sample` maps to ``x`` in [0, 1]."""
    it = _pl1d_at(x, n)
    i = int(it[0])
    t = it[1]
    a = pdf[off + i]
    b = pdf[off + i + 1]
    return cdf[off + i] + t * (a + 0.5 * t * (b - a)) / float(n - 1)
