"""Lights: directional lights and one environment (lat-long map, constant, or procedural sky).

Environment maps follow conventions.md exactly (Mitsuba 3 ``envmap``):

* world direction ``d`` -> map direction ``R^T d`` (``R`` = the light's rotation), then
  ``u = atan2(x, -z) / 2pi`` wrapped into [0, 1), ``v = acos(y) / pi``;
* bilinear lookup at ``x = u W - 0.5`` (periodic) and ``y = v (H - 1)`` (clamped): columns are
  texel-centred, rows are not (row 0 sits on the +Y pole).

**Importance sampling follows the map as it is looked up** (issue 21). The lookup is a
piecewise-bilinear function of (x, y) on ``(H - 1) x W`` *patches*: patch (j, c) spans
x in [c, c + 1] (periodic, so patch W - 1 joins the last and the first column) and
y in [j, j + 1], with the luminances of its four texels at its corners. The sampling density is
exactly proportional to the looked-up luminance in **solid angle**:

    pdf(w) = lum(lookup(u, v)) / (2 pi^2 Z),    Z = integral of lum(lookup(u, v)) sin(pi v) du dv

(``2 pi^2 sin(pi v) du dv`` is the solid angle of du dv), i.e. in (u, v) the density is the
bilinear luminance times the *exact* sin(pi v) Jacobian of the lat-long map, so a constant map is
uniform (1/4pi) and a one-texel sun is sampled along its bilinear footprint, not by a constant
per cell. ``Z`` is a sum of closed-form patch integrals (float64). Within a patch, the row
fraction ``t`` has density ``((1 - t) A0 + t A1) sin(a + b t)`` (a = pi j / (H - 1),
b = pi / (H - 1)); its closed-form CDF is inverted in float64 (Newton on the cubic CDF of the
chord of sin, then bracketed Newton on the exact CDF, usually one step); given ``t`` the column
fraction is linear and is inverted in closed form. Two warps reach a patch (both
give the same density; the pdf is exact and positive wherever the lookup is):

* ``SCHEME_HIERARCHICAL`` (default): a hierarchical (quadtree) warp over the patch masses (as
  Mitsuba's ``Hierarchical2D``, which Mitsuba's ``envmap`` uses): each level sends the uniforms
  to one of four children and rescales them, so nearby uniforms reach nearby patches and
  stratified samples stay stratified. The Warp struct stores the levels above the patches
  (float32, 2 x 2 children contiguous); the last step computes the four patch masses from the
  luminance texels, which the patch inversion reads anyway;
* ``SCHEME_MARGINAL``: the continuous marginal / conditional inversion (as Mitsuba's
  ``Marginal2D`` with continuous conditionals): ``xi[0]`` picks ``v`` from the marginal over the
  H - 1 row intervals, ``xi[1]`` picks ``u`` from the conditional *at that v* (the two bounding
  rows' prefix sums mixed by ``t``). Continuous too, but it stratifies less well than the
  hierarchy (``benchmarks.bench_env_sampling``); kept, private, for that benchmark.

``SCHEME_PIECEWISE_CONSTANT`` is the sampler before issue 21 (one cell per texel, density
constant in solid angle within a cell). It is kept, private, for ``benchmarks.bench_env_sampling``
only (``build_env_distribution(..., _scheme=...)``).

The NumPy functions (``env_pdf_numpy``, ``env_sample_numpy``) are float64 references of the Warp
functions ``env_pdf`` / ``env_sample``.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import warp as wp

from fit.errors import BRDFFileError, display_path
from fit.inputs import open_regular

from . import fastmath as fmath
from . import limits
from .errors import SceneError
from .image_io import oiio_filename

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

SCHEME_MARGINAL = 0
SCHEME_HIERARCHICAL = 1
SCHEME_PIECEWISE_CONSTANT = 2
#: the warp :func:`build_env_distribution` uses unless told otherwise
DEFAULT_SCHEME = SCHEME_HIERARCHICAL
SCHEME_NAMES = {"marginal": SCHEME_MARGINAL, "hierarchical": SCHEME_HIERARCHICAL,
                "piecewise-constant": SCHEME_PIECEWISE_CONSTANT}

#: Newton iterations (at most) for the row fraction inside a patch / row interval
NEWTON_ITERATIONS = 40


@wp.struct
class EnvMap:
    texels: wp.array2d(dtype=wp.vec3)    # (H, W) radiance (scale applied)
    lum: wp.array2d(dtype=float)         # (H, W) luminance of the texels (>= 0)
    pdf_scale: float                     # 1 / (2 pi^2 Z): pdf = lum(lookup) * pdf_scale
    scheme: int                          # SCHEME_*
    row_trig: wp.array2d(dtype=wp.float64)  # (H - 1, 5) per row interval: sin a, cos a, sin(a + b),
                                            # I0(1), I1(1) (K1 = I1(1), K0 = I0(1) - I1(1))
    row_cdf: wp.array(dtype=wp.float64)  # (H,) marginal CDF over the H - 1 row intervals
    col_prefix: wp.array2d(dtype=wp.float64)  # (H, W + 1) per-row prefix sums of patch columns
    mip: wp.array(dtype=float)           # hierarchical: levels 1.. (2 x 2 blocks), flat, float32
    mip_offset: wp.array(dtype=int)      # start of level l in ``mip`` at [l - 1]
    mip_blocks_x: wp.array(dtype=int)    # 2 x 2 blocks per row of level l at [l - 1]
    levels: int                          # levels of the pyramid, the patches' (level 0) included
    pc_pdf: wp.array2d(dtype=float)      # piecewise-constant scheme: (H, W) density per cell
    pc_marginal: wp.array(dtype=float)   # (H + 1,)
    pc_conditional: wp.array2d(dtype=float)  # (H, W + 1)
    rot: wp.mat33                        # map -> world rotation
    width: int
    height: int
    present: int                         # 0: no environment (black)
    can_sample: int                      # 0: all-black map, no importance sampling


@wp.struct
class Directional:
    to_light: wp.array(dtype=wp.vec3)    # unit vectors towards the light
    irradiance: wp.array(dtype=wp.vec3)
    count: int


# --------------------------------------------------------------------------------------------
# NumPy side
@dataclass
class EnvData:
    """The sampling distribution of one map (NumPy side), shapes for an (H, W) map."""
    image: np.ndarray           # (H, W, 3) float32 radiance
    rotation: np.ndarray        # (3, 3) map -> world
    lum: np.ndarray             # (H, W) float64 luminance of the texels, >= 0
    total: float                # Z = integral of lum(lookup) sin(pi v) du dv (0: black map)
    scheme: int = DEFAULT_SCHEME
    row_cdf: np.ndarray = None      # (H,) marginal CDF over the row intervals (SCHEME_MARGINAL)
    col_prefix: np.ndarray = None   # (H, W + 1) per-row prefix sums of (L[c] + L[c+1]) / 2
    mip: list = None                # hierarchical levels, level 0 = (H-1, W) patch masses / Z
    pc: dict = None                 # piecewise-constant scheme: pdf, marginal_cdf, conditional_cdf

    @property
    def pdf_scale(self) -> float:
        """1 / (2 pi^2 Z): the solid-angle pdf per unit of looked-up luminance (0: black map)."""
        return 1.0 / (2 * np.pi ** 2 * self.total) if self.total > 0 else 0.0


#: First bytes of the environment-map formats (OpenEXR magic number; Radiance "#?").
_MAGIC = {".exr": b"\x76\x2f\x31\x01", ".hdr": b"#?"}


def read_latlong(path, file="<scene>", key="file") -> np.ndarray:
    """(H, W, 3) float32 linear RGB of an HDR/EXR lat-long map (OpenImageIO), validated by
    :func:`check_texels`.

    Before reading: a regular file (a named pipe or folder is refused, never opened) of at
    most :data:`~warp_rbrdf.limits.MAX_ENV_BYTES`, and the size its header states within
    :func:`warp_rbrdf.limits.check_env_size` (a compressed EXR of a few kB can state
    10^5 x 10^5 texels). Each problem is a one-line :class:`SceneError` naming the key."""
    import OpenImageIO as oiio

    shown = display_path(path)
    try:
        with open_regular(path, limits.MAX_ENV_BYTES, "environment map") as f:
            magic = f.read(4)
    except BRDFFileError as e:
        raise SceneError(file, key, f"environment map {shown}: {e.problem}") from None
    except OSError as e:
        raise SceneError(file, key, f"environment map {shown}: cannot read ({e.strerror or e})") from None
    # the format must match the suffix: OpenImageIO would otherwise try every reader it has on
    # the bytes (libpng then prints to stderr)
    suffix = os.path.splitext(os.fspath(path))[1].lower()
    want = _MAGIC.get(suffix)
    if want is not None and not magic.startswith(want):
        raise SceneError(file, key, f"environment map {shown}: not a{'n OpenEXR' if suffix == '.exr' else ' Radiance HDR'} "
                                    f"file (it starts with {magic!r})")
    with oiio_filename(path) as name:   # OpenImageIO takes only UTF-8 names
        inp = oiio.ImageInput.open(name)
    if inp is None:
        err = " ".join(oiio.geterror().split())[:160]
        raise SceneError(file, key, f"cannot open environment map {shown} ({err})")
    try:
        spec = inp.spec()
        W, H, C = int(spec.width), int(spec.height), int(spec.nchannels)
        problem = limits.check_env_size(W, H)
        if problem:
            raise SceneError(file, key, f"environment map {shown}: {problem}")
        if not 1 <= C <= 64 or spec.depth > 1:
            raise SceneError(file, key, f"environment map {shown}: expected a 2-D image with 1 to 64 channels, "
                                        f"got {C} channels, depth {spec.depth}")
        px = inp.read_image(0, 0, 0, min(C, 3), oiio.FLOAT)
        if px is None:
            err = " ".join(inp.geterror().split())[:160]
            raise SceneError(file, key, f"cannot read environment map {shown} ({err})")
    finally:
        inp.close()
    px = np.asarray(px, np.float32)
    if px.size != H * W * min(C, 3):
        raise SceneError(file, key, f"cannot read environment map {shown} (got {px.size} values for "
                                    f"{W} x {H} x {min(C, 3)})")
    px = px.reshape(H, W, -1)
    if px.shape[2] < 3:
        px = np.repeat(px[:, :, :1], 3, axis=2)
    px = np.ascontiguousarray(px[:, :, :3])
    check_texels(px, file, key, shown)
    return px


def check_texels(img: np.ndarray, file="<scene>", key="file", what="environment map") -> None:
    """Policy for texels: every texel of an environment image must be finite, >= 0 and at most
    :data:`~warp_rbrdf.limits.MAX_ENV_TEXEL`; otherwise a one-line :class:`SceneError` with
    the count and the first bad texel (row, column). Nothing is clamped or zeroed silently."""
    bad = ~np.isfinite(img) | (img < 0) | (img > limits.MAX_ENV_TEXEL)
    if bad.any():
        flat = bad.reshape(-1, img.shape[-1]).any(axis=1)
        n = int(flat.sum())
        j, i = divmod(int(np.flatnonzero(flat)[0]), img.shape[1])
        v = img[j, i]
        kind = "NaN" if np.isnan(v).any() else "infinite" if np.isinf(v).any() else \
            "negative" if (v < 0).any() else f"above {limits.MAX_ENV_TEXEL:g}"
        raise SceneError(file, key, f"{what}: {n} of {img.shape[0] * img.shape[1]} texels are NaN, infinite, "
                                    f"negative or above {limits.MAX_ENV_TEXEL:g} (first: row {j}, column {i}, "
                                    f"{kind}); texels are refused, never clamped")


def direction_to_uv(d: np.ndarray, rotation: np.ndarray | None = None):
    """NumPy (u, v) of world directions ``d`` (..., 3) under ``rotation`` (map -> world)."""
    d = np.asarray(d, float)
    if rotation is not None:
        d = d @ np.asarray(rotation, float)  # R^T d for row vectors
    u = np.mod(np.arctan2(d[..., 0], -d[..., 2]) / (2 * np.pi), 1.0)
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    return u, v


def uv_to_direction(u, v) -> np.ndarray:
    u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
    st = np.sin(np.pi * v)
    return np.stack([np.sin(2 * np.pi * u) * st, np.cos(np.pi * v), -np.cos(2 * np.pi * u) * st], -1)


def lookup_numpy(image: np.ndarray, u, v) -> np.ndarray:
    """Bilinear lookup of the conventions (reference implementation, float64)."""
    H, W = image.shape[:2]
    u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
    x = u * W - 0.5
    y = np.clip(v * (H - 1), 0.0, H - 1)
    x0 = np.floor(x)
    fx = (x - x0)[..., None]
    x0 = x0.astype(np.int64) % W
    x1 = (x0 + 1) % W
    y0 = np.clip(np.floor(y).astype(np.int64), 0, H - 1)
    y1 = np.minimum(y0 + 1, H - 1)
    fy = (y - np.floor(y))[..., None]
    img = image.astype(np.float64)
    top = img[y0, x0] * (1 - fx) + img[y0, x1] * fx
    bot = img[y1, x0] * (1 - fx) + img[y1, x1] * fx
    return top * (1 - fy) + bot * fy


def luminance_of(image: np.ndarray) -> np.ndarray:
    """(H, W) float64 Rec.709 luminance of an (H, W, 3) image, negative values clamped to 0."""
    return np.maximum(np.asarray(image, np.float64) @ LUMINANCE, 0.0)


def lookup_luminance_numpy(lum: np.ndarray, u, v) -> np.ndarray:
    """Bilinear lookup (conventions) of a scalar (H, W) map at (u, v), float64."""
    return lookup_numpy(np.asarray(lum, np.float64)[..., None], u, v)[..., 0]


def row_geometry(H: int):
    """(a, b) of the H - 1 row intervals: interval j spans v = (j + t) / (H - 1), t in [0, 1],
    where sin(pi v) = sin(a[j] + b t)."""
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


def _mip_levels(level0: np.ndarray) -> list:
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


def build_env_distribution(image: np.ndarray, rotation=None, *, _scheme: int | None = None) -> EnvData:
    """The importance-sampling distribution of an (H, W, 3) lat-long map (``H >= 2``), see the
    module docstring. ``_scheme`` (private, benchmarks and tests): one of ``SCHEME_*``."""
    scheme = DEFAULT_SCHEME if _scheme is None else int(_scheme)
    if scheme not in SCHEME_NAMES.values():
        raise ValueError(f"unknown environment sampling scheme {scheme}")
    H, W = image.shape[:2]
    if H < 2:
        raise ValueError("an environment map needs at least 2 rows")
    lum = luminance_of(image)
    if not np.all(np.isfinite(lum)):
        raise ValueError("environment map holds non-finite values")
    rot = np.eye(3) if rotation is None else np.asarray(rotation, float)
    img32 = np.ascontiguousarray(image, np.float32)
    if scheme == SCHEME_PIECEWISE_CONSTANT:
        pc, total = _piecewise_constant(lum)
        return EnvData(image=img32, rotation=rot, lum=lum, total=total, scheme=scheme, pc=pc)
    K0, K1 = patch_row_moments(H)
    lc = 0.5 * (lum + np.roll(lum, -1, axis=1))          # (H, W) patch-column means per row
    patch = (K0[:, None] * lc[:-1] + K1[:, None] * lc[1:]) / ((H - 1) * W)  # (H-1, W) masses
    total = float(patch.sum())
    if not np.isfinite(total):
        raise ValueError("environment map holds non-finite values")
    env = EnvData(image=img32, rotation=rot, lum=lum, total=total, scheme=scheme)
    norm = total if total > 0 else 1.0
    if scheme == SCHEME_MARGINAL:
        rows = patch.sum(axis=1)
        cdf = np.concatenate([[0.0], np.cumsum(rows)]) / norm
        if total > 0:
            cdf[-1] = 1.0
        else:
            cdf = np.linspace(0.0, 1.0, H)
        env.row_cdf = cdf
        env.col_prefix = np.concatenate([np.zeros((H, 1)), np.cumsum(lc, axis=1)], axis=1)
    else:
        env.mip = _mip_levels(patch / norm)
    return env


def _piecewise_constant(lum: np.ndarray):
    """The sampler before issue 21: one cell per texel (rows' cells centred on the texel's
    v = r / (H - 1), half cells at the poles), weight = exact cell mean of the lookup's luminance
    times the cell's solid angle, v drawn ~ sin(pi v) in a cell: piecewise constant in solid
    angle."""
    H, W = lum.shape
    lum_x = 0.75 * lum + 0.125 * (np.roll(lum, 1, axis=1) + np.roll(lum, -1, axis=1))
    mean = np.empty_like(lum_x)
    mean[1:-1] = 0.75 * lum_x[1:-1] + 0.125 * (lum_x[:-2] + lum_x[2:])
    mean[0] = 0.75 * lum_x[0] + 0.25 * lum_x[1]
    mean[-1] = 0.75 * lum_x[-1] + 0.25 * lum_x[-2]
    omega = cell_solid_angles(H, W)
    w = mean * omega[:, None]
    total = float(w.sum())
    rows = w.sum(axis=1)
    if total > 0:
        pdf = mean / total
        marg = np.concatenate([[0.0], np.cumsum(rows) / total])
        cond = np.zeros((H, W + 1))
        nz = rows > 0
        cond[nz, 1:] = np.cumsum(w[nz], axis=1) / rows[nz, None]
        cond[~nz, 1:] = np.arange(1, W + 1) / W
        cond[:, -1] = 1.0
        marg[-1] = 1.0
    else:
        pdf = np.zeros((H, W))
        marg = np.linspace(0, 1, H + 1)
        cond = np.tile(np.linspace(0, 1, W + 1), (H, 1))
    # (its total is the solid-angle integral; report Z in the (u, v) units of the other schemes)
    return dict(pdf=pdf, marginal_cdf=marg, conditional_cdf=cond), total / (2 * np.pi ** 2)


def row_bounds(H: int):
    """Piecewise-constant scheme: per-row v extent of the cells, (v0, v1) arrays of shape (H,)."""
    r = np.arange(H)
    v0 = np.clip((r - 0.5) / (H - 1), 0.0, 1.0)
    v1 = np.clip((r + 0.5) / (H - 1), 0.0, 1.0)
    return v0, v1


def cell_solid_angles(H: int, W: int) -> np.ndarray:
    """Piecewise-constant scheme: solid angle of each row's cells, shape (H,)."""
    v0, v1 = row_bounds(H)
    return 2 * np.pi / W * (np.cos(np.pi * v0) - np.cos(np.pi * v1))


def env_pdf_numpy(env: EnvData, d: np.ndarray) -> np.ndarray:
    """Solid-angle pdf (1/sr) of world directions ``d`` (..., 3) (float64 reference of
    :func:`env_pdf`)."""
    u, v = direction_to_uv(d, env.rotation)
    if env.total <= 0:
        return np.zeros(np.shape(u))
    if env.scheme == SCHEME_PIECEWISE_CONSTANT:
        H, W = env.lum.shape
        c = np.clip(np.floor(u * W).astype(np.int64), 0, W - 1)
        r = np.clip(np.floor(v * (H - 1) + 0.5).astype(np.int64), 0, H - 1)
        return env.pc["pdf"][r, c]
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


def _uv_from_patch(env: EnvData, j, c, t, s):
    H, W = env.lum.shape
    u = np.mod((c + s + 0.5) / W, 1.0)
    v = (j + t) / (H - 1)
    return u, v


def env_sample_numpy(env: EnvData, xi: np.ndarray):
    """float64 reference of :func:`env_sample` for the marginal and hierarchical schemes:
    uniforms ``xi`` (N, 2) -> (world directions (N, 3), pdf (N,))."""
    xi = np.asarray(xi, np.float64)
    H, W = env.lum.shape
    L = env.lum
    a_all, b = row_geometry(H)
    if env.scheme == SCHEME_MARGINAL:
        y0 = np.minimum(xi[:, 0], 1.0 - 2.0 ** -53)
        j = np.clip(np.searchsorted(env.row_cdf, y0, side="right") - 1, 0, H - 2)
        c0, c1 = env.row_cdf[j], env.row_cdf[j + 1]
        yt = np.clip((y0 - c0) / np.maximum(c1 - c0, 1e-300), 0.0, 1.0)
        P = env.col_prefix
        t = solve_row_fraction_numpy(P[j, W], P[j + 1, W], a_all[j], b, yt)
        tot = (1 - t) * P[j, W] + t * P[j + 1, W]
        T = np.minimum(xi[:, 1], 1.0 - 2.0 ** -53) * tot
        lo = np.zeros(len(xi), np.int64)
        hi = np.full(len(xi), W, np.int64)
        while np.any(hi - lo > 1):
            mid = (lo + hi) // 2
            val = (1 - t) * P[j, mid] + t * P[j + 1, mid]
            go = (val <= T) & (hi - lo > 1)
            stay = (val > T) & (hi - lo > 1)
            lo = np.where(go, mid, lo)
            hi = np.where(stay, mid, hi)
        c = lo
        rest = T - ((1 - t) * P[j, c] + t * P[j + 1, c])
        c1 = (c + 1) % W
        g0 = (1 - t) * L[j, c] + t * L[j + 1, c]
        g1 = (1 - t) * L[j, c1] + t * L[j + 1, c1]
        half = 0.5 * (g0 + g1)
        ys = np.clip(rest / np.where(half > 0, half, 1.0), 0.0, 1.0)
        s = linear_inverse_numpy(g0, g1, ys)
    elif env.scheme == SCHEME_HIERARCHICAL:
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
    else:
        raise NotImplementedError("env_sample_numpy: the piecewise-constant scheme has no NumPy sampler")
    u, v = _uv_from_patch(env, j, c, t, s)
    d = uv_to_direction(u, v) @ np.asarray(env.rotation, float).T
    return d, env_pdf_numpy(env, d)


def constant_image(radiance) -> np.ndarray:
    return np.tile(np.asarray(radiance, np.float32), (4, 8, 1))


def sky_image(width=512, height=256, sun_elevation=35.0, sun_azimuth=135.0) -> np.ndarray:
    """A simple procedural sky: blue gradient, warm horizon, grey ground and a soft sun."""
    H, W = int(height), int(width)
    u = (np.arange(W) + 0.5) / W
    v = np.arange(H) / (H - 1)
    d = uv_to_direction(u[None, :], v[:, None])
    y = d[..., 1]
    t = np.clip(y, 0, 1) ** 0.5
    zenith = np.array([0.20, 0.38, 0.85])
    horizon = np.array([0.95, 0.95, 1.0])
    ground = np.array([0.28, 0.25, 0.22])
    sky = horizon * (1 - t[..., None]) + zenith * t[..., None]
    g = np.clip(-y / 0.05, 0, 1)[..., None]
    img = sky * (1 - g) + ground * g
    el, az = np.radians(sun_elevation), np.radians(sun_azimuth)
    sdir = uv_to_direction(az / (2 * np.pi), (0.5 * np.pi - el) / np.pi)
    ang = np.arccos(np.clip(d @ sdir, -1, 1))
    sigma = np.radians(2.0)
    sun = 400.0 * np.exp(-0.5 * (ang / sigma) ** 2)
    img = img + sun[..., None] * np.array([1.0, 0.92, 0.8])
    return img.astype(np.float32)


def environment_image(light, file="<scene>", key="lights") -> np.ndarray:
    """(H, W, 3) float32 radiance of an environment light (its texels times its ``scale``);
    texels are checked (:func:`check_texels`): a map with NaN, infinite or negative texels is
    refused, not repaired."""
    if light.image is not None:
        img = np.asarray(light.image, np.float32)
        if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 2:
            raise SceneError(file, key, f"in-memory environment image: expected (H >= 2, W, 3), got {img.shape}")
        check_texels(img, file, key, "in-memory environment image")
    elif light.type == "envmap":
        img = read_latlong(light.file, file, f"{key}.file")
    elif light.type == "constant":
        img = constant_image(light.radiance)
    else:
        img = sky_image(light.resolution[0], light.resolution[1], light.sun_elevation, light.sun_azimuth)
    scale = float(light.scale) if light.type != "constant" else 1.0
    if not (np.isfinite(scale) and 0.0 <= scale <= limits.MAX_ENV_SCALE):
        raise SceneError(file, f"{key}.scale", f"expected a number in [0, {limits.MAX_ENV_SCALE:g}], got {scale!r}")
    return (img * np.float32(scale)).astype(np.float32)


def _f64(a) -> np.ndarray:
    return np.ascontiguousarray(a, np.float64)


def _block_layout(m: np.ndarray) -> np.ndarray:
    """An (h, w) level, zero-padded to even sizes, as (h/2, w/2, 4) blocks of its 2 x 2 cells
    (v00, v10, v01, v11), so that one hierarchical step reads 4 consecutive values."""
    h, w = m.shape
    p = np.zeros((h + (h & 1), w + (w & 1)))
    p[:h, :w] = m
    return p.reshape(p.shape[0] // 2, 2, p.shape[1] // 2, 2).transpose(0, 2, 1, 3).reshape(p.shape[0] // 2, p.shape[1] // 2, 4)


def make_env_struct(env: EnvData | None, device) -> EnvMap:
    """The Warp struct of ``env`` (None: no environment). Arrays a scheme does not use hold one
    element."""
    s = EnvMap()
    if env is None:
        img = np.zeros((2, 2, 3), np.float32)
        env = build_env_distribution(img)
        s.present = 0
    else:
        s.present = 1
    H, W = env.image.shape[:2]
    s.texels = wp.array(env.image, dtype=wp.vec3, device=device)
    s.lum = wp.array(env.lum.astype(np.float32), dtype=float, device=device)
    s.pdf_scale = float(env.pdf_scale)
    s.scheme = int(env.scheme)
    a, b = row_geometry(H)
    i0, i1 = sin_integrals(a, b, 1.0)
    s.row_trig = wp.array(_f64(np.stack([np.sin(a), np.cos(a), np.sin(a + b), i0, i1], axis=1)),
                          dtype=wp.float64, device=device)
    one64 = np.zeros(1)
    s.row_cdf = wp.array(_f64(env.row_cdf if env.row_cdf is not None else one64), dtype=wp.float64, device=device)
    s.col_prefix = wp.array(_f64(env.col_prefix if env.col_prefix is not None else np.zeros((1, 1))),
                            dtype=wp.float64, device=device)
    # level 0 (the patch masses) is not stored: the sampler computes the 4 candidates from ``lum``
    # (which it reads for the chosen patch anyway), so the pyramid is 1/4 of the patches, float32
    levels = env.mip if env.mip is not None else [np.zeros((1, 1))]
    blocks = [_block_layout(m) for m in levels[1:]] or [np.zeros((1, 1, 4))]
    sizes = np.array([b.size for b in blocks])
    s.mip = wp.array(np.concatenate([b.ravel() for b in blocks]).astype(np.float32), dtype=float, device=device)
    s.mip_offset = wp.array(np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int32), dtype=int, device=device)
    s.mip_blocks_x = wp.array(np.array([b.shape[1] for b in blocks], np.int32), dtype=int, device=device)
    s.levels = len(levels)
    pc = env.pc or dict(pdf=np.zeros((1, 1)), marginal_cdf=np.zeros(1), conditional_cdf=np.zeros((1, 1)))
    s.pc_pdf = wp.array(pc["pdf"].astype(np.float32), dtype=float, device=device)
    s.pc_marginal = wp.array(pc["marginal_cdf"].astype(np.float32), dtype=float, device=device)
    s.pc_conditional = wp.array(pc["conditional_cdf"].astype(np.float32), dtype=float, device=device)
    s.rot = wp.mat33(*np.asarray(env.rotation, np.float32).ravel())
    s.width, s.height = W, H
    s.can_sample = 1 if (env.total > 0 and s.present) else 0
    return s


def make_directional_struct(dirs: np.ndarray, irr: np.ndarray, device) -> Directional:
    s = Directional()
    n = len(dirs)
    if n == 0:
        dirs = np.zeros((1, 3), np.float32)
        irr = np.zeros((1, 3), np.float32)
    s.to_light = wp.array(np.asarray(dirs, np.float32), dtype=wp.vec3, device=device)
    s.irradiance = wp.array(np.asarray(irr, np.float32), dtype=wp.vec3, device=device)
    s.count = n
    return s


# --------------------------------------------------------------------------------------------
# Warp side
@wp.func
def env_dir_to_uv(env: EnvMap, d: wp.vec3) -> wp.vec2:
    dl = wp.transpose(env.rot) * d
    u = fmath.atan2(dl[0], -dl[2]) * (0.5 / wp.pi)
    if u < 0.0:
        u = u + 1.0
    if u >= 1.0:
        u = u - 1.0
    # acos(y) as atan2(|(x, z)|, y): inline (no libm call) and accurate at the poles
    v = fmath.atan2(wp.sqrt(dl[0] * dl[0] + dl[2] * dl[2]), dl[1]) * (1.0 / wp.pi)
    return wp.vec2(u, v)


@wp.struct
class BilinearTaps:
    """The four texels and weights of the conventions' bilinear lookup at (u, v): columns
    ``x0``, ``x1`` (wrapping), rows ``y0``, ``y1`` (clamped), weights ``fx``, ``fy`` of the
    second column / row."""
    x0: int
    x1: int
    y0: int
    y1: int
    fx: float
    fy: float


@wp.func
def _next_column(c: int, W: int) -> int:
    """(c + 1) mod W for c in [0, W - 1], without an integer division (a division's latency
    sits on the address of every tap)."""
    return wp.where(c + 1 >= W, 0, c + 1)


@wp.func
def bilinear_taps(env: EnvMap, u: float, v: float) -> BilinearTaps:
    """Texels of the lookup at (u, v) in [0, 1]^2 (rows are not texel-centred: v = 0 and 1 are
    the first and last rows)."""
    W = env.width
    H = env.height
    x = u * float(W) - 0.5
    y = wp.clamp(v * float(H - 1), 0.0, float(H - 1))
    xf = wp.floor(x)
    t = BilinearTaps()
    t.fx = x - xf
    # wrap without an integer division (x0 is in [-1, W - 1] for u in [0, 1]; the clamp keeps a
    # NaN direction's index inside the map)
    x0 = int(xf)
    if x0 < 0:
        x0 = x0 + W
    if x0 >= W:
        x0 = x0 - W
    x0 = wp.clamp(x0, 0, W - 1)
    t.x0 = x0
    t.x1 = _next_column(x0, W)
    yf = wp.floor(y)
    t.fy = y - yf
    t.y0 = wp.clamp(int(yf), 0, H - 1)
    t.y1 = wp.min(t.y0 + 1, H - 1)
    return t


@wp.func
def env_lookup_uv(env: EnvMap, u: float, v: float) -> wp.vec3:
    t = bilinear_taps(env, u, v)
    top = env.texels[t.y0, t.x0] * (1.0 - t.fx) + env.texels[t.y0, t.x1] * t.fx
    bot = env.texels[t.y1, t.x0] * (1.0 - t.fx) + env.texels[t.y1, t.x1] * t.fx
    return top * (1.0 - t.fy) + bot * t.fy


@wp.func
def env_eval_uv(env: EnvMap, uv: wp.vec2) -> wp.vec3:
    """:func:`env_eval` at the map coordinates ``uv`` (:func:`env_dir_to_uv`) of a direction."""
    if env.present == 0:
        return wp.vec3(0.0)
    return env_lookup_uv(env, uv[0], uv[1])


@wp.func
def env_eval(env: EnvMap, d: wp.vec3) -> wp.vec3:
    """Radiance arriving from world direction ``d`` (pointing out to the environment)."""
    if env.present == 0:
        return wp.vec3(0.0)
    return env_eval_uv(env, env_dir_to_uv(env, d))


@wp.func
def env_lookup_lum(env: EnvMap, u: float, v: float) -> float:
    """Bilinear lookup of the luminance map (the same weights as :func:`env_lookup_uv`)."""
    t = bilinear_taps(env, u, v)
    top = env.lum[t.y0, t.x0] * (1.0 - t.fx) + env.lum[t.y0, t.x1] * t.fx
    bot = env.lum[t.y1, t.x0] * (1.0 - t.fx) + env.lum[t.y1, t.x1] * t.fx
    return top * (1.0 - t.fy) + bot * t.fy


@wp.func
def _pc_pdf(env: EnvMap, uv: wp.vec2) -> float:
    c = wp.clamp(int(uv[0] * float(env.width)), 0, env.width - 1)
    r = wp.clamp(int(wp.floor(uv[1] * float(env.height - 1) + 0.5)), 0, env.height - 1)
    return env.pc_pdf[r, c]


@wp.func
def env_pdf_uv(env: EnvMap, uv: wp.vec2) -> float:
    """:func:`env_pdf` at the map coordinates ``uv`` (:func:`env_dir_to_uv`) of a direction."""
    if env.can_sample == 0:
        return 0.0
    if env.scheme == SCHEME_PIECEWISE_CONSTANT:
        return _pc_pdf(env, uv)
    return env_lookup_lum(env, uv[0], uv[1]) * env.pdf_scale


@wp.func
def env_pdf(env: EnvMap, d: wp.vec3) -> float:
    """Solid-angle density (1/sr) of :func:`env_sample` for world direction ``d``."""
    if env.can_sample == 0:
        return 0.0
    return env_pdf_uv(env, env_dir_to_uv(env, d))


# --- inversion inside a patch (float64) -------------------------------------------------------
@wp.func
def _linear_inverse(g0: wp.float64, g1: wp.float64, y: wp.float64) -> wp.float64:
    """s in [0, 1] with integral_0^s ((1 - r) g0 + r g1) dr = y (g0 + g1) / 2."""
    one = wp.float64(1.0)
    zero = wp.float64(0.0)
    den = g0 + wp.sqrt(g0 * g0 * (one - y) + g1 * g1 * y)
    s = y
    if den > zero:
        s = y * (g0 + g1) / den
    return wp.clamp(s, zero, one)


@wp.func
def _row_cdf_density(A0: wp.float64, dA: wp.float64, sa: wp.float64, ca: wp.float64, b: wp.float64,
                     t: wp.float64) -> wp.vec2d:
    """(F(t), F'(t)) for F(t) = integral_0^t (A0 + dA s) sin(a + b s) ds, sa = sin a, ca = cos a:
    two float64 trig calls (the forms of :func:`sin_integrals`)."""
    two = wp.float64(2.0)
    h = wp.float64(0.5) * b * t
    sh = wp.sin(h)
    ch = wp.cos(h)
    s2 = two * sh * sh                    # 1 - cos(b t)
    sbt = two * sh * ch                   # sin(b t)
    cbt = wp.float64(1.0) - s2
    i0 = (ca * s2 + sa * sbt) / b         # cos a - cos(a + b t)  over b
    i1 = ((ca * sbt - sa * s2) / b - t * (ca * cbt - sa * sbt)) / b
    return wp.vec2d(A0 * i0 + dA * i1, (A0 + dA * t) * (sa * cbt + ca * sbt))


@wp.func
def _solve_row_fraction(A0: wp.float64, A1: wp.float64, env: EnvMap, j: int, y: wp.float64) -> wp.float64:
    """t in [0, 1] with F(t) = y F(1), F(t) = integral_0^t ((1 - s) A0 + s A1) sin(a + b s) ds on
    row interval ``j`` (``env.row_trig[j]`` = sin a, cos a, sin(a + b), I0(1), I1(1)): Newton on
    the cubic CDF of the density with sin replaced by its chord (no trig; the chord is within
    b^2/8 = 5e-6 of sin for a 512-row map; t within 1e-6), then bracketed Newton on the exact F
    (usually one step) -- the root of :func:`solve_row_fraction_numpy`."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    half = wp.float64(0.5)
    third = wp.float64(1.0 / 3.0)
    b = wp.float64(3.141592653589793) / wp.float64(env.height - 1)
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
    t = _linear_inverse(A0 * sa, A1 * env.row_trig[j, 2], y)
    for _ in range(4):
        q = t * (c1 + t * (c2 + t * c3)) - qt
        dq = c1 + t * (wp.float64(2.0) * c2 + t * wp.float64(3.0) * c3)
        if dq > zero:
            t = wp.clamp(t - q / dq, zero, one)
    # 2. the exact F, bracketed
    lo = zero
    hi = one
    for _ in range(NEWTON_ITERATIONS):
        fd = _row_cdf_density(A0, dA, sa, ca, b, t)
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
    return wp.clamp(t, zero, one)


@wp.func
def _search_f64(cdf: wp.array(dtype=wp.float64), n: int, x: wp.float64) -> int:
    """The last i in [0, n - 1] with cdf[i] <= x (binary search)."""
    lo = int(0)
    hi = n
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if cdf[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@wp.func
def _split(s: wp.float64, m0: wp.float64, m1: wp.float64) -> wp.vec2d:
    """Hierarchical step: (branch 0 or 1, s rescaled to [0, 1] inside it) for masses m0, m1."""
    zero = wp.float64(0.0)
    s = wp.clamp(s, zero, wp.float64(1.0)) * (m0 + m1)
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
    cn = _next_column(c, env.width)
    k1 = env.row_trig[j, 4]
    k0 = env.row_trig[j, 3] - k1
    return (k0 * wp.float64(env.lum[j, c] + env.lum[j, cn])
            + k1 * wp.float64(env.lum[j + 1, c] + env.lum[j + 1, cn]))


@wp.func
def _sample_patch_uv(env: EnvMap, xi: wp.vec2) -> wp.vec3d:
    """(u, v, lum) of a sample of the marginal or hierarchical scheme, float64: its map
    coordinates and the bilinear luminance there (the lookup's own taps: the patch's four
    texels with weights from the fractions ``t``, ``s``), so the pdf needs no second lookup."""
    H = env.height
    W = env.width
    one = wp.float64(1.0)
    zero = wp.float64(0.0)
    j = int(0)
    c = int(0)
    t = zero
    s = zero
    lum = zero
    y0 = wp.min(wp.float64(xi[0]), wp.float64(0.9999999999999999))
    y1 = wp.min(wp.float64(xi[1]), wp.float64(0.9999999999999999))
    if env.scheme == SCHEME_MARGINAL:
        j = _search_f64(env.row_cdf, H - 1, y0)
        c0 = env.row_cdf[j]
        c1 = env.row_cdf[j + 1]
        yt = zero
        if c1 > c0:
            yt = wp.clamp((y0 - c0) / (c1 - c0), zero, one)
        R0 = env.col_prefix[j, W]
        R1 = env.col_prefix[j + 1, W]
        t = _solve_row_fraction(R0, R1, env, j, yt)
        T = y1 * ((one - t) * R0 + t * R1)
        lo = int(0)
        hi = W
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if (one - t) * env.col_prefix[j, mid] + t * env.col_prefix[j + 1, mid] <= T:
                lo = mid
            else:
                hi = mid
        c = lo
        rest = T - ((one - t) * env.col_prefix[j, c] + t * env.col_prefix[j + 1, c])
        cn = _next_column(c, W)
        g0 = (one - t) * wp.float64(env.lum[j, c]) + t * wp.float64(env.lum[j + 1, c])
        g1 = (one - t) * wp.float64(env.lum[j, cn]) + t * wp.float64(env.lum[j + 1, cn])
        half = wp.float64(0.5) * (g0 + g1)
        ys = zero
        if half > zero:
            ys = wp.clamp(rest / half, zero, one)
        s = _linear_inverse(g0, g1, ys)
        lum = (one - s) * g0 + s * g1
    else:
        # levels >= 1: each stores its 2 x 2 children blocks contiguously (v00, v10, v01, v11)
        sx = y1
        sy = y0
        x = int(0)
        y = int(0)
        level = env.levels - 2
        while level >= 1:
            k = env.mip_offset[level - 1] + 4 * (y * env.mip_blocks_x[level - 1] + x)
            v00 = wp.float64(env.mip[k])
            v10 = wp.float64(env.mip[k + 1])
            v01 = wp.float64(env.mip[k + 2])
            v11 = wp.float64(env.mip[k + 3])
            ry = _split(sy, v00 + v10, v01 + v11)
            sy = ry[1]
            ca = v00
            cb = v10
            y = 2 * y
            if ry[0] > wp.float64(0.5):
                y = y + 1
                ca = v01
                cb = v11
            rx = _split(sx, ca, cb)
            sx = rx[1]
            x = 2 * x
            if rx[0] > wp.float64(0.5):
                x = x + 1
            level = level - 1
        # level 0: the four patches under (x, y), their masses from the texels
        y = 2 * y
        x = 2 * x
        p00 = _patch_mass(env, y, x)
        p10 = _patch_mass(env, y, x + 1)
        p01 = _patch_mass(env, y + 1, x)
        p11 = _patch_mass(env, y + 1, x + 1)
        ry = _split(sy, p00 + p10, p01 + p11)
        sy = ry[1]
        ca = p00
        cb = p10
        if ry[0] > wp.float64(0.5):
            y = y + 1
            ca = p01
            cb = p11
        rx = _split(sx, ca, cb)
        sx = rx[1]
        if rx[0] > wp.float64(0.5):
            x = x + 1
        j = y
        c = x
        cn = _next_column(c, W)
        L00 = wp.float64(env.lum[j, c])
        L10 = wp.float64(env.lum[j, cn])
        L01 = wp.float64(env.lum[j + 1, c])
        L11 = wp.float64(env.lum[j + 1, cn])
        t = _solve_row_fraction(L00 + L10, L01 + L11, env, j, sy)
        g0 = (one - t) * L00 + t * L01
        g1 = (one - t) * L10 + t * L11
        s = _linear_inverse(g0, g1, sx)
        lum = (one - s) * g0 + s * g1
    u = (wp.float64(c) + s + wp.float64(0.5)) / wp.float64(W)
    if u >= one:
        u = u - one
    v = (wp.float64(j) + t) / wp.float64(H - 1)
    return wp.vec3d(u, v, lum)


# --- the piecewise-constant scheme (before issue 21; benchmarks only) -------------------------
@wp.func
def _upper_bound_1d(cdf: wp.array(dtype=float), n: int, x: float) -> int:
    lo = int(0)
    hi = n
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if cdf[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@wp.func
def _upper_bound_row(cdf: wp.array2d(dtype=float), row: int, n: int, x: float) -> int:
    lo = int(0)
    hi = n
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if cdf[row, mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@wp.func
def _pc_sample_local(env: EnvMap, xi: wp.vec2) -> wp.vec3:
    H = env.height
    W = env.width
    x0 = wp.min(xi[0], 0.99999994)
    r = _upper_bound_1d(env.pc_marginal, H, x0)
    c0 = env.pc_marginal[r]
    c1 = env.pc_marginal[r + 1]
    tv = wp.clamp((x0 - c0) / wp.max(c1 - c0, 1.0e-30), 0.0, 1.0)
    x1 = wp.min(xi[1], 0.99999994)
    c = _upper_bound_row(env.pc_conditional, r, W, x1)
    d0 = env.pc_conditional[r, c]
    d1 = env.pc_conditional[r, c + 1]
    tu = wp.clamp((x1 - d0) / wp.max(d1 - d0, 1.0e-30), 0.0, 1.0)
    u = (float(c) + tu) / float(W)
    inv = 1.0 / float(H - 1)
    va = wp.clamp((float(r) - 0.5) * inv, 0.0, 1.0)
    vb = wp.clamp((float(r) + 0.5) * inv, 0.0, 1.0)
    ca = wp.cos(wp.pi * va)
    cb = wp.cos(wp.pi * vb)
    cos_t = wp.clamp(ca - tv * (ca - cb), -1.0, 1.0)   # v drawn with density ~ sin(pi v)
    sin_t = wp.sqrt(wp.max(0.0, 1.0 - cos_t * cos_t))
    phi = 2.0 * wp.pi * u
    return wp.vec3(wp.sin(phi) * sin_t, cos_t, -wp.cos(phi) * sin_t)


@wp.func
def env_sample_uv(env: EnvMap, xi: wp.vec2):
    """:func:`env_sample` and the map coordinates of the sampled point (``(vec4, vec2 uv)``),
    so its radiance (:func:`env_eval_uv`) needs no atan2. The pdf is the looked-up luminance
    at the sampled (u, v) itself (the taps the patch inversion read), not at the map
    coordinates recomputed from the float32 direction: radiance and pdf are taken at one point,
    and :func:`env_pdf` of the returned direction agrees to float rounding of the direction."""
    if env.can_sample == 0:
        return wp.vec4(0.0, 1.0, 0.0, 0.0), wp.vec2(0.0)
    if env.scheme == SCHEME_PIECEWISE_CONSTANT:
        dl = _pc_sample_local(env, xi)
        dw = env.rot * dl
        uvw = env_dir_to_uv(env, dw)
        return wp.vec4(dw[0], dw[1], dw[2], env_pdf_uv(env, uvw)), uvw
    uvl = _sample_patch_uv(env, xi)
    scp = fmath.sincos(2.0 * wp.pi * float(uvl[0]))
    sct = fmath.sincos(wp.pi * float(uvl[1]))
    st = sct[0]
    dw = env.rot * wp.vec3(scp[0] * st, sct[1], -scp[1] * st)
    pdf = float(uvl[2]) * env.pdf_scale
    return wp.vec4(dw[0], dw[1], dw[2], pdf), wp.vec2(float(uvl[0]), float(uvl[1]))


@wp.func
def env_sample(env: EnvMap, xi: wp.vec2) -> wp.vec4:
    """Importance-sample a world direction from uniforms ``xi`` in [0, 1)^2 (``xi[0]`` drives v,
    ``xi[1]`` u); returns (dx, dy, dz, pdf), pdf in 1/sr: the density at the sampled point, equal to
    ``env_pdf`` of the returned direction up to the float32 rounding of the direction (see
    :func:`env_sample_uv`); pdf = 0 if impossible. :func:`env_sample_uv` without the map coordinates."""
    s, _uv = env_sample_uv(env, xi)
    return s


# --------------------------------------------------------------------------------------------
# Debug/test kernels
@wp.kernel
def env_pdf_kernel(env: EnvMap, dirs: wp.array(dtype=wp.vec3), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = env_pdf(env, dirs[i])


@wp.kernel
def env_eval_kernel(env: EnvMap, dirs: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = env_eval(env, dirs[i])


@wp.kernel
def env_sample_kernel(env: EnvMap, xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec4)):
    i = wp.tid()
    out[i] = env_sample(env, xi[i])


@wp.kernel
def env_sample_patch_kernel(env: EnvMap, xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec4),
                            point: wp.array(dtype=wp.vec3d)):
    """:func:`env_sample` and the float64 (u, v, looked-up luminance) of the sampled point
    (marginal and hierarchical schemes)."""
    i = wp.tid()
    out[i] = env_sample(env, xi[i])
    point[i] = _sample_patch_uv(env, xi[i])
