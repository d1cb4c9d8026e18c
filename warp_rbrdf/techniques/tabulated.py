"""``tabulated`` technique: the material's tabulated inverse CDFs of rho cos (luminance) per
view row (:class:`fit.sampling.table.CDFTable`), sampled as piecewise-constant distributions
(:func:`warp_rbrdf.distribution.pc1d_sample`: binary search, continuous in the cell), exactly as
:meth:`CDFTable.sample` (its NumPy reference). Weight 1/pdf with the table's exact density.

Frame: ``theta_v, phi_v`` of ``wo`` in the local frame; the sampled light's azimuth ``phi_l`` is
measured from ``phi_v``; angles in radians, densities in 1/sr. The material's tables live in
``Materials.cdf_t`` / ``cdf_p`` at the offsets of its ``cdf_info`` (:mod:`..materials.data`).
"""
from __future__ import annotations

import functools

import numpy as np
import warp as wp

from fit.formats.angles import direction_to_spherical, spherical_to_direction

from .. import fastmath as fmath
from ..distribution import find_interval, pc1d_in_cell, pc1d_mass
from ..distribution.lanes import lane_types, lanes_out_type, make_find_interval_lanes
from ..materials.data import (
    CDF_N_P,
    CDF_N_T,
    CDF_N_V,
    CDF_OFF_P,
    CDF_OFF_T,
    N_CDF_INFO,
    Materials,
)


@wp.func
def tab_row(theta_v: float, n_v: int) -> int:
    return fmath.clamp(int(wp.floor(theta_v / wp.HALF_PI * float(n_v))), 0, n_v - 1)


@wp.func
def tab_sample(cdf_t: wp.array(dtype=float), cdf_p: wp.array(dtype=float), off_t: int, off_p: int,
               n_v: int, n_t: int, n_p: int, theta_v: float, mu: float, tau: float) -> wp.vec3:
    """(theta_l, phi_l, pdf) exactly as fit.sampling.table.CDFTable.sample: the view row's
    piecewise-constant theta_l CDF, then the |phi_l| CDF of the theta_l cell (the sign from
    ``tau < 1/2``, ``|2 tau - 1|`` the uniform), each continuous in its cell."""
    v = tab_row(theta_v, n_v)
    j = find_interval(cdf_t, off_t + v * (n_t + 1), n_t + 1, mu)
    k = find_interval(cdf_p, off_p + (v * n_t + j) * (n_p + 1), n_p + 1, wp.abs(2.0 * tau - 1.0))
    return tab_sample_cells(cdf_t, cdf_p, off_t, off_p, n_t, n_p, v, j, k, mu, tau)


@wp.func
def tab_sample_cells(cdf_t: wp.array(dtype=float), cdf_p: wp.array(dtype=float), off_t: int, off_p: int,
                     n_t: int, n_p: int, v: int, j: int, k: int, mu: float, tau: float) -> wp.vec3:
    """:func:`tab_sample` in view row ``v`` once its two searches have found the theta_l cell
    ``j`` and the |phi_l| cell ``k``."""
    frac_t, m_t = pc1d_in_cell(cdf_t, off_t + v * (n_t + 1), j, mu)
    dt = wp.HALF_PI / float(n_t)
    theta_l = (float(j) + frac_t) * dt
    s = 1.0
    if tau < 0.5:
        s = -1.0
    u = wp.abs(2.0 * tau - 1.0)
    frac_p, m_p = pc1d_in_cell(cdf_p, off_p + (v * n_t + j) * (n_p + 1), k, u)
    dp = wp.pi / float(n_p)
    phi_l = s * (float(k) + frac_p) * dp
    pdf = (m_t / dt) * (0.5 * m_p / dp) / fmath.fmax(wp.sin(theta_l), 1.0e-30)
    return wp.vec3(theta_l, phi_l, pdf)


@wp.func
def tab_pdf(cdf_t: wp.array(dtype=float), cdf_p: wp.array(dtype=float), off_t: int, off_p: int,
            n_v: int, n_t: int, n_p: int, theta_v: float, theta_l: float, sin_l: float,
            phi_abs: float) -> float:
    """Density (1/sr) of tab_sample at (theta_l, |phi_l|) (``sin_l``: sin theta_l, known to the
    caller from the direction); 0 at or below the horizon."""
    if theta_l < 0.0 or theta_l >= wp.HALF_PI:
        return 0.0
    v = tab_row(theta_v, n_v)
    dt = wp.HALF_PI / float(n_t)
    dp = wp.pi / float(n_p)
    j = fmath.clamp(int(wp.floor(theta_l / dt)), 0, n_t - 1)
    k = fmath.clamp(int(wp.floor(phi_abs / dp)), 0, n_p - 1)
    st = off_t + v * (n_t + 1)
    sp = off_p + (v * n_t + j) * (n_p + 1)
    m_t = pc1d_mass(cdf_t, st, j)
    m_p = pc1d_mass(cdf_p, sp, k)
    return (m_t / dt) * (0.5 * m_p / dp) / fmath.fmax(sin_l, 1.0e-30)


@wp.func
def view_frame(wo: wp.vec3) -> wp.vec3:
    """(theta_v, cos phi_v, sin phi_v) of the local view direction (phi_v = 0 at the pole):
    the view's azimuth as a rotation, so that sampled directions need no atan2 (theta_v by
    :func:`warp_rbrdf.fastmath.atan2`, within 3 float32 ulps of libm's)."""
    rxy = wp.sqrt(wo[0] * wo[0] + wo[1] * wo[1])
    c = 1.0
    s = 0.0
    if rxy > 1.0e-12:
        c = wo[0] / rxy
        s = wo[1] / rxy
    return wp.vec3(fmath.atan2(rxy, wo[2]), c, s)


@wp.func
def local_dir(theta_l: float, phi_l: float, vf: wp.vec3) -> wp.vec3:
    """Direction at polar angle theta_l and azimuth phi_l measured from the view's azimuth
    (``vf`` from :func:`view_frame`; sines and cosines by :func:`warp_rbrdf.fastmath.sincos`)."""
    t = fmath.sincos(theta_l)
    p = fmath.sincos(phi_l)
    return wp.vec3(t[0] * (p[1] * vf[1] - p[0] * vf[2]), t[0] * (p[0] * vf[1] + p[1] * vf[2]), t[1])


@wp.func
def rel_phi_abs(wi: wp.vec3, vf: wp.vec3) -> float:
    """|phi_l - phi_v| in [0, pi] of the light's local direction in the view frame ``vf``
    (:func:`view_frame`): the angle between the azimuths, one inline ``atan2`` of their cross
    and dot products."""
    cross = wi[1] * vf[1] - wi[0] * vf[2]
    dot = wi[0] * vf[1] + wi[1] * vf[2]
    return fmath.atan2(wp.abs(cross), dot)


@wp.func
def table_sample(mats: Materials, m: int, va: wp.vec3, xi: wp.vec2) -> wp.vec4:
    """(wi, 1/pdf) of the material's table in the view frame ``va`` (:func:`view_frame`)."""
    b = m * N_CDF_INFO
    q = tab_sample(mats.cdf_t, mats.cdf_p, mats.cdf_info[b + CDF_OFF_T], mats.cdf_info[b + CDF_OFF_P],
                   mats.cdf_info[b + CDF_N_V], mats.cdf_info[b + CDF_N_T], mats.cdf_info[b + CDF_N_P],
                   va[0], xi[0], xi[1])
    return sample_at(q, va)


@wp.func
def sample_at(q: wp.vec3, va: wp.vec3) -> wp.vec4:
    """(wi, 1/pdf) of :func:`tab_sample`'s ``q`` in the view frame ``va``."""
    wl = local_dir(q[0], q[1], va)
    wgt = 0.0
    if q[2] > 0.0:
        wgt = 1.0 / q[2]
    return wp.vec4(wl[0], wl[1], wl[2], wgt)


@wp.func
def sample(mats: Materials, m: int, wo: wp.vec3, xi: wp.vec2) -> wp.vec4:
    """(wi, weight = 1/pdf) in the local frame; weight 0: no sample."""
    return table_sample(mats, m, view_frame(wo), xi)


@wp.func
def pdf(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> float:
    """Density (1/sr) of :func:`sample` at ``wi``; 0 at or below the horizon."""
    if wi[2] <= 0.0:
        return 0.0
    b = m * N_CDF_INFO
    va = view_frame(wo)
    rxy = wp.sqrt(wi[0] * wi[0] + wi[1] * wi[1])
    tl = fmath.atan2(rxy, wi[2])
    sin_l = rxy / wp.sqrt(rxy * rxy + wi[2] * wi[2])    # sin theta_l of wi, of any length
    return tab_pdf(mats.cdf_t, mats.cdf_p, mats.cdf_info[b + CDF_OFF_T], mats.cdf_info[b + CDF_OFF_P],
                   mats.cdf_info[b + CDF_N_V], mats.cdf_info[b + CDF_N_T], mats.cdf_info[b + CDF_N_P],
                   va[0], tl, sin_l, rel_phi_abs(wi, va))


def kernel_functions(cdfs):
    """(sample, pdf) for the scene's materials using this technique."""
    return sample, pdf


@functools.lru_cache(maxsize=None)
def make_sample_lanes(K: int):
    """``sample_lanes(mats, m, wox, woy, woz, xi0, xi1, on) -> (8, K)``: :func:`sample` of every
    lane with ``on[i] != 0`` (views and uniforms as float lanes; the others a zero column),
    ``has_f`` 0 (the caller evaluates the material): the two searches of :func:`tab_sample`
    stepped over all lanes (:func:`warp_rbrdf.distribution.lanes.make_find_interval_lanes`),
    the rest lane by lane (:func:`tab_sample_cells`, :func:`sample_at`), so each lane's sample is
    the one-at-a-time sample. Cached: one function per ``K``."""
    vf, vi = lane_types(K)
    out_t = lanes_out_type(K)
    find_lanes = make_find_interval_lanes(K)

    @wp.func
    def sample_lanes(mats: Materials, m: int, wox: vf, woy: vf, woz: vf, xi0: vf, xi1: vf, on: vi) -> out_t:
        b = m * N_CDF_INFO
        off_t = mats.cdf_info[b + CDF_OFF_T]
        off_p = mats.cdf_info[b + CDF_OFF_P]
        n_v = mats.cdf_info[b + CDF_N_V]
        n_t = mats.cdf_info[b + CDF_N_T]
        n_p = mats.cdf_info[b + CDF_N_P]
        row = vi()
        st = vi()
        u = vf()
        tv = vf()          # the views' frames (view_frame), kept for the directions
        cv = vf()
        sv = vf()
        i = int(0)
        while i < K:
            va = view_frame(wp.vec3(wox[i], woy[i], woz[i]))
            tv[i] = va[0]
            cv[i] = va[1]
            sv[i] = va[2]
            row[i] = tab_row(va[0], n_v)
            st[i] = off_t + row[i] * (n_t + 1)
            u[i] = wp.abs(2.0 * xi1[i] - 1.0)
            i += 1
        j = find_lanes(mats.cdf_t, st, n_t + 1, xi0)
        sp = vi()
        i = int(0)
        while i < K:
            sp[i] = off_p + (row[i] * n_t + j[i]) * (n_p + 1)
            i += 1
        k = find_lanes(mats.cdf_p, sp, n_p + 1, u)
        out = out_t()
        i = int(0)
        while i < K:
            if on[i] != 0:
                q = tab_sample_cells(mats.cdf_t, mats.cdf_p, off_t, off_p, n_t, n_p, row[i], j[i], k[i], xi0[i],
                                     xi1[i])
                r = sample_at(q, wp.vec3(tv[i], cv[i], sv[i]))
                for c in range(4):
                    out[c, i] = r[c]
            i += 1
        return out

    return sample_lanes


def kernel_lanes(K: int, cdfs=()):
    """The technique's sample over ``K`` lanes (:func:`make_sample_lanes`; optional in the
    technique interface, :mod:`warp_rbrdf.lanes`)."""
    return make_sample_lanes(K)


# --------------------------------------------------------------------------------------------
# NumPy references
# --------------------------------------------------------------------------------------------
def numpy_sample(cdf, wo, xi):
    """NumPy reference of :func:`sample`: ``(wi (N, 3), weight (N,))``; ``cdf``: the material's
    CDFTable (or a CDFFit, whose ``table`` is used)."""
    table = getattr(cdf, "table", cdf)
    tv, pv = direction_to_spherical(wo)
    tl, pl, p = table.sample(tv, xi[:, 0], xi[:, 1])
    return spherical_to_direction(tl, pl + pv), np.where(p > 0, 1.0 / np.where(p > 0, p, 1.0), 0.0)


def numpy_pdf(cdf, wi, wo):
    """NumPy reference of :func:`pdf` (1/sr)."""
    table = getattr(cdf, "table", cdf)
    tv, pv = direction_to_spherical(wo)
    tl, pl = direction_to_spherical(wi)
    return np.where(np.asarray(wi)[:, 2] > 0, table.pdf(tv, tl, pl - pv), 0.0)
