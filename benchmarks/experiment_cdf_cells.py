"""EXPERIMENT (issue 6, not used by the renderer): per-cell univariate rational inverse CDFs.

Measures whether a layout of univariate maps -- which a sampler could evaluate in constant time
with two short fixed-degree rational evaluations -- can keep the derivative estimator within
1.2x the tabulated sampler's variance. It prints, per view row, the maps' degrees, how many
phi cells fit, and the variance ratio (NumPy, luminance albedo integral at the row's angle);
the findings are quoted in the README's issue-6 section ("Not yet met").

    python benchmarks/experiment_cdf_cells.py vch_golden_yellow_rgb                 # theta-space maps, no cap
    python benchmarks/experiment_cdf_cells.py vch_golden_yellow_rgb --cap 0.2       # keep >= 20 % of every cell's mass
    python benchmarks/experiment_cdf_cells.py vch_golden_yellow_rgb --space y --cap 0.2
    python benchmarks/experiment_cdf_cells.py vch_golden_yellow_rgb --warp       # + Warp mock-up speed
    CELLS_WARP_DEGREES=4,4 python benchmarks/experiment_cdf_cells.py vch_golden_yellow_rgb --warp \
        --max-degree-theta 4 --max-degree-phi 4

The table (:mod:`fit.cdf_table`) samples theta_l from a marginal CDF per view row ``v`` and
|phi_l| from a conditional CDF per (row ``v``, theta_l cell ``j``). This layout replaces each of
those 1-D inverse CDFs by a univariate rational map of the CDF variable on [0, 1]:

* ``F_v(mu)    -> theta_l in [0, pi/2]``  (one per row),
* ``G_vj(u)    -> |phi_l| in [0, pi]``    (one per row and theta_l cell; ``u = |2 tau - 1|``),

so one sample costs two univariate rational evaluations of fixed degree (no search), and
alpha = F_v'(mu) * 2 G_vj'(u) * sin(theta_l) is the exact inverse density of the map
(``1/pdf`` in sr). The theta_l cell of a sample is ``floor(theta_l / (pi/2) * n_t)``, the
table's own cell, so ``G_vj`` stands in for exactly the conditional the table would use.

**Intervals that bound the density, not only the values.** The estimator's variance follows
the map's SLOPE. The data points are the table's CDF values at its cell edges and cell
midpoints; the interval at a point ``x`` of a cell of mass ``m`` is ``[CDF^-1(x - d),
CDF^-1(x + d)]`` with ``d = 0.5 sqrt(B m / n)`` (n cells): the map's mass in every cell is
then within ``2d`` of the table's, a relative error ``e <= sqrt(B / (n m))``, so the
mass-weighted mean of ``e^2`` -- which is, to second order, the increase of the estimator's
relative variance -- stays below ``B``. ``B = budget * V_v`` where ``V_v`` is the tabulated
sampler's own relative variance (variance / mean^2 of the luminance albedo estimator at the
row's view angle), so the budget is a fraction of what the table itself costs.

**Normalised storage.** Each map is stored as power-basis coefficients of ``P`` and ``Q`` in
``x`` in [0, 1] (degree ``<= D``, zero-padded) with the endpoint normalisation folded in
(``P(0)/Q(0) = 0`` and ``P(1)/Q(1) = span`` up to rounding), so a sampler evaluates
``P/Q`` and ``(P'Q - PQ')/Q^2`` and nothing else.

**Verification, per map, by certificate.** ``Q > 0`` and ``P'Q - PQ' > 0`` on [0, 1] are
proved with Bernstein coefficients (subdivided; :func:`positive_on_unit`), so the map is
strictly increasing and covers [0, span] exactly -- never a grid check alone. A theta map that
fails (infeasible, no certificate) sends its whole row to the table; a phi map that fails
sends its cell to the table (``G`` replaced by the table's inverse conditional, whose density
is known: still exact). A row whose verified maps have more than ``max_variance_ratio`` times
the table's variance at the row's view angle (the gate of :mod:`fit.cdf_rows`) also goes to
the table; the reasons are recorded.
"""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import warp as wp
from numpy.polynomial import chebyshev as C
from numpy.polynomial import polynomial as P

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fit.cdf_table import CDFTable, inverse_pdf, table_where  # noqa: E402
from fit.formats.colour import LUMINANCE

HALF_PI = 0.5 * np.pi
CAP = float("inf")   # interval half-width <= CAP * the point's cell mass (0.2: a map keeps >= 20 % of every cell's mass)
CELLS_DEFAULTS = dict(budget=0.25, max_degree_theta=10, max_degree_phi=8, max_variance_ratio=1.2,
                      gate_samples=32768, map_time_limit=10.0)


# --------------------------------------------------------------------------------------------
def positive_on_unit(c, depth: int = 14) -> bool:
    """True when the polynomial with power coefficients ``c`` (ascending) is > 0 on [0, 1],
    proved with its Bernstein coefficients (all > 0 on a piece proves it there), subdividing
    pieces whose coefficients change sign up to ``depth`` times; False on a nonpositive value
    at a piece's end or when the depth runs out."""
    c = np.trim_zeros(np.asarray(c, float), "b")
    if c.size == 0:
        return False
    n = c.size - 1
    # power -> Bernstein on [0, 1]: b_k = sum_{i <= k} C(k, i) / C(n, i) a_i
    from math import comb

    b = np.array([sum(comb(k, i) / comb(n, i) * c[i] for i in range(k + 1)) for k in range(n + 1)])
    stack = [(b, 0)]
    while stack:
        b, d = stack.pop()
        if b[0] <= 0.0 or b[-1] <= 0.0:
            return False
        if np.all(b > 0.0):
            continue
        if d >= depth:
            return False
        # de Casteljau at 1/2
        left, right, w = [b[0]], [b[-1]], b.copy()
        for _ in range(n):
            w = 0.5 * (w[:-1] + w[1:])
            left.append(w[0])
            right.append(w[-1])
        stack += [(np.array(left), d + 1), (np.array(right[::-1]), d + 1)]
    return True


def to_power(f) -> tuple:
    """Power-basis coefficients (ascending, in x on [0, 1]) of P and Q of a univariate
    :class:`fit.rational.RationalFunction` on the domain [0, 1] (Chebyshev in t = 2x - 1)."""
    out = []
    for ex, co in ((f.num_exponents, f.num_coef), (f.den_exponents, f.den_coef)):
        ch = np.zeros(int(ex.max()) + 1 if len(ex) else 1)
        np.add.at(ch, ex[:, 0], co)
        out.append(_cheb_to_power01(ch))
    return out[0], out[1]


def _cheb_to_power01(ch) -> np.ndarray:
    """sum_k ch_k T_k(2x - 1) as ascending power coefficients in x (expanded term by term:
    numpy's ``Chebyshev.convert`` rounds differently, and certificates at the margin flip)."""
    out = np.zeros(len(ch))
    term = np.array([1.0])
    for k, a in enumerate(C.cheb2poly(ch)):
        if k:
            term = P.polymul(term, [-1.0, 2.0])   # (2x - 1)^k
        out[:len(term)] += a * term
    return out


def normalize(p, q, span: float) -> tuple:
    """``(p', q')`` with p'/q' = span (p/q - r0) / (r1 - r0), r0, r1 the values at x = 0, 1,
    scaled so that q'(0) = 1."""
    r0 = P.polyval(0.0, p) / P.polyval(0.0, q)
    r1 = P.polyval(1.0, p) / P.polyval(1.0, q)
    n = max(len(p), len(q))
    p, q = np.pad(p, (0, n - len(p))), np.pad(q, (0, n - len(q)))
    pn = span * (p - r0 * q) / (r1 - r0)
    s = 1.0 / q[0]
    return pn * s, q * s


def certify_map(p, q) -> dict:
    """Q > 0 and (P'Q - PQ') > 0 on [0, 1], by :func:`positive_on_unit` (q as :func:`normalize` returns it)."""
    q_ok = positive_on_unit(q)
    num = P.polysub(P.polymul(P.polyder(p), q), P.polymul(p, P.polyder(q)))
    return {"q_certified": bool(q_ok), "monotone_certified": bool(q_ok and positive_on_unit(num))}


def eval_maps(p, q, x):
    """Value and derivative of P/Q (power coefficients, rows of ``p``/``q`` per element of x)."""
    x = np.asarray(x, float)
    k = np.arange(p.shape[-1])
    xp = x[..., None] ** k
    dxp = np.where(k > 0, k * x[..., None] ** np.maximum(k - 1, 0), 0.0)
    Pv, Qv = (p * xp).sum(-1), (q * xp).sum(-1)
    dP, dQ = (p * dxp).sum(-1), (q * dxp).sum(-1)
    return Pv / Qv, (dP * Qv - Pv * dQ) / (Qv * Qv)


# --------------------------------------------------------------------------------------------
@dataclass
class CellMaps:
    """Coefficients of the cells layout; ``D = degree`` (zero-padded), power basis in x on [0, 1].

    ``theta_p, theta_q`` (n_v, Dt + 1); ``theta_ok`` (n_v,) bool (False: row sampled with the table);
    ``phi_p, phi_q`` (n_v, n_t, Dp + 1); ``phi_ok`` (n_v, n_t) bool (False: that cell's phi from
    the table)."""

    theta_p: np.ndarray
    theta_q: np.ndarray
    theta_ok: np.ndarray
    phi_p: np.ndarray
    phi_q: np.ndarray
    phi_ok: np.ndarray
    space: str = "theta"   # the theta map's output: "theta" (theta_l) or "y" (sin^2 theta_l)

    @property
    def degrees(self) -> tuple:
        return self.theta_p.shape[-1] - 1, self.phi_p.shape[-1] - 1

    def theta(self, v, mu):
        """(x, dx/dmu) of row(s) ``v`` (int array) at ``mu``; x = theta_l or sin^2 theta_l (``space``)."""
        return eval_maps(self.theta_p[v], self.theta_q[v], mu)

    def phi(self, v, j, u):
        """(|phi_l|, d|phi_l|/du) of row(s) ``v``, cell(s) ``j`` at ``u``."""
        return eval_maps(self.phi_p[v, j], self.phi_q[v, j], u)


def table_phi(table: CDFTable, v, j, u):
    """(|phi_l|, d|phi_l|/du) of the table's inverse conditional CDF of row v, cell j."""
    ph, m = table.phi_cell(v, j, u)
    return ph, np.where(m > 0, (np.pi / table.n_p) / np.where(m > 0, m, 1.0), 0.0)


def sample_cells(table: CDFTable, cells: CellMaps, theta_v, mu, tau):
    """NumPy reference of the Warp cells sampler: ``(theta_l, phi_l, alpha)``; rows without a
    theta map are sampled with the table (alpha = 1/its pdf); cells without a phi map take phi
    from the table's conditional (alpha uses its derivative)."""
    tv, mu, tau = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_v, mu, tau)))
    v = table.row(tv)
    x, dX = cells.theta(v, mu)
    s = np.where(tau < 0.5, -1.0, 1.0)
    u = np.abs(2.0 * tau - 1.0)
    if cells.space == "y":   # alpha = dy/dmu / (2 sin cos) * 2 dG * sin = dy/dmu dG / cos
        inside = (x >= 0) & (x <= 1)
        y = np.clip(x, 0.0, 1.0)
        ct = np.sqrt(1.0 - y)
        tl = np.arcsin(np.sqrt(y))
        inside &= ct > 1e-7
        jac = dX / np.where(ct > 1e-7, ct, 1.0)
    else:                    # alpha = dtheta/dmu * 2 dG * sin
        inside = (x >= 0) & (x <= HALF_PI)
        tl = np.clip(x, 0.0, HALF_PI)
        jac = dX * 2.0 * np.sin(tl)
    j = np.clip(np.floor(tl / HALF_PI * table.n_t), 0, table.n_t - 1).astype(np.intp)
    ph, dG = cells.phi(v, j, u)
    tp, tdp = table_phi(table, v, j, u)
    cok = cells.phi_ok[v, j]
    ph, dG = np.where(cok, ph, tp), np.where(cok, dG, tdp)
    inside &= (ph >= 0) & (ph <= np.pi)
    ph = np.clip(ph, 0.0, np.pi)
    alpha = np.where(inside, jac * dG, 0.0)
    return table_where(table, ~cells.theta_ok[v], tv, mu, tau, tl, s * ph, alpha)


# --------------------------------------------------------------------------------------------
def _intervals(cdf, edges, B: float, over):
    """Data of one 1-D map: points = the table CDF at cell edges and midpoints (duplicates
    dropped), intervals in CDF space of half-width 0.5 sqrt(B m / n) (m: the point's cell
    mass; at an edge the smaller neighbour), ends widened past [0, span] (the normalisation
    maps them onto the ends exactly)."""
    n = len(cdf) - 1
    span = float(edges[-1])
    m = np.diff(cdf)
    x = np.concatenate([cdf, 0.5 * (cdf[1:] + cdf[:-1])])
    mm = np.concatenate([np.minimum(np.r_[m[0], m], np.r_[m, m[-1]]), m])
    o = np.argsort(x, kind="stable")
    x, mm = x[o], mm[o]
    keep = np.r_[True, np.diff(x) > 1e-12]
    x, mm = x[keep], mm[keep]
    mm = np.maximum(mm, 0.0)
    d = np.maximum(np.minimum(0.5 * np.sqrt(B * mm / n), CAP * mm), 1e-7)
    y = np.interp(x, cdf, edges)
    lo = np.interp(np.clip(x - d, 0, 1), cdf, edges)
    hi = np.interp(np.clip(x + d, 0, 1), cdf, edges)
    lo[0], hi[0] = -over[1], -over[0]
    lo[-1], hi[-1] = span + over[0], span + over[1]
    return x, y, lo, np.maximum(hi, lo + 1e-9)


def fit_map(cdf, edges, B: float, over, max_degree: int, time_limit):
    """Fit, normalise and certify one 1-D map from the CDF values ``cdf`` at the values
    ``edges`` (n + 1 increasing; the map's range is [0, edges[-1]]): ``(p, q, info)``; p, q
    None when it fails."""
    from fit.rational.fitter import IntervalRationalFitter

    span = float(edges[-1])
    x, y, lo, hi = _intervals(cdf, edges, B, over)
    r = IntervalRationalFitter(max_degree=max_degree, domain=[[0.0, 1.0]], time_limit=time_limit,
                               best_effort=False).fit(x[:, None], y=y, lower=lo, upper=hi)
    info = {"degrees": [int(r.num_degree), int(r.den_degree)], "feasible": bool(r.feasible)}
    if r.function is None or not r.feasible:
        info["reason"] = "infeasible"
        return None, None, info
    p, q = normalize(*to_power(r.function), span)
    info.update(certify_map(p, q))
    if not info["monotone_certified"]:
        info["reason"] = "not q_certified" if not info["q_certified"] else "not monotone_certified"
        return None, None, info
    return p, q, info


def table_relative_variance(table: CDFTable, evaluate, v: int, n: int, seed: int = 1) -> float:
    """variance / mean^2 of the tabulated sampler's luminance albedo estimator at row v's angle."""
    from fit.formats.angles import spherical_to_direction

    rng = np.random.default_rng(seed)
    mu, tau = rng.random(n), rng.random(n)
    tv = float(table.theta_v[v])
    tl, pl, pdf = table.sample(np.full(n, tv), mu, tau)
    e = (np.asarray(evaluate(spherical_to_direction(tl, pl), spherical_to_direction(tv, 0.0)), float) @ LUMINANCE
         ) * np.cos(tl) * inverse_pdf(pdf)
    mean = e.mean()
    return float(e.var() / mean ** 2) if mean > 0 else 0.0


def variance_ratio(table: CDFTable, cells: CellMaps, evaluate, v: int, n: int, seed: int = 0) -> dict:
    """:func:`fit.cdf_rows.variance_ratio` of the cells sampler at row v."""
    from fit.cdf_rows import variance_ratio as ratio

    return ratio(table, lambda tv, mu, tau: sample_cells(table, cells, tv, mu, tau), evaluate, v, n, seed)


def fit_cells(table: CDFTable, evaluate, log=None, deadline: float | None = None, only_rows=None,
              space: str = "theta", **kw):
    """Fit every row's theta map and every (row, cell) phi map; ``(CellMaps, info)``.

    ``budget`` (B / the table's relative variance), ``max_degree_theta``, ``max_degree_phi``,
    ``max_variance_ratio`` (None: no gate), ``gate_samples``, ``map_time_limit`` (s per map);
    rows not started before ``deadline`` (a ``time.perf_counter()`` value) go to the table."""
    log = log or (lambda s: None)
    p = dict(CELLS_DEFAULTS, **kw)
    n_v, n_t = table.n_v, table.n_t
    Dt, Dp = p["max_degree_theta"], p["max_degree_phi"]
    th_p, th_q = np.zeros((n_v, Dt + 1)), np.zeros((n_v, Dt + 1))
    ph_p, ph_q = np.zeros((n_v, n_t, Dp + 1)), np.zeros((n_v, n_t, Dp + 1))
    th_q[:, 0] = ph_q[..., 0] = 1.0
    th_ok, ph_ok = np.zeros(n_v, bool), np.zeros((n_v, n_t), bool)
    cells = CellMaps(th_p, th_q, th_ok, ph_p, ph_q, ph_ok, space)
    rows = []
    gate = p["max_variance_ratio"]
    if space == "y":
        y_edges = np.sin(np.linspace(0.0, HALF_PI, n_t + 1)) ** 2
        y_edges[-1] = 1.0
    else:
        y_edges = np.linspace(0.0, HALF_PI, n_t + 1)
    p_edges = np.linspace(0.0, np.pi, table.n_p + 1)
    for v in range(n_v):
        t0 = time.perf_counter()
        info: dict = {}
        rows.append(info)
        if only_rows is not None and v not in only_rows:
            info["reason"] = "not fitted (only_rows)"
            continue
        if table.row_fallback[v]:
            info["reason"] = "table row has no mass (cosine fallback row)"
            continue
        if deadline is not None and t0 > deadline:
            info["reason"] = "fitting time limit reached"
            continue
        rv = table_relative_variance(table, evaluate, v, p["gate_samples"])
        B = p["budget"] * rv
        info.update(table_relative_variance=rv, budget=B)
        lim = p["map_time_limit"]
        tp, tq, ti = fit_map(table.cdf_theta[v], y_edges, B, (0.002, 0.01), Dt, lim)
        info["theta"] = ti
        if tp is None:
            info["reason"] = f"theta map {ti['reason']}"
            log(f"  row {v:2d}: TABLE ({info['reason']})")
            continue
        th_p[v, :len(tp)], th_q[v, :len(tq)] = tp, tq
        fails: dict = {}
        degs = []
        m_t = np.diff(table.cdf_theta[v])
        for j in range(n_t):
            # each cell's conditional gets an equal share of B in mass-weighted terms
            Bj = min(B / max(n_t * m_t[j], 1e-300), 1.0)
            gp, gq, gi = fit_map(table.cdf_phi[v, j], p_edges, Bj, (0.002, 0.02), Dp, lim)
            if gp is None:
                fails[gi["reason"]] = fails.get(gi["reason"], 0) + 1
                continue
            ph_p[v, j, :len(gp)], ph_q[v, j, :len(gq)] = gp, gq
            ph_ok[v, j] = True
            degs.append(gi["degrees"])
        th_ok[v] = True
        info["phi"] = {"rational_cells": int(ph_ok[v].sum()), "table_cells": fails,
                       "max_degrees": np.max(degs, 0).tolist() if degs else None}
        if gate is not None and np.isfinite(gate):
            info["variance"] = vr = variance_ratio(table, cells, evaluate, v, p["gate_samples"])
            if not vr["ratio"] <= gate:
                th_ok[v] = False
                ph_ok[v] = False
                info["reason"] = f"variance above {gate:g}x the table's"
        info["time_s"] = time.perf_counter() - t0
        log(f"  row {v:2d} (theta_v {np.degrees(table.theta_v[v]):5.1f} deg): theta {tuple(ti['degrees'])}, "
            f"phi rational on {int(ph_ok[v].sum())}/{n_t} cells, {info['time_s']:.1f} s, "
            + ("verified" if th_ok[v] else f"TABLE ({info.get('reason')})")
            + (f", variance {info['variance']['ratio']:.2f}x table" if "variance" in info else ""))
    # trim the zero padding to the largest degree used
    dt = max([int(np.max(np.flatnonzero(np.abs(th_p[v]) + np.abs(th_q[v])))) for v in range(n_v) if th_ok[v]] or [0])
    dp = max([int(np.max(np.flatnonzero(np.abs(ph_p[v, j]) + np.abs(ph_q[v, j]))))
              for v in range(n_v) for j in range(n_t) if ph_ok[v, j]] or [0])
    cells = CellMaps(th_p[:, :dt + 1].copy(), th_q[:, :dt + 1].copy(), th_ok, ph_p[..., :dp + 1].copy(),
                     ph_q[..., :dp + 1].copy(), ph_ok, space)
    p.update(variance_gate=gate is not None)
    return cells, {"params": p, "rows": rows, "verified_rows": int(th_ok.sum()), "n_rows": n_v,
                   "rational_cells": int(ph_ok.sum()), "degrees": [dt, dp]}


# --------------------------------------------------------------------------------------------
# Warp mock-up of the sampler (speed only): fixed degrees, coefficients read from arrays
# --------------------------------------------------------------------------------------------
# degrees of the mock-up's unrolled loops (maps are zero-padded to them): the fit's maximum
# degrees, from $CELLS_WARP_DEGREES ("theta,phi", default 10,8) since they are compile-time constants
DT, DP = (int(d) for d in os.environ.get("CELLS_WARP_DEGREES", "10,8").split(","))


def _ratio_func(D: int):
    """``@wp.func ratio(c, b, x) -> (P/Q, (P/Q)')`` with P = sum_k c[b + k] x^k and
    Q = sum_k c[b + D + 1 + k] x^k, k <= D: Horner with a constant trip count (the captured
    degree D, so the loop unrolls), P and Q chains interleaved."""
    N = D + 1

    @wp.func
    def ratio(c: wp.array(dtype=wp.float64), b: int, x: wp.float64) -> wp.vec2d:
        p = c[b + N - 1]
        q = c[b + 2 * N - 1]
        dp = wp.float64(0.0)
        dq = wp.float64(0.0)
        for k in range(D):
            dp = dp * x + p
            dq = dq * x + q
            p = p * x + c[b + D - 1 - k]
            q = q * x + c[b + N + D - 1 - k]
        iq = wp.float64(1.0) / q
        return wp.vec2d(p * iq, (dp * q - p * dq) * iq * iq)

    return ratio


def _warp_kernels():
    from warp_rbrdf import cdf_sampling as CS

    ratio_t, ratio_p = _ratio_func(DT), _ratio_func(DP)
    NT, NPH = DT + 1, DP + 1

    @wp.kernel
    def cells_kernel(tc: wp.array(dtype=wp.float64), pc: wp.array(dtype=wp.float64),
                     tok: wp.array(dtype=int), pok: wp.array(dtype=int),
                     cdf_t: wp.array(dtype=float), cdf_p: wp.array(dtype=float),
                     n_v: int, n_t: int, n_p: int,
                     wo: wp.array(dtype=wp.vec3), xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec4)):
        i = wp.tid()
        va = CS.view_frame(wo[i])
        mu = xi[i][0]
        tau = xi[i][1]
        v = CS.tab_row(va[0], n_v)
        if tok[v] == 0:
            q = CS.tab_sample(cdf_t, cdf_p, 0, 0, n_v, n_t, n_p, va[0], mu, tau)
            wl = CS.local_dir(q[0], q[1], va)
            out[i] = wp.vec4(wl[0], wl[1], wl[2], 1.0 / q[2])
            return
        F = ratio_t(tc, v * 2 * NT, wp.float64(mu))
        tl = wp.clamp(float(F[0]), 0.0, CS.HALF_PI_F)
        j = wp.clamp(int(tl * (float(n_t) / CS.HALF_PI_F)), 0, n_t - 1)
        s = 1.0
        if tau < 0.5:
            s = -1.0
        u = wp.abs(2.0 * tau - 1.0)
        ph = float(0.0)
        dg = float(0.0)
        if pok[v * n_t + j] == 1:
            G = ratio_p(pc, (v * n_t + j) * 2 * NPH, wp.float64(u))
            ph = wp.clamp(float(G[0]), 0.0, wp.pi)
            dg = float(G[1])
        else:
            sp = (v * n_t + j) * (n_p + 1)
            k = wp.clamp(CS._count_le(cdf_p, sp, n_p, u) - 1, 0, n_p - 1)
            q0 = cdf_p[sp + k]
            m_p = cdf_p[sp + k + 1] - q0
            dp = wp.pi / float(n_p)
            ph = (float(k) + wp.clamp((u - q0) / m_p, 0.0, 1.0)) * dp
            dg = dp / m_p
        wl = CS.local_dir(tl, s * ph, va)
        out[i] = wp.vec4(wl[0], wl[1], wl[2], float(F[1]) * 2.0 * dg * wp.sin(tl))

    @wp.kernel
    def table_kernel(cdf_t: wp.array(dtype=float), cdf_p: wp.array(dtype=float), n_v: int, n_t: int, n_p: int,
                     wo: wp.array(dtype=wp.vec3), xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec4)):
        i = wp.tid()
        va = CS.view_frame(wo[i])
        q = CS.tab_sample(cdf_t, cdf_p, 0, 0, n_v, n_t, n_p, va[0], xi[i][0], xi[i][1])
        wl = CS.local_dir(q[0], q[1], va)
        out[i] = wp.vec4(wl[0], wl[1], wl[2], 1.0 / q[2])

    return cells_kernel, table_kernel



def warp_speed(table: CDFTable, cells: CellMaps, n: int = 1_000_000, reps: int = 5, order: str = "coherent") -> dict:
    """Samples/s of the mock-up cells sampler and of the renderer's tabulated sampler
    (:func:`warp_rbrdf.cdf_sampling.tab_sample`), same view directions and random numbers,
    one thread, best of ``reps``; theta-space maps only."""
    from fit.formats.angles import spherical_to_direction

    if cells.space != "theta":
        raise ValueError("the Warp mock-up evaluates theta-space maps only")
    ck, tk = _warp_kernels()
    rng = np.random.default_rng(0)
    tv = np.arccos(rng.random(n))
    wo = spherical_to_direction(np.sort(tv) if order == "coherent" else tv, rng.random(n) * 2 * np.pi)
    xi = rng.random((n, 2))
    n_v, n_t = table.n_v, table.n_t
    tc = np.zeros((n_v, 2, DT + 1))
    tc[:, 0, :cells.theta_p.shape[1]], tc[:, 1, :cells.theta_q.shape[1]] = cells.theta_p, cells.theta_q
    pc = np.zeros((n_v, n_t, 2, DP + 1))
    pc[..., 0, :cells.phi_p.shape[2]], pc[..., 1, :cells.phi_q.shape[2]] = cells.phi_p, cells.phi_q
    dev = "cpu"
    arr = lambda a, t: wp.array(a, dtype=t, device=dev)  # noqa: E731
    ct, cp = arr(table.cdf_theta.ravel().astype(np.float32), float), arr(table.cdf_phi.ravel().astype(np.float32), float)
    dwo, dxi = arr(wo.astype(np.float32), wp.vec3), arr(xi.astype(np.float32), wp.vec2)
    out = wp.zeros(n, dtype=wp.vec4, device=dev)
    dims = [n_v, n_t, table.n_p]
    launches = {
        "cells": (ck, [arr(tc.ravel(), wp.float64), arr(pc.ravel(), wp.float64),
                       arr(cells.theta_ok.astype(np.int32), int), arr(cells.phi_ok.ravel().astype(np.int32), int),
                       ct, cp, *dims, dwo, dxi]),
        "tabulated": (tk, [ct, cp, *dims, dwo, dxi]),
    }
    for kern, inputs in launches.values():   # compile / load, warm up
        wp.launch(kern, dim=n, inputs=inputs, outputs=[out], device=dev)
    wp.synchronize()
    best = {}
    for _ in range(reps):
        for k, (kern, inputs) in launches.items():
            t = time.perf_counter()
            wp.launch(kern, dim=n, inputs=inputs, outputs=[out], device=dev)
            wp.synchronize()
            best[k] = min(best.get(k, np.inf), time.perf_counter() - t)
    res = {k: n / t for k, t in best.items()}
    res["ratio"] = res["cells"] / res["tabulated"]
    return res


def main(argv=None):
    import argparse

    global CAP
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("material", help="RGL material name (in $RBRDF_DATA/rgl) or 'lambert'")
    ap.add_argument("--space", choices=("theta", "y"), default="theta",
                    help="theta map's output: theta_l, or y = sin^2 theta_l (regular at both ends)")
    ap.add_argument("--cap", type=float, default=float("inf"),
                    help="interval half-width <= CAP x the point's cell mass (default: no cap)")
    ap.add_argument("--budget", type=float, default=CELLS_DEFAULTS["budget"],
                    help="B / the table's relative variance (default %(default)s)")
    ap.add_argument("--max-degree-theta", type=int, default=CELLS_DEFAULTS["max_degree_theta"])
    ap.add_argument("--max-degree-phi", type=int, default=CELLS_DEFAULTS["max_degree_phi"])
    ap.add_argument("--rows", default=None, help="comma-separated row indices (default: all)")
    ap.add_argument("--table", default=None, help="n_v,n_t,n_p of the table (default: fit.cdf_fit.DEFAULTS)")
    ap.add_argument("--warp", action="store_true",
                    help="also time a Warp mock-up of the sampler against the tabulated one (theta space)")
    a = ap.parse_args(argv)
    CAP = a.cap
    from fit.cdf_fit import DEFAULTS
    from fit.cdf_table import tabulate

    if a.material == "lambert":
        sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
        from analytic import lambert

        evaluate = lambert((0.8, 0.6, 0.4))
    else:
        from fit.formats import load_measured
        from studies.common import data_path

        evaluate = load_measured(data_path(f"rgl/{a.material}.bsdf")).evaluate
    tp = dict(DEFAULTS)
    if a.table:
        tp.update(zip(("n_v", "n_t", "n_p"), map(int, a.table.split(","))))
    table = tabulate(evaluate, **tp)
    rows = None if a.rows is None else [int(r) for r in a.rows.split(",")]
    t0 = time.perf_counter()
    cells, info = fit_cells(table, evaluate, log=print, only_rows=rows, space=a.space,
                            budget=a.budget, max_degree_theta=a.max_degree_theta, max_degree_phi=a.max_degree_phi)
    ratios = [r["variance"]["ratio"] for r in info["rows"] if "variance" in r]
    print(f"{a.material} (space {a.space}, cap {a.cap:g}, budget {a.budget:g}): {time.perf_counter() - t0:.1f} s; "
          f"{info['verified_rows']}/{len(rows) if rows else table.n_v} rows pass the 1.2x gate, "
          f"{info['rational_cells']} rational phi cells, degrees {info['degrees']}"
          + (f"; variance ratio of the rows that verified: median {np.median(ratios):.2f}, range "
             f"{min(ratios):.2f}-{max(ratios):.2f} ({len(ratios)} rows)" if ratios else ""))
    if a.warp:
        if cells.degrees[0] > DT or cells.degrees[1] > DP:
            raise SystemExit(f"degrees {cells.degrees} exceed the mock-up's {DT},{DP}: set CELLS_WARP_DEGREES")

        wp.config.quiet = True
        for order in ("coherent", "random"):
            r = warp_speed(table, cells, order=order)
            info[f"warp_{order}"] = r
            print(f"Warp mock-up, {order} view order: cells {r['cells'] / 1e6:.2f} M samples/s, tabulated "
                  f"{r['tabulated'] / 1e6:.2f} M/s, ratio {r['ratio']:.2f}x")
    return cells, info


if __name__ == "__main__":
    main()
