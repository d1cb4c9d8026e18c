"""Warp functions shared by the tabulated materials: Rusinkiewicz angles of a local direction
pair and the MERL grid's bins (:mod:`fit.formats.grid` is the NumPy definition).

Bins: ``theta_h`` -> ``floor(90 sqrt(theta_h / (pi/2)))``, ``theta_d`` -> ``floor(90 theta_d /
(pi/2))``, ``phi_d`` -> ``floor(180 phi_d / pi)`` (one-degree bins) after folding it into
[0, pi) by reciprocity when the table has 180 phi_d bins (MERL files), or wrapping it into
[0, 2 pi) when it has 360 (full circle, data from a non-reciprocal source such as an RGL-EPFL
file; no fold); all clamped to the grid. Angles in radians.
"""
from __future__ import annotations

import warp as wp

from .. import fastmath as fmath

N_TH, N_TD, N_PD = 90, 90, 180   # N_PD: phi_d bins of a table folded by reciprocity (MERL)
N_PD_FULL = 360                   # phi_d bins of a full-circle table (no fold)


@wp.func
def half_diff(wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    """Rusinkiewicz (theta_h, theta_d, phi_d) of a local direction pair (phi_d in (-pi, pi])."""
    s = wi + wo
    ln = wp.length(s)
    h = wp.vec3(0.0, 0.0, 1.0)
    if ln > 1.0e-9:
        h = s / ln
    rxy = wp.sqrt(h[0] * h[0] + h[1] * h[1])
    theta_h = wp.atan2(rxy, h[2])  # accurate near 0, unlike acos
    cp = 1.0
    sp = 0.0
    if rxy > 1.0e-12:
        cp = h[0] / rxy
        sp = h[1] / rxy
    # rotate wi by -phi_h about z, then by -theta_h about y
    x1 = cp * wi[0] + sp * wi[1]
    y1 = -sp * wi[0] + cp * wi[1]
    z1 = wi[2]
    ct = h[2]
    st = rxy
    x2 = ct * x1 - st * z1
    z2 = st * x1 + ct * z1
    theta_d = wp.atan2(wp.sqrt(x2 * x2 + y1 * y1), z2)
    phi_d = 0.0
    if wp.abs(x2) + wp.abs(y1) > 1.0e-12:
        phi_d = wp.atan2(y1, x2)
    return wp.vec3(theta_h, theta_d, phi_d)


@wp.func
def merl_theta_h_index(theta_h: float) -> int:
    t = fmath.fmax(theta_h, 0.0)
    return fmath.clamp(int(wp.floor(wp.sqrt(t / wp.HALF_PI) * 90.0)), 0, N_TH - 1)


@wp.func
def merl_theta_d_index(theta_d: float) -> int:
    return fmath.clamp(int(wp.floor(theta_d / wp.HALF_PI * 90.0)), 0, N_TD - 1)


@wp.func
def merl_phi_d_wrap(phi_d: float, n_phi_d: int) -> float:
    """``phi_d`` in (-pi, pi] (:func:`half_diff`) on a table of ``n_phi_d`` phi_d bins: 180
    folds it into [0, pi) (reciprocity), 360 wraps it into [0, 2 pi) (no fold); radians."""
    period = float(n_phi_d) / 180.0 * wp.pi
    p = phi_d
    if p < 0.0:
        p = p + period
    if p >= period:
        p = p - period
    return p


@wp.func
def merl_phi_d_index(phi_d: float, n_phi_d: int) -> int:
    """Bin of ``phi_d`` in (-pi, pi] on a table of ``n_phi_d`` phi_d bins (:func:`merl_phi_d_wrap`)."""
    return fmath.clamp(int(wp.floor(merl_phi_d_wrap(phi_d, n_phi_d) / wp.pi * 180.0)), 0, n_phi_d - 1)
