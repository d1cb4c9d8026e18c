"""warp_rbrdf.fastmath: the inline atan2 and sincos against the exact ones, in the kernel and in
NumPy."""
from __future__ import annotations

import numpy as np
import warp as wp

from warp_rbrdf import fastmath


@wp.kernel
def _atan2_kernel(y: wp.array(dtype=float), x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = fastmath.atan2(y[i], x[i])


def _points(n=200_000, seed=0):
    rng = np.random.default_rng(seed)
    y = rng.normal(size=n) * np.exp(rng.uniform(-20, 5, n))
    x = rng.normal(size=n) * np.exp(rng.uniform(-20, 5, n))
    special = np.array([[0.0, 1.0], [0.0, -1.0], [1.0, 0.0], [-1.0, 0.0], [1e-30, 1.0], [1.0, 1e-30],
                        [-1e-30, -1.0], [3.0, 3.0], [-2.0, 2.0], [0.0, 0.0]])
    return (np.concatenate([y, special[:, 0]]).astype(np.float32),
            np.concatenate([x, special[:, 1]]).astype(np.float32))


def test_kernel_atan2_within_stated_error_and_equal_to_numpy_reference():
    y, x = _points()
    out = wp.zeros(len(y), dtype=float, device="cpu")
    wp.launch(_atan2_kernel, dim=len(y), inputs=[wp.array(y, device="cpu"), wp.array(x, device="cpu"), out],
              device="cpu")
    got = out.numpy().astype(np.float64)
    exact = np.arctan2(y.astype(np.float64), x.astype(np.float64))
    exact = np.where((y == 0) & (x < 0), np.pi, exact)      # +pi for (+-0, x < 0): same angle
    err = np.abs(got - exact)
    assert err.max() <= 2.8e-7, err.max()
    assert got[-1] == 0.0                                   # atan2(0, 0)
    small = (np.abs(exact) > 0) & (np.abs(exact) < 1e-3)
    assert np.all(np.abs(got[small] / exact[small] - 1.0) <= 2e-7)    # relative near the pole
    np.testing.assert_allclose(got, fastmath.atan2_numpy(y, x), rtol=0, atol=2.4e-7)


def test_polynomial_is_what_the_docstring_states():
    a = np.linspace(0.0, 1.0, 100_001)
    r = fastmath.atan2_numpy(a, np.ones_like(a)).astype(np.float64)
    err = np.abs(r - np.arctan(a))
    assert err.max() <= 1.3e-7
    assert (err[1:] / np.arctan(a[1:])).max() <= 1.7e-7


@wp.kernel
def _sincos_kernel(x: wp.array(dtype=float), out: wp.array(dtype=wp.vec2)):
    i = wp.tid()
    out[i] = fastmath.sincos(x[i])


def test_kernel_sincos_within_stated_error_and_equal_to_numpy_reference():
    rng = np.random.default_rng(1)
    r = fastmath.SINCOS_RANGE
    x = np.concatenate([rng.uniform(-2 * np.pi, 2 * np.pi, 300_000), rng.uniform(-r, r, 100_000),
                        np.arange(-8, 9) * (np.pi / 4), [0.0, 1e-30, -1e-30, np.pi, -np.pi, 0.5 * np.pi]])
    x = x.astype(np.float32)
    out = wp.zeros(len(x), dtype=wp.vec2, device="cpu")
    wp.launch(_sincos_kernel, dim=len(x), inputs=[wp.array(x, device="cpu"), out], device="cpu")
    got = out.numpy().astype(np.float64)
    x64 = x.astype(np.float64)
    assert np.abs(got[:, 0] - np.sin(x64)).max() <= 2.4e-7
    assert np.abs(got[:, 1] - np.cos(x64)).max() <= 2.4e-7
    tiny = np.abs(x64) < 1e-3                                 # sin x ~ x: relative there
    assert np.all(np.abs(got[tiny, 0] - x64[tiny]) <= 2e-7 * np.abs(x64[tiny]))
    sn, cs = fastmath.sincos_numpy(x)
    np.testing.assert_allclose(got[:, 0], sn, rtol=0, atol=1.2e-7)
    np.testing.assert_allclose(got[:, 1], cs, rtol=0, atol=1.2e-7)
