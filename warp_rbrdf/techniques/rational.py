"""``rational`` technique: the verified rational inverse CDFs of a material
(:class:`fit.sampling.cdf_file.CDFFit`), with the derivative estimator's weight.

Layouts (``Materials.cdf_info[CDF_LAYOUT]``):

* pieces (default; :mod:`fit.sampling.pieces`): per view row, monotone rational-quadratic pieces of
  equal mass, found without a search (:func:`pieces_sample`); coefficients in
  ``Materials.cdf_pw``, the rows with a verified map flagged in ``Materials.cdf_row_ok``;
* global (the paper's: one F(theta_v, mu), one G(theta_v, theta_l, u)): generated, unrolled
  float64 code per fit (coefficients are literals: :mod:`warp_rbrdf.codegen`).

Weight: alpha = dtheta_l/dmu * dphi_l/dtau * sin(theta_l), the exact inverse density of the map
(eq. 3-4 of the supplementary text: for a monotone covering map ``f cos / pdf`` with pdf =
1/alpha IS the derivative estimator ``f cos alpha``). A row without a verified map, or a material
whose fit fell back, is sampled with the table (weight 1/pdf of the table).

``pdf`` is the TABLE's density (:func:`.tabulated.pdf`): the rational density would need the
inverse map. MIS with it stays unbiased: the power-heuristic weights computed from any one pdf
sum to one for every direction, and the table's pdf is > 0 wherever the rational density is
(the table mixes in a cosine density). Hence ``pdf_exact = False`` in the registry.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from fit.formats.angles import direction_to_spherical, spherical_to_direction

from ..codegen import lit as _lit
from ..codegen import load_generated, tree_sum
from ..materials.data import (
    CDF_LAYOUT,
    CDF_MAPS,
    CDF_N_MU,
    CDF_N_U,
    CDF_N_V,
    CDF_OFF_ROWS,
    LAYOUT_GLOBAL,
    LAYOUT_PIECES,
    N_CDF_INFO,
    Materials,
)
from . import tabulated
from .tabulated import local_dir, tab_row, view_frame

HALF_PI = 0.5 * np.pi


# --------------------------------------------------------------------------------------------
# Pieces layout (fit.sampling.pieces): rational-quadratic pieces uniform in mu / u
# --------------------------------------------------------------------------------------------
@wp.func
def rq_piece(pw: wp.array(dtype=float), b: int, x: float) -> wp.vec2:
    """(value, d/dx) of the rational-quadratic piece (y_k, h, a0, a1) at pw[b:b+4], x in [0, 1]."""
    y0 = pw[b]
    h = pw[b + 1]
    a0 = pw[b + 2]
    a1 = pw[b + 3]
    t = x * (1.0 - x)
    den = 1.0 + (a0 + a1 - 2.0) * t
    iden = 1.0 / den
    x2 = x * x
    w = 1.0 - x
    return wp.vec2(y0 + h * (x2 + a0 * t) * iden, h * (a1 * x2 + 2.0 * t + a0 * w * w) * iden * iden)


@wp.func
def rq_knots(pw: wp.array(dtype=float), b: int, x: float) -> wp.vec2:
    """(value, d/dx) of the same rational-quadratic piece stored by its two knots
    ``(y0, s0, y1, s1)`` at pw[b:b+4] (values and slopes dy/dx, x in [0, 1]): consecutive pieces
    share a knot, so the map is continuous by construction and a piece costs 2 floats.
    ``h = y1 - y0``: ``y = y0 + h (h x^2 + s0 x(1-x)) / (h + (s0 + s1 - 2h) x(1-x))``."""
    y0 = pw[b]
    s0 = pw[b + 1]
    y1 = pw[b + 2]
    s1 = pw[b + 3]
    h = y1 - y0
    t = x * (1.0 - x)
    den = h + (s0 + s1 - 2.0 * h) * t
    if den <= 0.0:                  # h = 0 and flat slopes: a constant piece
        return wp.vec2(y0, 0.0)
    iden = 1.0 / den
    x2 = x * x
    w = 1.0 - x
    return wp.vec2(y0 + h * (h * x2 + s0 * t) * iden, h * h * (s1 * x2 + 2.0 * h * t + s0 * w * w) * iden * iden)


@wp.func
def pieces_sample(pw: wp.array(dtype=float), off: int, n_v: int, n_mu: int, n_u: int, v: int,
                  va: wp.vec3, mu: float, tau: float) -> wp.vec4:
    """(wi, alpha): the direction of (theta_l, phi_l) of fit.sampling.pieces.sample_pieces in the
    view frame ``va`` (:func:`view_frame`) and alpha, on rational row ``v`` (the caller sends
    table rows to the table). Piece of mu: floor(mu n_mu), no search; sin and cos of
    theta_l computed once (end pieces: from y = sin^2 theta_l, no sin/cos at all). Theta pieces:
    4 floats each (:func:`rq_piece`); phi maps: knots (:func:`rq_knots`, see
    :func:`.cdf_data.pack_pieces`)."""
    xs = mu * float(n_mu)
    k = wp.clamp(int(xs), 0, n_mu - 1)
    F = rq_piece(pw, off + (v * n_mu + k) * 4, wp.clamp(xs - float(k), 0.0, 1.0))
    tl = float(0.0)
    st = float(0.0)
    ct = float(0.0)
    at = float(0.0)                  # dtheta_l/dmu * sin(theta_l)
    if k == 0 or k == n_mu - 1:      # end pieces in y = sin^2 theta_l
        y = wp.clamp(F[0], 0.0, 1.0)
        st = wp.sqrt(y)
        ct = wp.sqrt(1.0 - y)
        tl = wp.asin(st)
        at = F[1] * float(n_mu) / (2.0 * wp.max(ct, 1.0e-20))
    else:
        tl = wp.clamp(F[0], 0.0, wp.HALF_PI)
        st = wp.sin(tl)
        ct = wp.cos(tl)
        at = F[1] * float(n_mu) * st
    s = 1.0
    if tau < 0.5:
        s = -1.0
    u = wp.abs(2.0 * tau - 1.0)
    us = u * float(n_u)
    kp = wp.clamp(int(us), 0, n_u - 1)
    G = rq_knots(pw, off + n_v * n_mu * 4 + ((v * n_mu + k) * (n_u + 1) + kp) * 2,
                 wp.clamp(us - float(kp), 0.0, 1.0))
    ph = wp.clamp(G[0], 0.0, wp.pi)
    cp = wp.cos(ph)
    sp = s * wp.sin(ph)
    return wp.vec4(st * (cp * va[1] - sp * va[2]), st * (sp * va[1] + cp * va[2]), ct,
                   at * 2.0 * G[1] * float(n_u))



@wp.func
def maps_to_direction(q: wp.vec3, va: wp.vec3) -> wp.vec4:
    """(wi, alpha) from (theta_l, phi_l, alpha) of a generated global-layout sampler."""
    wl = local_dir(q[0], q[1], va)
    return wp.vec4(wl[0], wl[1], wl[2], q[2])


# --------------------------------------------------------------------------------------------
# Global layout: generated code (coefficients baked in)
# --------------------------------------------------------------------------------------------
def _emit_rf(L, pre, f, xs, dvar):
    """Lines computing the polynomials ``{pre}P``, ``{pre}Q`` of RationalFunction ``f`` at
    float64 expressions ``xs`` (one per variable) and their derivatives ``{pre}dP``,
    ``{pre}dQ`` in variable ``dvar``, and ``{pre}Plo, {pre}Qlo`` /
    ``{pre}Phi, {pre}Qhi``, the polynomials with ``dvar`` at the lower / upper end of its
    domain (the endpoint normalisation's f(x|0), f(x|1)).

    Each polynomial is grouped by the power of ``dvar``: ``P = sum_j a_j T_j(t_dvar)`` with
    ``a_j = sum_i c_ij prod T_i(other variables)``; the derivative is ``sum_j a_j dT_j`` and
    the ends are ``sum_j a_j (-1)^j`` and ``sum_j a_j`` -- one pass over the coefficients for
    all four values, balanced sums for instruction-level parallelism."""
    n = f.n_vars
    kmax = [0] * n
    for ex in (f.num_exponents, f.den_exponents):
        if len(ex):
            kmax = [max(k, int(m)) for k, m in zip(kmax, ex.max(axis=0))]
    for v in range(n):
        a, b = f.domain[v]
        L.append(f"    {pre}t{v} = (wp.float64(2.0) * {xs[v]} - {_lit(a + b)}) * {_lit(1.0 / (b - a))}")
        L.append(f"    {pre}T{v}_0 = wp.float64(1.0)")
        if kmax[v] >= 1:
            L.append(f"    {pre}T{v}_1 = {pre}t{v}")
        for k in range(2, kmax[v] + 1):
            L.append(f"    {pre}T{v}_{k} = wp.float64(2.0) * {pre}t{v} * {pre}T{v}_{k - 1} - {pre}T{v}_{k - 2}")
    # derivative table of dvar: dT_k/dx = k U_{k-1}(t) * 2/(b-a)
    a, b = f.domain[dvar]
    sc = 2.0 / (b - a)
    if kmax[dvar] >= 2:
        L.append(f"    {pre}U_1 = wp.float64(2.0) * {pre}t{dvar}")
    if kmax[dvar] >= 3:
        L.append(f"    {pre}U_2 = wp.float64(2.0) * {pre}t{dvar} * {pre}U_1 - wp.float64(1.0)")
    for k in range(3, kmax[dvar]):
        L.append(f"    {pre}U_{k} = wp.float64(2.0) * {pre}t{dvar} * {pre}U_{k - 1} - {pre}U_{k - 2}")

    def dT(k):
        return _lit(sc) if k == 1 else f"{_lit(k * sc)} * {pre}U_{k - 1}"

    for nm, ex, co in (("P", f.num_exponents, f.num_coef), ("Q", f.den_exponents, f.den_coef)):
        groups: dict = {}
        for e, c in zip(ex, co):
            if c == 0.0:
                continue
            fac = [_lit(c)] + [f"{pre}T{v}_{int(e[v])}" for v in range(n) if v != dvar and e[v] > 0]
            groups.setdefault(int(e[dvar]), []).append(" * ".join(fac))
        for j, terms in sorted(groups.items()):
            L.append(f"    {pre}{nm}a{j} = {tree_sum(terms)}")
        L.append(f"    {pre}{nm} = " + tree_sum([f"{pre}{nm}a{j}" + (f" * {pre}T{dvar}_{j}" if j else "")
                                                   for j in sorted(groups)]))
        L.append(f"    {pre}d{nm} = " + tree_sum([f"{pre}{nm}a{j} * {dT(j)}" for j in sorted(groups) if j]))
        L.append(f"    {pre}{nm}lo = " + tree_sum([("-" if j % 2 else "") + f"{pre}{nm}a{j}"
                                                    for j in sorted(groups)]))
        L.append(f"    {pre}{nm}hi = " + tree_sum([f"{pre}{nm}a{j}" for j in sorted(groups)]))


def _emit_normalized(L, pre, span):
    """Lines of ``{pre}v = span (R - R_lo) / (R_hi - R_lo)`` and its derivative ``{pre}dv``
    from the polynomials of :func:`_emit_rf` (R = P/Q), with ONE division: with
    D = P_hi Q_lo - P_lo Q_hi and N = P Q_lo - P_lo Q, value = span N Q_hi / (Q D) and
    derivative = span (P' Q - P Q') Q_hi Q_lo / (Q^2 D)."""
    sp = _lit(span)
    L += [f"    {pre}inv = wp.float64(1.0) / ({pre}Q * {pre}Q * ({pre}Phi * {pre}Qlo - {pre}Plo * {pre}Qhi))",
          f"    {pre}v = {sp} * ({pre}P * {pre}Qlo - {pre}Plo * {pre}Q) * {pre}Qhi * {pre}Q * {pre}inv",
          f"    {pre}dv = {sp} * ({pre}dP * {pre}Q - {pre}P * {pre}dQ) * {pre}Qhi * {pre}Qlo * {pre}inv"]


def _emit_maps(L, F, G):
    """Lines of the endpoint-normalized maps theta_l = F(tv, mu), |phi_l| = G(tv, theta_l, u)
    and alpha, ending in ``return vec3(theta_l, phi_l, alpha)``."""
    _emit_rf(L, "f", F, ["tv", "m"], 1)
    _emit_normalized(L, "f", HALF_PI)
    L += ["    tl = fv",
          "    inside = 1",
          "    if tl < wp.float64(0.0) or tl > wp.float64(1.5707963267948966):\n        inside = 0",
          "    tl = wp.clamp(tl, wp.float64(0.0), wp.float64(1.5707963267948966))",
          "    s = wp.float64(1.0)",
          "    if tau < 0.5:\n        s = wp.float64(-1.0)",
          "    u = wp.float64(wp.abs(2.0 * tau - 1.0))"]
    _emit_rf(L, "g", G, ["tv", "tl", "u"], 2)
    _emit_normalized(L, "g", np.pi)
    L += ["    ph = gv",
          "    if ph < wp.float64(0.0) or ph > wp.float64(3.141592653589793):\n        inside = 0",
          "    ph = wp.clamp(ph, wp.float64(0.0), wp.float64(3.141592653589793))",
          "    alpha = wp.float64(0.0)",
          "    if inside == 1:\n        alpha = fdv * wp.float64(2.0) * gdv * wp.sin(tl)",
          "    return wp.vec3(float(tl), float(s * ph), float(alpha))"]
    return "\n".join(L) + "\n"


def generate_sampler_function(cdf_fit, name: str) -> str:
    """``@wp.func name(theta_v, mu, tau) -> vec3(theta_l, phi_l, alpha)`` for a verified fit:
    the endpoint-normalized map of :meth:`fit.sampling.cdf_file.CDFFit.sample`, float64, unrolled."""
    L = ["@wp.func", f"def {name}(theta_v: float, mu: float, tau: float) -> wp.vec3:",
         f"    # generated rational inverse CDFs of {cdf_fit.name!r}",
         "    tv = wp.float64(wp.clamp(theta_v, 0.0, 1.5707963267948966))",
         "    m = wp.float64(mu)"]
    return _emit_maps(L, cdf_fit.maps.theta, cdf_fit.maps.phi)


GENERATED_HEADER = """# Generated by warp_rbrdf.techniques.rational -- do not edit.
import warp as wp
"""


def global_functions(fits) -> list:
    """The generated ``@wp.func (theta_v, mu, tau) -> vec3(theta_l, phi_l, alpha)`` of each
    global-layout fit, in order (one generated module)."""
    if not fits:
        return []
    src = GENERATED_HEADER + "\n\n" + "\n\n".join(generate_sampler_function(f, f"cdf_global_{i}")
                                                   for i, f in enumerate(fits))
    mod = load_generated(src, "rbrdf_cdf_global")
    return [getattr(mod, f"cdf_global_{i}") for i in range(len(fits))]


@wp.func
def _no_global(g: int, va: wp.vec3, xi: wp.vec2) -> wp.vec4:
    return wp.vec4(0.0, 0.0, 0.0, -1.0)


def _chain(funcs, first: int = 0):
    """``link(g, va, xi) -> (wi, alpha)`` of generated global-layout sampler ``g`` (one closure
    per function, see :mod:`warp_rbrdf.integrator` for why not a static loop)."""
    if first >= len(funcs):
        return _no_global
    func, rest = funcs[first], _chain(funcs, first + 1)

    @wp.func
    def link(g: int, va: wp.vec3, xi: wp.vec2) -> wp.vec4:
        if g == wp.static(first):
            return maps_to_direction(wp.static(func)(va[0], xi[0], xi[1]), va)
        return wp.static(rest)(g, va, xi)

    return link


def kernel_functions(global_fits=()):
    """``(sample, pdf)`` for a scene: pieces maps from the material's data, the generated code
    of its global-layout fits (index ``cdf_info[CDF_MAPS]``), the table on table rows."""
    global_sample = _chain(global_functions(list(global_fits)))

    @wp.func
    def rational_sample(mats: Materials, m: int, wo: wp.vec3, xi: wp.vec2) -> wp.vec4:
        b = m * N_CDF_INFO
        va = view_frame(wo)
        layout = mats.cdf_info[b + CDF_LAYOUT]
        if layout == LAYOUT_PIECES:
            n_v = mats.cdf_info[b + CDF_N_V]
            v = tab_row(va[0], n_v)
            if mats.cdf_row_ok[mats.cdf_info[b + CDF_OFF_ROWS] + v] != 0:   # else: a table row
                return pieces_sample(mats.cdf_pw, mats.cdf_info[b + CDF_MAPS], n_v, mats.cdf_info[b + CDF_N_MU],
                                     mats.cdf_info[b + CDF_N_U], v, va, xi[0], xi[1])
        elif layout == LAYOUT_GLOBAL:
            q = wp.static(global_sample)(mats.cdf_info[b + CDF_MAPS], va, xi)
            if q[3] >= 0.0:
                return q
        return tabulated.table_sample(mats, m, va, xi)

    return rational_sample, tabulated.pdf


# --------------------------------------------------------------------------------------------
# NumPy references
# --------------------------------------------------------------------------------------------
def numpy_sample(cdf, wo, xi):
    """NumPy reference of the sampler: ``(wi (N, 3), weight (N,))`` from ``CDFFit.sample``
    (alpha on rational rows, 1/pdf of the table elsewhere)."""
    tv, pv = direction_to_spherical(wo)
    tl, pl, alpha = cdf.sample(tv, xi[:, 0], xi[:, 1])
    return spherical_to_direction(tl, pl + pv), alpha


def numpy_pdf(cdf, wi, wo):
    """The density MIS uses: the table's (approximate for the rational maps)."""
    return tabulated.numpy_pdf(cdf, wi, wo)
