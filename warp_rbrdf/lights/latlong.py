"""The lat-long conventions of environment maps (conventions.md; Mitsuba 3 ``envmap``), NumPy.

* world direction ``d`` -> map direction ``R^T d`` (``R`` = the light's rotation, map -> world),
  then ``u = atan2(x, -z) / 2pi`` wrapped into [0, 1), ``v = acos(y) / pi`` (v = 0: the +Y pole);
* bilinear lookup at ``x = u W - 0.5`` (periodic) and ``y = v (H - 1)`` (clamped): columns are
  texel-centred, rows are not (row 0 sits on the +Y pole, row H - 1 on the -Y pole).

These are the float64 references of the Warp lookup (:mod:`warp_rbrdf.lights.env_map`).
"""
from __future__ import annotations

import numpy as np

#: Rec.709 luminance weights of linear RGB
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def direction_to_uv(d: np.ndarray, rotation: np.ndarray | None = None):
    """(u, v) in [0, 1)^2 x [0, 1] of world directions ``d`` (..., 3) under ``rotation`` (3, 3),
    map -> world (None: identity); arrays of shape (...)."""
    d = np.asarray(d, float)
    if rotation is not None:
        d = d @ np.asarray(rotation, float)  # R^T d for row vectors
    u = np.mod(np.arctan2(d[..., 0], -d[..., 2]) / (2 * np.pi), 1.0)
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / np.pi
    return u, v


def uv_to_direction(u, v) -> np.ndarray:
    """Unit map directions (..., 3) of map coordinates ``u``, ``v`` (broadcast)."""
    u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
    st = np.sin(np.pi * v)
    return np.stack([np.sin(2 * np.pi * u) * st, np.cos(np.pi * v), -np.cos(2 * np.pi * u) * st], -1)


def lookup_numpy(image: np.ndarray, u, v) -> np.ndarray:
    """Bilinear lookup of an (H, W, C) image at (u, v) (broadcast), float64, shape (..., C)."""
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
