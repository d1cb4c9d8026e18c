"""Directional albedo by quadrature.

``albedo(theta_i) = integral over the upper hemisphere of rho(wi, wo) cos(theta_o) d wo``
(dimensionless, per channel; light-fixed), or view-fixed ``albedo(theta_o) = integral of
rho(wi, wo) cos(theta_i) d wi`` (what a uniformly lit surface shows; the two are equal for a
reciprocal BRDF, such as a 2-D fit of (theta_h, theta_d), and differ for the non-reciprocal RGL
measurements). Midpoint rule in (theta_o, phi_o) over the whole azimuth range
[0, 2 pi): measured tables are not exactly mirror-symmetric about the plane of incidence (a
resampled RGL material differs by ~3 % between +phi and -phi), so no symmetry is assumed.
``evaluate`` is any function ``(wi (...,3), wo (...,3)) -> (..., C)``.
"""
from __future__ import annotations

import numpy as np

from ..formats.angles import spherical_to_direction


def directional_albedo(evaluate, theta_i: float, n_theta: int = 90, n_phi: int = 360,
                       fixed: str = "light") -> np.ndarray:
    """Albedo for light at ``theta_i`` (radians, phi_i = 0); returns shape (C,). ``fixed="view"``:
    the view-fixed albedo for the view at that angle (``theta_i`` is then the view's).

    ``n_theta`` x ``n_phi`` midpoint cells over the other direction's theta in [0, pi/2], phi in
    [0, 2 pi).
    """
    if fixed not in ("light", "view"):
        raise ValueError(f"fixed={fixed!r}: expected 'light' or 'view'")
    t = (np.arange(n_theta) + 0.5) / n_theta * (0.5 * np.pi)
    p = (np.arange(n_phi) + 0.5) / n_phi * (2.0 * np.pi)
    tt, pp = np.meshgrid(t, p, indexing="ij")
    wo = spherical_to_direction(tt, pp)
    wi = spherical_to_direction(np.full_like(tt, theta_i), np.zeros_like(tt))
    f = np.asarray(evaluate(wi, wo) if fixed == "light" else evaluate(wo, wi), float)
    w = (np.cos(tt) * np.sin(tt))[..., None] * (0.5 * np.pi / n_theta) * (2.0 * np.pi / n_phi)
    return (f * w).sum(axis=(0, 1))
