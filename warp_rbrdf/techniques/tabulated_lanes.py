"""The ``tabulated`` technique's sample over ``K`` lanes (:mod:`warp_rbrdf.lanes`): the two
binary searches of :func:`.tabulated.tab_sample` (the view row's theta_l CDF, then the |phi_l|
CDF of the chosen cell) stepped over all lanes
(:func:`warp_rbrdf.distribution.lanes.make_find_interval_lanes`), the rest lane by lane
(:func:`.tabulated.tab_sample_cells`, :func:`.tabulated.sample_at`): each lane's sample is the
one-at-a-time sample. The material is evaluated at the samples by the caller (``has_f`` 0).

No ``from __future__ import annotations``: Warp reads the lane function's argument types from
annotations that name closure types.
"""
import functools

import warp as wp

from ..distribution.lanes import lane_types, lanes_out_type, make_find_interval_lanes
from ..materials.data import CDF_N_P, CDF_N_T, CDF_N_V, CDF_OFF_P, CDF_OFF_T, N_CDF_INFO, Materials
from .tabulated import sample_at, tab_row, tab_sample_cells, view_frame


@functools.lru_cache(maxsize=None)
def make_sample_lanes(K: int):
    """``sample_lanes(mats, m, wox, woy, woz, xi0, xi1, on) -> (8, K)``: :func:`.tabulated.sample`
    of every lane with ``on[i] != 0`` (views and uniforms as float lanes; the others a zero
    column), ``has_f`` 0. Cached: one function per ``K``."""
    vf, vi = lane_types(K)
    out_t = lanes_out_type(K)
    find_lanes = make_find_interval_lanes(K)

    @wp.func
    def sample_lanes(mats: Materials, m: int, wox: vf, woy: vf, woz: vf, xi0: vf, xi1: vf, on: vi) -> out_t:
        b = m * N_CDF_INFO
        off_t = mats.cdf_info[b + CDF_OFF_T]
        off_p = mats.cdf_info[b + CDF_OFF_P]
        n_v = mats.cdf_info[b + CDF_N_V]
        n_t = mats.cdf_info[b + CDF_N_T]
        n_p = mats.cdf_info[b + CDF_N_P]
        row = vi()
        st = vi()
        u = vf()
        i = int(0)
        while i < K:
            va = view_frame(wp.vec3(wox[i], woy[i], woz[i]))
            row[i] = tab_row(va[0], n_v)
            st[i] = off_t + row[i] * (n_t + 1)
            u[i] = wp.abs(2.0 * xi1[i] - 1.0)
            i += 1
        j = find_lanes(mats.cdf_t, st, n_t + 1, xi0)
        sp = vi()
        i = int(0)
        while i < K:
            sp[i] = off_p + (row[i] * n_t + j[i]) * (n_p + 1)
            i += 1
        k = find_lanes(mats.cdf_p, sp, n_p + 1, u)
        out = out_t()
        i = int(0)
        while i < K:
            if on[i] != 0:
                va = view_frame(wp.vec3(wox[i], woy[i], woz[i]))
                q = tab_sample_cells(mats.cdf_t, mats.cdf_p, off_t, off_p, n_t, n_p, row[i], j[i], k[i], xi0[i],
                                     xi1[i])
                r = sample_at(q, va)
                for c in range(4):
                    out[c, i] = r[c]
            i += 1
        return out

    return sample_lanes
