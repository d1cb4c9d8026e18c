"""The render kernel's lanes (:func:`warp_rbrdf.integrator.make_kernels`): ``K`` samples of a
pixel advance together through their camera rays and first hits, then the first vertex's
environment samples of all of them (:mod:`warp_rbrdf.lights.env_lanes`: every material whose
strategy samples the environment) and its BSDF samples where the material's technique has a
lane form (a technique module's optional ``kernel_lanes(K, fits)``: the ``rgl`` technique,
:func:`warp_rbrdf.materials.rgl.make_sample_f_lanes`, with f_r; ``tabulated``,
:func:`warp_rbrdf.techniques.tabulated.make_sample_lanes`), each sample's radiance then one at a time with
those given. A lane form draws ``K`` samples at once so that the independent loads and
divisions of their searches and descents overlap (``docs/cpu_lanes.md``); its samples are the
one-at-a-time samples, so a render does not depend on the lanes (``tests/test_lanes.py``).

No ``from __future__ import annotations`` here: Warp reads the lane functions' argument types
from their annotations, which name this module's closure types.
"""
import warp as wp

from . import geometry as G
from .distribution.lanes import lane_types, lanes_out_type
from .materials.data import Materials

#: samples of a pixel the render kernel advances together (0 or 1: one at a time, the kernel
#: without the lanes' code)
LANES = 16
#: the 2-D sample dimensions of the first vertex's environment and BSDF samples (``dim`` and
#: ``dim + 1`` of the integrator's ``radiance_sample`` at depth 0)
FIRST_LIGHT_DIM = 1
FIRST_BSDF_DIM = 2
#: what the lanes give a sample's ``radiance_sample`` (bits): its camera ray and closest hit,
#: the first vertex's BSDF sample, f_r at it, its environment sample
PRE_HIT = 1
PRE_BSDF = 2
PRE_ENV = 4
PRE_F = 8
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
