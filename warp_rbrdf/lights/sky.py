"""The procedural sky of ``type = "sky"`` lights: a lat-long (H, W, 3) float32 radiance map."""
from __future__ import annotations

import numpy as np

from .latlong import uv_to_direction


def sky_image(width=512, height=256, sun_elevation=35.0, sun_azimuth=135.0) -> np.ndarray:
    """A simple procedural sky, (height, width, 3) float32 in the lat-long conventions: blue
    gradient, warm horizon, grey ground (below the horizon) and a soft sun (Gaussian, 2 degrees)
    at ``sun_elevation`` degrees above the horizon and ``sun_azimuth`` degrees (0 = -Z,
    90 = +X, the u convention)."""
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
