"""Lights: directional lights and one environment (lat-long map, constant, or procedural sky).

Environment maps follow conventions.md exactly (Mitsuba 3 ``envmap``):

* world direction ``d`` -> map direction ``R^T d`` (``R`` = the light's rotation), then
  ``u = atan2(x, -z) / 2pi`` wrapped into [0, 1), ``v = acos(y) / pi``;
* bilinear lookup at ``x = u W - 0.5`` (periodic) and ``y = v (H - 1)`` (clamped): columns are
  texel-centred, rows are not (row 0 sits on the +Y pole).

Importance sampling (:func:`build_env_distribution`) uses one cell per texel, centred on the
texel's lookup position: column ``c`` covers ``u`` in [c/W, (c+1)/W]; row ``r`` covers
``v`` in [(r-1/2)/(H-1), (r+1/2)/(H-1)] clipped to [0, 1] (half cells at the poles). A cell's
weight is the *exact mean of the bilinear lookup's luminance over the cell* (in pixel
coordinates: the separable (1/8, 3/4, 1/8) stencil, (3/4, 1/4) at the poles) times the cell's
*solid angle*. Within a cell, ``u`` is uniform and ``v`` is drawn with density proportional to
``sin(pi v)``, i.e. the sin-theta Jacobian of the lat-long map is accounted for exactly and the
density is **piecewise constant in solid angle**: ``pdf(w) = mean_lum(cell) / sum(mean_lum * Omega)``.
It is positive wherever the lookup is positive, and a constant map gets the uniform density
1/(4 pi).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from .errors import SceneError

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@wp.struct
class EnvMap:
    texels: wp.array2d(dtype=wp.vec3)    # (H, W) radiance (scale applied)
    pdf: wp.array2d(dtype=float)         # (H, W) solid-angle density of each cell
    marginal_cdf: wp.array(dtype=float)  # (H + 1,)
    conditional_cdf: wp.array2d(dtype=float)  # (H, W + 1)
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
    image: np.ndarray           # (H, W, 3) float32 radiance
    rotation: np.ndarray        # (3, 3)
    pdf: np.ndarray             # (H, W)
    marginal_cdf: np.ndarray    # (H+1,)
    conditional_cdf: np.ndarray  # (H, W+1)
    total: float                # sum of weights (0: black map)


def read_latlong(path, file="<scene>", key="file") -> np.ndarray:
    """(H, W, 3) float32 linear RGB of an HDR/EXR lat-long map (OpenImageIO)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise SceneError(file, key, f"cannot open environment map {path} ({oiio.geterror()})")
    try:
        spec = inp.spec()
        px = inp.read_image(0, 0, 0, min(spec.nchannels, 3), oiio.FLOAT)
    finally:
        inp.close()
    if px is None:
        raise SceneError(file, key, f"cannot read environment map {path}")
    px = np.asarray(px, np.float32).reshape(spec.height, spec.width, -1)
    if px.shape[2] == 1:
        px = np.repeat(px, 3, axis=2)
    if spec.height < 2:
        raise SceneError(file, key, f"environment map {path} must have at least 2 rows")
    return np.ascontiguousarray(px[:, :, :3])


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


def row_bounds(H: int):
    """Per-row v extent of the sampling cells: (v0, v1) arrays of shape (H,)."""
    r = np.arange(H)
    v0 = np.clip((r - 0.5) / (H - 1), 0.0, 1.0)
    v1 = np.clip((r + 0.5) / (H - 1), 0.0, 1.0)
    return v0, v1


def cell_solid_angles(H: int, W: int) -> np.ndarray:
    """Solid angle of each row's cells, shape (H,): (2 pi / W) (cos pi v0 - cos pi v1)."""
    v0, v1 = row_bounds(H)
    return 2 * np.pi / W * (np.cos(np.pi * v0) - np.cos(np.pi * v1))


def build_env_distribution(image: np.ndarray, rotation=None) -> EnvData:
    H, W = image.shape[:2]
    lum = np.maximum(image.astype(np.float64) @ LUMINANCE, 0.0)
    # exact cell mean of the bilinear lookup (separable stencil), columns periodic
    lum_x = 0.75 * lum + 0.125 * (np.roll(lum, 1, axis=1) + np.roll(lum, -1, axis=1))
    mean = np.empty_like(lum_x)
    mean[1:-1] = 0.75 * lum_x[1:-1] + 0.125 * (lum_x[:-2] + lum_x[2:])
    mean[0] = 0.75 * lum_x[0] + 0.25 * lum_x[1]
    mean[-1] = 0.75 * lum_x[-1] + 0.25 * lum_x[-2]
    omega = cell_solid_angles(H, W)
    w = mean * omega[:, None]
    total = float(w.sum())
    if not np.isfinite(total):
        raise ValueError("environment map holds non-finite values")
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
    rot = np.eye(3) if rotation is None else np.asarray(rotation, float)
    return EnvData(image=np.ascontiguousarray(image, np.float32), rotation=rot, pdf=pdf,
                   marginal_cdf=marg, conditional_cdf=cond, total=total)


def env_pdf_numpy(env: EnvData, d: np.ndarray) -> np.ndarray:
    """Solid-angle pdf of world directions ``d`` (reference implementation)."""
    H, W = env.image.shape[:2]
    u, v = direction_to_uv(d, env.rotation)
    c = np.clip(np.floor(u * W).astype(np.int64), 0, W - 1)
    r = np.clip(np.floor(v * (H - 1) + 0.5).astype(np.int64), 0, H - 1)
    return env.pdf[r, c]


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
    if light.image is not None:
        img = np.asarray(light.image, np.float32)
    elif light.type == "envmap":
        img = read_latlong(light.file, file, f"{key}.file")
    elif light.type == "constant":
        img = constant_image(light.radiance)
    else:
        img = sky_image(light.resolution[0], light.resolution[1], light.sun_elevation, light.sun_azimuth)
    img = np.nan_to_num(np.maximum(img, 0.0), nan=0.0, posinf=0.0) * (light.scale if light.type != "constant" else 1.0)
    return img.astype(np.float32)


def make_env_struct(env: EnvData | None, device) -> EnvMap:
    s = EnvMap()
    if env is None:
        img = np.zeros((2, 2, 3), np.float32)
        env = build_env_distribution(img)
        s.present = 0
    else:
        s.present = 1
    H, W = env.image.shape[:2]
    s.texels = wp.array(env.image, dtype=wp.vec3, device=device)
    s.pdf = wp.array(env.pdf.astype(np.float32), dtype=float, device=device)
    s.marginal_cdf = wp.array(env.marginal_cdf.astype(np.float32), dtype=float, device=device)
    s.conditional_cdf = wp.array(env.conditional_cdf.astype(np.float32), dtype=float, device=device)
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
    u = wp.atan2(dl[0], -dl[2]) * (0.5 / wp.pi)
    if u < 0.0:
        u = u + 1.0
    if u >= 1.0:
        u = u - 1.0
    v = wp.acos(wp.clamp(dl[1], -1.0, 1.0)) * (1.0 / wp.pi)
    return wp.vec2(u, v)


@wp.func
def env_lookup_uv(env: EnvMap, u: float, v: float) -> wp.vec3:
    W = env.width
    H = env.height
    x = u * float(W) - 0.5
    y = wp.clamp(v * float(H - 1), 0.0, float(H - 1))
    xf = wp.floor(x)
    fx = x - xf
    x0 = int(xf) % W
    if x0 < 0:
        x0 = x0 + W
    x1 = (x0 + 1) % W
    yf = wp.floor(y)
    fy = y - yf
    y0 = wp.clamp(int(yf), 0, H - 1)
    y1 = wp.min(y0 + 1, H - 1)
    top = env.texels[y0, x0] * (1.0 - fx) + env.texels[y0, x1] * fx
    bot = env.texels[y1, x0] * (1.0 - fx) + env.texels[y1, x1] * fx
    return top * (1.0 - fy) + bot * fy


@wp.func
def env_eval(env: EnvMap, d: wp.vec3) -> wp.vec3:
    """Radiance arriving from world direction ``d`` (pointing out to the environment)."""
    if env.present == 0:
        return wp.vec3(0.0)
    uv = env_dir_to_uv(env, d)
    return env_lookup_uv(env, uv[0], uv[1])


@wp.func
def env_pdf(env: EnvMap, d: wp.vec3) -> float:
    """Solid-angle density of :func:`env_sample` for world direction ``d``."""
    if env.can_sample == 0:
        return 0.0
    uv = env_dir_to_uv(env, d)
    c = wp.clamp(int(uv[0] * float(env.width)), 0, env.width - 1)
    r = wp.clamp(int(wp.floor(uv[1] * float(env.height - 1) + 0.5)), 0, env.height - 1)
    return env.pdf[r, c]


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
def env_sample(env: EnvMap, xi: wp.vec2) -> wp.vec4:
    """Importance-sample a world direction; returns (dx, dy, dz, pdf). pdf = 0 if impossible."""
    if env.can_sample == 0:
        return wp.vec4(0.0, 1.0, 0.0, 0.0)
    H = env.height
    W = env.width
    x0 = wp.min(xi[0], 0.99999994)
    r = _upper_bound_1d(env.marginal_cdf, H, x0)
    c0 = env.marginal_cdf[r]
    c1 = env.marginal_cdf[r + 1]
    tv = wp.clamp((x0 - c0) / wp.max(c1 - c0, 1.0e-30), 0.0, 1.0)
    x1 = wp.min(xi[1], 0.99999994)
    c = _upper_bound_row(env.conditional_cdf, r, W, x1)
    d0 = env.conditional_cdf[r, c]
    d1 = env.conditional_cdf[r, c + 1]
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
    dl = wp.vec3(wp.sin(phi) * sin_t, cos_t, -wp.cos(phi) * sin_t)
    pdf = env.pdf[r, c]
    dw = env.rot * dl
    return wp.vec4(dw[0], dw[1], dw[2], pdf)


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
