"""``measured``: the 3-D (theta_h, theta_d, phi_d) table of :class:`fit.formats.measured.MeasuredBRDF`
(MERL ``.binary``, or an RGL ``.bsdf`` resampled onto the MERL grid), nearest bin exactly as
:meth:`MeasuredBRDF.evaluate` (:mod:`.frame`); ``scale`` multiplies it.

``Materials.param[m]`` is the table's number of phi_d bins: 180 for a MERL file (phi_d folded
into [0, pi) by reciprocity, as the format defines), 360 for an RGL file (phi_d over [0, 2 pi),
not folded: the files are not reciprocal, and folding would give half of the (light, view)
pairs the value of (view, light), a visible seam). The kernel folds only when it is 180."""
from __future__ import annotations

import numpy as np
import warp as wp

from fit.formats import load_measured

from ..errors import SceneError
from .data import LoadedMaterial, Materials
from .frame import (
    N_TD,
    half_diff,
    merl_phi_d_index,
    merl_theta_d_index,
    merl_theta_h_index,
)


#: ``Materials.param`` of a measured material: n_phi_d + PARAM_DIVIDE * divide_by, divide_by 0
#: (the table holds rho), 1 (f cos(theta_light): divide by the light's cosine), 2 (the view's)
#: (:attr:`fit.formats.measured.MeasuredBRDF.kernel_table`).
PARAM_DIVIDE = 1000


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
    return LoadedMaterial(spec, b, scaled(b.evaluate, spec.scale), scale=spec.scale, table=table,
                          param=b.n_phi_d + PARAM_DIVIDE * divide_by)


@wp.func
def measured_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0)
    a = half_diff(wi, wo)
    i = merl_theta_h_index(a[0])
    j = merl_theta_d_index(a[1])
    p = mats.param[m]
    n_pd = p % PARAM_DIVIDE      # 180: folded by reciprocity, 360: full circle
    divide_by = p // PARAM_DIVIDE
    k = merl_phi_d_index(a[2], n_pd)
    v = mats.tables[mats.offset[m] + (i * N_TD + j) * n_pd + k]
    if divide_by == 1:           # the table holds f cos(theta_light) (RGL-derived, view incident)
        v = v / wi[2]
    elif divide_by == 2:         # f cos(theta_view) (RGL-derived, light incident)
        v = v / wo[2]
    return wp.cw_mul(v, mats.scale[m])


def kernel_eval(loaded_list):
    return measured_eval
