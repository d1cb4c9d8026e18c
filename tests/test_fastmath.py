"""warp_rbrdf.fastmath: the inline atan2 against the exact one, in the kernel and in NumPy."""
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
