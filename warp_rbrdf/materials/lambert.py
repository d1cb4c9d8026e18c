"""``lambert``: rho = albedo / pi (1/sr), the same for every direction pair above the horizon."""
from __future__ import annotations

import numpy as np
import warp as wp

from .data import LoadedMaterial, Materials


def load(spec, scene_file="<scene>", key="materials") -> LoadedMaterial:
    rho = np.asarray(spec.albedo, float) / np.pi

    def evaluate(wi, wo):
        wi, wo = np.asarray(wi, float), np.asarray(wo, float)
        above = (wi[..., 2:3] > 0) & (wo[..., 2:3] > 0)
        return np.broadcast_to(rho, np.broadcast_shapes(wi.shape, wo.shape)[:-1] + (3,)) * above

    return LoadedMaterial(spec, None, evaluate, scale=spec.albedo)


@wp.func
def lambert_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0)
    return mats.scale[m] * (1.0 / wp.pi)


def kernel_eval(loaded_list):
    return lambert_eval
