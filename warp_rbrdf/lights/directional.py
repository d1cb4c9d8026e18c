"""Directional lights as the render kernels see them: the Warp struct ``Directional``."""
from __future__ import annotations

import numpy as np
import warp as wp


@wp.struct
class Directional:
    to_light: wp.array(dtype=wp.vec3)    # unit vectors towards the light
    irradiance: wp.array(dtype=wp.vec3)  # W/m^2 on a surface facing the light, RGB
    count: int


def make_directional_struct(dirs: np.ndarray, irr: np.ndarray, device) -> Directional:
    """The struct of ``count = len(dirs)`` lights: unit directions towards each light ``dirs``
    (n, 3) and irradiances ``irr`` (n, 3) (n = 0: one zero entry per array, ``count = 0``)."""
    s = Directional()
    n = len(dirs)
    if n == 0:
        dirs = np.zeros((1, 3), np.float32)
        irr = np.zeros((1, 3), np.float32)
    s.to_light = wp.array(np.asarray(dirs, np.float32), dtype=wp.vec3, device=device)
    s.irradiance = wp.array(np.asarray(irr, np.float32), dtype=wp.vec3, device=device)
    s.count = n
    return s
