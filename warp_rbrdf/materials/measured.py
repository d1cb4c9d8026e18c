"""``measured``: the 3-D (theta_h, theta_d, phi_d) table of :class:`fit.formats.measured.MeasuredBRDF`
(MERL ``.binary``, or an RGL ``.bsdf`` resampled onto the MERL grid), read exactly as
:meth:`MeasuredBRDF.evaluate` with the material's ``interpolation``: ``"linear"`` (default,
trilinear between the 8 bin centres around the point, in the grid's own coordinates:
square-root spaced theta_h, periodic phi_d; bins without a sample left out) or ``"nearest"``
(the bin the point falls in, the MERL reference code's lookup; :mod:`.frame`); ``scale``
multiplies it.

``Materials.param[m]`` is the table's number of phi_d bins: 180 for a MERL file (phi_d folded
into [0, pi) by reciprocity, as the format defines), 360 for an RGL file (phi_d over [0, 2 pi),
not folded: the files are not reciprocal, and folding would give half of the (light, view)
pairs the value of (view, light), a visible seam). The kernel folds only when it is 180."""
from __future__ import annotations

from functools import partial

import numpy as np
import warp as wp

from fit.formats import load_measured

from .. import fastmath as fmath
from ..errors import SceneError
from .data import LoadedMaterial, Materials
from .frame import (
    N_TD,
    N_TH,
    half_diff,
    merl_phi_d_index,
    merl_phi_d_wrap,
    merl_theta_d_index,
    merl_theta_h_index,
)


#: ``Materials.param`` of a measured material: n_phi_d + PARAM_DIVIDE * divide_by +
#: PARAM_NEAREST * nearest; divide_by 0 (the table holds rho, -1 in bins without a sample),
#: 1 (f cos(theta_light): divide by the light's cosine), 2 (the view's)
#: (:attr:`fit.formats.measured.MeasuredBRDF.kernel_table`); nearest 1 for ``"nearest"``.
PARAM_DIVIDE = 1000
PARAM_NEAREST = 10000


def read(spec, scene_file, key):
    """The :class:`MeasuredBRDF` of a spec (``spec.data`` when given in memory, else its file)."""
    if spec.data is not None:
        return spec.data
    try:
        return load_measured(spec.file, incident=getattr(spec, "incident", "view"))
    except Exception as e:  # noqa: BLE001 - BRDFFileError and I/O errors, reported in one line
        raise SceneError(scene_file, f"{key}.file", f"cannot read measured BRDF ({e})") from None


def scaled(evaluate, scale):
    s = np.asarray(scale, float)
    return lambda wi, wo: np.asarray(evaluate(wi, wo), float) * s


def load(spec, scene_file="<scene>", key="materials") -> LoadedMaterial:
    b = read(spec, scene_file, key)
    table, divide_by = b.kernel_table
    interpolation = getattr(spec, "interpolation", "linear")
    nearest = int(interpolation == "nearest")
    return LoadedMaterial(spec, b, scaled(partial(b.evaluate, interpolation=interpolation), spec.scale),
                          scale=spec.scale, table=table,
                          param=b.n_phi_d + PARAM_DIVIDE * divide_by + PARAM_NEAREST * nearest)


@wp.func
def measured_trilinear(mats: Materials, base: int, a: wp.vec3, n_pd: int) -> wp.vec3:
    """The table at ``base`` read trilinearly at Rusinkiewicz angles ``a`` (theta_h, theta_d,
    phi_d in (-pi, pi]) between the 8 bin centres around it (:func:`fit.formats.grid.
    trilinear_corners`): theta_h and theta_d clamped to the first and last centres, phi_d
    periodic over the table's n_pd bins; a channel's bins below 0 (no sample) are left out and
    the other weights renormalised."""
    u = fmath.clamp(wp.sqrt(fmath.fmax(a[0], 0.0) / wp.HALF_PI) * 90.0 - 0.5, 0.0, float(N_TH - 1))
    v = fmath.clamp(a[1] / wp.HALF_PI * 90.0 - 0.5, 0.0, float(N_TD - 1))
    w = merl_phi_d_wrap(a[2], n_pd) / wp.pi * 180.0 - 0.5
    i0 = fmath.fmin(int(wp.floor(u)), N_TH - 2)
    j0 = fmath.fmin(int(wp.floor(v)), N_TD - 2)
    kf = wp.floor(w)
    fu = u - float(i0)
    fv = v - float(j0)
    fw = w - kf
    k0 = int(kf)
    if k0 < 0:
        k0 = k0 + n_pd
    k1 = k0 + 1
    if k1 >= n_pd:
        k1 = k1 - n_pd
    acc = wp.vec3(0.0)
    ws = wp.vec3(0.0)
    for c in range(8):
        di = c // 4
        dj = (c // 2) % 2
        dk = c % 2
        wt = wp.where(di == 1, fu, 1.0 - fu) * wp.where(dj == 1, fv, 1.0 - fv)
        k = k0
        if dk == 1:
            k = k1
            wt = wt * fw
        else:
            wt = wt * (1.0 - fw)
        val = mats.tables[base + ((i0 + di) * N_TD + j0 + dj) * n_pd + k]
        for ch in range(3):
            if val[ch] >= 0.0:
                acc[ch] = acc[ch] + wt * val[ch]
                ws[ch] = ws[ch] + wt
    out = wp.vec3(0.0)
    for ch in range(3):
        if ws[ch] > 0.0:
            out[ch] = acc[ch] / ws[ch]
    return out


@wp.func
def measured_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0)
    a = half_diff(wi, wo)
    p = mats.param[m]
    n_pd = p % PARAM_DIVIDE      # 180: folded by reciprocity, 360: full circle
    divide_by = (p // PARAM_DIVIDE) % 10
    v = wp.vec3(0.0)
    if p >= PARAM_NEAREST:       # interpolation = "nearest"
        i = merl_theta_h_index(a[0])
        j = merl_theta_d_index(a[1])
        k = merl_phi_d_index(a[2], n_pd)
        v = wp.max(mats.tables[mats.offset[m] + (i * N_TD + j) * n_pd + k], wp.vec3(0.0))
    else:
        v = measured_trilinear(mats, mats.offset[m], a, n_pd)
    if divide_by == 1:           # the table holds f cos(theta_light) (RGL-derived, view incident)
        v = v / wi[2]
    elif divide_by == 2:         # f cos(theta_view) (RGL-derived, light incident)
        v = v / wo[2]
    return wp.cw_mul(v, mats.scale[m])


def kernel_eval(loaded_list):
    return measured_eval
