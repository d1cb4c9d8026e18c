"""``rational`` technique: the verified rational inverse CDFs of a material
(:class:`fit.sampling.cdf_file.CDFFit`), with the derivative estimator's weight.

Layouts (``Materials.cdf_info[CDF_LAYOUT]``):

* pieces (default; :mod:`fit.sampling.pieces`): per view row, monotone rational-quadratic pieces of
  equal mass, found without a search (:func:`pieces_sample`); coefficients in
  ``Materials.cdf_pw``, the rows with a verified map flagged in ``Materials.cdf_row_ok``;
* global (the paper's: one F(theta_v, mu), one G(theta_v, theta_l, u)): packed Chebyshev
  polynomials in ``Materials.cdf_gi`` / ``cdf_gf`` / ``cdf_gq`` (:func:`.cdf_data.pack_global`), evaluated
  in float64 by :func:`global_sample`.

Both layouts are data: the kernels' source is the same for every CDF file (a new file compiles
nothing).

Weight: alpha = dtheta_l/dmu * dphi_l/dtau * sin(theta_l), the exact inverse density of the map
(eq. 3-4 of the supplementary text: for a monotone covering map ``f cos / pdf`` with pdf =
1/alpha IS the derivative estimator ``f cos alpha``). A row without a verified map, or a material
whose fit fell back, is sampled with the table (weight 1/pdf of the table).

``pdf`` is the TABLE's density (:func:`.tabulated.pdf`): the rational density would need the
inverse map. MIS with it stays unbiased: the power-heuristic weights computed from any one pdf
sum to one for every direction, and the table's pdf is > 0 wherever the rational density is
(the table mixes in a cosine density). Hence ``pdf_exact = False`` in the registry.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from fit.formats.angles import direction_to_spherical, spherical_to_direction

from .. import fastmath as fmath
from ..chebyshev import cheb_sum2_d
from ..materials.data import (
    CDF_LAYOUT,
    CDF_MAPS,
    CDF_N_MU,
    CDF_N_U,
    CDF_N_V,
    CDF_OFF_ROWS,
    LAYOUT_GLOBAL,
    LAYOUT_PIECES,
    N_CDF_INFO,
    Materials,
)
from . import tabulated
from .cdf_data import GLOBAL_PHI, GLOBAL_THETA
from .tabulated import local_dir, tab_row, view_frame

HALF_PI = 0.5 * np.pi


# --------------------------------------------------------------------------------------------
# Pieces layout (fit.sampling.pieces): rational-quadratic pieces uniform in mu / u
# --------------------------------------------------------------------------------------------
@wp.func
def rq_piece(pw: wp.array(dtype=float), b: int, x: float) -> wp.vec2:
    """(value, d/dx) of the rational-quadratic piece (y_k, h, a0, a1) at pw[b:b+4], x in [0, 1]."""
    y0 = pw[b]
    h = pw[b + 1]
    a0 = pw[b + 2]
    a1 = pw[b + 3]
    t = x * (1.0 - x)
    den = 1.0 + (a0 + a1 - 2.0) * t
    iden = 1.0 / den
    x2 = x * x
    w = 1.0 - x
    return wp.vec2(y0 + h * (x2 + a0 * t) * iden, h * (a1 * x2 + 2.0 * t + a0 * w * w) * iden * iden)


@wp.func
def rq_knots(pw: wp.array(dtype=float), b: int, x: float) -> wp.vec2:
    """(value, d/dx) of the same rational-quadratic piece stored by its two knots
    ``(y0, s0, y1, s1)`` at pw[b:b+4] (values and slopes dy/dx, x in [0, 1]): consecutive pieces
    share a knot, so the map is continuous by construction and a piece costs 2 floats.
    ``h = y1 - y0``: ``y = y0 + h (h x^2 + s0 x(1-x)) / (h + (s0 + s1 - 2h) x(1-x))``."""
    y0 = pw[b]
    s0 = pw[b + 1]
    y1 = pw[b + 2]
    s1 = pw[b + 3]
    h = y1 - y0
    t = x * (1.0 - x)
    den = h + (s0 + s1 - 2.0 * h) * t
    if den <= 0.0:                  # h = 0 and flat slopes: a constant piece
        return wp.vec2(y0, 0.0)
    iden = 1.0 / den
    x2 = x * x
    w = 1.0 - x
    return wp.vec2(y0 + h * (h * x2 + s0 * t) * iden, h * h * (s1 * x2 + 2.0 * h * t + s0 * w * w) * iden * iden)


@wp.func
def pieces_sample(pw: wp.array(dtype=float), off: int, n_v: int, n_mu: int, n_u: int, v: int,
                  va: wp.vec3, mu: float, tau: float) -> wp.vec4:
    """(wi, alpha): the direction of (theta_l, phi_l) of fit.sampling.pieces.sample_pieces in the
    view frame ``va`` (:func:`view_frame`) and alpha, on rational row ``v`` (the caller sends
    table rows to the table). Piece of mu: floor(mu n_mu), no search; sin and cos of
    theta_l and of phi_l by the inline :func:`warp_rbrdf.fastmath.sincos` (end pieces of theta:
    from y = sin^2 theta_l, no sin/cos at all). Theta pieces:
    4 floats each (:func:`rq_piece`); phi maps: knots (:func:`rq_knots`, see
    :func:`.cdf_data.pack_pieces`)."""
    xs = mu * float(n_mu)
    k = fmath.clamp(int(xs), 0, n_mu - 1)
    F = rq_piece(pw, off + (v * n_mu + k) * 4, fmath.clamp(xs - float(k), 0.0, 1.0))
    st = float(0.0)
    ct = float(0.0)
    at = float(0.0)                  # dtheta_l/dmu * sin(theta_l)
    if k == 0 or k == n_mu - 1:      # end pieces in y = sin^2 theta_l
        y = fmath.clamp(F[0], 0.0, 1.0)
        st = wp.sqrt(y)
        ct = wp.sqrt(1.0 - y)
        at = F[1] * float(n_mu) / (2.0 * fmath.fmax(ct, 1.0e-20))
    else:
        sc = fmath.sincos(fmath.clamp(F[0], 0.0, wp.HALF_PI))
        st = sc[0]
        ct = sc[1]
        at = F[1] * float(n_mu) * st
    s = 1.0
    if tau < 0.5:
        s = -1.0
    u = wp.abs(2.0 * tau - 1.0)
    us = u * float(n_u)
    kp = fmath.clamp(int(us), 0, n_u - 1)
    G = rq_knots(pw, off + n_v * n_mu * 4 + ((v * n_mu + k) * (n_u + 1) + kp) * 2,
                 fmath.clamp(us - float(kp), 0.0, 1.0))
    sph = fmath.sincos(fmath.clamp(G[0], 0.0, wp.pi))
    cp = sph[1]
    sp = s * sph[0]
    return wp.vec4(st * (cp * va[1] - sp * va[2]), st * (sp * va[1] + cp * va[2]), ct,
                   at * 2.0 * G[1] * float(n_u))



@wp.func
def maps_to_direction(q: wp.vec3, va: wp.vec3) -> wp.vec4:
    """(wi, alpha) from (theta_l, phi_l, alpha) of a generated global-layout sampler."""
    wl = local_dir(q[0], q[1], va)
    return wp.vec4(wl[0], wl[1], wl[2], q[2])


# --------------------------------------------------------------------------------------------
# Global layout: F and G as packed Chebyshev polynomials (Materials.cdf_gi / cdf_gf / cdf_gq)
# --------------------------------------------------------------------------------------------
@wp.func
def _map_input(gf: wp.array(dtype=wp.float64), d: int, v: int, x: wp.float64) -> wp.float64:
    """Variable ``v`` mapped onto [-1, 1] with the domain data at ``gf[d]`` (:func:`.cdf_data.pack_global`)."""
    return (wp.float64(2.0) * x - gf[d + 1 + 2 * v]) * gf[d + 2 + 2 * v]


@wp.func
def _normalized(gf: wp.array(dtype=wp.float64), gi: wp.array(dtype=int), gq: wp.array(dtype=wp.vec2d),
                r: int, ta: wp.float64, tb: wp.float64, tc: wp.float64, span: wp.float64) -> wp.vec2d:
    """(value, d/dx) of the endpoint-normalized map ``span (R - R_lo) / (R_hi - R_lo)`` of the
    map whose record starts at ``gi[r]`` (coefficient rows in ``gq``, domain data in ``gf``;
    R = P/Q; R_lo, R_hi: its CDF variable, the last, at the ends of its domain) with ONE
    division: with D = P_hi Q_lo - P_lo Q_hi and N = P Q_lo - P_lo Q, value = span N Q_hi /
    (Q D), derivative = span (P' Q - P Q') Q_hi Q_lo / (Q^2 D)
    (:func:`fit.sampling.maps.normalized_map`)."""
    s = cheb_sum2_d(gq, gi, gi[r + 1], gi[r], ta, tb, tc)   # P, Q, P', Q', P_lo, Q_lo, P_hi, Q_hi
    sc = gf[gi[r + 2]]
    inv = wp.float64(1.0) / (s[1] * s[1] * (s[6] * s[5] - s[4] * s[7]))
    v = span * (s[0] * s[5] - s[4] * s[1]) * s[7] * s[1] * inv
    dv = span * (s[2] * sc * s[1] - s[0] * s[3] * sc) * s[7] * s[5] * inv
    return wp.vec2d(v, dv)


@wp.func
def global_sample(gf: wp.array(dtype=wp.float64), gi: wp.array(dtype=int), gq: wp.array(dtype=wp.vec2d),
                  g: int, theta_v: float, mu: float, tau: float) -> wp.vec3:
    """``(theta_l, phi_l, alpha)`` of the global-layout maps whose record starts at ``gi[g]``:
    :meth:`fit.sampling.cdf_file.CDFFit.sample` (:func:`fit.sampling.maps.sample_maps`),
    float64; alpha = 0 where a clamp acts."""
    half_pi = wp.float64(1.5707963267948966)
    pi = wp.float64(3.141592653589793)
    zero = wp.float64(0.0)
    tv = wp.float64(fmath.clamp(theta_v, 0.0, 1.5707963267948966))
    d = gi[g + GLOBAL_THETA + 2]
    f = _normalized(gf, gi, gq, g + GLOBAL_THETA, zero, _map_input(gf, d, 0, tv),
                    _map_input(gf, d, 1, wp.float64(mu)), half_pi)
    tl = f[0]
    inside = 1
    if tl < zero or tl > half_pi:
        inside = 0
    tl = fmath.clamp(tl, zero, half_pi)
    s = wp.float64(1.0)
    if tau < 0.5:
        s = wp.float64(-1.0)
    u = wp.float64(wp.abs(2.0 * tau - 1.0))
    d = gi[g + GLOBAL_PHI + 2]
    h = _normalized(gf, gi, gq, g + GLOBAL_PHI, _map_input(gf, d, 0, tv), _map_input(gf, d, 1, tl),
                    _map_input(gf, d, 2, u), pi)
    ph = h[0]
    if ph < zero or ph > pi:
        inside = 0
    ph = fmath.clamp(ph, zero, pi)
    alpha = zero
    if inside == 1:
        alpha = f[1] * wp.float64(2.0) * h[1] * wp.sin(tl)
    return wp.vec3(float(tl), float(s * ph), float(alpha))


@wp.func
def rational_sample(mats: Materials, m: int, wo: wp.vec3, xi: wp.vec2) -> wp.vec4:
    """(wi, alpha) of material ``m``'s maps (pieces or global layout; weight 1/pdf of the table on
    table rows and for a table-only material)."""
    b = m * N_CDF_INFO
    va = view_frame(wo)
    layout = mats.cdf_info[b + CDF_LAYOUT]
    if layout == LAYOUT_PIECES:
        n_v = mats.cdf_info[b + CDF_N_V]
        v = tab_row(va[0], n_v)
        if mats.cdf_row_ok[mats.cdf_info[b + CDF_OFF_ROWS] + v] != 0:   # else: a table row
            return pieces_sample(mats.cdf_pw, mats.cdf_info[b + CDF_MAPS], n_v, mats.cdf_info[b + CDF_N_MU],
                                 mats.cdf_info[b + CDF_N_U], v, va, xi[0], xi[1])
    elif layout == LAYOUT_GLOBAL:
        g = mats.cdf_info[b + CDF_MAPS]
        return maps_to_direction(global_sample(mats.cdf_gf, mats.cdf_gi, mats.cdf_gq, g, va[0], xi[0], xi[1]), va)
    return tabulated.table_sample(mats, m, va, xi)


def kernel_functions(global_fits=()):
    """``(sample, pdf)``, the same for every scene (``global_fits`` is not needed: the maps are
    data): pieces maps from ``cdf_pw``, global-layout maps from ``cdf_gi`` / ``cdf_gf`` / ``cdf_gq`` (record
    at ``cdf_info[CDF_MAPS]``), the table on table rows."""
    return rational_sample, tabulated.pdf


# --------------------------------------------------------------------------------------------
# NumPy references
# --------------------------------------------------------------------------------------------
def numpy_sample(cdf, wo, xi):
    """NumPy reference of the sampler: ``(wi (N, 3), weight (N,))`` from ``CDFFit.sample``
    (alpha on rational rows, 1/pdf of the table elsewhere)."""
    tv, pv = direction_to_spherical(wo)
    tl, pl, alpha = cdf.sample(tv, xi[:, 0], xi[:, 1])
    return spherical_to_direction(tl, pl + pv), alpha


def numpy_pdf(cdf, wi, wo):
    """The density MIS uses: the table's (approximate for the rational maps)."""
    return tabulated.numpy_pdf(cdf, wi, wo)
