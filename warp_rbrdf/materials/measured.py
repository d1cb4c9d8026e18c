"""``measured``: the 3-D (theta_h, theta_d, phi_d) table of :class:`fit.formats.measured.MeasuredBRDF`
(MERL ``.binary``, or an RGL ``.bsdf`` resampled onto the MERL grid), nearest bin exactly as the
MERL format defines it (:mod:`.frame`); ``scale`` multiplies it."""
from __future__ import annotations

import numpy as np
import warp as wp

from fit.formats import load_measured

from ..errors import SceneError
from .data import LoadedMaterial, Materials
from .frame import (
    N_PD,
    N_TD,
    half_diff,
    merl_phi_d_index,
    merl_theta_d_index,
    merl_theta_h_index,
)


def read(spec, scene_file, key):
    """The :class:`MeasuredBRDF` of a spec (``spec.data`` when given in memory, else its file)."""
    if spec.data is not None:
        return spec.data
    try:
        return load_measured(spec.file)
    except Exception as e:  # noqa: BLE001 - BRDFFileError and I/O errors, reported in one line
        raise SceneError(scene_file, f"{key}.file", f"cannot read measured BRDF ({e})") from None


def scaled(evaluate, scale):
    s = np.asarray(scale, float)
    return lambda wi, wo: np.asarray(evaluate(wi, wo), float) * s


def load(spec, scene_file="<scene>", key="materials") -> LoadedMaterial:
    b = read(spec, scene_file, key)
    return LoadedMaterial(spec, b, scaled(b.evaluate, spec.scale), scale=spec.scale, table=b.values)


@wp.func
def measured_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0)
    a = half_diff(wi, wo)
    i = merl_theta_h_index(a[0])
    j = merl_theta_d_index(a[1])
    k = merl_phi_d_index(a[2])
    v = mats.tables[mats.offset[m] + (i * N_TD + j) * N_PD + k]
    return wp.cw_mul(v, mats.scale[m])


def kernel_eval(loaded_list):
    return measured_eval
