"""The importance-sampling distribution of a lat-long environment map (NumPy, float64).

**Sampling follows the map as it is looked up** (:mod:`warp_rbrdf.lights.latlong`). The lookup
is a piecewise-bilinear function of (x, y) on ``(H - 1) x W`` *patches*: patch (j, c) spans
x in [c, c + 1] (periodic, so patch W - 1 joins the last and the first column) and
y in [j, j + 1], with the luminances of its four texels at its corners. The sampling density is
exactly proportional to the looked-up luminance in **solid angle**:

    pdf(w) = lum(lookup(u, v)) / (2 pi^2 Z),    Z = integral of lum(lookup(u, v)) sin(pi v) du dv

(``2 pi^2 sin(pi v) du dv`` is the solid angle of du dv), i.e. in (u, v) the density is the
bilinear luminance times the *exact* sin(pi v) Jacobian of the lat-long map, so a constant map is
uniform (1/4pi) and a one-texel sun is sampled along its bilinear footprint, not by a constant
per cell. ``Z`` is a sum of closed-form patch integrals (float64).

**MIS compensation** (:func:`compensated_distribution`; Karlík et al., "MIS compensation:
optimizing sampling techniques in multiple importance sampling", ACM TOG 38(6), 2019). Where the
environment sample is combined with a BSDF sample by MIS, the BSDF sample already covers the
dim, smooth part of the map; the environment sample does better spending its samples on what
stands out. The compensated distribution samples ``max(lum - c, 0)`` with ``c`` a fraction of
the map's mean luminance over the sphere (``pi Z / 2``), through the same lookup, hierarchy and
inversion. It is unbiased under MIS for the reason a black region of any map is: where its pdf
is 0 the BSDF sample's MIS weight is 1, and every BSDF sampler of the renderer covers its BSDF's
support. It is never used for the environment sample alone (sampler ``light``).

A patch is reached by a **hierarchical (quadtree) warp** over the patch masses (as Mitsuba 3's
``Hierarchical2D``, which its ``envmap`` uses): each level sends the uniforms to one of four
children and rescales them, so nearby uniforms reach nearby patches and stratified samples stay
stratified. Within a patch, the row fraction ``t`` has density
``((1 - t) A0 + t A1) sin(a + b t)`` (a = pi j / (H - 1), b = pi / (H - 1)); its closed-form CDF
is inverted in float64 (bracketed Newton); given ``t`` the column fraction is linear and is
inverted in closed form. The pdf is exact and positive wherever the lookup is.

:func:`env_pdf_numpy` and :func:`env_sample_numpy` are the float64 references of the Warp
``env_pdf`` (:mod:`warp_rbrdf.lights.env_map`) and ``env_sample``
(:mod:`warp_rbrdf.lights.env_sampling`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .latlong import direction_to_uv, lookup_luminance_numpy, luminance_of, uv_to_direction

#: Newton iterations (at most) for the row fraction inside a patch
NEWTON_ITERATIONS = 40


@dataclass
class EnvData:
    """The sampling distribution of one map (NumPy side), shapes for an (H, W) map."""
    image: np.ndarray           # (H, W, 3) float32 radiance
    rotation: np.ndarray        # (3, 3) map -> world
    lum: np.ndarray             # (H, W) float64 luminance of the texels, >= 0
    total: float                # Z = integral of lum(lookup) sin(pi v) du dv (0: black map)
    mip: list                   # sum pyramid of the (H - 1, W) patch masses / Z, level 0 first

    @property
    def pdf_scale(self) -> float:
        """1 / (2 pi^2 Z): the solid-angle pdf per unit of looked-up luminance (0: black map)."""
        return 1.0 / (2 * np.pi ** 2 * self.total) if self.total > 0 else 0.0


def row_geometry(H: int):
    """(a, b) of the H - 1 row intervals: interval j spans v = (j + t) / (H - 1), t in [0, 1],
    where sin(pi v) = sin(a[j] + b t); ``a`` has shape (H - 1,), ``b`` = pi / (H - 1)."""
    b = np.pi / (H - 1)
    return b * np.arange(H - 1), b


def sin_integrals(a, b, t):
    """I0 = integral_0^t sin(a + b s) ds and I1 = integral_0^t s sin(a + b s) ds, in forms that
    stay accurate for small b t (float64)."""
    h = 0.5 * b * t
    sh = np.sin(h)
    i0 = 2.0 * np.sin(a + h) * sh / b
    i1 = (2.0 * np.cos(a + h) * sh / b - t * np.cos(a + b * t)) / b
    return i0, i1


def patch_row_moments(H: int):
    """(K0, K1), shape (H - 1,): integral_0^1 (1 - t) sin(a + b t) dt and integral_0^1 t sin(a + b t) dt
    of each row interval (the weights of its two bounding rows)."""
    a, b = row_geometry(H)
    i0, i1 = sin_integrals(a, b, 1.0)
    return i0 - i1, i1


def patch_masses(lum: np.ndarray) -> np.ndarray:
    """(H - 1, W) integrals of the bilinear luminance times sin(pi v) over each patch, in
    (u, v) units (their sum is Z), from the (H, W) texel luminances ``lum``."""
    H, W = lum.shape
    K0, K1 = patch_row_moments(H)
    lc = 0.5 * (lum + np.roll(lum, -1, axis=1))          # (H, W) patch-column means per row
    return (K0[:, None] * lc[:-1] + K1[:, None] * lc[1:]) / ((H - 1) * W)


def mip_levels(level0: np.ndarray) -> list:
    """Sum-pyramid of ``level0`` (h, w): each level halves both sizes (rounding up; a missing
    child counts 0) down to 1 x 1."""
    levels = [level0]
    while levels[-1].shape != (1, 1):
        m = levels[-1]
        h, w = m.shape
        p = np.zeros((h + (h & 1), w + (w & 1)))
        p[:h, :w] = m
        levels.append(p[0::2, 0::2] + p[1::2, 0::2] + p[0::2, 1::2] + p[1::2, 1::2])
    return levels


def build_env_distribution(image: np.ndarray, rotation=None) -> EnvData:
    """The importance-sampling distribution of an (H, W, 3) lat-long map (``H >= 2``) under
    ``rotation`` (3, 3) map -> world (None: identity), see the module docstring."""
    H, W = image.shape[:2]
    if H < 2:
        raise ValueError("an environment map needs at least 2 rows")
    lum = luminance_of(image)
    if not np.all(np.isfinite(lum)):
        raise ValueError("environment map holds non-finite values")
    rot = np.eye(3) if rotation is None else np.asarray(rotation, float)
    env = _distribution(np.ascontiguousarray(image, np.float32), rot, lum)
    if not np.isfinite(env.total):
        raise ValueError("environment map holds non-finite values")
    return env


def _distribution(image: np.ndarray, rotation: np.ndarray, lum: np.ndarray) -> EnvData:
    """The distribution sampling the texel luminances ``lum`` (H, W) of ``image``: its patch
    masses' sum ``Z`` and their normalised hierarchy."""
    patch = patch_masses(lum)
    total = float(patch.sum())
    return EnvData(image=image, rotation=rotation, lum=lum, total=total,
                   mip=mip_levels(patch / (total if 0 < total < np.inf else 1.0)))


def mean_luminance(env: EnvData) -> float:
    """The mean of the looked-up luminance over the sphere (solid-angle weighted):
    ``Z 2 pi^2 / (4 pi) = pi Z / 2``."""
    return 0.5 * np.pi * env.total


def compensated_distribution(env: EnvData, fraction: float) -> EnvData:
    """The MIS-compensated distribution of ``env`` (module docstring): the texel luminances
    ``max(lum - fraction * mean_luminance(env), 0)`` with their own ``Z`` and hierarchy, the same
    image and rotation (the radiance is unchanged; only the sampling density and its pdf
    change). ``fraction`` in [0, 1]; 0, a black map, or a map the compensation would leave with
    less than 10^-3 of its mass (e.g. a constant map at ``fraction`` = 1) return ``env`` itself."""
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"MIS compensation must be in [0, 1], got {fraction}")
    if fraction == 0.0 or env.total <= 0.0:
        return env
    c = _distribution(env.image, env.rotation, np.maximum(env.lum - fraction * mean_luminance(env), 0.0))
    return c if c.total > 1e-3 * env.total else env


def env_pdf_numpy(env: EnvData, d: np.ndarray) -> np.ndarray:
    """Solid-angle pdf (1/sr) of world directions ``d`` (..., 3) (float64 reference of
    ``env_pdf``)."""
    u, v = direction_to_uv(d, env.rotation)
    if env.total <= 0:
        return np.zeros(np.shape(u))
    return lookup_luminance_numpy(env.lum, u, v) * env.pdf_scale


def linear_inverse_numpy(g0, g1, y):
    """s in [0, 1] with integral_0^s ((1 - r) g0 + r g1) dr = y (g0 + g1) / 2 (g0, g1 >= 0)."""
    g0, g1, y = np.broadcast_arrays(*(np.asarray(x, np.float64) for x in (g0, g1, y)))
    den = g0 + np.sqrt(g0 * g0 * (1 - y) + g1 * g1 * y)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(den > 0, y * (g0 + g1) / np.where(den > 0, den, 1.0), y)
    return np.clip(s, 0.0, 1.0)


def solve_row_fraction_numpy(A0, A1, a, b, y):
    """t in [0, 1] with F(t) = y F(1), F(t) = integral_0^t ((1 - s) A0 + s A1) sin(a + b s) ds:
    bracketed Newton (float64), started from the inverse of the density's linear interpolant."""
    A0, A1, a, y = np.broadcast_arrays(*(np.asarray(x, np.float64) for x in (A0, A1, a, y)))
    dA = A1 - A0

    def F(t):
        i0, i1 = sin_integrals(a, b, t)
        return A0 * i0 + dA * i1

    target = y * F(np.ones_like(y))
    t = linear_inverse_numpy(A0 * np.sin(a), A1 * np.sin(a + b), y)
    lo, hi = np.zeros_like(t), np.ones_like(t)
    done = np.zeros(t.shape, bool)
    for _ in range(NEWTON_ITERATIONS):
        f = F(t) - target
        hi = np.where(f > 0, t, hi)
        lo = np.where(f > 0, lo, t)
        dens = (A0 + dA * t) * np.sin(a + b * t)
        with np.errstate(invalid="ignore", divide="ignore"):
            nt = t - f / np.where(dens > 0, dens, 1.0)
        bad = (dens <= 0) | ~(nt > lo) | ~(nt < hi)
        nt = np.where(bad, 0.5 * (lo + hi), nt)
        conv = np.abs(nt - t) < 1e-12
        t = np.where(done, t, nt)
        done |= conv
        if done.all():
            break
    return np.clip(t, 0.0, 1.0)


def patch_point_direction(env: EnvData, j, c, t, s):
    """World directions (N, 3) and their pdf (N,) of the points at row fraction ``t`` and column
    fraction ``s`` of patches (j, c): u = (c + s + 1/2) / W (wrapped), v = (j + t) / (H - 1)."""
    H, W = env.lum.shape
    u = np.mod((c + s + 0.5) / W, 1.0)
    v = (j + t) / (H - 1)
    d = uv_to_direction(u, v) @ np.asarray(env.rotation, float).T
    return d, env_pdf_numpy(env, d)


def env_sample_numpy(env: EnvData, xi: np.ndarray):
    """float64 reference of ``env_sample``: uniforms ``xi`` (N, 2) (``xi[:, 0]`` drives v,
    ``xi[:, 1]`` u) -> (world directions (N, 3), pdf (N,))."""
    xi = np.asarray(xi, np.float64)
    H, W = env.lum.shape
    L = env.lum
    a_all, b = row_geometry(H)
    sx, sy = xi[:, 1].copy(), xi[:, 0].copy()
    x = np.zeros(len(xi), np.int64)
    y = np.zeros(len(xi), np.int64)
    for m in env.mip[-2::-1]:
        h, w = m.shape
        x, y = 2 * x, 2 * y
        pad = np.zeros((h + 1, w + 1))
        pad[:h, :w] = m
        v00, v10, v01, v11 = pad[y, x], pad[y, x + 1], pad[y + 1, x], pad[y + 1, x + 1]
        r0, r1 = v00 + v10, v01 + v11
        sy = np.clip(sy, 0.0, 1.0) * (r0 + r1)
        down = ((sy > r0) | (r0 <= 0)) & (r1 > 0)
        y = y + down
        sy = np.where(down, (sy - r0) / np.where(r1 > 0, r1, 1.0), sy / np.where(r0 > 0, r0, 1.0))
        ca, cb = np.where(down, v01, v00), np.where(down, v11, v10)
        sx = np.clip(sx, 0.0, 1.0) * (ca + cb)
        right = ((sx > ca) | (ca <= 0)) & (cb > 0)
        x = x + right
        sx = np.where(right, (sx - ca) / np.where(cb > 0, cb, 1.0), sx / np.where(ca > 0, ca, 1.0))
    j, c = y, x
    c1 = (c + 1) % W
    t = solve_row_fraction_numpy(L[j, c] + L[j, c1], L[j + 1, c] + L[j + 1, c1], a_all[j], b,
                                 np.clip(sy, 0.0, 1.0))
    g0 = (1 - t) * L[j, c] + t * L[j + 1, c]
    g1 = (1 - t) * L[j, c1] + t * L[j + 1, c1]
    s = linear_inverse_numpy(g0, g1, np.clip(sx, 0.0, 1.0))
    return patch_point_direction(env, j, c, t, s)
