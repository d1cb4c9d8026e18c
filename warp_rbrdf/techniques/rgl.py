"""``rgl`` technique: the RGL-EPFL format's own importance sampling of an ``rgl`` material
(Dupuy & Jakob 2018; Mitsuba 3's ``measured`` plugin): given the tensors' incident direction
``wt`` (the view, the default roles), two uniforms are warped by the **luminance** warp (the
luminance of the ``rgb`` tensor over its warped coordinates), then by the **VNDF** warp to a
micro-normal ``wm`` (``theta_m = u_x^2 pi/2``, ``phi_m = phi_t + (2 u_y - 1) pi``) and
reflected: ``wx = 2 (wm . wt) wm - wt``. Its density in 1/sr is exact:

    pdf(wx) = p_vndf(u_m) p_lum(s) / (max(2 pi^2 u_x sin theta_m, 1e-6) * 4 (wt . wm))

(the Jacobians of the (theta_m, phi_m) parametrization and of the reflection), the same as
the reference's ``pdf``. Only for ``rgl`` materials whose view is the incident direction (the
sample draws the light given the view); a scene with ``incident = "light"`` cannot use it
(refused at load). Directions in the local frame (z = normal); ``wo`` the view, ``wi`` the light.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from fit.formats.rgl_interpolants import interval

from .. import fastmath as fmath
from ..materials import rgl as R
from ..materials.data import Materials
from ..materials.rgl_tables import (
    bilinear,
    rgb_eval,
    theta_interval,
    warp_eval,
    warp_invert,
    warp_sample,
)
from ..registry import material

RGL_CODE = material("rgl").code
MIN_JACOBIAN = 1.0e-6


@wp.func
def _incidence(mats: Materials, h: int, wt: wp.vec3) -> wp.vec4:
    """(t0, w1, phi_t, theta_t) of the tensors' incident direction ``wt``: its theta_i slice
    interval (``t0`` as a float, ``w1`` the weight of slice ``t0 + 1``), azimuth and elevation
    (radians)."""
    theta_t = R.elevation(wt)
    tw = theta_interval(mats, mats.rgl_i[h + R.RGL_THETA], mats.rgl_i[h + R.RGL_N_THETA], theta_t)
    return wp.vec4(tw[0], tw[1], fmath.atan2(wt[1], wt[0]), theta_t)


@wp.func
def _draw(mats: Materials, h: int, n: int, t0: int, w1: float, phi_t: float, wo: wp.vec3, xi: wp.vec2):
    """The format's sample for view ``wo`` (theta_i slice ``t0``, weight ``w1``, azimuth
    ``phi_t``): ``(wi, pdf, ok, u, s, phi_m)`` -- the light, its density in 1/sr, 1 when the sample
    is usable (above both horizons, finite positive pdf), the VNDF warp's output ``u`` (u_x,
    u_y, its density), the luminance warp's output ``s`` and the micro-normal's azimuth."""
    s = warp_sample(mats, mats.rgl_i[h + R.RGL_LUM_DATA], mats.rgl_i[h + R.RGL_LUM_COND],
                    mats.rgl_i[h + R.RGL_LUM_MARG], mats.rgl_i[h + R.RGL_LUM_NY],
                    mats.rgl_i[h + R.RGL_LUM_NX], n, t0, w1, xi[1], xi[0])
    u = warp_sample(mats, mats.rgl_i[h + R.RGL_VNDF_DATA], mats.rgl_i[h + R.RGL_VNDF_COND],
                    mats.rgl_i[h + R.RGL_VNDF_MARG], mats.rgl_i[h + R.RGL_VNDF_NY],
                    mats.rgl_i[h + R.RGL_VNDF_NX], n, t0, w1, s[0], s[1])
    theta_m = u[0] * u[0] * wp.HALF_PI
    phi_m = (2.0 * u[1] - 1.0) * wp.pi + phi_t
    sct = fmath.sincos(theta_m)
    scp = fmath.sincos(phi_m)
    st = sct[0]
    wm = wp.vec3(scp[1] * st, scp[0] * st, sct[1])
    c = wp.dot(wm, wo)
    jac = wp.max(2.0 * wp.pi * wp.pi * u[0] * st, MIN_JACOBIAN) * 4.0 * c
    p = u[2] * s[2] / jac
    wi = wm * (2.0 * c) - wo
    ok = int(1)  # noqa: UP018, RUF046 - a Warp variable assigned in a branch
    if c <= 0.0 or wi[2] <= 0.0 or not (p > 0.0) or p > 1.0e30:
        ok = 0
    return wi, p, ok, u, s, phi_m


@wp.func
def sample(mats: Materials, m: int, wo: wp.vec3, xi: wp.vec2) -> wp.vec4:
    if mats.kind[m] != wp.static(RGL_CODE) or wo[2] <= 0.0:
        return wp.vec4(0.0)
    h = mats.offset[m]
    if mats.rgl_i[h + R.RGL_VIEW_INCIDENT] == 0:
        return wp.vec4(0.0)
    inc = _incidence(mats, h, wo)
    t0 = int(inc[0])
    w1 = inc[1]
    phi_t = inc[2]
    n = mats.rgl_i[h + R.RGL_N_THETA]
    wi, p, ok, _u, _s, _phi_m = _draw(mats, h, n, t0, w1, phi_t, wo, xi)
    if ok == 0:
        return wp.vec4(0.0)
    return wp.vec4(wi[0], wi[1], wi[2], 1.0 / p)


@wp.func
def pdf(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> float:
    if mats.kind[m] != wp.static(RGL_CODE) or wi[2] <= 0.0 or wo[2] <= 0.0:
        return 0.0
    h = mats.offset[m]
    if mats.rgl_i[h + R.RGL_VIEW_INCIDENT] == 0:
        return 0.0
    sv = wi + wo
    wm = sv / wp.length(sv)
    inc = _incidence(mats, h, wo)
    t0 = int(inc[0])
    w1 = inc[1]
    umx = R.theta_to_u(R.elevation(wm))
    umy = R.phi_to_u(fmath.atan2(wm[1], wm[0]) - inc[2])
    n = mats.rgl_i[h + R.RGL_N_THETA]
    sw = warp_invert(mats, mats.rgl_i[h + R.RGL_VNDF_DATA], mats.rgl_i[h + R.RGL_VNDF_COND],
                     mats.rgl_i[h + R.RGL_VNDF_MARG], mats.rgl_i[h + R.RGL_VNDF_NY],
                     mats.rgl_i[h + R.RGL_VNDF_NX], n, t0, w1, umx, umy)
    lum = warp_eval(mats, mats.rgl_i[h + R.RGL_LUM_DATA], mats.rgl_i[h + R.RGL_LUM_NY],
                    mats.rgl_i[h + R.RGL_LUM_NX], n, t0, w1, sw[0], sw[1])
    st = wp.sqrt(wm[0] * wm[0] + wm[1] * wm[1])
    jac = wp.max(2.0 * wp.pi * wp.pi * umx * st, MIN_JACOBIAN) * 4.0 * wp.dot(wo, wm)
    if jac <= 0.0:
        return 0.0
    return wp.max(sw[2] * lum / jac, 0.0)


@wp.func
def _value(mats: Materials, m: int, h: int, n: int, t0: int, w1: float, theta_t: float, phi_t: float,
           umx: float, umy: float, sx: float, sy: float, wi: wp.vec3) -> wp.vec3:
    """f_r of the material with header ``h`` (view incident) from its warped coordinates: the
    rgb tensor at (sx, sy), the jacobian ndf(umx, umy) / (4 sigma(theta_t, phi_t)), clamped to
    0, scaled, divided by cos(theta_l) -- the steps of :func:`warp_rbrdf.materials.rgl.rgl_eval`
    after its inverse VNDF warp."""
    v = rgb_eval(mats, mats.rgl_i[h + R.RGL_RGB], mats.rgl_i[h + R.RGL_LUM_NY], mats.rgl_i[h + R.RGL_LUM_NX],
                 n, t0, w1, sx, sy)
    if mats.rgl_i[h + R.RGL_JACOBIAN] != 0:
        ndf = bilinear(mats, mats.rgl_i[h + R.RGL_NDF], mats.rgl_i[h + R.RGL_NDF_NY],
                       mats.rgl_i[h + R.RGL_NDF_NX], umx, umy)
        sig = bilinear(mats, mats.rgl_i[h + R.RGL_SIGMA], mats.rgl_i[h + R.RGL_SIGMA_NY],
                       mats.rgl_i[h + R.RGL_SIGMA_NX], R.theta_to_u(theta_t), R.phi_to_u(phi_t))
        v = v * (ndf / (4.0 * sig))
    v = wp.vec3(wp.max(v[0], 0.0), wp.max(v[1], 0.0), wp.max(v[2], 0.0))
    return wp.cw_mul(v, mats.scale[m]) / wi[2]


@wp.func
def sample_f(mats: Materials, m: int, wo: wp.vec3, xi: wp.vec2):
    """:func:`sample` and f_r at the sampled light (``(vec4 sample, vec3 f, 1)``; ``0`` last:
    not an rgl material with the view incident, use :func:`sample` and the material's eval).
    The value is read at the luminance warp's output, the point the inverse VNDF warp of the
    sampled micro-normal returns (up to rounding), so no inverse warp is needed."""
    if mats.kind[m] != wp.static(RGL_CODE) or wo[2] <= 0.0:
        return wp.vec4(0.0), wp.vec3(0.0), 1
    h = mats.offset[m]
    if mats.rgl_i[h + R.RGL_VIEW_INCIDENT] == 0:
        return wp.vec4(0.0), wp.vec3(0.0), 1
    inc = _incidence(mats, h, wo)
    t0 = int(inc[0])
    w1 = inc[1]
    phi_t = inc[2]
    theta_t = inc[3]
    n = mats.rgl_i[h + R.RGL_N_THETA]
    wi, pdf_s, ok, u, s, phi_m = _draw(mats, h, n, t0, w1, phi_t, wo, xi)
    if ok == 0:
        return wp.vec4(0.0), wp.vec3(0.0), 1
    f = _value(mats, m, h, n, t0, w1, theta_t, phi_t, u[0], R.phi_to_u(phi_m - phi_t), s[0], s[1], wi)
    return wp.vec4(wi[0], wi[1], wi[2], 1.0 / pdf_s), f, 1


@wp.func
def eval_pdf(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3):
    """f_r and :func:`pdf` at one direction pair with one inverse VNDF warp (``(vec3 f, float
    pdf, 1)``; ``0`` last: not an rgl material with the view incident, use the material's eval
    and :func:`pdf`)."""
    if mats.kind[m] != wp.static(RGL_CODE):
        return wp.vec3(0.0), 0.0, 0
    h = mats.offset[m]
    if mats.rgl_i[h + R.RGL_VIEW_INCIDENT] == 0:
        return wp.vec3(0.0), 0.0, 0
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0), 0.0, 1
    sv = wi + wo
    wm = sv / wp.length(sv)
    inc = _incidence(mats, h, wo)
    t0 = int(inc[0])
    w1 = inc[1]
    phi_t = inc[2]
    theta_t = inc[3]
    n = mats.rgl_i[h + R.RGL_N_THETA]
    umx = R.theta_to_u(R.elevation(wm))
    umy = R.phi_to_u(fmath.atan2(wm[1], wm[0]) - phi_t)
    sw = warp_invert(mats, mats.rgl_i[h + R.RGL_VNDF_DATA], mats.rgl_i[h + R.RGL_VNDF_COND],
                     mats.rgl_i[h + R.RGL_VNDF_MARG], mats.rgl_i[h + R.RGL_VNDF_NY],
                     mats.rgl_i[h + R.RGL_VNDF_NX], n, t0, w1, umx, umy)
    f = _value(mats, m, h, n, t0, w1, theta_t, phi_t, umx, umy, sw[0], sw[1], wi)
    lum = warp_eval(mats, mats.rgl_i[h + R.RGL_LUM_DATA], mats.rgl_i[h + R.RGL_LUM_NY],
                    mats.rgl_i[h + R.RGL_LUM_NX], n, t0, w1, sw[0], sw[1])
    st = wp.sqrt(wm[0] * wm[0] + wm[1] * wm[1])
    jac = wp.max(2.0 * wp.pi * wp.pi * umx * st, MIN_JACOBIAN) * 4.0 * wp.dot(wo, wm)
    p = float(0.0)  # noqa: UP018 - a Warp variable assigned in a branch
    if jac > 0.0:
        p = wp.max(sw[2] * lum / jac, 0.0)
    return f, p, 1


def kernel_functions(cdfs=()):
    return sample, pdf


def kernel_fused(cdfs=()):
    """``(sample_f, eval_pdf)``: the sample with f_r at its direction, and f_r with the pdf at
    one pair, each sharing the warps (the integrator's per-sample cost; optional in the
    technique interface, :func:`warp_rbrdf.integrator.make_bsdf_sampling`)."""
    return sample_f, eval_pdf


# --------------------------------------------------------------------------------------------
# NumPy references (float64), on the material's RGLBRDF (``cdf`` is the loaded material's data)
# --------------------------------------------------------------------------------------------
def numpy_sample(b, wo, xi):
    """NumPy reference of :func:`sample` for an :class:`fit.formats.rgl.RGLBRDF` ``b``:
    ``(wi (N, 3), weight (N,))``, weight 0 where no sample."""
    wo = np.asarray(wo, float)
    xi = np.asarray(xi, float)
    lum = b.luminance_warp
    theta_t = np.arctan2(np.hypot(wo[:, 0], wo[:, 1]), wo[:, 2])
    phi_t = np.arctan2(wo[:, 1], wo[:, 0])
    t0, w1 = interval(b.theta_i, theta_t)
    sx, sy, p_lum = lum.sample(xi[:, 1], xi[:, 0], t0, w1)
    ux, uy, p_vndf = b.vndf_warp.sample(sx, sy, t0, w1)
    theta_m = ux * ux * np.pi / 2
    phi_m = (2 * uy - 1) * np.pi + phi_t
    st = np.sin(theta_m)
    wm = np.stack([np.cos(phi_m) * st, np.sin(phi_m) * st, np.cos(theta_m)], -1)
    c = np.sum(wm * wo, -1)
    jac = np.maximum(2 * np.pi**2 * ux * st, MIN_JACOBIAN) * 4 * c
    with np.errstate(divide="ignore", invalid="ignore"):
        p = p_vndf * p_lum / jac
    wi = 2 * c[:, None] * wm - wo
    ok = (c > 0) & (wi[:, 2] > 0) & (p > 0) & (wo[:, 2] > 0)
    return np.where(ok[:, None], wi, 0.0), np.where(ok, 1.0 / np.where(ok, p, 1.0), 0.0)


def numpy_pdf(b, wi, wo):
    """NumPy reference of :func:`pdf` (1/sr of the light ``wi`` given the view ``wo``)."""
    wi = np.asarray(wi, float)
    wo = np.asarray(wo, float)
    wm = wi + wo
    wm /= np.linalg.norm(wm, axis=-1, keepdims=True)
    theta_t = np.arctan2(np.hypot(wo[:, 0], wo[:, 1]), wo[:, 2])
    phi_t = np.arctan2(wo[:, 1], wo[:, 0])
    theta_m = np.arctan2(np.hypot(wm[:, 0], wm[:, 1]), wm[:, 2])
    umx = np.sqrt(theta_m * 2 / np.pi)
    umy = (np.arctan2(wm[:, 1], wm[:, 0]) - phi_t + np.pi) / (2 * np.pi)
    umy -= np.floor(umy)
    t0, w1 = interval(b.theta_i, theta_t)
    sx, sy, p_vndf = b.vndf_warp.invert(umx, umy, t0, w1)
    p_lum = b.luminance_warp.density(sx, sy, t0, w1)
    jac = np.maximum(2 * np.pi**2 * umx * np.hypot(wm[:, 0], wm[:, 1]), MIN_JACOBIAN) * 4 * np.sum(wo * wm, -1)
    ok = (wi[:, 2] > 0) & (wo[:, 2] > 0) & (jac > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok, np.maximum(p_vndf * p_lum / np.where(ok, jac, 1.0), 0.0), 0.0)
