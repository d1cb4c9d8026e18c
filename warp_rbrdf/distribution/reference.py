"""NumPy references (float64, vectorized) of the sampling distributions whose Warp functions are
:mod:`.warp_1d` and :mod:`.warp_2d`: the same conventions, the same index arithmetic.

Every distribution lives on the unit interval or the unit square; a caller maps it onto its
own domain (an angle range, a texture) and divides densities by that domain's size.

* :func:`find_interval`: the interval of a sorted array that holds ``x``;
* :class:`PiecewiseConstant1D`: ``n`` cells of constant density;
* :class:`PiecewiseLinear1D`: ``n`` nodes, density linear between them;
* :class:`PiecewiseConstant2D`: ``ny x nx`` cells, a marginal over rows and one conditional
  per row;
* :class:`Marginal2D`: the bilinear warp of the RGL-EPFL format (a density on ``ny x nx``
  nodes, conditioned on a parameter with slices interpolated linearly).

A distribution is built from non-negative finite values. One of zero total mass samples
uniformly (its CDF is the uniform one), and its densities are those of the uniform CDF: the
sampler and its density always agree.
"""
from __future__ import annotations

import numpy as np


def find_interval(cdf, x, strict: bool = False):
    """Index ``i`` in ``[0, size - 2]`` of the interval ``[cdf[i], cdf[i + 1])`` that holds
    ``x`` (``cdf`` sorted, ``size >= 2`` entries along its last axis): the last ``i`` with
    ``cdf[i] <= x`` (``strict``: ``cdf[i] < x``), clamped to ``[0, size - 2]`` (0 below the
    first entry, ``size - 2`` at or above the last). ``cdf`` 1-D, or one row per ``x``."""
    cdf = np.asarray(cdf, float)
    x = np.asarray(x, float)
    size = cdf.shape[-1]
    if cdf.ndim == 1:
        count = np.searchsorted(cdf, x, side="left" if strict else "right")
    else:
        hit = cdf < x[..., None] if strict else cdf <= x[..., None]
        count = hit.sum(-1)
    return np.clip(count - 1, 0, max(size - 2, 0)).astype(np.intp)


def _checked(values, ndim: int) -> np.ndarray:
    v = np.asarray(values, float)
    if v.ndim != ndim or min(v.shape) < 1:
        raise ValueError(f"expected a non-empty {ndim}-D array, got shape {v.shape}")
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError("distribution values must be finite and non-negative")
    return v


def constant_cdf(values) -> tuple[np.ndarray, float]:
    """``(cdf (n + 1,), integral)`` of ``n`` cell values on the unit interval: the normalized
    running sum (``cdf[0] = 0``, ``cdf[n] = 1``; the uniform CDF when the total is 0) and the
    integral of the piecewise-constant function (its mean)."""
    v = _checked(values, 1)
    total = float(v.sum())
    if total <= 0:
        return np.linspace(0.0, 1.0, v.size + 1), 0.0
    cdf = np.concatenate([[0.0], np.cumsum(v) / total])
    cdf[-1] = 1.0
    return cdf, total / v.size


class PiecewiseConstant1D:
    """``n`` cells of constant density on [0, 1] (pbrt-v4 ``PiecewiseConstant1D``). Arrays:
    ``cdf`` (n + 1,); ``integral`` the mean of the values (0: sampled uniformly)."""

    def __init__(self, values):
        self.cdf, self.integral = constant_cdf(values)
        self.n = self.cdf.size - 1

    def mass(self, i):
        return self.cdf[i + 1] - self.cdf[i]

    def sample(self, u):
        """``(x, pdf, index)`` of uniforms ``u`` in [0, 1): cell ``index``, then ``x`` inside it
        at the remainder of ``u`` rescaled to the cell (a cell of no mass, reached only at the
        top end, gives its centre); ``pdf`` = mass * n."""
        u = np.asarray(u, float)
        i = find_interval(self.cdf, u)
        m = self.mass(i)
        frac = np.where(m > 0, (u - self.cdf[i]) / np.where(m > 0, m, 1.0), 0.5)
        frac = np.clip(frac, 0.0, 1.0)
        return (i + frac) / self.n, m * self.n, i

    def cell(self, x):
        return np.clip(np.floor(np.asarray(x, float) * self.n), 0, self.n - 1).astype(np.intp)

    def pdf(self, x):
        """Density at ``x`` (0 outside [0, 1])."""
        x = np.asarray(x, float)
        return np.where((x >= 0) & (x <= 1), self.mass(self.cell(x)) * self.n, 0.0)

    def invert(self, x):
        """The ``u`` that :meth:`sample` maps to ``x`` (the CDF at ``x``)."""
        x = np.clip(np.asarray(x, float), 0.0, 1.0)
        i = self.cell(x)
        return self.cdf[i] + (x * self.n - i) * self.mass(i)


def linear_fraction(a, b, y):
    """Fraction ``t`` in [0, 1] of a cell of unit width whose density goes linearly from ``a``
    to ``b``, where the integral from 0 to ``t`` is ``y``: the root of
    ``a t + (b - a) t^2 / 2 = y`` written without cancellation,
    ``t = 2 y / (a + sqrt(a^2 + 2 y (b - a)))`` (0 where the cell has no density)."""
    a, b, y = (np.asarray(v, float) for v in (a, b, y))
    den = a + np.sqrt(np.maximum(a * a + 2.0 * y * (b - a), 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(den > 0, 2.0 * y / np.where(den > 0, den, 1.0), 0.0)
    return np.clip(t, 0.0, 1.0)


def format_fraction(a, b, y):
    """The same root as :func:`linear_fraction` as the RGL-EPFL format's loader and Mitsuba 3's
    ``Marginal2D`` compute it, the warp's own arithmetic: ``2 y / (a + b)`` where the cell is
    nearly constant (``|a - b| < 1e-4 (a + b)``: relative error up to ~2.5e-5 of the root),
    else ``(a - sqrt(a^2 - 2 y (a - b))) / (a - b)``."""
    a, b, y = (np.asarray(v, float) for v in (a, b, y))
    const = np.abs(a - b) < 1e-4 * (a + b)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(const, 2.0 * y / (a + b), (a - np.sqrt(np.maximum(a * a - 2.0 * y * (a - b), 0.0))) / (a - b))


class PiecewiseLinear1D:
    """A density linear between ``n >= 2`` equally spaced nodes of [0, 1] (Mitsuba 3's
    ``ContinuousDistribution``). Arrays: ``pdf`` (n,) the normalized node densities, ``cdf``
    (n,) its integral at the nodes (trapezoids; ``cdf[0] = 0``, ``cdf[-1] = 1``); ``integral``
    the integral of the values (0: the uniform density)."""

    def __init__(self, values):
        v = _checked(values, 1)
        if v.size < 2:
            raise ValueError("a piecewise-linear distribution needs at least 2 nodes")
        self.n = v.size
        cells = 0.5 * (v[1:] + v[:-1]) / (self.n - 1)
        self.integral = float(cells.sum())
        if self.integral <= 0:
            v = np.ones_like(v)
            cells = np.full(self.n - 1, 1.0 / (self.n - 1))
        total = float(cells.sum())
        self.pdf_nodes = v / total
        self.cdf = np.concatenate([[0.0], np.cumsum(cells) / total])
        self.cdf[-1] = 1.0

    def sample(self, u):
        """``(x, pdf, index)`` of uniforms ``u`` in [0, 1): node interval ``index``, then the
        fraction inside it where the linear density's integral is the remainder of ``u``."""
        u = np.asarray(u, float)
        i = find_interval(self.cdf, u)
        a, b = self.pdf_nodes[i], self.pdf_nodes[i + 1]
        t = linear_fraction(a, b, (u - self.cdf[i]) * (self.n - 1))
        return (i + t) / (self.n - 1), a + t * (b - a), i

    def _at(self, x):
        x = np.clip(np.asarray(x, float), 0.0, 1.0)
        i = np.minimum((x * (self.n - 1)).astype(np.intp), self.n - 2)
        return i, x * (self.n - 1) - i

    def pdf(self, x):
        x = np.asarray(x, float)
        i, t = self._at(x)
        a, b = self.pdf_nodes[i], self.pdf_nodes[i + 1]
        return np.where((x >= 0) & (x <= 1), a + t * (b - a), 0.0)

    def invert(self, x):
        i, t = self._at(x)
        a, b = self.pdf_nodes[i], self.pdf_nodes[i + 1]
        return self.cdf[i] + t * (a + 0.5 * t * (b - a)) / (self.n - 1)


class PiecewiseConstant2D:
    """``ny x nx`` cells of constant density on the unit square (pbrt-v4
    ``PiecewiseConstant2D``): the marginal over rows (``marginal``, a
    :class:`PiecewiseConstant1D` of the row sums) and one conditional per row (``cond``,
    (ny, nx + 1) CDFs; a row of no mass is uniform). ``x`` runs along a row, ``y`` across rows;
    ``u[..., 1]`` picks the row, ``u[..., 0]`` the column."""

    def __init__(self, values):
        v = _checked(values, 2)
        self.ny, self.nx = v.shape
        self.marginal = PiecewiseConstant1D(v.sum(axis=1))
        self.cond = np.stack([constant_cdf(r)[0] for r in v])
        self.integral = self.marginal.integral / self.nx

    def sample(self, u):
        """``(x, y, pdf)`` of uniforms ``u`` (N, 2)."""
        u = np.asarray(u, float)
        y, p_y, row = self.marginal.sample(u[..., 1])
        c = self.cond[row]
        k = find_interval(c, u[..., 0])
        c0 = np.take_along_axis(c, k[..., None], -1)[..., 0]
        m = np.take_along_axis(c, k[..., None] + 1, -1)[..., 0] - c0
        frac = np.clip(np.where(m > 0, (u[..., 0] - c0) / np.where(m > 0, m, 1.0), 0.5), 0.0, 1.0)
        return (k + frac) / self.nx, y, p_y * m * self.nx

    def _cells(self, x, y):
        col = np.clip(np.floor(np.asarray(x, float) * self.nx), 0, self.nx - 1).astype(np.intp)
        return col, self.marginal.cell(y)

    def pdf(self, x, y):
        x, y = np.asarray(x, float), np.asarray(y, float)
        col, row = self._cells(x, y)
        m = self.cond[row, col + 1] - self.cond[row, col]
        inside = (x >= 0) & (x <= 1) & (y >= 0) & (y <= 1)
        return np.where(inside, self.marginal.pdf(y) * m * self.nx, 0.0)

    def invert(self, x, y):
        """``u`` (N, 2) that :meth:`sample` maps to (x, y)."""
        x = np.clip(np.asarray(x, float), 0.0, 1.0)
        col, row = self._cells(x, y)
        c0 = self.cond[row, col]
        ux = c0 + (x * self.nx - col) * (self.cond[row, col + 1] - c0)
        return np.stack([ux, self.marginal.invert(y)], -1)


def _patch(u, n: int):
    """Cell in [0, n - 2] and position inside it of unit coordinates ``u`` on ``n`` nodes."""
    x = np.asarray(u, float) * (n - 1)
    i = np.minimum(np.maximum(x, 0.0).astype(np.intp), n - 2)
    return i, x - i


class Marginal2D:
    """The bilinear warp of the RGL-EPFL format (Mitsuba 3 ``Marginal2D``, the reference
    loader's ``powitacq`` warp) with one interpolated parameter: ``data`` (S, ny, nx) node
    values of S slices (a 2-D array: one slice, no parameter). Per slice, the density is
    bilinear between the nodes of the unit square; ``cond`` (S, ny, nx) the running integral
    along each row, ``marg`` (S, ny) the integral of the row totals down the rows (node
    units: a cell is 1 x 1), everything divided by the slice's total so that the density
    integrates to 1. Looked-up quantities are interpolated between slices ``t0`` and
    ``t0 + 1`` with the weight ``w1`` of the second. A slice of no positive mass raises
    ``ValueError``."""

    def __init__(self, data):
        d = np.asarray(data, float)
        if d.ndim == 2:
            d = d[None]
        if d.ndim != 3 or d.shape[1] < 2 or d.shape[2] < 2:
            raise ValueError(f"expected (S, ny, nx) node values with ny, nx >= 2, got {d.shape}")
        self.S, self.ny, self.nx = d.shape
        cond = np.zeros_like(d)
        cond[:, :, 1:] = np.cumsum(0.5 * (d[:, :, 1:] + d[:, :, :-1]), axis=2)
        rows = cond[:, :, -1]
        marg = np.zeros((self.S, self.ny))
        marg[:, 1:] = np.cumsum(0.5 * (rows[:, 1:] + rows[:, :-1]), axis=1)
        total = marg[:, -1]
        if not np.all(np.isfinite(total) & (total > 0)):
            raise ValueError("every slice of a Marginal2D needs a positive finite mass")
        self.data = d / total[:, None, None]
        self.cond = cond / total[:, None, None]
        self.marg = marg / total[:, None]

    def _lerp(self, arr, t0, w1, *index):
        a = arr[(t0,) + index]
        if self.S > 1:
            a = a + w1 * (arr[(t0 + 1,) + index] - a)
        return a

    def _slice(self, arr, t0, w1):
        """``arr[t0]`` (one slice per point) interpolated towards slice ``t0 + 1``."""
        a = arr[t0]
        if self.S > 1:
            w = w1.reshape(w1.shape + (1,) * (a.ndim - 1))
            a = a + w * (arr[t0 + 1] - a)
        return a

    def _slices(self, t0, w1, n):
        if self.S == 1:
            return np.zeros(n, np.intp), np.zeros(n)
        return np.broadcast_to(t0, n).astype(np.intp), np.broadcast_to(np.asarray(w1, float), n)

    def pdf(self, x, y, t0=0, w1=0.0):
        """Density at points (x, y) of the unit square (bilinear in the nodes)."""
        ix, fx = _patch(x, self.nx)
        iy, fy = _patch(y, self.ny)
        t0, w1 = self._slices(t0, w1, ix.size)
        v = [self._lerp(self.data, t0, w1, iy + a, ix + b) for a, b in ((0, 0), (0, 1), (1, 0), (1, 1))]
        lo = v[0] + fx * (v[1] - v[0])
        hi = v[2] + fx * (v[3] - v[2])
        return (lo + fy * (hi - lo)) * ((self.nx - 1) * (self.ny - 1))

    def invert(self, x, y, t0=0, w1=0.0):
        """``(sx, sy, pdf)``: the uniforms :meth:`sample` maps to (x, y), and the density there."""
        ix, fx = _patch(x, self.nx)
        iy, fy = _patch(y, self.ny)
        t0, w1 = self._slices(t0, w1, ix.size)
        v00, v10, v01, v11 = (self._lerp(self.data, t0, w1, iy + a, ix + b)
                              for a, b in ((0, 0), (0, 1), (1, 0), (1, 1)))
        cc0, cc1 = self._lerp(self.cond, t0, w1, iy, ix), self._lerp(self.cond, t0, w1, iy + 1, ix)
        r0 = self._lerp(self.cond, t0, w1, iy, self.nx - 1)
        r1 = self._lerp(self.cond, t0, w1, iy + 1, self.nx - 1)
        m0 = self._lerp(self.marg, t0, w1, iy)
        gy = 1.0 - fy
        c0, c1 = gy * v00 + fy * v01, gy * v10 + fy * v11
        rr = gy * r0 + fy * r1
        with np.errstate(divide="ignore", invalid="ignore"):
            sx = np.where(rr > 0, (fx * (c0 + 0.5 * fx * (c1 - c0)) + gy * cc0 + fy * cc1) / rr, 0.0)
        sy = fy * (r0 + 0.5 * fy * (r1 - r0)) + m0
        return sx, sy, (c0 + fx * (c1 - c0)) * ((self.nx - 1) * (self.ny - 1))

    def sample(self, sx, sy, t0=0, w1=0.0):
        """``(x, y, pdf)`` of uniforms (sx, sy), clamped to [2^-24, 1 - 2^-24]: the row by the
        interpolated marginal CDF (the last with a value ``< sy``), the fraction inside it by
        the linear density of the row totals, then the column the same way along the
        conditional CDF interpolated between the row's two node rows (fractions by
        :func:`format_fraction`, the format's own arithmetic)."""
        eps = 2.0 ** -24
        sx = np.clip(np.asarray(sx, float), eps, 1.0 - eps)
        sy = np.clip(np.asarray(sy, float), eps, 1.0 - eps)
        t0, w1 = self._slices(t0, w1, sx.size)
        nx, ny = self.nx, self.ny
        m = self._slice(self.marg, t0, w1)
        row = find_interval(m, sy, strict=True)
        sy = sy - np.take_along_axis(m, row[:, None], 1)[:, 0]
        r0 = self._lerp(self.cond, t0, w1, row, nx - 1)
        r1 = self._lerp(self.cond, t0, w1, row + 1, nx - 1)
        fy = format_fraction(r0, r1, sy)
        gy = 1.0 - fy
        sx = sx * (gy * r0 + fy * r1)
        cond = self._slice(self.cond, t0, w1)
        ca = np.take_along_axis(cond, row[:, None, None], 1)[:, 0]
        cb = np.take_along_axis(cond, row[:, None, None] + 1, 1)[:, 0]
        cc = gy[:, None] * ca + fy[:, None] * cb
        col = find_interval(cc, sx, strict=True)
        sx = sx - np.take_along_axis(cc, col[:, None], 1)[:, 0]
        v00, v10, v01, v11 = (self._lerp(self.data, t0, w1, row + a, col + b)
                              for a, b in ((0, 0), (0, 1), (1, 0), (1, 1)))
        c0, c1 = gy * v00 + fy * v01, gy * v10 + fy * v11
        fx = format_fraction(c0, c1, sx)
        pdf = ((1.0 - fx) * c0 + fx * c1) * ((nx - 1) * (ny - 1))
        return (col + fx) / (nx - 1), (row + fy) / (ny - 1), pdf
