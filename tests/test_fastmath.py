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


@wp.kernel
def _minmax_kernel(a: wp.array(dtype=float), b: wp.array(dtype=float), a64: wp.array(dtype=wp.float64),
                   b64: wp.array(dtype=wp.float64), out: wp.array2d(dtype=float), out64: wp.array2d(dtype=wp.float64),
                   outi: wp.array2d(dtype=int)):
    i = wp.tid()
    out[i, 0] = fastmath.fmin(a[i], b[i])
    out[i, 1] = fastmath.fmax(a[i], b[i])
    out[i, 2] = fastmath.clamp(a[i], b[i], b[i] + 1.0)
    out[i, 3] = wp.min(a[i], b[i])
    out[i, 4] = wp.max(a[i], b[i])
    out[i, 5] = wp.clamp(a[i], b[i], b[i] + 1.0)
    out64[i, 0] = fastmath.fmin(a64[i], b64[i])
    out64[i, 1] = fastmath.fmax(a64[i], b64[i])
    out64[i, 2] = fastmath.clamp(a64[i], b64[i], b64[i] + wp.float64(1.0))
    outi[i, 0] = fastmath.fmin(i - 3, 2)
    outi[i, 1] = fastmath.fmax(i - 3, 2)
    outi[i, 2] = fastmath.clamp(i - 3, -1, 2)


def test_min_max_clamp_equal_warps_on_numbers_and_follow_the_stated_nan_rule():
    """fmin / fmax / clamp give Warp's wp.min / wp.max / wp.clamp for every pair of distinct
    numbers (float32, float64; ints as Warp's), the second operand for equal ones, and the
    module docstring's NaN rule: a NaN first operand gives the second, a NaN x clamps to lo."""
    rng = np.random.default_rng(3)
    n = 20_000
    a = rng.normal(size=n).astype(np.float32)
    b = rng.normal(size=n).astype(np.float32)
    b[:50] = a[:50]                                    # ties
    a[50:60], b[50:60] = -0.0, 0.0                     # signed zeros
    a[60:70] = np.nan                                  # NaN first operand
    dev = "cpu"
    out = wp.zeros((n, 6), dtype=float, device=dev)
    out64 = wp.zeros((n, 3), dtype=wp.float64, device=dev)
    outi = wp.zeros((n, 3), dtype=int, device=dev)
    wp.launch(_minmax_kernel, dim=n, inputs=[wp.array(a, device=dev), wp.array(b, device=dev),
                                             wp.array(a.astype(np.float64), dtype=wp.float64, device=dev),
                                             wp.array(b.astype(np.float64), dtype=wp.float64, device=dev),
                                             out, out64, outi], device=dev)
    o, o64, oi = out.numpy(), out64.numpy(), outi.numpy()
    num = slice(0, 50), slice(70, n)                   # numbers (ties, then distinct pairs)
    for s in num:
        np.testing.assert_array_equal(o[s, :3], o[s, 3:])             # Warp's values
        np.testing.assert_array_equal(o[s, 0], np.minimum(a[s], b[s]))
        np.testing.assert_array_equal(o[s, 1], np.maximum(a[s], b[s]))
        np.testing.assert_array_equal(o[s, 2], np.clip(a[s], b[s], b[s] + np.float32(1)))
        a64, b64 = a[s].astype(np.float64), b[s].astype(np.float64)
        np.testing.assert_array_equal(o64[s], np.stack([np.minimum(a64, b64), np.maximum(a64, b64),
                                                        np.clip(a64, b64, b64 + 1.0)], -1))
    zeros = slice(50, 60)                              # -0 against +0: the second operand, +0
    assert np.all(np.signbit(o[zeros, 0]) == False) and np.all(np.signbit(o[zeros, 1]) == False)  # noqa: E712
    nan = slice(60, 70)                                # NaN first: the second operand; clamp: lo
    np.testing.assert_array_equal(o[nan, 0], b[nan])
    np.testing.assert_array_equal(o[nan, 1], b[nan])
    np.testing.assert_array_equal(o[nan, 2], b[nan])
    np.testing.assert_array_equal(o64[nan, 2], b[nan].astype(np.float64))
    k = np.arange(n) - 3
    np.testing.assert_array_equal(oi[:, 0], np.minimum(k, 2))
    np.testing.assert_array_equal(oi[:, 1], np.maximum(k, 2))
    np.testing.assert_array_equal(oi[:, 2], np.clip(k, -1, 2))


def test_the_kernels_take_min_max_clamp_from_fastmath():
    """The render kernels' modules call fastmath's fmin / fmax / clamp, not Warp's scalar
    wp.min / wp.max / wp.clamp (two compares and two selects each on the CPU: module docstring
    of warp_rbrdf.fastmath); Warp's vector forms (an argument ``wp.vec3(...)``) stay."""
    import re
    from pathlib import Path

    root = Path(fastmath.__file__).parent
    found = []
    for path in sorted(root.rglob("*.py")):
        if path.name == "fastmath.py":
            continue
        for n, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"\bwp\.(min|max|clamp)\(", line) and "wp.vec3(" not in line:
                found.append(f"{path.relative_to(root)}:{n}: {line.strip()}")
    assert not found, "\n".join(found)
