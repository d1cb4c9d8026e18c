"""The MERL-MIT (theta_h, theta_d, phi_d) grid: its sizes, bin centres and bin indices.

The MERL-MIT layout samples an isotropic BRDF on 90 x 90 x 180 bins:

* theta_h in [0, pi/2): bin ``i`` covers ``sqrt(theta_h / (pi/2)) * 90`` in ``[i, i+1)``
  (denser near the specular peak); bin centre ``((i + 0.5) / 90)**2 * pi/2``.
* theta_d in [0, pi/2): bin ``j`` covers ``theta_d / (pi/2) * 90`` in ``[j, j+1)``;
  centre ``(j + 0.5) / 90 * pi/2``.
* phi_d in [0, pi) (reciprocity folds phi_d and phi_d + pi together): bin ``k`` covers
  ``phi_d / pi * 180`` in ``[k, k+1)``; centre ``(k + 0.5) / 180 * pi``.

All angles are in radians (Rusinkiewicz angles, :mod:`fit.formats.angles`).
"""
from __future__ import annotations

import numpy as np

from .angles import HALF_PI

N_THETA_H = 90
N_THETA_D = 90
N_PHI_D = 180
MERL_SHAPE = (N_THETA_H, N_THETA_D, N_PHI_D)


def theta_h_centres() -> np.ndarray:
    """Bin centres of theta_h in radians, shape (90,)."""
    return ((np.arange(N_THETA_H) + 0.5) / N_THETA_H) ** 2 * HALF_PI


def theta_d_centres() -> np.ndarray:
    """Bin centres of theta_d in radians, shape (90,)."""
    return (np.arange(N_THETA_D) + 0.5) / N_THETA_D * HALF_PI


def phi_d_centres() -> np.ndarray:
    """Bin centres of phi_d in radians in [0, pi), shape (180,)."""
    return (np.arange(N_PHI_D) + 0.5) / N_PHI_D * np.pi


def theta_h_index(theta_h) -> np.ndarray:
    """MERL bin of theta_h (radians): ``floor(90 * sqrt(theta_h / (pi/2)))``, clamped."""
    t = np.clip(np.asarray(theta_h, float), 0.0, None)
    return np.clip(np.floor(np.sqrt(t / HALF_PI) * N_THETA_H), 0, N_THETA_H - 1).astype(np.intp)


def theta_d_index(theta_d) -> np.ndarray:
    """MERL bin of theta_d (radians): ``floor(theta_d / (pi/2) * 90)``, clamped."""
    t = np.asarray(theta_d, float)
    return np.clip(np.floor(t / HALF_PI * N_THETA_D), 0, N_THETA_D - 1).astype(np.intp)


def phi_d_index(phi_d) -> np.ndarray:
    """MERL bin of phi_d (radians), folded to [0, pi) by reciprocity, clamped."""
    p = np.mod(np.asarray(phi_d, float), np.pi)
    return np.clip(np.floor(p / np.pi * N_PHI_D), 0, N_PHI_D - 1).astype(np.intp)
