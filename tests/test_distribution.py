"""The sampling distributions (:mod:`warp_rbrdf.distribution`), tested once: the Warp functions
equal their NumPy references on random inputs (float32 and float64 searches), sampling then
inverting gives the uniforms back, and a chi-square test of each Warp sampler against its own
Warp density. Histogram bins are unions of equal parts of the distributions' cells, where the
midpoint rule integrates a constant, linear or bilinear density exactly."""
from __future__ import annotations

import numpy as np
import pytest
from chi2 import chi2_pvalue

from fit.formats.rgl_interpolants import VNDFWarp
from warp_rbrdf import distribution as D
from warp_rbrdf.distribution import reference as R
from warp_rbrdf.runtime import init_warp

wp = init_warp()
N = 100_000
P_MIN = 1e-3


@wp.kernel
def _find32(cdf: wp.array(dtype=float), off: int, size: int, x: wp.array(dtype=float), out: wp.array(dtype=int)):
    i = wp.tid()
    out[i] = D.find_interval(cdf, off, size, x[i])


@wp.kernel
def _find64(cdf: wp.array(dtype=wp.float64), off: int, size: int, x: wp.array(dtype=wp.float64),
            out: wp.array(dtype=int)):
    i = wp.tid()
    out[i] = D.find_interval(cdf, off, size, x[i])


@wp.kernel
def _find_row(cdf: wp.array2d(dtype=float), row: int, size: int, x: wp.array(dtype=float), out: wp.array(dtype=int)):
    i = wp.tid()
    out[i] = D.find_interval_row(cdf, row, size, x[i])


@wp.kernel
def _pc1d64(cdf: wp.array(dtype=wp.float64), off: int, n: int, u: wp.array(dtype=wp.float64),
            out: wp.array2d(dtype=wp.float64)):
    """Per uniform: x, pdf(x) as sampled, index, pdf at x, inverse at x."""
    t = wp.tid()
    i, frac, m = D.pc1d_sample(cdf, off, n, u[t])
    x = (wp.float64(i) + frac) / wp.float64(n)
    out[t, 0] = x
    out[t, 1] = m * wp.float64(n)
    out[t, 2] = wp.float64(i)
    out[t, 3] = D.pc1d_pdf(cdf, off, n, x)
    out[t, 4] = D.pc1d_invert(cdf, off, n, x)


@wp.kernel
def _pc1d32(cdf: wp.array(dtype=float), off: int, n: int, u: wp.array(dtype=float), out: wp.array2d(dtype=float)):
    t = wp.tid()
    i, frac, m = D.pc1d_sample(cdf, off, n, u[t])
    x = (float(i) + frac) / float(n)
    out[t, 0] = x
    out[t, 1] = m * float(n)
    out[t, 2] = float(i)
    out[t, 3] = D.pc1d_pdf(cdf, off, n, x)
    out[t, 4] = D.pc1d_invert(cdf, off, n, x)


@wp.kernel
def _pl1d(cdf: wp.array(dtype=float), pdf: wp.array(dtype=float), off: int, n: int, u: wp.array(dtype=float),
          out: wp.array2d(dtype=float)):
    t = wp.tid()
    i, frac, p = D.pl1d_sample(cdf, pdf, off, n, u[t])
    x = (float(i) + frac) / float(n - 1)
    out[t, 0] = x
    out[t, 1] = p
    out[t, 2] = float(i)
    out[t, 3] = D.pl1d_pdf(pdf, off, n, x)
    out[t, 4] = D.pl1d_invert(cdf, pdf, off, n, x)


@wp.kernel
def _pc2d(marg: wp.array(dtype=float), cond: wp.array(dtype=float), ny: int, nx: int, u: wp.array(dtype=wp.vec2),
          out: wp.array2d(dtype=float)):
    """Per uniform pair: x, y, pdf as sampled, pdf at (x, y), the inverse (ux, uy)."""
    t = wp.tid()
    x, y, p = D.pc2d_sample(marg, 1, cond, 2, ny, nx, u[t][0], u[t][1])
    out[t, 0] = x
    out[t, 1] = y
    out[t, 2] = p
    out[t, 3] = D.pc2d_pdf(marg, 1, cond, 2, ny, nx, x, y)
    ux, uy = D.pc2d_invert(marg, 1, cond, 2, ny, nx, x, y)
    out[t, 4] = ux
    out[t, 5] = uy


@wp.kernel
def _m2d(vals: wp.array(dtype=float), data: int, cond: int, marg: int, ny: int, nx: int, n_slices: int, t0: int,
         w1: float, u: wp.array(dtype=wp.vec2), out: wp.array2d(dtype=float)):
    """Per uniform pair: the sample (x, y, pdf), the density at it, its inverse (sx, sy, pdf)."""
    t = wp.tid()
    s = D.marginal2d_sample(vals, data, cond, marg, ny, nx, n_slices, t0, w1, u[t][0], u[t][1])
    inv = D.marginal2d_invert(vals, data, cond, marg, ny, nx, n_slices, t0, w1, s[0], s[1])
    out[t, 0] = s[0]
    out[t, 1] = s[1]
    out[t, 2] = s[2]
    out[t, 3] = D.marginal2d_pdf(vals, data, ny, nx, n_slices, t0, w1, s[0], s[1])
    out[t, 4] = inv[0]
    out[t, 5] = inv[1]
    out[t, 6] = inv[2]


@wp.kernel
def _pc1d_pdf(cdf: wp.array(dtype=float), n: int, x: wp.array(dtype=float), out: wp.array(dtype=float)):
    t = wp.tid()
    out[t] = D.pc1d_pdf(cdf, 0, n, x[t])


@wp.kernel
def _pl1d_pdf(pdf: wp.array(dtype=float), off: int, n: int, x: wp.array(dtype=float), out: wp.array(dtype=float)):
    t = wp.tid()
    out[t] = D.pl1d_pdf(pdf, off, n, x[t])


@wp.kernel
def _pc2d_pdf(marg: wp.array(dtype=float), cond: wp.array(dtype=float), ny: int, nx: int, p: wp.array(dtype=wp.vec2),
              out: wp.array(dtype=float)):
    t = wp.tid()
    out[t] = D.pc2d_pdf(marg, 1, cond, 2, ny, nx, p[t][0], p[t][1])


@wp.kernel
def _m2d_pdf(vals: wp.array(dtype=float), data: int, ny: int, nx: int, n_slices: int, t0: int, w1: float,
             p: wp.array(dtype=wp.vec2), out: wp.array(dtype=float)):
    t = wp.tid()
    out[t] = D.marginal2d_pdf(vals, data, ny, nx, n_slices, t0, w1, p[t][0], p[t][1])


def _density(kernel, inputs, x):
    """``kernel`` (a density kernel above) at points ``x`` (N,) or (N, 2)."""
    x = np.asarray(x, np.float32)
    pts = wp.array(x, dtype=wp.vec2) if x.ndim == 2 else wp.array(x)
    out = wp.zeros(len(x), dtype=float)
    wp.launch(kernel, dim=len(x), inputs=[*inputs, pts], outputs=[out])
    return out.numpy().astype(float)


def _launch(kernel, n, cols, inputs, dtype=float):
    out = wp.zeros((n, cols), dtype=dtype)
    wp.launch(kernel, dim=n, inputs=inputs, outputs=[out])
    return out.numpy().astype(float)


def _values(rng, n, zeros=()):
    v = rng.gamma(0.7, size=n)
    v[list(zeros)] = 0.0
    return v


def _chi2_1d(x, pdf, edges_, sub=4):
    """p-value of samples ``x`` against the density ``pdf(points) -> values`` on bins ``edges_``
    (midpoint rule on ``sub`` points per bin)."""
    mids = edges_[:-1, None] + (np.arange(sub) + 0.5) / sub * np.diff(edges_)[:, None]
    probs = pdf(mids.ravel()).reshape(mids.shape).mean(1) * np.diff(edges_)
    assert abs(probs.sum() - 1) < 1e-4
    return chi2_pvalue(np.histogram(x, edges_)[0], probs, len(x))


def _chi2_2d(xy, pdf, ex, ey, sub=3):
    mx = (ex[:-1, None] + (np.arange(sub) + 0.5) / sub * np.diff(ex)[:, None]).ravel()
    my = (ey[:-1, None] + (np.arange(sub) + 0.5) / sub * np.diff(ey)[:, None]).ravel()
    gx, gy = np.meshgrid(mx, my, indexing="ij")
    dens = pdf(gx.ravel(), gy.ravel()).reshape(len(ex) - 1, sub, len(ey) - 1, sub).mean((1, 3))
    probs = dens * np.outer(np.diff(ex), np.diff(ey))
    assert abs(probs.sum() - 1) < 1e-4
    return chi2_pvalue(np.histogram2d(xy[:, 0], xy[:, 1], [ex, ey])[0], probs, len(xy))


# ------------------------------------------------------------------------------------ searches
def test_find_interval_matches_reference_float32_float64_and_rows():
    rng = np.random.default_rng(0)
    for size in (1, 2, 3, 8, 33):
        cdf = np.sort(np.round(rng.random(size), 2))       # ties included
        x = np.concatenate([rng.uniform(-0.2, 1.2, 500), cdf, [cdf[0] - 1, cdf[-1] + 1]])
        want = R.find_interval(cdf, x)
        pad = np.concatenate([[5.0, -5.0], cdf])            # the distribution at offset 2
        for dt, kern in ((np.float32, _find32), (np.float64, _find64)):
            got = wp.zeros(len(x), dtype=int)
            wp.launch(kern, dim=len(x), inputs=[wp.array(pad.astype(dt)), 2, size, wp.array(x.astype(dt))],
                      outputs=[got])
            assert np.array_equal(got.numpy(), R.find_interval(cdf.astype(dt), x.astype(dt))), (size, dt)
        got = wp.zeros(len(x), dtype=int)
        table = np.stack([cdf[::-1], cdf]).astype(np.float32)
        wp.launch(_find_row, dim=len(x), inputs=[wp.array(table), 1, size, wp.array(x.astype(np.float32))],
                  outputs=[got])
        assert np.array_equal(got.numpy(), R.find_interval(cdf.astype(np.float32), x.astype(np.float32)))
        assert want.min() >= 0 and want.max() <= max(size - 2, 0)
    # the convention: the last i with cdf[i] <= x, clamped; strict: cdf[i] < x
    c = np.array([0.0, 0.2, 0.2, 0.7, 1.0])
    assert R.find_interval(c, [-1, 0, 0.1, 0.2, 0.5, 1.0, 2]).tolist() == [0, 0, 0, 2, 2, 3, 3]
    assert R.find_interval(c, [0.2, 0.7], strict=True).tolist() == [0, 2]


# ------------------------------------------------------------------------------------------ 1-D
def test_piecewise_constant_1d():
    rng = np.random.default_rng(1)
    n = 24
    ref = R.PiecewiseConstant1D(_values(rng, n, zeros=(0, 5, 6, 23)))
    assert ref.integral > 0 and ref.cdf[0] == 0 and ref.cdf[-1] == 1
    u = rng.random(N)
    # float64: the Warp functions equal the reference
    cdf64 = np.concatenate([[9.0], ref.cdf])
    got = _launch(_pc1d64, N, 5, [wp.array(cdf64, dtype=wp.float64), 1, n, wp.array(u, dtype=wp.float64)],
                  wp.float64)
    x, p, i = ref.sample(u)
    assert np.array_equal(got[:, 2], i)
    np.testing.assert_allclose(got[:, 0], x, rtol=0, atol=1e-14)
    np.testing.assert_allclose(got[:, 1], p, rtol=1e-14)
    np.testing.assert_allclose(got[:, 3], ref.pdf(x), rtol=1e-12)
    np.testing.assert_allclose(got[:, 4], u, rtol=0, atol=1e-12)          # invert(sample(u)) = u
    np.testing.assert_allclose(ref.invert(x), u, rtol=0, atol=1e-12)
    assert not np.any(np.isin(i, (0, 5, 6, 23)))                          # no sample in a cell of no mass
    # float32: the same on the table rounded to float32
    u32 = u.astype(np.float32)
    ref.cdf = ref.cdf.astype(np.float32).astype(float)
    got = _launch(_pc1d32, N, 5, [wp.array(cdf64.astype(np.float32)), 1, n, wp.array(u32)])
    x, p, i = ref.sample(u32.astype(float))
    assert np.array_equal(got[:, 2], i)
    np.testing.assert_allclose(got[:, 0], x, atol=2e-7)
    np.testing.assert_allclose(got[:, 1], p, rtol=1e-6)
    np.testing.assert_allclose(got[:, 4], u32, atol=1e-6)
    # chi-square: the float32 sampler against its own density, 3 bins per cell
    pdf = lambda q: _density(_pc1d_pdf, [wp.array(ref.cdf.astype(np.float32)), n], q)  # noqa: E731
    assert _chi2_1d(got[:, 0], pdf, np.linspace(0, 1, 3 * n + 1)) > P_MIN
    # a distribution of no mass samples uniformly
    zero = R.PiecewiseConstant1D(np.zeros(4))
    assert zero.integral == 0 and np.allclose(zero.pdf([0.1, 0.6]), 1.0)


def test_piecewise_linear_1d():
    rng = np.random.default_rng(2)
    n = 17
    vals = _values(rng, n, zeros=(0, 7, 8, 9))                     # a cell of no mass (7..9)
    ref = R.PiecewiseLinear1D(vals)
    u = rng.random(N).astype(np.float32)
    arr = lambda a: wp.array(np.concatenate([[3.0, 3.0], a]).astype(np.float32))  # noqa: E731 - at offset 2
    got = _launch(_pl1d, N, 5, [arr(ref.cdf), arr(ref.pdf_nodes), 2, n, wp.array(u)])
    x, p, i = ref.sample(u.astype(float))
    assert np.mean(got[:, 2] == i) > 0.999                                 # (float32 CDF at the edges)
    np.testing.assert_allclose(got[:, 0], x, atol=2e-6)
    np.testing.assert_allclose(got[:, 1], ref.pdf(got[:, 0]), rtol=1e-4, atol=1e-5)   # (steep near a 0 node)
    np.testing.assert_allclose(got[:, 3], got[:, 1], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(got[:, 4], u, atol=2e-6)                    # invert(sample(u)) = u
    np.testing.assert_allclose(ref.invert(x), u, atol=1e-12)
    assert not np.any((got[:, 0] > 7 / 16 + 1e-6) & (got[:, 0] < 9 / 16 - 1e-6))
    # the stable solve: a constant cell, a cell from 0, a nearly constant cell
    t = R.linear_fraction([2.0, 0.0, 1.0], [2.0, 4.0, 1.0 + 1e-9], [0.5, 0.5, 0.25])
    np.testing.assert_allclose(t, [0.25, 0.5, 0.25], rtol=1e-8)

    pdf = lambda q: _density(_pl1d_pdf, [arr(ref.pdf_nodes), 2, n], q)  # noqa: E731
    assert _chi2_1d(got[:, 0], pdf, np.linspace(0, 1, 3 * (n - 1) + 1)) > P_MIN
    # the same samples against the piecewise-constant density of the same values fail
    pc = R.PiecewiseConstant1D(0.5 * (vals[1:] + vals[:-1]) + 0.3 * np.abs(np.diff(vals)))
    assert _chi2_1d(got[:, 0], pc.pdf, np.linspace(0, 1, 3 * (n - 1) + 1)) < 1e-6


# ------------------------------------------------------------------------------------------ 2-D
def test_piecewise_constant_2d():
    rng = np.random.default_rng(3)
    ny, nx = 6, 9
    v = rng.gamma(0.7, size=(ny, nx))
    v[2] = 0.0                                                              # a row of no mass
    v[4, 3:5] = 0.0
    ref = R.PiecewiseConstant2D(v)
    marg = np.concatenate([[7.0], ref.marginal.cdf]).astype(np.float32)    # at offset 1
    cond = np.concatenate([[7.0, 7.0], ref.cond.ravel()]).astype(np.float32)  # at offset 2
    u = rng.random((N, 2)).astype(np.float32)
    got = _launch(_pc2d, N, 6, [wp.array(marg), wp.array(cond), ny, nx, wp.array(u, dtype=wp.vec2)])
    x, y, p = ref.sample(u.astype(float))
    assert np.mean(np.abs(got[:, 0] - x) < 1e-5) > 0.999 and np.mean(np.abs(got[:, 1] - y) < 1e-5) > 0.999
    np.testing.assert_allclose(got[:, 3], ref.pdf(got[:, 0], got[:, 1]), rtol=1e-4)
    np.testing.assert_allclose(got[:, 2], got[:, 3], rtol=1e-5)             # the sample's pdf is pdf()
    np.testing.assert_allclose(got[:, 4:6], u, atol=2e-6)                   # invert(sample(u)) = u
    np.testing.assert_allclose(ref.invert(x, y), u, atol=1e-6)
    np.testing.assert_allclose(ref.integral, v.mean())
    assert not np.any((got[:, 1] > 2 / 6) & (got[:, 1] < 3 / 6))

    def pdf(qx, qy):
        return _density(_pc2d_pdf, [wp.array(marg), wp.array(cond), ny, nx], np.stack([qx, qy], -1))

    assert _chi2_2d(got[:, :2], pdf, np.linspace(0, 1, 2 * nx + 1), np.linspace(0, 1, 2 * ny + 1)) > P_MIN


def _pack_m2d(ref):
    """The flat float32 layout of :mod:`warp_rbrdf.distribution.warp_2d` (data, cond, marg),
    after 3 unused entries."""
    parts = [np.full(3, 9.0), ref.data.ravel(), ref.cond.ravel(), ref.marg.ravel()]
    return wp.array(np.concatenate(parts).astype(np.float32)), 3, 3 + ref.data.size, 3 + 2 * ref.data.size


@pytest.mark.parametrize("slices", [1, 3])
def test_marginal2d_bilinear_warp(slices):
    rng = np.random.default_rng(4 + slices)
    ny, nx = 7, 8
    data = rng.gamma(1.5, size=(slices, ny, nx))
    data[0, 2, :] *= 1e-3                                                   # a nearly empty node row
    t0, w1 = (1, 0.3) if slices > 1 else (0, 0.0)
    u = rng.random((N, 2)).astype(np.float32)
    # the RGL format's NumPy interpolant (theta_i the parameter): the same tables and warps
    ref, fmt = R.Marginal2D(data), VNDFWarp(data, np.linspace(0, 1, slices))
    np.testing.assert_allclose(fmt.cond, ref.cond, rtol=1e-12)
    np.testing.assert_allclose(fmt.marg, ref.marg, rtol=1e-12)
    tt, ww = np.full(N, t0), np.full(N, w1)
    x, y, p = ref.sample(u[:, 0], u[:, 1], t0, w1)
    for a, b in zip(fmt.sample(u[:, 0], u[:, 1], tt, ww), (x, y, p)):
        np.testing.assert_allclose(a, b, rtol=1e-8, atol=1e-10)
    for a, b in zip(fmt.invert(x, y, tt, ww), ref.invert(x, y, t0, w1)):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)
    for a in ("data", "cond", "marg"):   # the reference reads the float32 tables the kernel reads
        setattr(ref, a, getattr(ref, a).astype(np.float32).astype(float))
    vals, d_off, c_off, m_off = _pack_m2d(ref)
    got = _launch(_m2d, N, 7, [vals, d_off, c_off, m_off, ny, nx, slices, t0, w1, wp.array(u, dtype=wp.vec2)])
    x, y, p = ref.sample(u[:, 0], u[:, 1], t0, w1)
    # (float32: the format's solve cancels digits in cells where the density varies little)
    np.testing.assert_allclose(got[:, 0], x, atol=1e-4)
    np.testing.assert_allclose(got[:, 1], y, atol=1e-4)
    np.testing.assert_allclose(got[:, 2], p, rtol=1e-3)
    np.testing.assert_allclose(got[:, 3], got[:, 2], rtol=1e-4)             # the sample's pdf is pdf()
    np.testing.assert_allclose(got[:, 4:6], u, atol=1e-4)                   # invert(sample(u)) = u
    np.testing.assert_allclose(got[:, 6], got[:, 2], rtol=1e-4)
    sx, sy, pi = ref.invert(x, y, t0, w1)
    # (the format's solve is exact to ~2.5e-5 of a cell where the density is nearly constant)
    np.testing.assert_allclose(np.stack([sx, sy], -1), u, atol=1e-5)
    np.testing.assert_allclose(pi, ref.pdf(x, y, t0, w1), rtol=1e-12)

    def pdf(qx, qy):
        return _density(_m2d_pdf, [vals, d_off, ny, nx, slices, t0, w1], np.stack([qx, qy], -1))

    ex = np.linspace(0, 1, 2 * (nx - 1) + 1)
    ey = np.linspace(0, 1, 2 * (ny - 1) + 1)
    assert _chi2_2d(got[:, :2], pdf, ex, ey) > P_MIN
