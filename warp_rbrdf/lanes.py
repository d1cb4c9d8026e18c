"""The render kernel's lanes: the first vertex's BSDF samples of ``K`` samples of a pixel drawn
together (:func:`warp_rbrdf.integrator.make_kernels`), through the lane forms of the techniques
that have one (a technique module's optional ``kernel_lanes(K, fits)``: the ``rgl`` technique,
:func:`warp_rbrdf.materials.rgl.make_sample_f_lanes`). A lane form draws ``K`` samples at once
so that the independent loads of their binary searches overlap (``docs/cpu_lanes.md``); its
samples are the one-at-a-time technique's, so a render does not depend on the lanes.

No ``from __future__ import annotations`` here: Warp reads the lane functions' argument types
from their annotations, which name this module's closure types.
"""
import warp as wp

from . import geometry as G
from .distribution.lanes import lane_types, lanes_out_type
from .materials.data import Materials

#: samples of a pixel the render kernel advances together where a technique has a lane form
#: (``kernel_lanes``: the ``rgl`` technique); 0 or 1: one at a time
LANES = 16
#: the 2-D sample dimension of the first vertex's BSDF sample (``dim + 1`` of the integrator's
#: ``radiance_sample`` at depth 0)
FIRST_BSDF_DIM = 2
#: rows of a lane's state: camera ray, (hit, t, material), geometric and shading normals
LS_D, LS_HIT, LS_T, LS_M, LS_NG, LS_NS = 0, 3, 4, 5, 6, 9
N_LANE_STATE = 12


@wp.func
def _no_lane_technique(t: int) -> bool:
    return False


def make_lanes_sampling(lane_techniques, K: int):
    """``(lanes_sample_f, is_lane_technique)`` over ``lane_techniques``: (code, the technique's
    lane function of ``K`` lanes: ``(mats, m, wox, woy, woz, xi0, xi1, on) -> (7, K)``, e.g.
    :func:`warp_rbrdf.materials.rgl.make_sample_f_lanes`), selected by the technique code."""
    out_t = lanes_out_type(K)
    vf, vi = lane_types(K)
    if not lane_techniques:
        @wp.func
        def no_lanes(mats: Materials, m: int, t: int, wox: vf, woy: vf, woz: vf, xi0: vf, xi1: vf, on: vi) -> out_t:
            return out_t()

        return no_lanes, _no_lane_technique
    code, func = lane_techniques[0]
    rest, rest_is = make_lanes_sampling(lane_techniques[1:], K)

    @G.inline_func
    def lanes_sample_f(mats: Materials, m: int, t: int, wox: vf, woy: vf, woz: vf, xi0: vf, xi1: vf, on: vi) -> out_t:
        if t == wp.static(code):
            return wp.static(func)(mats, m, wox, woy, woz, xi0, xi1, on)
        return wp.static(rest)(mats, m, t, wox, woy, woz, xi0, xi1, on)

    @G.inline_func
    def is_lane_technique(t: int) -> bool:
        if t == wp.static(code):
            return True
        return wp.static(rest_is)(t)

    return lanes_sample_f, is_lane_technique
