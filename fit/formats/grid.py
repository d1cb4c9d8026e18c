"""The MERL-MIT (theta_h, theta_d, phi_d) grid: its sizes, bin centres and bin indices.

The MERL-MIT layout samples an isotropic BRDF on 90 x 90 x 180 bins:

* theta_h in [0, pi/2): bin ``i`` covers ``sqrt(theta_h / (pi/2)) * 90`` in ``[i, i+1)``
  (denser near the specular peak); bin centre ``((i + 0.5) / 90)**2 * pi/2``.
* theta_d in [0, pi/2): bin ``j`` covers ``theta_d / (pi/2) * 90`` in ``[j, j+1)``;
  centre ``(j + 0.5) / 90 * pi/2``.
* phi_d: bins of one degree, ``k`` covers ``phi_d / pi * 180`` in ``[k, k+1)``, centre
  ``(k + 0.5) / 180 * pi``, over one of two ranges (``n_phi_d``, the number of phi_d bins):

  - ``n_phi_d = 180`` (:data:`N_PHI_D`, the MERL files): phi_d in [0, pi). Swapping the light
    and the view maps phi_d to phi_d + pi, so reciprocity folds phi_d and phi_d + pi into
    one bin; the MERL format defines this fold.
  - ``n_phi_d = 360`` (:data:`N_PHI_D_FULL`, data from a *non-reciprocal* source such as an
    RGL-EPFL file): phi_d in [0, 2 pi), no fold; (wi, wo) and (wo, wi) have their own bins
    ``k`` and ``(k + 180) % 360``. Its first 180 bins have exactly the MERL grid's centres.

All angles are in radians (Rusinkiewicz angles, :mod:`fit.formats.angles`). The phi_d functions
take ``n_phi_d`` (default 180, the MERL grid).
"""
from __future__ import annotations

import numpy as np

from .angles import HALF_PI

N_THETA_H = 90
N_THETA_D = 90
#: phi_d bins of the MERL grid: [0, pi), folded by reciprocity.
N_PHI_D = 180
#: phi_d bins of the full-circle grid: [0, 2 pi), no fold (non-reciprocal data).
N_PHI_D_FULL = 360
#: The allowed phi_d bin counts.
PHI_D_BINS = (N_PHI_D, N_PHI_D_FULL)
MERL_SHAPE = (N_THETA_H, N_THETA_D, N_PHI_D)
FULL_SHAPE = (N_THETA_H, N_THETA_D, N_PHI_D_FULL)


def n_phi_d_for(reciprocal: bool) -> int:
    """Number of phi_d bins of a table: 180 (folded) if ``reciprocal``, else 360."""
    return N_PHI_D if reciprocal else N_PHI_D_FULL


def grid_shape(n_phi_d: int = N_PHI_D) -> tuple:
    """``(90, 90, n_phi_d)``; ``n_phi_d`` must be 180 or 360."""
    return (N_THETA_H, N_THETA_D, _check(n_phi_d))


def phi_d_period(n_phi_d: int = N_PHI_D) -> float:
    """The phi_d range the bins cover: pi (180 bins, folded) or 2 pi (360 bins)."""
    return _check(n_phi_d) / N_PHI_D * np.pi


def _check(n_phi_d) -> int:
    n = int(n_phi_d)
    if n not in PHI_D_BINS:
        raise ValueError(f"the number of phi_d bins must be one of {PHI_D_BINS}, got {n_phi_d!r}")
    return n


def theta_h_centres() -> np.ndarray:
    """Bin centres of theta_h in radians, shape (90,)."""
    return ((np.arange(N_THETA_H) + 0.5) / N_THETA_H) ** 2 * HALF_PI


def theta_d_centres() -> np.ndarray:
    """Bin centres of theta_d in radians, shape (90,)."""
    return (np.arange(N_THETA_D) + 0.5) / N_THETA_D * HALF_PI


def phi_d_centres(n_phi_d: int = N_PHI_D) -> np.ndarray:
    """Bin centres of phi_d in radians, ``(k + 0.5) / 180 * pi``: shape (180,) in [0, pi) or
    (360,) in [0, 2 pi)."""
    return (np.arange(_check(n_phi_d)) + 0.5) / N_PHI_D * np.pi


def theta_h_index(theta_h) -> np.ndarray:
    """MERL bin of theta_h (radians): ``floor(90 * sqrt(theta_h / (pi/2)))``, clamped."""
    t = np.clip(np.asarray(theta_h, float), 0.0, None)
    return np.clip(np.floor(np.sqrt(t / HALF_PI) * N_THETA_H), 0, N_THETA_H - 1).astype(np.intp)


def theta_d_index(theta_d) -> np.ndarray:
    """MERL bin of theta_d (radians): ``floor(theta_d / (pi/2) * 90)``, clamped."""
    t = np.asarray(theta_d, float)
    return np.clip(np.floor(t / HALF_PI * N_THETA_D), 0, N_THETA_D - 1).astype(np.intp)


def phi_d_index(phi_d, n_phi_d: int = N_PHI_D) -> np.ndarray:
    """Bin of phi_d (radians), clamped: with 180 bins phi_d is folded into [0, pi) by
    reciprocity, with 360 bins it is wrapped into [0, 2 pi) (no fold); then
    ``floor(phi_d / pi * 180)``."""
    n = _check(n_phi_d)
    p = np.mod(np.asarray(phi_d, float), phi_d_period(n))
    return np.clip(np.floor(p / np.pi * N_PHI_D), 0, n - 1).astype(np.intp)
