"""``projected``: the 2-D (theta_h, theta_d) table of :class:`fit.projection.projected.ProjectedBRDF`
(an ``.npz`` from ``rbrdf-fit project``, or a measured file projected at load with ``statistic``),
nearest cluster; empty clusters give 0; ``scale`` multiplies it."""
from __future__ import annotations

import numpy as np
import warp as wp

from fit.projection.projected import ProjectedBRDF
from fit.projection.project import project

from ..errors import SceneError
from . import measured
from .data import LoadedMaterial, Materials
from .frame import N_TD, half_diff, merl_theta_d_index, merl_theta_h_index


def load(spec, scene_file="<scene>", key="materials") -> LoadedMaterial:
    if spec.data is not None:
        p = spec.data
    elif spec.file.suffix.lower() == ".npz":
        try:
            p = ProjectedBRDF.load(spec.file)
        except Exception as e:  # noqa: BLE001 - one line
            raise SceneError(scene_file, f"{key}.file", f"cannot read projected BRDF ({e})") from None
    else:
        p = project(measured.read(spec, scene_file, key), statistic=spec.statistic)
    return LoadedMaterial(spec, p, measured.scaled(p.evaluate, spec.scale), scale=spec.scale,
                          table=np.nan_to_num(p.value, nan=0.0))


@wp.func
def projected_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0)
    a = half_diff(wi, wo)
    i = merl_theta_h_index(a[0])
    j = merl_theta_d_index(a[1])
    v = mats.tables[mats.offset[m] + i * N_TD + j]
    return wp.cw_mul(v, mats.scale[m])


def kernel_eval(loaded_list):
    return projected_eval
