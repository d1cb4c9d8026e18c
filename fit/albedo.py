"""Directional albedo by quadrature.

``albedo(theta_i) = integral over the upper hemisphere of rho(wi, wo) cos(theta_o) d wo``
(dimensionless, per channel). Midpoint rule in (theta_o, phi_o); ``evaluate`` is any
function ``(wi (...,3), wo (...,3)) -> (..., C)``.
"""
from __future__ import annotations

import numpy as np

from .angles import spherical_to_direction


def directional_albedo(evaluate, theta_i: float, n_theta: int = 90, n_phi: int = 180) -> np.ndarray:
    """Albedo for light at ``theta_i`` (radians, phi_i = 0); returns shape (C,).

    Isotropy is used: phi_o in [0, pi] and the result doubled.
    """
    t = (np.arange(n_theta) + 0.5) / n_theta * (0.5 * np.pi)
    p = (np.arange(n_phi) + 0.5) / n_phi * np.pi
    tt, pp = np.meshgrid(t, p, indexing="ij")
    wo = spherical_to_direction(tt, pp)
    wi = spherical_to_direction(np.full_like(tt, theta_i), np.zeros_like(tt))
    f = np.asarray(evaluate(wi, wo), float)
    w = (np.cos(tt) * np.sin(tt))[..., None] * (0.5 * np.pi / n_theta) * (np.pi / n_phi) * 2.0
    return (f * w).sum(axis=(0, 1))
