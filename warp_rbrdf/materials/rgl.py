"""``rgl``: an RGL-EPFL ``.bsdf`` file evaluated exactly in the kernel with the format's own
interpolation -- the inverse VNDF warp of the incidence, the ``rgb`` tensor bilinear over the
warped coordinates and linear in theta_i, the ``ndf / (4 sigma)`` factor -- with no resampling
(:mod:`fit.formats.rgl` is the NumPy reference; the Warp interpolants are
:mod:`.rgl_tables`). It is the reference representation the others are measured against; its
own importance sampling is the ``rgl`` technique (:mod:`warp_rbrdf.techniques.rgl`).

Roles: the scene key ``incident`` (default ``"view"``, the reference implementations' roles)
says which of (light, view) is the tensors' incident direction ``wt``; the other one is ``wx``
and rho = reference value / cos(theta_x). ``scale`` multiplies the result.

Packing: the material's floats go to ``Materials.rgl_f`` (theta_i, the VNDF and luminance warps
as normalized densities with their conditional and marginal CDFs, rgb, ndf, sigma) and a header
of :data:`N_RGL_INFO` ints (fields ``RGL_*``; offsets into ``rgl_f``) to ``Materials.rgl_i``;
``Materials.offset[m]`` is the header's start.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from fit.formats.rgl import read_rgl

from .. import fastmath as fmath
from .. import registry
from ..errors import SceneError
from .data import LoadedMaterial, Materials
from .rgl_tables import bilinear, rgb_eval, theta_interval, warp_invert

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


@wp.func
def elevation(w: wp.vec3) -> float:
    """theta of a unit vector (radians), accurate near the pole."""
    return fmath.atan2(wp.sqrt(w[0] * w[0] + w[1] * w[1]), w[2])


@wp.func
def theta_to_u(theta: float) -> float:
    return wp.sqrt(wp.max(theta, 0.0) * (2.0 / wp.pi))


@wp.func
def phi_to_u(phi: float) -> float:
    u = (phi + wp.pi) * (0.5 / wp.pi)
    return u - wp.floor(u)


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
    sw = warp_invert(mats, mats.rgl_i[h + RGL_VNDF_DATA], mats.rgl_i[h + RGL_VNDF_COND],
                     mats.rgl_i[h + RGL_VNDF_MARG], mats.rgl_i[h + RGL_VNDF_NY],
                     mats.rgl_i[h + RGL_VNDF_NX], n, t0, w1, umx, umy)
    v = rgb_eval(mats, mats.rgl_i[h + RGL_RGB], mats.rgl_i[h + RGL_LUM_NY], mats.rgl_i[h + RGL_LUM_NX],
                 n, t0, w1, sw[0], sw[1])
    if mats.rgl_i[h + RGL_JACOBIAN] != 0:
        ndf = bilinear(mats, mats.rgl_i[h + RGL_NDF], mats.rgl_i[h + RGL_NDF_NY],
                       mats.rgl_i[h + RGL_NDF_NX], umx, umy)
        sig = bilinear(mats, mats.rgl_i[h + RGL_SIGMA], mats.rgl_i[h + RGL_SIGMA_NY],
                       mats.rgl_i[h + RGL_SIGMA_NX], theta_to_u(theta_t), phi_to_u(phi_t))
        v = v * (ndf / (4.0 * sig))
    return wp.vec3(wp.max(v[0], 0.0), wp.max(v[1], 0.0), wp.max(v[2], 0.0))


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
