"""Inline replacements for libm functions the render kernels call per sample
(:func:`atan2`, :func:`sincos`) and for Warp's float ``min`` / ``max`` / ``clamp``
(:func:`fmin`, :func:`fmax`, :func:`clamp`).

``wp.atan2`` compiles to a call of libm's ``atan2f``: 8 % of a shaded sample's time on the
reference sphere with an ``rgl`` material (``python -m benchmarks.profile_render``; each sample
takes the azimuth and elevation of the view, the micro-normal and the environment direction).
:func:`atan2` is a branch-free polynomial the compiler inlines:

    atan(a) = a P(a^2),  a = min(|x|, |y|) / max(|x|, |y|) in [0, 1],

``P`` of degree 8 (Chebyshev interpolation of atan(sqrt(z)) / sqrt(z) on z in [0, 1]), then the
octant fix-ups. Error in float32 against the exact atan2: at most 1.3e-7 rad absolute and
1.7e-7 relative on [0, pi/4], 2.7e-7 absolute over the circle (``pi - r`` rounds to float32:
``tests/test_fastmath.py`` measures it), about two float32 ulps -- below the 1e-4 the ``rgl`` material's parity with Mitsuba 3 asks for, and an
angle, not a density: a sample and its pdf are computed from the same directions.

:func:`sincos` replaces the libm ``sincosf`` calls of the environment sample's direction and
the rgl sampler's micro-normal (a call clobbers every vector register, so the caller spills
around it): Cody-Waite reduction by pi/2 and the Cephes minimax polynomials, within 2.4e-7 of
the exact values for |x| <= 1000 (``tests/test_fastmath.py``).
:func:`atan2_numpy` is the same arithmetic in NumPy float32 (tests).

:func:`fmin`, :func:`fmax` and :func:`clamp` (float32, float64 and int overloads) replace
``wp.min``, ``wp.max`` and ``wp.clamp`` in the kernels. Warp 1.19's float versions follow C's
``fmin`` / ``fmax`` (a NaN operand is "missing"): on the CPU each is two compares and two
selects, ``(a <= b) ? a : ((b == b) ? b : a)``, on the path of every clamp of a search, a warp
and a lookup. Here each is one select, ``a < b ? a : b`` (``a > b ? a : b``), one ``minss`` /
``maxss``: the same value for every pair of numbers but two signed zeros (the second operand,
where Warp's gives the first) and a NaN in the second operand (NaN, where Warp's gives the
first); a NaN in the first operand gives the second, as Warp's does, so ``fmax(x, 0.0)`` maps a
NaN to 0. ``clamp(x, lo, hi)`` is ``fmin(fmax(x, lo), hi)``: ``lo`` for a NaN ``x``, as Warp's.
The native snippets of the rational evaluation use the same selects
(:data:`warp_rbrdf.materials.rational_channels.MINMAX_SOURCE`). What it buys is measured in
``docs/rendering.md`` (per-sample cost) and ``docs/bench_eval.md``.
"""
from __future__ import annotations

import numpy as np
import warp as wp

# --- min / max / clamp --------------------------------------------------------------------------
@wp.func
def fmin(a: wp.float32, b: wp.float32) -> wp.float32:
    """``a < b ? a : b`` (one ``minss``; module docstring)."""
    return wp.where(a < b, a, b)


@wp.func
def fmin(a: wp.float64, b: wp.float64) -> wp.float64:  # noqa: F811 - a Warp overload
    return wp.where(a < b, a, b)


@wp.func
def fmin(a: int, b: int) -> int:  # noqa: F811 - a Warp overload
    return wp.min(a, b)


@wp.func
def fmax(a: wp.float32, b: wp.float32) -> wp.float32:
    """``a > b ? a : b`` (one ``maxss``; module docstring)."""
    return wp.where(a > b, a, b)


@wp.func
def fmax(a: wp.float64, b: wp.float64) -> wp.float64:  # noqa: F811 - a Warp overload
    return wp.where(a > b, a, b)


@wp.func
def fmax(a: int, b: int) -> int:  # noqa: F811 - a Warp overload
    return wp.max(a, b)


@wp.func
def clamp(x: wp.float32, lo: wp.float32, hi: wp.float32) -> wp.float32:
    """``fmin(fmax(x, lo), hi)``: ``lo`` for a NaN ``x`` (module docstring)."""
    return fmin(fmax(x, lo), hi)


@wp.func
def clamp(x: wp.float64, lo: wp.float64, hi: wp.float64) -> wp.float64:  # noqa: F811 - a Warp overload
    return fmin(fmax(x, lo), hi)


@wp.func
def clamp(x: int, lo: int, hi: int) -> int:  # noqa: F811 - a Warp overload
    return wp.clamp(x, lo, hi)


#: coefficients of P (increasing powers of a^2)
ATAN_COEFFS = (0.9999999842426359, -0.3333306678069136, 0.19992483578497855, -0.1420257051166726,
               0.10636754097973429, -0.07495445442966431, 0.04258760746076035, -0.016005030500485688,
               0.0028340642981916574)
_C = tuple(float(np.float32(c)) for c in ATAN_COEFFS)


@wp.func
def atan2(y: float, x: float) -> float:
    """atan2(y, x) in [-pi, pi] (radians), as ``wp.atan2`` up to 2.7e-7; (0, 0) -> 0."""
    ax = wp.abs(x)
    ay = wp.abs(y)
    mx = fmax(ax, ay)
    a = fmin(ax, ay) / fmax(mx, 1.0e-37)
    s = a * a
    p = wp.static(_C[8])
    p = p * s + wp.static(_C[7])
    p = p * s + wp.static(_C[6])
    p = p * s + wp.static(_C[5])
    p = p * s + wp.static(_C[4])
    p = p * s + wp.static(_C[3])
    p = p * s + wp.static(_C[2])
    p = p * s + wp.static(_C[1])
    p = p * s + wp.static(_C[0])
    r = a * p
    r = wp.where(ay > ax, wp.HALF_PI - r, r)
    r = wp.where(x < 0.0, wp.pi - r, r)
    return wp.where(y < 0.0, -r, r)


def atan2_numpy(y, x) -> np.ndarray:
    """:func:`atan2` in NumPy float32 (the same operations, for tests)."""
    y = np.asarray(y, np.float32)
    x = np.asarray(x, np.float32)
    ax, ay = np.abs(x), np.abs(y)
    a = np.minimum(ax, ay) / np.maximum(np.maximum(ax, ay), np.float32(1e-37))
    s = a * a
    p = np.float32(_C[8])
    for c in _C[7::-1]:
        p = p * s + np.float32(c)
    r = a * p
    r = np.where(ay > ax, np.float32(np.pi / 2) - r, r)
    r = np.where(x < 0, np.float32(np.pi) - r, r)
    return np.where(y < 0, -r, r).astype(np.float32)


# --- sincos -----------------------------------------------------------------------------------
#: pi/2 in three float32 parts (Cody-Waite): the first two have few enough bits that k * part is
#: exact for |k| < 2^10, so r = x - k pi/2 loses nothing for |x| < 1000
_PIO2 = (1.5703125, 4.837512969970703125e-4, 7.54978995489188216e-8)
#: minimax polynomials on [-pi/4, pi/4] (Cephes ``sinf`` / ``cosf``): sin r = r + r^3 S(r^2),
#: cos r = 1 - r^2 / 2 + r^4 C(r^2)
SIN_COEFFS = (-1.6666654611e-1, 8.3321608736e-3, -1.9515295891e-4)
COS_COEFFS = (4.166664568298827e-2, -1.388731625493765e-3, 2.443315711809948e-5)
#: |x| up to which :func:`sincos` keeps its stated error (radians)
SINCOS_RANGE = 1000.0


@wp.func
def sincos(x: float) -> wp.vec2:
    """(sin x, cos x) for |x| <= SINCOS_RANGE (radians), within 2.4e-7 of the exact values
    (``tests/test_fastmath.py``): the quadrant ``k = round(2x / pi)``, ``r = x - k pi/2`` by
    Cody-Waite, two polynomials, a swap and sign by ``k mod 4``. Inline, no libm call."""
    k = wp.floor(x * 0.6366197723675814 + 0.5)
    r = x - k * wp.static(_PIO2[0])
    r = r - k * wp.static(_PIO2[1])
    r = r - k * wp.static(_PIO2[2])
    z = r * r
    sp = wp.static(SIN_COEFFS[2])
    sp = sp * z + wp.static(SIN_COEFFS[1])
    sp = sp * z + wp.static(SIN_COEFFS[0])
    sr = r + r * z * sp
    cp = wp.static(COS_COEFFS[2])
    cp = cp * z + wp.static(COS_COEFFS[1])
    cp = cp * z + wp.static(COS_COEFFS[0])
    cr = 1.0 - 0.5 * z + z * z * cp
    q = int(k) & 3
    sn = wp.where(q == 0, sr, wp.where(q == 1, cr, wp.where(q == 2, -sr, -cr)))
    cs = wp.where(q == 0, cr, wp.where(q == 1, -sr, wp.where(q == 2, -cr, sr)))
    return wp.vec2(sn, cs)


def sincos_numpy(x) -> tuple[np.ndarray, np.ndarray]:
    """:func:`sincos` in NumPy float32 (the same operations, for tests)."""
    x = np.asarray(x, np.float32)
    f = np.float32
    k = np.floor(x * f(0.6366197723675814) + f(0.5))
    r = x - k * f(_PIO2[0])
    r = r - k * f(_PIO2[1])
    r = r - k * f(_PIO2[2])
    z = r * r
    sp = (f(SIN_COEFFS[2]) * z + f(SIN_COEFFS[1])) * z + f(SIN_COEFFS[0])
    sr = r + r * z * sp
    cp = (f(COS_COEFFS[2]) * z + f(COS_COEFFS[1])) * z + f(COS_COEFFS[0])
    cr = f(1.0) - f(0.5) * z + z * z * cp
    q = k.astype(np.int64) & 3
    sn = np.select([q == 0, q == 1, q == 2], [sr, cr, -sr], -cr)
    cs = np.select([q == 0, q == 1, q == 2], [cr, -sr, -cr], sr)
    return sn.astype(np.float32), cs.astype(np.float32)
