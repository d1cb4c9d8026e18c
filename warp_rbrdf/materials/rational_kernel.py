"""The Warp evaluation of rational BRDF fits packed as records (:mod:`.rational_records`).

Both evaluators follow the file's recipe exactly (:mod:`fit.rational.coefficient_file`):
Rusinkiewicz angles -> (moved onto the measured domain: the domain record) -> the piece
(``x <= edge`` picks the lower piece) -> clamp onto the piece's box -> input transform (identity
/ sqrt) -> map onto [-1, 1] -> Chebyshev sums -> P/Q per channel -> value transform (linear /
log) -> ``max(y, min)``, ``min(y, max)`` -> the step-7 range, or the fallback table in a
flagged channel -> step 8, the value factor: in a leaf flagged ``LEAF_INV_COS`` (a model with
``value_factor = "1/cos_theta_i"``, :mod:`.rational_records`) the three channels divided by
``max(wi.z, COS_FLOOR)`` (wi.z: cos theta_i of the light's local direction, which the
unclamped Rusinkiewicz angles give; :data:`fit.rational.model.COS_FLOOR`), in float32 after
their rounding; 0 below the horizon. The polynomial part runs in float64; the angles come
from the float32 shading frame.

* :func:`rational_eval`: one function for every fit (the packed Chebyshev groups,
  :func:`warp_rbrdf.chebyshev.cheb_sum6`): its source never depends on the fit.
* :func:`make_rational_eval` ``(classes)``: the same recipe from code specialised to a set of
  degree classes (:mod:`warp_rbrdf.chebyshev_dense`): a leaf of one of them is evaluated by its
  class's generated code, any other by the packed form; steps 5-7 run on the three channels at
  once (:mod:`.rational_channels`: one vector, ``exp`` inline). The renderer builds it for the
  classes of a scene's fits (:func:`.rational.kernel_eval`), so a new fit compiles only when it
  brings a class no compiled kernel has. A fit with a flat record (at most four (theta_h,
  theta_d) boxes, :mod:`.rational_records`) is evaluated from it by one native function without
  a walk or ``atan2`` (:mod:`.rational_flat2d`); any other walks the records. The walk computes
  only the angles a fit reads: theta_h and
  theta_d by the float32 operations of :func:`.frame.half_diff` with the inline
  :func:`warp_rbrdf.fastmath.atan2` for libm's ``atan2f`` (a call costs about 20 ns; the
  angles differ by at most 3 float32 ulps), ``phi_d`` only where a split or a leaf reads it,
  and the measured-domain move (``acos``, ``cos`` in float64) only where ``cos theta_h cos
  theta_d`` is within :data:`DOMAIN_MARGIN` of the cut-off's cosine or beyond it (elsewhere
  the move changes nothing). Its values are the NumPy reference's at its angles within float32
  rounding (``tests/test_rational_classes.py``).
"""
from __future__ import annotations

import functools

import warp as wp

from fit.formats.grid import N_THETA_D
from fit.rational.model import COS_FLOOR

from .. import fastmath as fmath
from ..chebyshev import cheb_sum6, vec6d
from ..chebyshev_dense import class_of_key, make_dense_pq
from . import frame as F
from .data import Materials
from .rational_channels import channels
from .rational_flat2d import angles_2d, make_flat2d
from .rational_flat3d import angles_3d, make_flat3d
from .rational_records import (
    CH_RANGE,
    CH_TABLE,
    DOMAIN_CHILD,
    DOMAIN_FLOATS,
    FH_BOX,
    FH_LOGMAX,
    FH_MAX,
    FH_MIN,
    FH_OFFSET,
    FH_RANGES,
    FH_VARS,
    LEAF_CLAMP,
    LEAF_CLASS,
    LEAF_DENSE,
    LEAF_FH,
    LEAF_FLAGS,
    LEAF_INV_COS,
    LEAF_LOG,
    LEAF_MAX,
    LEAF_MIN,
    LEAF_MODES,
    LEAF_NV,
    LEAF_POLY,
    LEAF_TABLE,
    LEAF_VARS,
    FLAT_FLOATS,
    FLAT_PIECES,
    FLAT_TREE,
    FLAT_VAR,
    NODE_DOMAIN,
    NODE_FLAT2D,
    NODE_FLAT3D,
    NODE_SPLIT,
    SPLIT_CHILDREN,
    SPLIT_EDGES,
    SPLIT_N,
    SPLIT_VAR,
)

#: a pair with ``cos theta_h cos theta_d >= cos c + DOMAIN_MARGIN`` lies inside the measured
#: domain whatever the float32 rounding of its angles (about 1e-7 rad); there the move onto it
#: is the identity and is skipped
DOMAIN_MARGIN = 1.0e-5

vec6f = wp.types.vector(length=6, dtype=wp.float32)

#: step 8's floor of cos theta_i (:data:`fit.rational.model.COS_FLOOR`) as the float32 the
#: kernels compare ``wi.z`` with and divide by (relative rounding 5e-8)
COS_FLOOR_F32 = wp.constant(wp.float32(COS_FLOOR))


@wp.func
def _mapped_input(ci: wp.array(dtype=int), cf: wp.array(dtype=wp.float64), code: int, b: int, flags: int,
                  a: wp.vec3) -> wp.float64:
    """Steps 1-3 of the recipe for a variable of code ``code`` (a leaf's variable code) whose
    header entries start at float ``b``: clamp onto the box, transform, map onto [-1, 1];
    phi_d folded into [0, pi] first by the mirror symmetry of isotropy, |phi_d| (file version 3,
    :mod:`fit.rational.variables3d`; the light's and the view's roles are kept)."""
    src = code & 3
    x = wp.float64(a[src])
    if src == 2:
        x = wp.float64(wp.abs(a[2]))
    if (flags & LEAF_CLAMP) != 0:
        x = fmath.clamp(x, cf[b], cf[b + 1])
    if (code >> 2) == 1:
        x = wp.sqrt(fmath.fmax(x, wp.float64(0.0)))
    return (wp.float64(2.0) * x - cf[b + 2]) * cf[b + 3]


@wp.func
def _channel(cf: wp.array(dtype=wp.float64), mode: int, h: int, flags: int, c: int, p: wp.float64,
             q: wp.float64, tab: float) -> float:
    """Steps 5-7 of channel ``c`` (``mode``) of a leaf with header at float ``h``: P/Q, value
    transform, clamps; ``tab``: the fallback table's value, used where the channel is flagged
    and a table is present."""
    y = wp.float64(0.0)
    if (mode & CH_TABLE) != 0:
        y = wp.float64(tab)
    else:
        y = p / q
        if (flags & LEAF_LOG) != 0:
            if (flags & LEAF_MAX) != 0:
                y = fmath.fmin(y, cf[h + FH_LOGMAX])
            y = wp.exp(y) - cf[h + FH_OFFSET]
        if (flags & LEAF_MIN) != 0:
            y = fmath.fmax(y, cf[h + FH_MIN])
        if (flags & LEAF_MAX) != 0:
            y = fmath.fmin(y, cf[h + FH_MAX])
    if (mode & CH_RANGE) != 0:
        y = fmath.clamp(y, cf[h + FH_RANGES + 2 * c], cf[h + FH_RANGES + 2 * c + 1])
    return float(y)


@wp.func
def _onto_domain(a: wp.vec3, cos_cut: wp.float64, cut: wp.float64) -> wp.vec3:
    """Rusinkiewicz angles ``a`` (theta_h, theta_d, phi_d) moved onto the measured domain
    ``cos theta_h cos theta_d >= cos_cut`` (:func:`onto_measured_domain`, in float64)."""
    th = fmath.fmin(wp.float64(a[0]), cut)
    lim = wp.acos(fmath.fmin(cos_cut / wp.cos(th), wp.float64(1.0)))
    return wp.vec3(float(th), float(fmath.fmin(wp.float64(a[1]), lim)), a[2])


@wp.func
def _fallback_table(mats: Materials, m: int, cf: wp.array(dtype=wp.float64), h: int, a: wp.vec3) -> wp.vec3:
    """The projected table's cluster at (theta_h, theta_d) clamped onto the leaf's box."""
    ih = F.merl_theta_h_index(float(fmath.clamp(wp.float64(a[0]), cf[h + FH_BOX], cf[h + FH_BOX + 1])))
    jd = F.merl_theta_d_index(float(fmath.clamp(wp.float64(a[1]), cf[h + FH_BOX + 2], cf[h + FH_BOX + 3])))
    return mats.tables[mats.param[m] + ih * N_THETA_D + jd]


@wp.func
def rational_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    """rho (1/sr) of rational material ``m``: its packed fit (:func:`.rational_records.pack_model`,
    ints from ``coef_i[3 m]``, floats from ``coef_i[3 m + 1]``, coefficient rows from
    ``coef_i[3 m + 2]``) at (wi, wo) (local unit directions, wi towards the light), divided by
    ``max(wi.z, COS_FLOOR)`` in a leaf flagged ``LEAF_INV_COS``, times ``Materials.scale[m]``; 0
    below the horizon."""
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0)
    ci = mats.coef_i
    cf = mats.coef_f
    ib = ci[3 * m]
    fb = ci[3 * m + 1]
    a = F.half_diff(wi, wo)
    n = ib
    if ci[n] == NODE_DOMAIN:       # no extrapolation beyond the measured domain
        d = fb + ci[n + DOMAIN_FLOATS]
        a = _onto_domain(a, cf[d], cf[d + 1])
        n = ib + ci[n + DOMAIN_CHILD]
    if ci[n] == NODE_FLAT2D or ci[n] == NODE_FLAT3D:       # the same fit's tree follows
        n = ib + ci[n + FLAT_TREE]
    while ci[n] == NODE_SPLIT:     # piece k: the first with x <= edge k + 1
        x = wp.float64(a[ci[n + SPLIT_VAR]])
        if ci[n + SPLIT_VAR] == 2:
            x = wp.abs(x)
        e = fb + ci[n + SPLIT_EDGES]
        k = int(0)      # noqa: UP018, RUF046 - Warp: a dynamic int (a literal is constant in the loop)
        for j in range(ci[n + SPLIT_N] - 1):
            if x > cf[e + j]:
                k = j + 1
        n = ib + ci[n + SPLIT_CHILDREN + k]
    nv = ci[n + LEAF_NV]
    flags = ci[n + LEAF_FLAGS]
    h = fb + ci[n + LEAF_FH]
    t0 = _mapped_input(ci, cf, ci[n + LEAF_VARS], h + FH_VARS, flags, a)
    t1 = wp.float64(0.0)
    t2 = wp.float64(0.0)
    if nv >= 2:
        t1 = _mapped_input(ci, cf, ci[n + LEAF_VARS + 1], h + FH_VARS + 4, flags, a)
    if nv >= 3:
        t2 = _mapped_input(ci, cf, ci[n + LEAF_VARS + 2], h + FH_VARS + 8, flags, a)
    ta = wp.float64(0.0)        # padded in front (chebyshev module docstring)
    tb = wp.float64(0.0)
    tc = t0
    if nv == 2:
        tb = t0
        tc = t1
    elif nv == 3:
        ta = t0
        tb = t1
        tc = t2
    tab = wp.vec3(0.0)
    if (flags & LEAF_TABLE) != 0:   # the projected table (theta_h, theta_d) clamped onto the box
        tab = _fallback_table(mats, m, cf, h, a)
    pq = cheb_sum6(mats.coef_q, ci, ci[3 * m + 2] + ci[n + LEAF_POLY + 1], ib + ci[n + LEAF_POLY],
                   ta, tb, tc)
    r = n + LEAF_MODES
    y = wp.vec3(_channel(cf, ci[r], h, flags, 0, pq[0], pq[3], tab[0]),
                _channel(cf, ci[r + 1], h, flags, 1, pq[1], pq[4], tab[1]),
                _channel(cf, ci[r + 2], h, flags, 2, pq[2], pq[5], tab[2]))
    if (flags & LEAF_INV_COS) != 0:     # step 8: the value factor 1 / cos theta_i
        y = y / fmath.fmax(wi[2], COS_FLOOR_F32)
    return wp.cw_mul(y, mats.scale[m])


# --------------------------------------------------------------------------------------------
# Specialised to the scene's degree classes
# --------------------------------------------------------------------------------------------
@wp.func
def half_diff_frame(wi: wp.vec3, wo: wp.vec3) -> vec6f:
    """``(theta_h, theta_d, x, y, cos theta_h, cos theta_d)`` of a local direction pair: the
    angles by the float32 operations of :func:`.frame.half_diff` with
    :func:`warp_rbrdf.fastmath.atan2` (radians, within 3 float32 ulps of its values), and the
    light's direction in the half vector's frame, whose ``atan2(y, x)`` is phi_d
    (:func:`phi_d_of`)."""
    s = wi + wo
    ln = wp.length(s)
    h = wp.vec3(0.0, 0.0, 1.0)
    if ln > 1.0e-9:
        h = s / ln
    rxy = wp.sqrt(h[0] * h[0] + h[1] * h[1])
    theta_h = fmath.atan2(rxy, h[2])
    cp = 1.0
    sp = 0.0
    if rxy > 1.0e-12:
        cp = h[0] / rxy
        sp = h[1] / rxy
    x1 = cp * wi[0] + sp * wi[1]
    y1 = -sp * wi[0] + cp * wi[1]
    z1 = wi[2]
    ct = h[2]
    st = rxy
    x2 = ct * x1 - st * z1
    z2 = st * x1 + ct * z1
    theta_d = fmath.atan2(wp.sqrt(x2 * x2 + y1 * y1), z2)
    return vec6f(theta_h, theta_d, x2, y1, ct, z2)


@wp.func
def phi_d_of(g: vec6f) -> float:
    """phi_d in (-pi, pi] (radians) of :func:`half_diff_frame`'s output (as :func:`.frame.half_diff`,
    with :func:`warp_rbrdf.fastmath.atan2`)."""
    phi_d = 0.0
    if wp.abs(g[2]) + wp.abs(g[3]) > 1.0e-12:
        phi_d = fmath.atan2(g[3], g[2])
    return phi_d


@wp.func
def _packed_pq(rows: wp.array(dtype=vec6d), ci: wp.array(dtype=int), cf: wp.array(dtype=wp.float64), n: int,
               ib: int, fb: int, rb: int, ta: wp.float64, tb: wp.float64, tc: wp.float64) -> vec6d:
    """P and Q of leaf ``n`` from its packed group (any class)."""
    return cheb_sum6(rows, ci, rb + ci[n + LEAF_POLY + 1], ib + ci[n + LEAF_POLY], ta, tb, tc)


@wp.func
def _no_pq(rows: wp.array(dtype=vec6d), ci: wp.array(dtype=int), cf: wp.array(dtype=wp.float64), n: int,
           ib: int, fb: int, rb: int, ta: wp.float64, tb: wp.float64, tc: wp.float64) -> vec6d:
    """The end of a chain whose classes cover every leaf of the scene (never reached): P = 0,
    Q = 1; keeps the packed groups' code (:func:`warp_rbrdf.chebyshev.cheb_sum6`) out of the
    kernel."""
    return vec6d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0), wp.float64(1.0), wp.float64(1.0),
                 wp.float64(1.0))


@functools.lru_cache(maxsize=None)
def make_leaf_pq(keys: tuple, packed: bool = True):
    """``leaf_pq(rows, ci, cf, n, ib, fb, rb, ta, tb, tc) -> vec6d``: P and Q of leaf ``n`` by
    its class's code when its class is among ``keys`` (:func:`warp_rbrdf.chebyshev_dense.class_key`),
    else from its packed group (``packed``; False: every leaf has one of the classes, and the
    packed group's code is left out)."""
    if not keys:
        return _packed_pq if packed else _no_pq
    key = keys[0]
    dense = make_dense_pq(key)
    rest = make_leaf_pq(keys[1:], packed)

    @functools.partial(wp.func, inline=True)
    def leaf_pq(rows: wp.array(dtype=vec6d), ci: wp.array(dtype=int), cf: wp.array(dtype=wp.float64), n: int,
                ib: int, fb: int, rb: int, ta: wp.float64, tb: wp.float64, tc: wp.float64) -> vec6d:
        if ci[n + LEAF_CLASS] == wp.static(key):
            return wp.static(dense)(wp.address_of(cf[fb + ci[n + LEAF_DENSE]]), ta, tb, tc)
        return wp.static(rest)(rows, ci, cf, n, ib, fb, rb, ta, tb, tc)

    return leaf_pq


@functools.lru_cache(maxsize=None)
def make_rational_eval(classes: tuple):
    """``rational_eval(mats, m, wi, wo) -> vec3`` (the recipe of :func:`rational_eval`, module
    docstring) specialised to the degree classes ``classes``: a sorted tuple of
    :func:`warp_rbrdf.chebyshev_dense.class_key`, with 0 when some leaf has none
    (:func:`.rational_records.packed_classes`; only then is the packed groups' code compiled
    in). Cached: one function per tuple."""
    leaf_pq = make_leaf_pq(tuple(k for k in classes if k), 0 in classes or not classes)
    keys2d = tuple(k for k in classes if k and class_of_key(k)[0] == 2)
    keys3d = tuple(k for k in classes if k and class_of_key(k)[0] == 3)
    flat2d = make_flat2d(keys2d, DOMAIN_MARGIN)
    flat3d = make_flat3d(keys3d, DOMAIN_MARGIN)

    @functools.partial(wp.func, inline=True)
    def rational_eval_classes(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
        if wi[2] <= 0.0 or wo[2] <= 0.0:
            return wp.vec3(0.0)
        # contiguous views: their element size is a constant of the code (no multiply per
        # index, as the struct's arrays have run-time strides)
        ci = wp.array(ptr=wp.address_of(mats.coef_i[0]), shape=(mats.coef_i.shape[0],), dtype=int)
        cf = wp.array(ptr=wp.address_of(mats.coef_f[0]), shape=(mats.coef_f.shape[0],), dtype=wp.float64)
        ib = ci[3 * m]
        fb = ci[3 * m + 1]
        if wp.static(len(keys2d) > 0):       # a flat record: no walk (.rational_flat2d)
            nf = ib
            if ci[nf] == NODE_DOMAIN:
                nf = ib + ci[nf + DOMAIN_CHILD]
            if ci[nf] == NODE_FLAT2D:
                v = wp.static(flat2d)(wp.address_of(cf[fb + ci[nf + FLAT_FLOATS]]),
                                      wp.address_of(ci[nf + FLAT_PIECES]), wp.address_of(cf[fb]),
                                      wp.address_of(mats.tables[mats.param[m]]), ci[nf + FLAT_VAR],
                                      angles_2d(wi, wo))
                if v[3] != 0.0:
                    return wp.cw_mul(wp.vec3(v[0], v[1], v[2]), mats.scale[m])
        if wp.static(len(keys3d) > 0):       # a 3-D flat record: no walk (.rational_flat3d)
            nf = ib
            if ci[nf] == NODE_DOMAIN:
                nf = ib + ci[nf + DOMAIN_CHILD]
            if ci[nf] == NODE_FLAT3D:
                v = wp.static(flat3d)(wp.address_of(cf[fb + ci[nf + FLAT_FLOATS]]),
                                      wp.address_of(ci[nf + FLAT_PIECES]), wp.address_of(cf[fb]),
                                      wp.address_of(mats.tables[mats.param[m]]), ci[nf + FLAT_VAR],
                                      angles_3d(wi, wo), wi[2])
                if v[3] != 0.0:
                    return wp.cw_mul(wp.vec3(v[0], v[1], v[2]), mats.scale[m])
        g = half_diff_frame(wi, wo)
        a = wp.vec3(g[0], g[1], 0.0)
        have_phi = int(0)  # noqa: UP018, RUF046 - Warp: a dynamic int
        n = ib
        if ci[n] == NODE_DOMAIN:
            d = fb + ci[n + DOMAIN_FLOATS]
            if wp.float64(g[4]) * wp.float64(g[5]) < cf[d] + wp.float64(DOMAIN_MARGIN):
                a = _onto_domain(a, cf[d], cf[d + 1])
            n = ib + ci[n + DOMAIN_CHILD]
        if ci[n] == NODE_FLAT2D or ci[n] == NODE_FLAT3D:
            n = ib + ci[n + FLAT_TREE]
        while ci[n] == NODE_SPLIT:
            var = ci[n + SPLIT_VAR]
            if var == 2 and have_phi == 0:
                a = wp.vec3(a[0], a[1], phi_d_of(g))
                have_phi = 1
            x = wp.float64(a[var])
            if var == 2:
                x = wp.abs(x)
            e = fb + ci[n + SPLIT_EDGES]
            k = int(0)  # noqa: UP018, RUF046 - Warp: a dynamic int
            for j in range(ci[n + SPLIT_N] - 1):   # the edges increase: k = #{edges < x}
                k += wp.where(x > cf[e + j], 1, 0)
            n = ib + ci[n + SPLIT_CHILDREN + k]
        nv = ci[n + LEAF_NV]
        flags = ci[n + LEAF_FLAGS]
        h = fb + ci[n + LEAF_FH]
        c0 = ci[n + LEAF_VARS]
        c1 = ci[n + LEAF_VARS + 1]
        c2 = ci[n + LEAF_VARS + 2]
        if have_phi == 0 and ((c0 & 3) == 2 or (nv >= 2 and (c1 & 3) == 2) or (nv >= 3 and (c2 & 3) == 2)):
            a = wp.vec3(a[0], a[1], phi_d_of(g))
        t0 = _mapped_input(ci, cf, c0, h + FH_VARS, flags, a)
        t1 = wp.float64(0.0)
        t2 = wp.float64(0.0)
        if nv >= 2:
            t1 = _mapped_input(ci, cf, c1, h + FH_VARS + 4, flags, a)
        if nv >= 3:
            t2 = _mapped_input(ci, cf, c2, h + FH_VARS + 8, flags, a)
        ta = wp.float64(0.0)
        tb = wp.float64(0.0)
        tc = t0
        if nv == 2:
            tb = t0
            tc = t1
        elif nv == 3:
            ta = t0
            tb = t1
            tc = t2
        tab = wp.vec3(0.0)
        if (flags & LEAF_TABLE) != 0:
            tab = _fallback_table(mats, m, cf, h, a)
        pq = wp.static(leaf_pq)(mats.coef_q, ci, cf, n, ib, fb, ci[3 * m + 2], ta, tb, tc)
        r = n + LEAF_MODES
        y = channels(pq, wp.address_of(cf[h]), flags, ci[r], ci[r + 1], ci[r + 2], tab)
        if (flags & LEAF_INV_COS) != 0:     # step 8: the value factor 1 / cos theta_i
            y = y / fmath.fmax(wi[2], COS_FLOOR_F32)
        return wp.cw_mul(y, mats.scale[m])

    return rational_eval_classes
