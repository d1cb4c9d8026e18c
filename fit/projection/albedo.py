"""Directional albedo by quadrature.

``albedo(theta_i) = integral over the upper hemisphere of rho(wi, wo) cos(theta_o) d wo``
(dimensionless, per channel). Midpoint rule in (theta_o, phi_o) over the whole azimuth range
[0, 2 pi): measured tables are not exactly mirror-symmetric about the plane of incidence (a
resampled RGL material differs by ~3 % between +phi and -phi), so no symmetry is assumed.
``evaluate`` is any function ``(wi (...,3), wo (...,3)) -> (..., C)``.
"""
from __future__ import annotations

import numpy as np

from ..formats.angles import spherical_to_direction


def directional_albedo(evaluate, theta_i: float, n_theta: int = 90, n_phi: int = 360) -> np.ndarray:
    """Albedo for light at ``theta_i`` (radians, phi_i = 0); returns shape (C,).

    ``n_theta`` x ``n_phi`` midpoint cells over theta_o in [0, pi/2], phi_o in [0, 2 pi).
    """
    t = (np.arange(n_theta) + 0.5) / n_theta * (0.5 * np.pi)
    p = (np.arange(n_phi) + 0.5) / n_phi * (2.0 * np.pi)
    tt, pp = np.meshgrid(t, p, indexing="ij")
    wo = spherical_to_direction(tt, pp)
    wi = spherical_to_direction(np.full_like(tt, theta_i), np.zeros_like(tt))
    f = np.asarray(evaluate(wi, wo), float)
    w = (np.cos(tt) * np.sin(tt))[..., None] * (0.5 * np.pi / n_theta) * (2.0 * np.pi / n_phi)
    return (f * w).sum(axis=(0, 1))
