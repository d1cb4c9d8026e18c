"""Per-material inverse-CDF BRDF samplers in Warp (issue 6).

Samplers (``sampler = ...`` per material in scene files):

* ``"tabulated"``: the table of :mod:`fit.sampling.table` inverted by binary search (baseline);
  estimator f cos / pdf with the table's pdf.
* ``"rational"``: the verified rational inverse CDFs of :mod:`fit.sampling.cdf_file`: by default the
  pieces layout (:func:`pieces_sample`: one rational-quadratic piece per map, found without a
  search, coefficients in ``Materials.cdf_pw``), else generated unrolled float64 code per fit
  (global layout); constant time either way; estimator f cos / pdf with pdf = 1 / alpha
  (eq. 3 of the supplementary text: for a monotone covering map this IS the sampled density).
* ``"rational-derivative"``: same directions; the derivative estimator f cos * alpha
  (eq. 4), alpha = dtheta/dmu * dphi/dtau * sin(theta_l), without any pdf. It equals the
  standard estimator sample by sample up to rounding (both are exact for the map the RFs define).
* ``"mis-tabulated"`` / ``"mis-rational"``: one environment sample + one sample of the
  tabulated / rational BRDF sampler, power heuristic. MIS needs the BRDF pdf of directions
  drawn by the light; for the rational sampler that would need the inverse map, so BOTH MIS
  weights use the TABULATED pdf p~ as an approximation of the rational density, while the
  BRDF sample's contribution itself uses the exact alpha. This stays unbiased: the weights
  w_L = p_L^2 / (p_L^2 + p~^2) and w_B = p~^2 / (p_L^2 + p~^2) sum to one for every direction,
  and p~ > 0 wherever the rational density is > 0 (the table is mixed with a cosine density).
  Tested by rendering against a reference.

A material whose rational fit FAILED verification (``CDFFit.fallback``) uses the tabulated
sampler instead; :func:`prepare_samplers` prints that (never silent).

Frame: theta_v, phi_v of wo in the local frame; phi_l is measured from phi_v.
"""
from __future__ import annotations

import numpy as np
import warp as wp

HALF_PI_F = 1.5707963267948966


@wp.func
def _count_le(cdf: wp.array(dtype=float), start: int, n: int, x: float) -> int:
    """Number of entries <= x among cdf[start .. start + n] (n + 1 increasing entries)."""
    lo = int(0)
    hi = n + 1
    while lo < hi:
        mid = (lo + hi) // 2
        if cdf[start + mid] <= x:
            lo = mid + 1
        else:
            hi = mid
    return lo


@wp.func
def tab_row(theta_v: float, n_v: int) -> int:
    return wp.clamp(int(wp.floor(theta_v / HALF_PI_F * float(n_v))), 0, n_v - 1)


@wp.func
def tab_sample(cdf_t: wp.array(dtype=float), cdf_p: wp.array(dtype=float), off_t: int, off_p: int,
               n_v: int, n_t: int, n_p: int, theta_v: float, mu: float, tau: float) -> wp.vec3:
    """(theta_l, phi_l, pdf) exactly as fit.sampling.table.CDFTable.sample (binary search)."""
    v = tab_row(theta_v, n_v)
    st = off_t + v * (n_t + 1)
    j = wp.clamp(_count_le(cdf_t, st, n_t, mu) - 1, 0, n_t - 1)
    c0 = cdf_t[st + j]
    m_t = cdf_t[st + j + 1] - c0
    dt = HALF_PI_F / float(n_t)
    frac = 0.5
    if m_t > 0.0:
        frac = wp.clamp((mu - c0) / m_t, 0.0, 1.0)
    theta_l = (float(j) + frac) * dt
    s = 1.0
    if tau < 0.5:
        s = -1.0
    u = wp.abs(2.0 * tau - 1.0)
    sp = off_p + (v * n_t + j) * (n_p + 1)
    k = wp.clamp(_count_le(cdf_p, sp, n_p, u) - 1, 0, n_p - 1)
    q0 = cdf_p[sp + k]
    m_p = cdf_p[sp + k + 1] - q0
    dp = wp.pi / float(n_p)
    fp = 0.5
    if m_p > 0.0:
        fp = wp.clamp((u - q0) / m_p, 0.0, 1.0)
    phi_l = s * (float(k) + fp) * dp
    pdf = (m_t / dt) * (0.5 * m_p / dp) / wp.max(wp.sin(theta_l), 1.0e-30)
    return wp.vec3(theta_l, phi_l, pdf)


@wp.func
def tab_pdf(cdf_t: wp.array(dtype=float), cdf_p: wp.array(dtype=float), off_t: int, off_p: int,
            n_v: int, n_t: int, n_p: int, theta_v: float, theta_l: float, phi_abs: float) -> float:
    """Density (1/sr) of tab_sample at (theta_l, |phi_l|); 0 at or below the horizon."""
    if theta_l < 0.0 or theta_l >= HALF_PI_F:
        return 0.0
    v = tab_row(theta_v, n_v)
    dt = HALF_PI_F / float(n_t)
    dp = wp.pi / float(n_p)
    j = wp.clamp(int(wp.floor(theta_l / dt)), 0, n_t - 1)
    k = wp.clamp(int(wp.floor(phi_abs / dp)), 0, n_p - 1)
    st = off_t + v * (n_t + 1)
    sp = off_p + (v * n_t + j) * (n_p + 1)
    m_t = cdf_t[st + j + 1] - cdf_t[st + j]
    m_p = cdf_p[sp + k + 1] - cdf_p[sp + k]
    return (m_t / dt) * (0.5 * m_p / dp) / wp.max(wp.sin(theta_l), 1.0e-30)


@wp.func
def view_angles(wo: wp.vec3) -> wp.vec2:
    """(theta_v, phi_v) of the local view direction."""
    rxy = wp.sqrt(wo[0] * wo[0] + wo[1] * wo[1])
    phi = 0.0
    if rxy > 1.0e-12:
        phi = wp.atan2(wo[1], wo[0])
    return wp.vec2(wp.atan2(rxy, wo[2]), phi)


@wp.func
def view_frame(wo: wp.vec3) -> wp.vec3:
    """(theta_v, cos phi_v, sin phi_v) of the local view direction (phi_v = 0 at the pole):
    the view's azimuth as a rotation, so that sampled directions need no atan2."""
    rxy = wp.sqrt(wo[0] * wo[0] + wo[1] * wo[1])
    c = 1.0
    s = 0.0
    if rxy > 1.0e-12:
        c = wo[0] / rxy
        s = wo[1] / rxy
    return wp.vec3(wp.atan2(rxy, wo[2]), c, s)


@wp.func
def local_dir(theta_l: float, phi_l: float, vf: wp.vec3) -> wp.vec3:
    """Direction at polar angle theta_l and azimuth phi_l measured from the view's azimuth
    (``vf`` from :func:`view_frame`)."""
    st = wp.sin(theta_l)
    cp = wp.cos(phi_l)
    sp = wp.sin(phi_l)
    return wp.vec3(st * (cp * vf[1] - sp * vf[2]), st * (sp * vf[1] + cp * vf[2]), wp.cos(theta_l))


@wp.func
def rel_phi_abs(wi: wp.vec3, phi_v: float) -> float:
    """|phi_l - phi_v| folded into [0, pi]."""
    p = wp.atan2(wi[1], wi[0]) - phi_v
    if p > wp.pi:
        p = p - 2.0 * wp.pi
    if p < -wp.pi:
        p = p + 2.0 * wp.pi
    return wp.abs(p)


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
def pieces_sample(pw: wp.array(dtype=float), off: int, n_v: int, n_mu: int, n_u: int,
                  va: wp.vec3, mu: float, tau: float) -> wp.vec4:
    """(wi, alpha): the direction of (theta_l, phi_l) of fit.sampling.pieces.sample_pieces in the
    view frame ``va`` (:func:`view_frame`) and alpha, on a rational row (the generated caller
    sends table rows to the table). Piece of mu: floor(mu n_mu), no search; sin and cos of
    theta_l computed once (end pieces: from y = sin^2 theta_l, no sin/cos at all). Theta pieces:
    4 floats each (:func:`rq_piece`); phi maps: knots (:func:`rq_knots`, see :func:`pack_pieces`)."""
    v = tab_row(va[0], n_v)
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
        tl = wp.clamp(F[0], 0.0, HALF_PI_F)
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
    """(wi, alpha) from (theta_l, phi_l, alpha) of a generated global sampler; alpha < 0
    (a table row) passes through."""
    if q[2] < 0.0:
        return wp.vec4(0.0, 0.0, 0.0, -1.0)
    wl = local_dir(q[0], q[1], va)
    return wp.vec4(wl[0], wl[1], wl[2], q[2])


# --------------------------------------------------------------------------------------------
# Generated rational samplers
# --------------------------------------------------------------------------------------------
def _lit(x: float) -> str:
    return f"wp.float64({float(x)!r})"


def _tree_sum(terms) -> str:
    """A balanced sum of expression strings: independent partial sums instead of one serial
    chain (the compiler may not reassociate floating-point adds, and a 45-term chain is a
    45-add latency chain)."""
    if not terms:
        return "wp.float64(0.0)"
    while len(terms) > 1:
        terms = [f"({terms[i]} + {terms[i + 1]})" if i + 1 < len(terms) else terms[i]
                 for i in range(0, len(terms), 2)]
    return terms[0]


def _emit_rf(L, pre, f, xs, dvar, ends=False):
    """Lines computing the polynomials ``{pre}P``, ``{pre}Q`` of RationalFunction ``f`` at
    float64 expressions ``xs`` (one per variable) and their derivatives ``{pre}dP``,
    ``{pre}dQ`` in variable ``dvar``; with ``ends`` also ``{pre}Plo, {pre}Qlo`` /
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
            L.append(f"    {pre}{nm}a{j} = {_tree_sum(terms)}")
        L.append(f"    {pre}{nm} = " + _tree_sum([f"{pre}{nm}a{j}" + (f" * {pre}T{dvar}_{j}" if j else "")
                                                   for j in sorted(groups)]))
        L.append(f"    {pre}d{nm} = " + _tree_sum([f"{pre}{nm}a{j} * {dT(j)}" for j in sorted(groups) if j]))
        if ends:
            L.append(f"    {pre}{nm}lo = " + _tree_sum([("-" if j % 2 else "") + f"{pre}{nm}a{j}"
                                                        for j in sorted(groups)]))
            L.append(f"    {pre}{nm}hi = " + _tree_sum([f"{pre}{nm}a{j}" for j in sorted(groups)]))


def _emit_normalized(L, pre, span, ends=None):
    """Lines of ``{pre}v = span (R - R_lo) / (R_hi - R_lo)`` and its derivative ``{pre}dv``
    from the polynomials of :func:`_emit_rf` (R = P/Q), with ONE division: with
    D = P_hi Q_lo - P_lo Q_hi and N = P Q_lo - P_lo Q, value = span N Q_hi / (Q D) and
    derivative = span (P' Q - P Q') Q_hi Q_lo / (Q^2 D). ``ends = (R_lo, R_hi)`` as numbers
    when they are constants (univariate F)."""
    sp = _lit(span)
    if ends is not None:
        r0, r1 = ends
        L += [f"    {pre}inv = wp.float64(1.0) / ({pre}Q * {pre}Q)",
              f"    {pre}v = {_lit(span / (r1 - r0))} * ({pre}P - {_lit(r0)} * {pre}Q) * {pre}Q * {pre}inv",
              f"    {pre}dv = {_lit(span / (r1 - r0))} * ({pre}dP * {pre}Q - {pre}P * {pre}dQ) * {pre}inv"]
        return
    L += [f"    {pre}inv = wp.float64(1.0) / ({pre}Q * {pre}Q * ({pre}Phi * {pre}Qlo - {pre}Plo * {pre}Qhi))",
          f"    {pre}v = {sp} * ({pre}P * {pre}Qlo - {pre}Plo * {pre}Q) * {pre}Qhi * {pre}Q * {pre}inv",
          f"    {pre}dv = {sp} * ({pre}dP * {pre}Q - {pre}P * {pre}dQ) * {pre}Qhi * {pre}Qlo * {pre}inv"]


def _emit_maps(L, F, G, f_vars, g_vars):
    """Lines of the endpoint-normalized maps theta_l = F(f_vars..., mu), |phi_l| =
    G(g_vars..., theta_l, u) (CDF variable last) and alpha, ending in ``return vec3(theta_l,
    phi_l, alpha)``; a univariate F gets its end values as constants."""
    _emit_rf(L, "f", F, f_vars + ["m"], F.n_vars - 1, ends=F.n_vars > 1)
    ends = None
    if F.n_vars == 1:
        ends = tuple(float(F(np.full((1, 1), x))[0]) for x in (0.0, 1.0))
    _emit_normalized(L, "f", HALF_PI_F, ends)
    L += ["    tl = fv",
          "    inside = 1",
          "    if tl < wp.float64(0.0) or tl > wp.float64(1.5707963267948966):\n        inside = 0",
          "    tl = wp.clamp(tl, wp.float64(0.0), wp.float64(1.5707963267948966))",
          "    s = wp.float64(1.0)",
          "    if tau < 0.5:\n        s = wp.float64(-1.0)",
          "    u = wp.float64(wp.abs(2.0 * tau - 1.0))"]
    _emit_rf(L, "g", G, g_vars + ["tl", "u"], G.n_vars - 1, ends=True)
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
    L = ["@wp.func", f"def {name}(pw: wp.array(dtype=float), theta_v: float, mu: float, tau: float) -> wp.vec3:",
         f"    # generated rational inverse CDFs of {cdf_fit.name!r}",
         "    tv = wp.float64(wp.clamp(theta_v, 0.0, 1.5707963267948966))",
         "    m = wp.float64(mu)"]
    return _emit_maps(L, cdf_fit.maps.theta, cdf_fit.maps.phi, ["tv"], ["tv"])


def generate_pieces_sampler_function(cdf_fit, name: str, offset: int) -> str:
    """Pieces layout (:mod:`fit.sampling.pieces`): a call of :func:`pieces_sample` on the fit's
    coefficients at ``offset`` in the packed array (:func:`pack_pieces`); no generated maps."""
    t, pm = cdf_fit.table, cdf_fit.maps
    L = ["@wp.func", f"def {name}(pw: wp.array(dtype=float), va: wp.vec3, mu: float, tau: float) -> wp.vec4:",
         f"    # pieces-layout inverse CDFs of {cdf_fit.name!r}"]
    table_rows = np.flatnonzero(~pm.row_ok)
    if len(table_rows):   # rows sampled with the table: alpha = -1 tells the caller
        L += [f"    v = CS.tab_row(va[0], {t.n_v})",
              "    if " + " or ".join(f"v == {int(v)}" for v in table_rows) + ":",
              "        return wp.vec4(0.0, 0.0, 0.0, -1.0)"]
    L.append(f"    return CS.pieces_sample(pw, {offset}, {t.n_v}, {pm.n_mu}, {pm.n_u}, va, mu, tau)")
    return "\n".join(L) + "\n"


def generate_sampler_functions(fits, pw_offsets=None):
    """``[(name, code)]``: per fit a generated ``@wp.func name(pw, va, mu, tau) -> vec4(wi,
    alpha)`` (``va`` from :func:`view_frame`; alpha < 0: sample the table)."""
    out = []
    for i, f in enumerate(fits):
        name = f"cdfsamp_{i}"
        if f.layout == "pieces":
            out.append((name, generate_pieces_sampler_function(f, name, pw_offsets[i])))
            continue
        maps = generate_sampler_function(f, f"{name}_maps")
        out.append((name, maps + "\n\n" + "\n".join([
            "@wp.func", f"def {name}(pw: wp.array(dtype=float), va: wp.vec3, mu: float, tau: float) -> wp.vec4:",
            f"    return CS.maps_to_direction({name}_maps(pw, va[0], mu, tau), va)"]) + "\n"))
    return out


def pack_pieces(fits):
    """``(float32 array, offsets)``: the pieces-layout fits' coefficients concatenated, per fit
    ``[theta pieces (n_v, n_mu, 4), phi knots (n_v, n_mu, n_u + 1, 2)]`` (:func:`rq_piece`,
    :func:`rq_knots`); offset -1 for fits of other layouts (the table rows are literals of the
    generated code)."""
    from fit.sampling.pieces import pieces_phi_knots

    parts, offsets, off = [], [], 0
    for f in fits:
        if f.layout != "pieces":
            offsets.append(-1)
            continue
        pm = f.maps
        a = np.concatenate([pm.theta.ravel(), pieces_phi_knots(pm).ravel()])
        parts.append(a)
        offsets.append(off)
        off += a.size
    return (np.concatenate(parts).astype(np.float32) if parts else np.zeros(1, np.float32)), offsets


# --------------------------------------------------------------------------------------------
# NumPy side: which tables/fits a scene needs
# --------------------------------------------------------------------------------------------
TABLE_SAMPLERS = ("tabulated", "mis-tabulated", "rational", "rational-derivative", "mis-rational")
RATIONAL_SAMPLERS = ("rational", "rational-derivative", "mis-rational")
FALLBACK = {"rational": "tabulated", "rational-derivative": "tabulated", "mis-rational": "mis-tabulated"}


def material_evaluate(spec, kind_data):
    """NumPy ``evaluate(wi, wo) -> (..., 3)`` of a material (scale applied), for tabulation."""
    if spec.type == "lambert":
        alb = np.asarray(spec.albedo, float)
        return lambda wi, wo: np.broadcast_to(alb / np.pi, np.broadcast_shapes(
            np.shape(wi), np.shape(wo))[:-1] + (3,)) * ((np.asarray(wi)[..., 2:3] > 0) & (np.asarray(wo)[..., 2:3] > 0))
    scale = np.asarray(spec.scale, float)
    ev = kind_data.evaluate
    return lambda wi, wo: np.asarray(ev(wi, wo), float) * scale


def prepare_sampler(spec, kind_data, log=print):
    """``(sampler name actually used, CDFFit or None, CDFTable or None)`` for one material.

    Tables only for table/rational samplers; fits only for rational ones (from ``spec.cdf``:
    a CDFFit or a path to an ``rbrdf-cdf`` file, else fitted now). Fallbacks are printed."""
    name = spec.sampler
    if name not in TABLE_SAMPLERS:
        return name, None, None
    from fit.sampling.table import tabulate

    cdf = getattr(spec, "cdf", None)
    fitobj = None
    if cdf is not None:
        if isinstance(cdf, (str, bytes)) or hasattr(cdf, "suffix"):
            from fit.sampling.cdf_file import load

            fitobj = load(cdf)
        else:
            fitobj = cdf
    if name in RATIONAL_SAMPLERS:
        if fitobj is None:
            from fit.sampling.cdf_file import fit_cdf

            log(f"material {spec.name!r}: fitting rational inverse CDFs (give `cdf = \"file.json\"` "
                f"from `rbrdf-fit cdf` to skip this)")
            fitobj = fit_cdf(material_evaluate(spec, kind_data), name=spec.name)
        if fitobj.fallback:
            log(f"material {spec.name!r}: rational sampler FALLBACK to {FALLBACK[name]!r} "
                f"({fitobj.reason})")
            return FALLBACK[name], None, fitobj.table
        return name, fitobj, fitobj.table
    table = fitobj.table if fitobj is not None else tabulate(material_evaluate(spec, kind_data))
    return name, None, table
