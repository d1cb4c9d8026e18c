"""The environment sample of the render kernels (Warp): the hierarchical warp to a patch of the
lookup, then the inversion inside the patch, in float64 (the distribution and its NumPy
reference: :mod:`warp_rbrdf.lights.env_distribution`).

Inside patch (j, c) the row fraction ``t`` has density ``((1 - t) A0 + t A1) sin(a + b t)``:
Newton on the cubic CDF of the chord of sin, then bracketed Newton on the exact CDF (usually one
step; its sine and cosine of the half angle b t / 2 < 0.25 by their series, inlined, where
libm's float64 ``sincos`` is a call: :func:`_half_sincos`); given ``t`` the column fraction is
linear and is inverted in closed form (:func:`linear_inverse`)."""
from __future__ import annotations

import warp as wp

from .. import fastmath as fmath
from .env_distribution import NEWTON_ITERATIONS
from .env_map import EnvMap, next_column


@wp.func
def linear_inverse(g0: wp.float64, g1: wp.float64, y: wp.float64) -> wp.float64:
    """s in [0, 1] with integral_0^s ((1 - r) g0 + r g1) dr = y (g0 + g1) / 2."""
    one = wp.float64(1.0)
    zero = wp.float64(0.0)
    den = g0 + wp.sqrt(g0 * g0 * (one - y) + g1 * g1 * y)
    s = y
    if den > zero:
        s = y * (g0 + g1) / den
    return fmath.clamp(s, zero, one)


#: half-angle h = b t / 2 below which :func:`_half_sincos` sums its series (b = pi / (H - 1) <= 0.5:
#: maps of 8 rows or more); larger ones call libm
SERIES_MAX_HALF_ANGLE = 0.25
#: the series' factors 1 / n and the cubic's 1/3 as float64 constants (``wp.float64(1.0 / 3.0)``
#: in a Warp function divides in float32)
_F2 = wp.constant(wp.float64(1.0 / 2.0))
_F6 = wp.constant(wp.float64(1.0 / 6.0))
_F12 = wp.constant(wp.float64(1.0 / 12.0))
_F20 = wp.constant(wp.float64(1.0 / 20.0))
_F30 = wp.constant(wp.float64(1.0 / 30.0))
_F42 = wp.constant(wp.float64(1.0 / 42.0))
_F56 = wp.constant(wp.float64(1.0 / 56.0))
_F72 = wp.constant(wp.float64(1.0 / 72.0))
_F90 = wp.constant(wp.float64(1.0 / 90.0))
_F110 = wp.constant(wp.float64(1.0 / 110.0))
_F132 = wp.constant(wp.float64(1.0 / 132.0))
_THIRD = wp.constant(wp.float64(1.0 / 3.0))


@wp.func
def _half_sincos(h: wp.float64) -> wp.vec2d:
    """(sin h, cos h) in float64. For 0 <= h <= :data:`SERIES_MAX_HALF_ANGLE` their Taylor series
    to h^11 and h^12 (Horner in h^2; the first omitted terms are below h^13 / 13! = 2.4e-18 and
    h^14 / 14! = 4e-20 there, under half an ulp of the values), inlined where libm's
    ``sincos`` is a call; else ``wp.sin`` and ``wp.cos``."""
    one = wp.float64(1.0)
    if h > wp.float64(SERIES_MAX_HALF_ANGLE):
        return wp.vec2d(wp.sin(h), wp.cos(h))
    z = h * h
    s = one - z * _F110
    s = one - z * _F72 * s
    s = one - z * _F42 * s
    s = one - z * _F20 * s
    s = one - z * _F6 * s
    c = one - z * _F132
    c = one - z * _F90 * c
    c = one - z * _F56 * c
    c = one - z * _F30 * c
    c = one - z * _F12 * c
    c = one - z * _F2 * c
    return wp.vec2d(h * s, c)


@wp.func
def _row_cdf_density(A0: wp.float64, dA: wp.float64, sa: wp.float64, ca: wp.float64, b: wp.float64,
                     inv_b: wp.float64, t: wp.float64) -> wp.vec2d:
    """(F(t), F'(t)) for F(t) = integral_0^t (A0 + dA s) sin(a + b s) ds, sa = sin a, ca = cos a,
    inv_b = 1 / b: the sine and cosine of b t / 2 by :func:`_half_sincos` (the forms of
    :func:`~.env_distribution.sin_integrals`)."""
    two = wp.float64(2.0)
    sc = _half_sincos(wp.float64(0.5) * b * t)
    sh = sc[0]
    ch = sc[1]
    s2 = two * sh * sh                    # 1 - cos(b t)
    sbt = two * sh * ch                   # sin(b t)
    cbt = wp.float64(1.0) - s2
    i0 = (ca * s2 + sa * sbt) * inv_b     # cos a - cos(a + b t)  over b
    i1 = ((ca * sbt - sa * s2) * inv_b - t * (ca * cbt - sa * sbt)) * inv_b
    return wp.vec2d(A0 * i0 + dA * i1, (A0 + dA * t) * (sa * cbt + ca * sbt))


@wp.func
def solve_row_fraction(A0: wp.float64, A1: wp.float64, env: EnvMap, j: int, y: wp.float64) -> wp.float64:
    """t in [0, 1] with F(t) = y F(1), F(t) = integral_0^t ((1 - s) A0 + s A1) sin(a + b s) ds on
    row interval ``j`` (``env.row_trig[j]`` = sin a, cos a, sin(a + b), I0(1), I1(1)): Newton on
    the cubic CDF of the density with sin replaced by its chord (no trig; the chord is within
    b^2/8 = 5e-6 of sin for a 512-row map; t within 1e-6; it stops once a step is below 1e-9),
    then bracketed Newton on the exact F (usually one step) -- the root of
    :func:`~.env_distribution.solve_row_fraction_numpy`."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    half = wp.float64(0.5)
    third = _THIRD
    b = wp.float64(3.141592653589793) / wp.float64(env.height - 1)
    inv_b = one / b
    sa = env.row_trig[j, 0]
    ca = env.row_trig[j, 1]
    dA = A1 - A0
    target = y * (A0 * env.row_trig[j, 3] + dA * env.row_trig[j, 4])
    # 1. the chord density q(t) = (A0 + dA t)(sa + ds t): cubic CDF, monotone on [0, 1]
    ds = env.row_trig[j, 2] - sa
    c1 = A0 * sa
    c2 = half * (A0 * ds + dA * sa)
    c3 = third * dA * ds
    qt = y * (c1 + c2 + c3)
    t = linear_inverse(A0 * sa, A1 * env.row_trig[j, 2], y)
    for _ in range(4):
        q = t * (c1 + t * (c2 + t * c3)) - qt
        dq = c1 + t * (wp.float64(2.0) * c2 + t * wp.float64(3.0) * c3)
        if dq > zero:
            nt = fmath.clamp(t - q / dq, zero, one)
            step = wp.abs(nt - t)
            t = nt
            if step < wp.float64(1.0e-9):
                break
    # 2. the exact F, bracketed
    lo = zero
    hi = one
    for _ in range(NEWTON_ITERATIONS):
        fd = _row_cdf_density(A0, dA, sa, ca, b, inv_b, t)
        f = fd[0] - target
        if f > zero:
            hi = t
        else:
            lo = t
        nt = half * (lo + hi)
        if fd[1] > zero:
            cand = t - f / fd[1]
            if cand > lo and cand < hi:
                nt = cand
        step = wp.abs(nt - t)
        t = nt
        if step < wp.float64(1.0e-6):   # Newton: the error left is ~ step^2 (about 1e-12)
            break
    return fmath.clamp(t, zero, one)


@wp.func
def _split(s: wp.float64, m0: wp.float64, m1: wp.float64) -> wp.vec2d:
    """Hierarchical step: (branch 0 or 1, s rescaled to [0, 1] inside it) for masses m0, m1."""
    zero = wp.float64(0.0)
    s = fmath.clamp(s, zero, wp.float64(1.0)) * (m0 + m1)
    if (s > m0 or m0 <= zero) and m1 > zero:
        return wp.vec2d(wp.float64(1.0), (s - m0) / m1)
    if m0 > zero:
        return wp.vec2d(zero, s / m0)
    return wp.vec2d(zero, zero)


@wp.func
def _patch_mass(env: EnvMap, j: int, c: int) -> wp.float64:
    """Mass of patch (j, c) up to a common factor (0 outside the map)."""
    if j >= env.height - 1 or c >= env.width:
        return wp.float64(0.0)
    cn = next_column(c, env.width)
    k1 = env.row_trig[j, 4]
    k0 = env.row_trig[j, 3] - k1
    return (k0 * wp.float64(env.lum[j, c] + env.lum[j, cn])
            + k1 * wp.float64(env.lum[j + 1, c] + env.lum[j + 1, cn]))


@wp.func
def descend_level(env: EnvMap, level: int, x: int, y: int, sx: wp.float64, sy: wp.float64):
    """One level (>= 1) of the hierarchical warp: ``(x, y, sx, sy)`` of the chosen child block
    of block (x, y) and the uniforms rescaled inside it. Each level stores its 2 x 2 children
    blocks contiguously (v00, v10, v01, v11)."""
    k = env.mip_offset[level - 1] + 4 * (y * env.mip_blocks_x[level - 1] + x)
    v00 = wp.float64(env.mip[k])
    v10 = wp.float64(env.mip[k + 1])
    v01 = wp.float64(env.mip[k + 2])
    v11 = wp.float64(env.mip[k + 3])
    ry = _split(sy, v00 + v10, v01 + v11)
    ca = v00
    cb = v10
    y = 2 * y
    if ry[0] > wp.float64(0.5):
        y = y + 1
        ca = v01
        cb = v11
    rx = _split(sx, ca, cb)
    x = 2 * x
    if rx[0] > wp.float64(0.5):
        x = x + 1
    return x, y, rx[1], ry[1]


@wp.func
def patch_select(env: EnvMap, x: int, y: int, sx: wp.float64, sy: wp.float64):
    """The last step of the descent from level-1 block (x, y) with the rescaled uniforms (sx,
    sy): over the four patches under it (their masses from the texels), ``(j, c, sx, sy)`` of
    the chosen patch (its row interval and column) and the uniforms rescaled inside it."""
    y = 2 * y
    x = 2 * x
    p00 = _patch_mass(env, y, x)
    p10 = _patch_mass(env, y, x + 1)
    p01 = _patch_mass(env, y + 1, x)
    p11 = _patch_mass(env, y + 1, x + 1)
    ry = _split(sy, p00 + p10, p01 + p11)
    ca = p00
    cb = p10
    if ry[0] > wp.float64(0.5):
        y = y + 1
        ca = p01
        cb = p11
    rx = _split(sx, ca, cb)
    if rx[0] > wp.float64(0.5):
        x = x + 1
    return y, x, rx[1], ry[1]


@wp.func
def patch_invert(env: EnvMap, j: int, c: int, sx: wp.float64, sy: wp.float64) -> wp.vec3d:
    """(u, v, lum) of the sample in patch (j, c) with the uniforms (sx, sy) rescaled inside it:
    the row fraction by :func:`solve_row_fraction`, the column fraction in closed form."""
    H = env.height
    W = env.width
    one = wp.float64(1.0)
    cn = next_column(c, W)
    L00 = wp.float64(env.lum[j, c])
    L10 = wp.float64(env.lum[j, cn])
    L01 = wp.float64(env.lum[j + 1, c])
    L11 = wp.float64(env.lum[j + 1, cn])
    t = solve_row_fraction(L00 + L10, L01 + L11, env, j, sy)
    g0 = (one - t) * L00 + t * L01
    g1 = (one - t) * L10 + t * L11
    s = linear_inverse(g0, g1, sx)
    lum = (one - s) * g0 + s * g1
    u = (wp.float64(c) + s + wp.float64(0.5)) / wp.float64(W)
    if u >= one:
        u = u - one
    v = (wp.float64(j) + t) / wp.float64(H - 1)
    return wp.vec3d(u, v, lum)


@wp.func
def patch_point(env: EnvMap, x: int, y: int, sx: wp.float64, sy: wp.float64) -> wp.vec3d:
    """(u, v, lum) of the sample whose descent ended at level-1 block (x, y) with the rescaled
    uniforms (sx, sy): :func:`patch_select`, then :func:`patch_invert` (module docstring)."""
    j, c, px, py = patch_select(env, x, y, sx, sy)
    return patch_invert(env, j, c, px, py)


@wp.func
def descend(env: EnvMap, xi: wp.vec2):
    """The hierarchical warp of the uniforms ``xi`` (``xi[0]`` drives v, ``xi[1]`` u) down to
    level 1: ``(x, y, sx, sy)``, the level-1 block and the uniforms rescaled inside it
    (float64), for :func:`patch_point`."""
    sy = fmath.fmin(wp.float64(xi[0]), wp.float64(0.9999999999999999))
    sx = fmath.fmin(wp.float64(xi[1]), wp.float64(0.9999999999999999))
    x = int(0)
    y = int(0)
    level = env.levels - 2
    while level >= 1:
        x, y, sx, sy = descend_level(env, level, x, y, sx, sy)
        level = level - 1
    return x, y, sx, sy


@wp.func
def sample_patch_point(env: EnvMap, xi: wp.vec2) -> wp.vec3d:
    """(u, v, lum) of the sample of uniforms ``xi`` (``xi[0]`` drives v, ``xi[1]`` u), float64:
    its map coordinates and the bilinear luminance there (the lookup's own taps: the patch's
    four texels with weights from the fractions ``t``, ``s``), so the pdf needs no second
    lookup: :func:`descend`, then :func:`patch_point`. :mod:`.env_lanes` steps the descent of
    K samples together."""
    x, y, sx, sy = descend(env, xi)
    return patch_point(env, x, y, sx, sy)


@wp.func
def point_sample(rot: wp.mat33, pdf_scale: float, uvl: wp.vec3d):
    """The environment sample at the point ``uvl`` = (u, v, looked-up luminance) of
    :func:`sample_patch_point`: ``(vec4 (dx, dy, dz, pdf), vec2 uv)``, the world direction
    (``rot``: map -> world), its solid-angle pdf (1/sr, ``pdf_scale`` per unit of luminance) and
    the map coordinates in float32."""
    scp = fmath.sincos(2.0 * wp.pi * float(uvl[0]))
    sct = fmath.sincos(wp.pi * float(uvl[1]))
    st = sct[0]
    dw = rot * wp.vec3(scp[0] * st, sct[1], -scp[1] * st)
    pdf = float(uvl[2]) * pdf_scale
    return wp.vec4(dw[0], dw[1], dw[2], pdf), wp.vec2(float(uvl[0]), float(uvl[1]))


@wp.func
def env_sample_uv(env: EnvMap, xi: wp.vec2):
    """:func:`env_sample` and the map coordinates of the sampled point (``(vec4, vec2 uv)``),
    so its radiance (``env_eval_uv``) needs no atan2. The pdf is the looked-up luminance
    at the sampled (u, v) itself (the taps the patch inversion read), not at the map
    coordinates recomputed from the float32 direction: radiance and pdf are taken at one point,
    and ``env_pdf`` of the returned direction agrees to float rounding of the direction."""
    if env.can_sample == 0:
        return wp.vec4(0.0, 1.0, 0.0, 0.0), wp.vec2(0.0)
    ds, uv = point_sample(env.rot, env.pdf_scale, sample_patch_point(env, xi))
    return ds, uv


@wp.func
def env_sample(env: EnvMap, xi: wp.vec2) -> wp.vec4:
    """Importance-sample a world direction from uniforms ``xi`` in [0, 1)^2 (``xi[0]`` drives v,
    ``xi[1]`` u); returns (dx, dy, dz, pdf), pdf in 1/sr: the density at the sampled point, equal to
    ``env_pdf`` of the returned direction up to the float32 rounding of the direction (see
    :func:`env_sample_uv`); pdf = 0 if impossible. :func:`env_sample_uv` without the map coordinates."""
    s, _uv = env_sample_uv(env, xi)
    return s
