"""``rgl``: an RGL-EPFL ``.bsdf`` file as a BSDF of the renderer, in one place: load (file ->
the material's tables), eval, sample and pdf (Dupuy & Jakob 2018; Mitsuba 3's ``measured``
plugin). It is both the ``rgl`` material kind and the ``rgl`` sampling technique of
:mod:`warp_rbrdf.registry`. :mod:`fit.formats.rgl` is the NumPy reference of the evaluation;
the format's warps are the ``Marginal2D`` of :mod:`warp_rbrdf.distribution`.

**Roles.** The scene key ``incident`` (default ``"view"``, the reference implementations'
roles) says which of (light, view) is the tensors' incident direction ``wt``; the other one is
``wx``. Directions in the local frame (z = normal), ``wo`` the view, ``wi`` the light; angles
in radians, densities in 1/sr.

**Eval**, exactly with the format's interpolation and no resampling: the micro-normal ``wm`` of
(wt, wx) at unit-square coordinates ``u_m = (sqrt(theta_m 2/pi), (phi_m - phi_t + pi) / 2 pi)``,
the inverse VNDF warp of ``u_m`` -> ``s``, the ``rgb`` tensor bilinear at ``s`` and linear in
theta_t, times ``ndf(u_m) / (4 sigma(theta_t, phi_t))``; rho = that / cos(theta_x), times
``scale``.

**Sample** (only with the view incident: it draws the light given the view; a scene with
``incident = "light"`` cannot use it, refused at load): two uniforms are warped by the
**luminance** warp (the luminance of the ``rgb`` tensor over ``s``), then by the **VNDF** warp to
``u_m``, i.e. ``theta_m = u_x^2 pi/2``, ``phi_m = phi_t + (2 u_y - 1) pi``, and the view is
reflected: ``wx = 2 (wm . wt) wm - wt``. Its density is exact, the reference's ``pdf``:

    pdf(wx) = p_vndf(u_m) p_lum(s) / (max(2 pi^2 u_x sin theta_m, 1e-6) * 4 (wt . wm))

The render kernel's lanes draw 16 such samples at once (:func:`make_sample_f_lanes`: the two
warps' searches stepped over the lanes, :mod:`warp_rbrdf.lanes`), each the sample above.

**Packing**: the material's float32 tables go to ``Materials.rgl_f`` (theta_i, the VNDF and
luminance warps as normalized densities with their conditional and marginal CDFs, rgb, ndf,
sigma) and a header of :data:`N_RGL_INFO` ints (fields ``RGL_*``: sizes and offsets into
``rgl_f``) to ``Materials.rgl_i``; ``Materials.offset[m]`` is the header's start.
"""
from __future__ import annotations

import functools

import numpy as np
import warp as wp

from fit.formats.rgl import read_rgl
from fit.formats.rgl_interpolants import interval

from .. import fastmath as fmath
from .. import registry
from ..distribution import bilinear_lerp, find_interval, marginal2d_invert, marginal2d_pdf, marginal2d_sample
from ..distribution.lanes import lane_types, lanes_out_type, make_marginal2d_sample_lanes
from ..errors import SceneError
from .data import LoadedMaterial, Materials

# header fields (ints at Materials.offset[m] + field)
RGL_N_THETA = 0      # theta_i slices
RGL_THETA = 1        # offset of theta_i (radians)
RGL_VNDF_NY = 2
RGL_VNDF_NX = 3
RGL_VNDF_DATA = 4    # offsets of the VNDF warp's normalized densities, conditional, marginal CDFs
RGL_VNDF_COND = 5
RGL_VNDF_MARG = 6
RGL_LUM_NY = 7       # the luminance warp: same layout, on the rgb grid
RGL_LUM_NX = 8
RGL_LUM_DATA = 9
RGL_LUM_COND = 10
RGL_LUM_MARG = 11
RGL_RGB = 12         # (n_theta, 3, lum_ny, lum_nx), negative entries clamped to 0
RGL_NDF_NY = 13
RGL_NDF_NX = 14
RGL_NDF = 15
RGL_SIGMA_NY = 16
RGL_SIGMA_NX = 17
RGL_SIGMA = 18
RGL_JACOBIAN = 19    # 1: multiply by ndf / (4 sigma)
RGL_VIEW_INCIDENT = 20   # 1: the view is the tensors' incident direction; 0: the light
N_RGL_INFO = 21
_OFFSET_FIELDS = (RGL_THETA, RGL_VNDF_DATA, RGL_VNDF_COND, RGL_VNDF_MARG, RGL_LUM_DATA,
                  RGL_LUM_COND, RGL_LUM_MARG, RGL_RGB, RGL_NDF, RGL_SIGMA)

RGL_CODE = registry.material("rgl").code
MIN_JACOBIAN = 1.0e-6


# --------------------------------------------------------------------------------------------
# Load
# --------------------------------------------------------------------------------------------
def pack(b) -> tuple:
    """``(floats, header)`` of an :class:`fit.formats.rgl.RGLBRDF`: the float32 tables and a
    function ``header(base) -> int32 (N_RGL_INFO,)`` with offsets relative to ``base``."""
    parts, at = [], {}
    size = 0

    def add(field_, a):
        nonlocal size
        a = np.ascontiguousarray(a, np.float32).ravel()
        at[field_] = size
        parts.append(a)
        size += a.size

    vndf, lum = b.vndf_warp, b.luminance_warp    # normalized densities, conditional, marginal
    ndf = np.asarray(b.fields["ndf"].data, np.float64)
    sigma = np.asarray(b.fields["sigma"].data, np.float64)
    add(RGL_THETA, b.theta_i)
    for (fd, fc, fm), w in (((RGL_VNDF_DATA, RGL_VNDF_COND, RGL_VNDF_MARG), vndf),
                            ((RGL_LUM_DATA, RGL_LUM_COND, RGL_LUM_MARG), lum)):
        add(fd, w.data)
        add(fc, w.cond)
        add(fm, w.marg)
    add(RGL_RGB, b.rgb)
    add(RGL_NDF, ndf)
    add(RGL_SIGMA, sigma)
    head = np.zeros(N_RGL_INFO, np.int32)
    head[RGL_N_THETA] = b.theta_i.size
    head[[RGL_VNDF_NY, RGL_VNDF_NX]] = vndf.ny, vndf.nx
    head[[RGL_LUM_NY, RGL_LUM_NX]] = lum.ny, lum.nx
    head[[RGL_NDF_NY, RGL_NDF_NX]] = ndf.shape
    head[[RGL_SIGMA_NY, RGL_SIGMA_NX]] = sigma.shape
    head[RGL_JACOBIAN] = int(b.jacobian)
    head[RGL_VIEW_INCIDENT] = int(b.incident == "view")
    for f, o in at.items():
        head[f] = o

    def header(base: int) -> np.ndarray:
        h = head.copy()
        h[list(_OFFSET_FIELDS)] += base
        return h

    return np.concatenate(parts), header


def read(spec, scene_file, key):
    """The :class:`fit.formats.rgl.RGLBRDF` of a spec (``spec.data`` in memory, else its file)."""
    if spec.data is not None:
        return spec.data
    try:
        return read_rgl(spec.file, incident=spec.incident)
    except Exception as e:  # noqa: BLE001 - BRDFFileError and I/O errors, one line
        raise SceneError(scene_file, f"{key}.file", f"cannot read RGL BRDF ({e})") from None


def load(spec, scene_file="<scene>", key="materials") -> LoadedMaterial:
    b = read(spec, scene_file, key)
    if b.incident != "view" and registry.strategy(spec.sampler).technique == "rgl":
        raise SceneError(scene_file, f"{key}.sampler",
                         f"sampler {spec.sampler!r} draws the light given the view, the tensors' "
                         f"incident direction; it needs incident = \"view\" (this material has "
                         f"{b.incident!r})")
    try:
        floats, header = pack(b)
    except ValueError as e:
        raise SceneError(scene_file, f"{key}.file", f"cannot build the RGL tables ({e})") from None
    s = np.asarray(spec.scale, float)
    return LoadedMaterial(spec, b, lambda wi, wo: np.asarray(b.evaluate(wi, wo), float) * s,
                          scale=spec.scale, rgl=(floats, header))


# --------------------------------------------------------------------------------------------
# The tables in the kernel (header at h = Materials.offset[m])
# --------------------------------------------------------------------------------------------
@wp.func
def elevation(w: wp.vec3) -> float:
    """theta of a unit vector (radians), accurate near the pole."""
    return fmath.atan2(wp.sqrt(w[0] * w[0] + w[1] * w[1]), w[2])


@wp.func
def theta_to_u(theta: float) -> float:
    return wp.sqrt(fmath.fmax(theta, 0.0) * (2.0 / wp.pi))


@wp.func
def phi_to_u(phi: float) -> float:
    u = (phi + wp.pi) * (0.5 / wp.pi)
    return u - wp.floor(u)


@wp.func
def theta_interval(mats: Materials, off: int, n: int, x: float) -> wp.vec2:
    """(t0, w1) of incidence ``x`` over the ``n`` sorted angles at ``rgl_f[off]`` (the reference's
    ``find_interval``): ``t0`` in [0, n-2] as a float, ``w1`` the clamped weight of slice
    ``t0 + 1``; (0, 0) for one slice."""
    if n < 2:
        return wp.vec2(0.0, 0.0)
    t0 = find_interval(mats.rgl_f, off, n, x)
    p0 = mats.rgl_f[off + t0]
    p1 = mats.rgl_f[off + t0 + 1]
    w1 = fmath.clamp((x - p0) / (p1 - p0), 0.0, 1.0)
    return wp.vec2(float(t0), w1)


@wp.func
def _incidence(mats: Materials, h: int, wt: wp.vec3) -> wp.vec4:
    """(t0, w1, phi_t, theta_t) of the tensors' incident direction ``wt``: its theta_i slice
    interval (``t0`` as a float, ``w1`` the weight of slice ``t0 + 1``), azimuth, elevation."""
    theta_t = elevation(wt)
    tw = theta_interval(mats, mats.rgl_i[h + RGL_THETA], mats.rgl_i[h + RGL_N_THETA], theta_t)
    return wp.vec4(tw[0], tw[1], fmath.atan2(wt[1], wt[0]), theta_t)


@wp.func
def _vndf_invert(mats: Materials, h: int, n: int, t0: int, w1: float, umx: float, umy: float) -> wp.vec3:
    """(sx, sy, p_vndf): the inverse VNDF warp of the micro-normal coordinates (umx, umy)."""
    return marginal2d_invert(mats.rgl_f, mats.rgl_i[h + RGL_VNDF_DATA], mats.rgl_i[h + RGL_VNDF_COND],
                             mats.rgl_i[h + RGL_VNDF_MARG], mats.rgl_i[h + RGL_VNDF_NY],
                             mats.rgl_i[h + RGL_VNDF_NX], n, t0, w1, umx, umy)


@wp.func
def _lum_pdf(mats: Materials, h: int, n: int, t0: int, w1: float, sx: float, sy: float) -> float:
    """Density of the luminance warp at (sx, sy)."""
    return marginal2d_pdf(mats.rgl_f, mats.rgl_i[h + RGL_LUM_DATA], mats.rgl_i[h + RGL_LUM_NY],
                          mats.rgl_i[h + RGL_LUM_NX], n, t0, w1, sx, sy)


@wp.func
def _value(mats: Materials, h: int, n: int, t0: int, w1: float, theta_t: float, phi_t: float,
           umx: float, umy: float, sx: float, sy: float) -> wp.vec3:
    """The reference value (f_r cos theta_x, clamped to 0) from the warped coordinates: the
    rgb tensor at (sx, sy), times ndf(umx, umy) / (4 sigma(theta_t, phi_t))."""
    ny = mats.rgl_i[h + RGL_LUM_NY]
    nx = mats.rgl_i[h + RGL_LUM_NX]
    plane = ny * nx
    stride = 0
    if n > 1:
        stride = 3 * plane
    rgb = mats.rgl_i[h + RGL_RGB]
    v = wp.vec3(0.0)
    for c in range(3):
        v[c] = bilinear_lerp(mats.rgl_f, rgb + (t0 * 3 + c) * plane, ny, nx, stride, w1, sx, sy)
    if mats.rgl_i[h + RGL_JACOBIAN] != 0:
        ndf = bilinear_lerp(mats.rgl_f, mats.rgl_i[h + RGL_NDF], mats.rgl_i[h + RGL_NDF_NY],
                            mats.rgl_i[h + RGL_NDF_NX], 0, 0.0, umx, umy)
        sig = bilinear_lerp(mats.rgl_f, mats.rgl_i[h + RGL_SIGMA], mats.rgl_i[h + RGL_SIGMA_NY],
                            mats.rgl_i[h + RGL_SIGMA_NX], 0, 0.0, theta_to_u(theta_t), phi_to_u(phi_t))
        v = v * (ndf / (4.0 * sig))
    return wp.vec3(fmath.fmax(v[0], 0.0), fmath.fmax(v[1], 0.0), fmath.fmax(v[2], 0.0))


@wp.func
def _pdf_at(st: float, umx: float, cos_tm: float, p_vndf: float, p_lum: float) -> float:
    """The sample's density in 1/sr from the warps' densities: the Jacobians of the (theta_m,
    phi_m) parametrization (``st`` = sin theta_m) and of the reflection (``cos_tm`` = wt . wm)."""
    jac = fmath.fmax(2.0 * wp.pi * wp.pi * umx * st, MIN_JACOBIAN) * 4.0 * cos_tm
    if jac <= 0.0:
        return 0.0
    return fmath.fmax(p_vndf * p_lum / jac, 0.0)


# --------------------------------------------------------------------------------------------
# Eval
# --------------------------------------------------------------------------------------------
@wp.func
def rgl_reference_eval(mats: Materials, h: int, wt: wp.vec3, wx: wp.vec3) -> wp.vec3:
    """The reference ``eval`` (f_r cos(theta_x)) of the material with header ``h`` for the
    tensors' incident direction ``wt`` and the other direction ``wx`` (both above the plane)."""
    s = wt + wx
    wm = s / wp.length(s)
    theta_t = elevation(wt)
    phi_t = fmath.atan2(wt[1], wt[0])
    umx = theta_to_u(elevation(wm))
    umy = phi_to_u(fmath.atan2(wm[1], wm[0]) - phi_t)
    n = mats.rgl_i[h + RGL_N_THETA]
    tw = theta_interval(mats, mats.rgl_i[h + RGL_THETA], n, theta_t)
    t0 = int(tw[0])
    w1 = tw[1]
    sw = _vndf_invert(mats, h, n, t0, w1, umx, umy)
    return _value(mats, h, n, t0, w1, theta_t, phi_t, umx, umy, sw[0], sw[1])


@wp.func
def rgl_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0)
    h = mats.offset[m]
    wt = wi
    wx = wo
    if mats.rgl_i[h + RGL_VIEW_INCIDENT] != 0:
        wt = wo
        wx = wi
    v = rgl_reference_eval(mats, h, wt, wx)
    return wp.cw_mul(v, mats.scale[m]) / wx[2]


def kernel_eval(loaded_list):
    return rgl_eval


# --------------------------------------------------------------------------------------------
# Sample and pdf (the view incident)
# --------------------------------------------------------------------------------------------
@wp.func
def _warps(mats: Materials, h: int, n: int, t0: int, w1: float, xi: wp.vec2):
    """``(s, u)``: the luminance warp's output ``s`` of the uniforms ``xi`` and the VNDF warp's
    output ``u`` of ``s`` (x, y, density each; theta_i slice ``t0``, weight ``w1``)."""
    s = marginal2d_sample(mats.rgl_f, mats.rgl_i[h + RGL_LUM_DATA], mats.rgl_i[h + RGL_LUM_COND],
                          mats.rgl_i[h + RGL_LUM_MARG], mats.rgl_i[h + RGL_LUM_NY],
                          mats.rgl_i[h + RGL_LUM_NX], n, t0, w1, xi[1], xi[0])
    u = marginal2d_sample(mats.rgl_f, mats.rgl_i[h + RGL_VNDF_DATA], mats.rgl_i[h + RGL_VNDF_COND],
                          mats.rgl_i[h + RGL_VNDF_MARG], mats.rgl_i[h + RGL_VNDF_NY],
                          mats.rgl_i[h + RGL_VNDF_NX], n, t0, w1, s[0], s[1])
    return s, u


@wp.func
def _draw(phi_t: float, wo: wp.vec3, s: wp.vec3, u: wp.vec3):
    """The format's sample for view ``wo`` (azimuth ``phi_t``) from the two warps' outputs
    (:func:`_warps`): ``(wi, pdf, ok, phi_m)`` -- the light, its density in 1/sr, 1 when the
    sample is usable (above both horizons, finite positive pdf) and the micro-normal's azimuth."""
    theta_m = u[0] * u[0] * wp.HALF_PI
    phi_m = (2.0 * u[1] - 1.0) * wp.pi + phi_t
    sct = fmath.sincos(theta_m)
    scp = fmath.sincos(phi_m)
    st = sct[0]
    wm = wp.vec3(scp[1] * st, scp[0] * st, sct[1])
    c = wp.dot(wm, wo)
    jac = fmath.fmax(2.0 * wp.pi * wp.pi * u[0] * st, MIN_JACOBIAN) * 4.0 * c
    p = u[2] * s[2] / jac
    wi = wm * (2.0 * c) - wo
    ok = int(1)  # noqa: UP018, RUF046 - a Warp variable assigned in a branch
    if c <= 0.0 or wi[2] <= 0.0 or not (p > 0.0) or p > 1.0e30:
        ok = 0
    return wi, p, ok, phi_m


@wp.func
def _sample_f_from(mats: Materials, m: int, h: int, n: int, inc: wp.vec4, wo: wp.vec3, s: wp.vec3, u: wp.vec3):
    """:func:`sample_f`'s result from the two warps' outputs (``inc``: :func:`_incidence` of
    ``wo``)."""
    wi, pdf_s, ok, phi_m = _draw(inc[2], wo, s, u)
    if ok == 0:
        return wp.vec4(0.0), wp.vec3(0.0), 1
    return wp.vec4(wi[0], wi[1], wi[2], 1.0 / pdf_s), _drawn_value(mats, m, h, n, inc, s, u, wi, phi_m), 1


@wp.func
def _drawn_value(mats: Materials, m: int, h: int, n: int, inc: wp.vec4, s: wp.vec3, u: wp.vec3, wi: wp.vec3,
                 phi_m: float) -> wp.vec3:
    """f_r at a usable sample of :func:`_draw` (light ``wi``, micro-normal azimuth ``phi_m``)."""
    v = _value(mats, h, n, int(inc[0]), inc[1], inc[3], inc[2], u[0], phi_to_u(phi_m - inc[2]), s[0], s[1])
    return wp.cw_mul(v, mats.scale[m]) / wi[2]


@wp.func
def _view_incident(mats: Materials, m: int) -> int:
    """1: material ``m`` is an rgl material whose view is the tensors' incident direction."""
    if mats.kind[m] != wp.static(RGL_CODE):
        return 0
    return mats.rgl_i[mats.offset[m] + RGL_VIEW_INCIDENT]


@wp.func
def sample_f(mats: Materials, m: int, wo: wp.vec3, xi: wp.vec2):
    """:func:`sample` and f_r at the sampled light (``(vec4 sample, vec3 f, 1)``; a zero sample
    where there is none). The value is read at the luminance warp's output, the point the
    inverse VNDF warp of the sampled micro-normal returns (up to rounding), so no inverse warp
    is needed."""
    if _view_incident(mats, m) == 0 or wo[2] <= 0.0:
        return wp.vec4(0.0), wp.vec3(0.0), 1
    h = mats.offset[m]
    inc = _incidence(mats, h, wo)
    n = mats.rgl_i[h + RGL_N_THETA]
    s, u = _warps(mats, h, n, int(inc[0]), inc[1], xi)
    return _sample_f_from(mats, m, h, n, inc, wo, s, u)


@wp.func
def sample(mats: Materials, m: int, wo: wp.vec3, xi: wp.vec2) -> wp.vec4:
    """(wi, 1/pdf) of the format's sample; zero where there is none."""
    if _view_incident(mats, m) == 0 or wo[2] <= 0.0:
        return wp.vec4(0.0)
    h = mats.offset[m]
    inc = _incidence(mats, h, wo)
    s, u = _warps(mats, h, mats.rgl_i[h + RGL_N_THETA], int(inc[0]), inc[1], xi)
    wi, p, ok, _phi_m = _draw(inc[2], wo, s, u)
    if ok == 0:
        return wp.vec4(0.0)
    return wp.vec4(wi[0], wi[1], wi[2], 1.0 / p)


@wp.func
def eval_pdf(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3):
    """f_r and :func:`pdf` at one direction pair with one inverse VNDF warp (``(vec3 f, float
    pdf, 1)``; ``0`` last: not an rgl material with the view incident, use the material's eval
    and :func:`pdf`)."""
    if _view_incident(mats, m) == 0:
        return wp.vec3(0.0), 0.0, 0
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0), 0.0, 1
    h = mats.offset[m]
    sv = wi + wo
    wm = sv / wp.length(sv)
    inc = _incidence(mats, h, wo)
    t0 = int(inc[0])
    n = mats.rgl_i[h + RGL_N_THETA]
    umx = theta_to_u(elevation(wm))
    umy = phi_to_u(fmath.atan2(wm[1], wm[0]) - inc[2])
    sw = _vndf_invert(mats, h, n, t0, inc[1], umx, umy)
    v = _value(mats, h, n, t0, inc[1], inc[3], inc[2], umx, umy, sw[0], sw[1])
    p = _pdf_at(wp.sqrt(wm[0] * wm[0] + wm[1] * wm[1]), umx, wp.dot(wo, wm), sw[2],
                _lum_pdf(mats, h, n, t0, inc[1], sw[0], sw[1]))
    return wp.cw_mul(v, mats.scale[m]) / wi[2], p, 1


@wp.func
def pdf(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> float:
    """Density (1/sr) of :func:`sample` at the light ``wi``; 0 at or below either horizon."""
    if _view_incident(mats, m) == 0 or wi[2] <= 0.0 or wo[2] <= 0.0:
        return 0.0
    h = mats.offset[m]
    sv = wi + wo
    wm = sv / wp.length(sv)
    inc = _incidence(mats, h, wo)
    t0 = int(inc[0])
    n = mats.rgl_i[h + RGL_N_THETA]
    umx = theta_to_u(elevation(wm))
    umy = phi_to_u(fmath.atan2(wm[1], wm[0]) - inc[2])
    sw = _vndf_invert(mats, h, n, t0, inc[1], umx, umy)
    return _pdf_at(wp.sqrt(wm[0] * wm[0] + wm[1] * wm[1]), umx, wp.dot(wo, wm), sw[2],
                   _lum_pdf(mats, h, n, t0, inc[1], sw[0], sw[1]))


def kernel_functions(cdfs=()):
    """``(sample, pdf)``: the technique's Warp functions (:mod:`warp_rbrdf.techniques`)."""
    return sample, pdf


def kernel_fused(cdfs=()):
    """``(sample_f, eval_pdf)``: the sample with f_r at its direction, and f_r with the pdf at
    one pair, each sharing the warps (the integrator's per-sample cost; optional in the
    technique interface, :func:`warp_rbrdf.integrator.make_bsdf_sampling`)."""
    return sample_f, eval_pdf



@functools.lru_cache(maxsize=None)
def make_sample_f_lanes(K: int):
    """``sample_f_lanes(mats, m, wox, woy, woz, xi0, xi1, on) -> out``: :func:`sample_f` of
    ``K`` lanes of material ``m`` (views and uniforms as float lanes, ``on`` int lanes: 0 = an
    idle lane, whose result is zero), its two warps drawn for all lanes at once
    (:func:`warp_rbrdf.distribution.lanes.make_marginal2d_sample_lanes`); ``out`` a ``(8, K)``
    matrix, per lane ``(wi, 1 / pdf, f_r, 1)`` -- :func:`sample_f`'s sample and value. Cached: one
    function per ``K``."""
    vf, vi = lane_types(K)
    out_t = lanes_out_type(K)
    warp_lanes = make_marginal2d_sample_lanes(K)

    @wp.func
    def sample_f_lanes(mats: Materials, m: int, wox: vf, woy: vf, woz: vf, xi0: vf, xi1: vf, on: vi) -> out_t:
        out = out_t()
        if _view_incident(mats, m) == 0:
            return out
        h = mats.offset[m]
        n = mats.rgl_i[h + RGL_N_THETA]
        go = vi()
        t0 = vi()
        w1 = vf()
        phi = vf()
        theta = vf()
        sx = vf()
        sy = vf()
        i = int(0)  # noqa: UP018, RUF046 - a Warp loop variable
        while i < K:             # loops, not unrolled: one copy of each step's code
            sx[i] = 0.5
            sy[i] = 0.5
            if on[i] != 0 and woz[i] > 0.0:
                inc = _incidence(mats, h, wp.vec3(wox[i], woy[i], woz[i]))
                go[i] = 1
                t0[i] = int(inc[0])
                w1[i] = inc[1]
                phi[i] = inc[2]
                theta[i] = inc[3]
                sx[i] = xi1[i]
                sy[i] = xi0[i]
            i += 1
        s0, s1, s2 = warp_lanes(mats.rgl_f, mats.rgl_i[h + RGL_LUM_DATA], mats.rgl_i[h + RGL_LUM_COND],
                                mats.rgl_i[h + RGL_LUM_MARG], mats.rgl_i[h + RGL_LUM_NY],
                                mats.rgl_i[h + RGL_LUM_NX], n, t0, w1, sx, sy)
        u0, u1, u2 = warp_lanes(mats.rgl_f, mats.rgl_i[h + RGL_VNDF_DATA], mats.rgl_i[h + RGL_VNDF_COND],
                                mats.rgl_i[h + RGL_VNDF_MARG], mats.rgl_i[h + RGL_VNDF_NY],
                                mats.rgl_i[h + RGL_VNDF_NX], n, t0, w1, s0, s1)
        pm = vf()
        i = int(0)  # noqa: UP018, RUF046 - a Warp loop variable
        while i < K:             # the samples' directions, then their values: the value's loads back to back
            out[7, i] = 1.0
            if go[i] != 0:
                wi, pdf_s, ok, phi_m = _draw(phi[i], wp.vec3(wox[i], woy[i], woz[i]), wp.vec3(s0[i], s1[i], s2[i]),
                                             wp.vec3(u0[i], u1[i], u2[i]))
                go[i] = ok
                if ok != 0:
                    out[0, i] = wi[0]
                    out[1, i] = wi[1]
                    out[2, i] = wi[2]
                    out[3, i] = 1.0 / pdf_s
                    pm[i] = phi_m
            i += 1
        i = int(0)  # noqa: UP018, RUF046 - a Warp loop variable
        while i < K:
            if go[i] != 0:
                f = _drawn_value(mats, m, h, n, wp.vec4(float(t0[i]), w1[i], phi[i], theta[i]),
                                 wp.vec3(s0[i], s1[i], s2[i]), wp.vec3(u0[i], u1[i], u2[i]),
                                 wp.vec3(out[0, i], out[1, i], out[2, i]), pm[i])
                out[4, i] = f[0]
                out[5, i] = f[1]
                out[6, i] = f[2]
            i += 1
        return out

    return sample_f_lanes


def kernel_lanes(K: int, cdfs=()):
    """:func:`make_sample_f_lanes`: the technique's sample with f_r over ``K`` lanes (optional in
    the technique interface; :func:`warp_rbrdf.integrator.make_kernels`)."""
    return make_sample_f_lanes(K)

# --------------------------------------------------------------------------------------------
# NumPy references of the technique (float64), on the material's RGLBRDF ``b``
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
