"""Interpolants of the RGL-EPFL BRDF tables (:mod:`fit.formats.rgl`): a vectorized
re-implementation of the reference loader's ``Marginal2D`` (rgl-epfl/brdf-loader, "powitacq").

* :func:`interval`: the reference ``find_interval`` over a sorted parameter axis (theta_i)
  with the linear weight of the next slice;
* :func:`patch`: cell index and fractional position of a unit-square coordinate;
* :class:`Bilinear`: bilinear interpolant of a 2-D table (``ndf``, ``sigma``);
* :class:`VNDFWarp`: the marginal/conditional warp of the ``vndf`` densities, conditioned on
  theta_i (inverse and forward);
* :class:`RGBTable`: the bilinear (s) x linear (theta_i) interpolant of the ``rgb`` tensor.

Coordinates are in the unit square; angles in radians.
"""
from __future__ import annotations

import numpy as np

from ..errors import BRDFFileError


def interval(values: np.ndarray, x: np.ndarray):
    """Reference ``find_interval`` over a sorted parameter axis, with the linear weight.

    Returns ``(i0, w1)``: the left index clamped to [0, n-2] and the weight of ``i0 + 1``
    clamped to [0, 1] (clamped interpolation outside the axis). For n == 1: (0, 0).
    """
    n = values.size
    if n == 1:
        return np.zeros(x.shape, np.intp), np.zeros(x.shape)
    i0 = np.searchsorted(values[1:-1], x, side="right")
    p0 = values[i0]
    p1 = values[i0 + 1]
    w1 = np.clip((x - p0) / (p1 - p0), 0.0, 1.0)
    return i0, w1


def patch(u: np.ndarray, n: int):
    """Cell index in [0, n-2] and fractional position for a coordinate u in [0, 1]."""
    x = u * (n - 1)
    i = np.minimum(np.maximum(x, 0.0).astype(np.intp), n - 2)
    return i, x - i


class Bilinear:
    """Plain bilinear interpolant of a 2-D table (reference ``Marginal2D<0>`` without CDF)."""

    def __init__(self, table: np.ndarray):
        t = np.asarray(table, np.float64)
        self.ny, self.nx = t.shape
        self.corners = np.ascontiguousarray(
            np.stack([t[:-1, :-1], t[:-1, 1:], t[1:, :-1], t[1:, 1:]], axis=-1)
        ).reshape(-1, 4)

    def eval(self, ux, uy):
        ix, fx = patch(ux, self.nx)
        iy, fy = patch(uy, self.ny)
        c = np.take(self.corners, iy * (self.nx - 1) + ix, axis=0)
        a = c[:, 0] + fx * (c[:, 1] - c[:, 0])
        b = c[:, 2] + fx * (c[:, 3] - c[:, 2])
        return a + fy * (b - a)


class VNDFWarp:
    """Marginal/conditional warp of 2-D densities, conditioned on theta_i (reference
    ``Marginal2D<2>`` with one phi_i slice): per-slice CDFs, linear interpolation of every
    looked-up quantity between the two nearest theta_i slices."""

    def __init__(self, data: np.ndarray, theta: np.ndarray, path=None):
        d = np.asarray(data, np.float64)  # (S, ny, nx)
        self.S, self.ny, self.nx = d.shape
        self.theta = np.asarray(theta, np.float64)
        cond = np.zeros_like(d)
        cond[:, :, 1:] = np.cumsum(0.5 * (d[:, :, 1:] + d[:, :, :-1]), axis=2)
        rows = cond[:, :, -1]
        marg = np.zeros((self.S, self.ny))
        marg[:, 1:] = np.cumsum(0.5 * (rows[:, 1:] + rows[:, :-1]), axis=1)
        total = marg[:, -1]
        bad = ~(np.isfinite(total) & (total > 0))
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise BRDFFileError(path, f"vndf slice theta_i[{k}] has no positive finite mass; "
                                      "cannot build its warp")
        norm = (1.0 / total)[:, None, None]
        d = d * norm
        cond = cond * norm
        marg = marg * norm[:, :, 0]
        rows = cond[:, :, -1]
        self.data = d
        self.cond = cond
        self.marg = marg
        # Per patch: v00 v10 v01 v11, cond(y,x) cond(y+1,x), row totals r(y) r(y+1), marg(y)
        S, ny, nx = self.S, self.ny, self.nx
        tab = np.empty((S, ny - 1, nx - 1, 9))
        tab[..., 0] = d[:, :-1, :-1]
        tab[..., 1] = d[:, :-1, 1:]
        tab[..., 2] = d[:, 1:, :-1]
        tab[..., 3] = d[:, 1:, 1:]
        tab[..., 4] = cond[:, :-1, :-1]
        tab[..., 5] = cond[:, 1:, :-1]
        tab[..., 6] = rows[:, :-1, None]
        tab[..., 7] = rows[:, 1:, None]
        tab[..., 8] = marg[:, :-1, None]
        self.table = tab.reshape(-1, 9)
        self.slice_stride = (ny - 1) * (nx - 1) if S > 1 else 0

    def _patch(self, ux, uy, t0, w1):
        """The 9 patch values (``table``'s columns) at (ux, uy), lerped between slices, and
        the fractional position (fx, fy) inside the patch."""
        ix, fx = patch(ux, self.nx)
        iy, fy = patch(uy, self.ny)
        k = (t0 * (self.ny - 1) + iy) * (self.nx - 1) + ix
        g = np.take(self.table, k, axis=0)
        if self.slice_stride:
            g1 = np.take(self.table, k + self.slice_stride, axis=0)
            g += w1[:, None] * (g1 - g)
        return g, fx, fy

    def density(self, sx, sy, t0, w1):
        """Normalized density of the warp at points (sx, sy) of the unit square (bilinear,
        lerped slices): the reference ``Marginal2D::eval``."""
        g, fx, fy = self._patch(sx, sy, t0, w1)
        a = g[:, 0] + fx * (g[:, 1] - g[:, 0])
        b = g[:, 2] + fx * (g[:, 3] - g[:, 2])
        return (a + fy * (b - a)) * ((self.nx - 1) * (self.ny - 1))

    def invert(self, ux, uy, t0, w1):
        """Inverse warp of points (ux, uy) of the unit square; returns (sx, sy, pdf)."""
        g, fx, fy = self._patch(ux, uy, t0, w1)
        v00, v10, v01, v11, cc0, cc1, r0, r1, m0 = g.T
        gy = 1.0 - fy
        c0 = gy * v00 + fy * v01
        c1 = gy * v10 + fy * v11
        pdf = c0 + fx * (c1 - c0)
        rr = gy * r0 + fy * r1
        sx = (fx * (c0 + 0.5 * fx * (c1 - c0)) + gy * cc0 + fy * cc1) / rr
        sy = fy * (r0 + 0.5 * fy * (r1 - r0)) + m0
        return sx, sy, pdf * ((self.nx - 1) * (self.ny - 1))

    # -- forward warp (used by the tests and for sampling) ------------------------------
    def _lerp(self, arr, t0, w1, *index):
        a = arr[(t0,) + index]
        if self.S > 1:
            a = a + w1 * (arr[(t0 + 1,) + index] - a)
        return a

    def sample(self, sx, sy, t0, w1):
        """Forward warp (reference ``Marginal2D::sample``): points of the unit square ->
        (ux, uy, pdf). Vectorized with O(N * (nx + ny)) work; meant for tests and sampling."""
        eps = 1.0 - np.float32(0.999999940395355225)
        sx = np.clip(np.asarray(sx, float), eps, 1.0 - eps)
        sy = np.clip(np.asarray(sy, float), eps, 1.0 - eps)
        t0 = np.asarray(t0)
        w1 = np.asarray(w1, float)
        ny, nx = self.ny, self.nx
        # row: marginal CDF (interpolated across slices) < sy, counted over 1..ny-2
        m = self.marg[t0]
        if self.S > 1:
            m = m + w1[:, None] * (self.marg[t0 + 1] - m)
        row = np.clip(np.sum(m[:, 1:ny - 1] < sy[:, None], axis=1), 0, ny - 2)
        sy = sy - np.take_along_axis(m, row[:, None], axis=1)[:, 0]
        r0 = self._lerp(self.cond, t0, w1, row, nx - 1)
        r1 = self._lerp(self.cond, t0, w1, row + 1, nx - 1)
        const = np.abs(r0 - r1) < 1e-4 * (r0 + r1)
        with np.errstate(divide="ignore", invalid="ignore"):
            fy = np.where(const, 2.0 * sy / (r0 + r1),
                          (r0 - np.sqrt(np.maximum(r0 * r0 - 2.0 * sy * (r0 - r1), 0.0))) / (r0 - r1))
        sx = sx * ((1.0 - fy) * r0 + fy * r1)
        ca = self.cond[t0, row]
        cb = self.cond[t0, row + 1]
        if self.S > 1:
            ca = ca + w1[:, None] * (self.cond[t0 + 1, row] - ca)
            cb = cb + w1[:, None] * (self.cond[t0 + 1, row + 1] - cb)
        cc = (1.0 - fy)[:, None] * ca + fy[:, None] * cb
        col = np.clip(np.sum(cc[:, 1:nx - 1] < sx[:, None], axis=1), 0, nx - 2)
        sx = sx - np.take_along_axis(cc, col[:, None], axis=1)[:, 0]
        v00 = self._lerp(self.data, t0, w1, row, col)
        v10 = self._lerp(self.data, t0, w1, row, col + 1)
        v01 = self._lerp(self.data, t0, w1, row + 1, col)
        v11 = self._lerp(self.data, t0, w1, row + 1, col + 1)
        c0 = (1.0 - fy) * v00 + fy * v01
        c1 = (1.0 - fy) * v10 + fy * v11
        const = np.abs(c0 - c1) < 1e-4 * (c0 + c1)
        with np.errstate(divide="ignore", invalid="ignore"):
            fx = np.where(const, 2.0 * sx / (c0 + c1),
                          (c0 - np.sqrt(np.maximum(c0 * c0 - 2.0 * sx * (c0 - c1), 0.0))) / (c0 - c1))
        pdf = ((1.0 - fx) * c0 + fx * c1) * ((nx - 1) * (ny - 1))
        return (col + fx) / (nx - 1), (row + fy) / (ny - 1), pdf


class RGBTable:
    """Bilinear (s) x linear (theta_i) interpolant of the (n_theta, 3, ny, nx) rgb tensor."""

    def __init__(self, rgb: np.ndarray):
        r = np.asarray(rgb, np.float64)  # (S, 3, ny, nx)
        self.S, _, self.ny, self.nx = r.shape
        r = np.moveaxis(r, 1, -1)  # (S, ny, nx, 3)
        tab = np.concatenate([r[:, :-1, :-1], r[:, :-1, 1:], r[:, 1:, :-1], r[:, 1:, 1:]], axis=-1)
        self.table = np.ascontiguousarray(tab).reshape(-1, 12)
        self.slice_stride = (self.ny - 1) * (self.nx - 1) if self.S > 1 else 0

    def eval(self, sx, sy, t0, w1):
        ix, fx = patch(sx, self.nx)
        iy, fy = patch(sy, self.ny)
        k = (t0 * (self.ny - 1) + iy) * (self.nx - 1) + ix
        g = np.take(self.table, k, axis=0)
        if self.slice_stride:
            g1 = np.take(self.table, k + self.slice_stride, axis=0)
            g += w1[:, None] * (g1 - g)
        fx = fx[:, None]
        a = g[:, 0:3] + fx * (g[:, 3:6] - g[:, 0:3])
        b = g[:, 6:9] + fx * (g[:, 9:12] - g[:, 6:9])
        return a + fy[:, None] * (b - a)

