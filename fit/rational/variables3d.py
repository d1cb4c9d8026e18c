"""The variables of a 3-D rational BRDF fit: Rusinkiewicz ``(theta_h, theta_d, phi_d)`` with
``phi_d`` folded by the mirror symmetry of isotropy, not by reciprocity.

An isotropic BRDF is unchanged when the pair (light, view) is mirrored in the plane of the
normal and the half vector: ``phi_d -> -phi_d`` (measured on the RGL files: median relative
difference 3e-8, 99th percentile 5e-5, i.e. interpolation noise). It is **not** unchanged under
``phi_d -> phi_d + pi`` (swapping light and view) unless it is reciprocal, and the RGL
measurements are not (median 2-19 % on the glossy films). So a 3-D fit reads

    theta_h in [0, pi/2],  theta_d in [0, pi/2],  phi_d = |phi_d| in [0, pi]       (radians)

with ``phi_d`` of :func:`fit.formats.angles.directions_to_half_diff` (in (-pi, pi], light =
``wi``), and keeps the measurement's own (light, view) roles. The renderer computes the same
fold (:mod:`warp_rbrdf.materials.rational`).
"""
from __future__ import annotations

import numpy as np

from ..formats.angles import directions_to_half_diff

#: Variable names of a 3-D BRDF fit, in order (coefficient file version 3).
VARIABLES_3D = ("theta_h", "theta_d", "phi_d")


def fold_phi_d(phi_d) -> np.ndarray:
    """``|phi_d|`` in [0, pi] (radians) of ``phi_d`` in (-pi, pi]."""
    return np.abs(np.asarray(phi_d, dtype=np.float64))


def half_diff_3d(wi, wo) -> np.ndarray:
    """``(theta_h, theta_d, |phi_d|)`` (radians), shape ``broadcast(...) + (3,)``, of local unit
    directions ``wi`` (towards the light) and ``wo`` (towards the viewer) ``(..., 3)``."""
    th, _, td, pd = directions_to_half_diff(np.asarray(wi, float), np.asarray(wo, float))
    th, td, pd = np.broadcast_arrays(th, td, fold_phi_d(pd))
    return np.stack([th, td, pd], axis=-1)


def evaluate_directions(model, wi, wo) -> np.ndarray:
    """rho (1/sr) ``(..., 3)`` of a 3-D model (variables :data:`VARIABLES_3D`) at direction
    pairs ``(..., 3)``; 0 where either direction is at or below the tangent plane."""
    wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
    out = np.asarray(model(half_diff_3d(wi, wo)), dtype=np.float64)
    above = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
    return np.where(above[..., None], out, 0.0)


def is_3d(model) -> bool:
    """Whether ``model`` is a 3-D BRDF fit (its variables are :data:`VARIABLES_3D`)."""
    return tuple(v.name for v in getattr(model, "variables", ())) == VARIABLES_3D
