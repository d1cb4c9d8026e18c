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


#: How a table on the grid is read between its bin centres (:func:`trilinear_corners`).
INTERPOLATIONS = ("linear", "nearest")


def trilinear_corners(theta_h, theta_d, phi_d, n_phi_d: int = N_PHI_D):
    """The 8 bin centres around a point of the grid and their trilinear weights.

    Coordinates are continuous bin positions whose integers are the centres: ``u = 90
    sqrt(theta_h / (pi/2)) - 0.5`` (theta_h square-root spaced, as the bins),
    ``v = 90 theta_d / (pi/2) - 0.5`` and ``w = 180 phi_d / pi - 0.5`` after the fold or wrap of
    :func:`phi_d_index`. ``u`` and ``v`` are clamped to the first and last centres (the value
    is held constant beyond them); ``w`` is periodic: with 180 bins, bin 179 and bin 0 are
    neighbours across phi_d = pi (the reciprocity fold), with 360 across 2 pi = 0.

    Returns ``(i, j, k, weight)``: integer arrays of shape ``broadcast(...) + (8,)`` and
    float64 weights of that shape, summing to 1 over the last axis (a coordinate within 1e-9
    of a centre is snapped to it: weights exactly 0 and 1). Angles in radians.
    """
    n = _check(n_phi_d)
    th, td, pd = np.broadcast_arrays(np.asarray(theta_h, float), np.asarray(theta_d, float),
                                     np.asarray(phi_d, float))
    u = np.clip(np.sqrt(np.clip(th, 0.0, None) / HALF_PI) * N_THETA_H - 0.5, 0.0, N_THETA_H - 1.0)
    v = np.clip(td / HALF_PI * N_THETA_D - 0.5, 0.0, N_THETA_D - 1.0)
    w = np.mod(pd, phi_d_period(n)) / np.pi * N_PHI_D - 0.5
    i0 = np.minimum(np.floor(u).astype(np.intp), N_THETA_H - 2)
    j0 = np.minimum(np.floor(v).astype(np.intp), N_THETA_D - 2)
    k0f = np.floor(w)
    # a coordinate within 1e-9 of a centre is that centre (rounding of the angles): weights
    # exactly 0 and 1, so a table read at its own centres returns its values bit for bit
    a, b, c = (np.where(f < 1e-9, 0.0, np.where(f > 1.0 - 1e-9, 1.0, f))
               for f in (u - i0, v - j0, w - k0f))
    k0 = np.mod(k0f.astype(np.intp), n)
    k1 = np.mod(k0 + 1, n)
    ii, jj, kk, ww = [], [], [], []
    for di, wa in ((0, 1.0 - a), (1, a)):
        for dj, wb in ((0, 1.0 - b), (1, b)):
            for k, wc in ((k0, 1.0 - c), (k1, c)):
                ii.append(i0 + di)
                jj.append(j0 + dj)
                kk.append(k)
                ww.append(wa * wb * wc)
    return (np.stack(ii, -1), np.stack(jj, -1), np.stack(kk, -1), np.stack(ww, -1))
