"""Rational inverse CDFs for importance sampling (Pacanowski et al. 2012, supplementary sec. 2).

From a tabulated sampler (:mod:`fit.cdf_table`) two rational functions are fitted with the
project's interval fitter (:class:`fit.fitter.IntervalRationalFitter`):

* ``F(theta_v, mu)``            -> theta_l  (CDF^-1_v(mu), bivariate),
* ``G(theta_v, theta_l, u)``    -> |phi_l|  (half-range CDF^-1_v(tau | theta_l), trivariate),

and the sampler maps uniform ``(mu, tau)`` to a light direction by

    theta_l = clamp(F(theta_v, mu), 0, pi/2)
    u = |2 tau - 1|,  phi_l = sign(tau - 1/2) * clamp(G(theta_v, theta_l, u), 0, pi)

(phi_l measured from the view's azimuth, in [-pi, pi]; the sampled density is symmetric in
phi_l like the table's). The derivative estimator (eq. 3-4 of the supplementary text) uses

    alpha = dtheta_l/dmu * dphi_l/dtau * sin(theta_l) = dF/dmu * 2 dG/du * sin(theta_l)

in place of 1 / pdf; ``alpha = 0`` where a clamp is active (those samples contribute 0).

Endpoint handling ("clamp with overshoot"): the fit is constrained to overshoot both ends,
``F(theta_v, 0) < 0``, ``F(theta_v, 1) > pi/2``, ``G(., ., 0) < 0``, ``G(., ., 1) > pi``, and
the result is clamped. Together with monotonicity this makes the map a bijection from the
unclamped part of the (mu, tau) square onto the whole hemisphere (it covers every direction),
so ``E[f(l) alpha] = integral of f`` exactly, whatever the fit's accuracy: accuracy only changes
the variance. A map that folds (dF/dmu <= 0 or dG/du <= 0 where unclamped) or does not cover
(an end not overshot) would be biased, so every fit is VERIFIED:

* Q > 0 on the whole domain box: the fitter's exact Bernstein certificate (no poles);
* endpoint overshoot: ``-P`` at mu = 0 / u = 0 and ``P - (range) Q`` at mu = 1 / u = 1 are
  proved > 0 by the same exact Bernstein certificate (polynomials in the remaining variables),
  and re-checked on the dense grid;
* monotonicity: dF/dmu > 0 and dG/du > 0 at every point of a dense grid where the clamp is not
  active (``VERIFY_GRID``: theta 257 x 2049 (theta_v, mu); phi 33 x 65 x 513 (theta_v, theta_l,
  u), plus the global minimum over the grid, reported).

If a fit fails any check after ``refinements`` rounds (denser data, tighter intervals), the
material FALLS BACK to the tabulated sampler: ``CDFFit.fallback`` is True with the reason, it is
printed by the CLI and by the renderer, and recorded in the CDF file. Never silently.
"""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .cdf_table import CDFTable, inverse_cdf_phi, inverse_cdf_theta, table_where, tabulate
from .errors import BRDFFileError
from .rational.function import RationalFunction

FORMAT = "rbrdf-cdf"
VERSION = 2   # 2: optional "layout"/"rows" (fit.cdf_rows); version-1 files (global layout) still load
HALF_PI = 0.5 * np.pi
VERIFY_GRID = {"theta": (257, 2049), "phi": (33, 65, 513)}


def verify_axes(what: str) -> list:
    """The 1-D axes of the verification grid of ``"theta"`` (theta_v, mu) or ``"phi"``
    (theta_v, theta_l, u), sizes :data:`VERIFY_GRID`."""
    n = VERIFY_GRID[what]
    ranges = [(0, HALF_PI), (0, 1)] if what == "theta" else [(0, HALF_PI), (0, HALF_PI), (0, 1)]
    return [np.linspace(a, b, k) for (a, b), k in zip(ranges, n)]


def _cheb_points(n: int) -> np.ndarray:
    """n Chebyshev-Lobatto points on [0, 1] (denser at the ends, where inverse CDFs are steep)."""
    return 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, n)))


def _monotone_intervals(y, tol, lo_end, hi_end, over):
    """Intervals around increasing rows ``y[..., k]`` (last axis = the CDF variable) that are
    disjoint and increasing along the last axis (so the data alone are monotone), width <= 2 tol;
    the end points get overshoot intervals ``[lo_end - over[1], lo_end - over[0]]`` and
    ``[hi_end + over[0], hi_end + over[1]]``."""
    y = np.asarray(y, float)
    lo = y - tol
    hi = y + tol
    mid = 0.5 * (y[..., 1:] + y[..., :-1])
    gap = 0.05 * (y[..., 1:] - y[..., :-1])
    lo[..., 1:] = np.maximum(lo[..., 1:], mid + gap)
    hi[..., :-1] = np.minimum(hi[..., :-1], mid - gap)
    lo[..., 0], hi[..., 0] = lo_end - over[1], lo_end - over[0]
    lo[..., -1], hi[..., -1] = hi_end + over[0], hi_end + over[1]
    lo[..., 1] = np.maximum(lo[..., 1], hi[..., 0] + 1e-6)
    hi[..., -2] = np.minimum(hi[..., -2], lo[..., -1] - 1e-6)
    hi = np.maximum(hi, lo + 1e-9)
    return lo, hi


# --------------------------------------------------------------------------------------------
def _restrict(f: RationalFunction, var: int, value: float, sign: float = 1.0,
              minus_q: float = 0.0) -> RationalFunction | None:
    """Polynomial ``sign * (P - minus_q Q)`` with variable ``var`` fixed to an end of its domain
    (value = 0: t = -1, value = 1: t = +1), returned as the denominator of a RationalFunction in
    the remaining variables so that ``certify_denominator`` proves it > 0."""
    t = -1.0 if value == 0 else 1.0
    keep = [v for v in range(f.n_vars) if v != var]
    terms: dict = {}
    for ex, co, s in ((f.num_exponents, f.num_coef, sign), (f.den_exponents, f.den_coef, -sign * minus_q)):
        if s == 0:
            continue
        for e, c in zip(ex, co):
            key = tuple(int(e[k]) for k in keep)
            terms[key] = terms.get(key, 0.0) + s * c * t ** int(e[var])
    if not terms:
        return None
    E = np.array(list(terms), dtype=np.int64).reshape(-1, len(keep))
    C = np.array(list(terms.values()))
    return RationalFunction(f.domain[keep], np.zeros((0, len(keep)), np.int64), np.zeros(0), E, C)


def restrict_rf(f: RationalFunction, var: int, value: float) -> RationalFunction:
    """``f`` with variable ``var`` fixed to the lower (value 0) or upper (value 1) end of its
    domain, as a rational function of the remaining variables (exact: T_k(+-1) = (+-1)^k)."""
    t = -1.0 if value == 0 else 1.0
    keep = [v for v in range(f.n_vars) if v != var]

    def collapse(ex, co):
        terms: dict = {}
        for e, c in zip(ex, co):
            key = tuple(int(e[k]) for k in keep)
            terms[key] = terms.get(key, 0.0) + c * t ** int(e[var])
        E = np.array(list(terms), dtype=np.int64).reshape(-1, len(keep))
        return E, np.array(list(terms.values()), float)

    ne, nc = collapse(f.num_exponents, f.num_coef)
    de, dc = collapse(f.den_exponents, f.den_coef)
    return RationalFunction(f.domain[keep], ne, nc, de, dc)


def normalized_map(f: RationalFunction, var: int, x, span: float):
    """``(value, derivative)`` of the endpoint-normalized map
    ``span * (f(x) - f(x|var=lo)) / (f(x|var=hi) - f(x|var=lo))`` (exact endpoints 0 and span)."""
    x = np.asarray(x, float)
    keep = [v for v in range(f.n_vars) if v != var]
    xr = x[..., keep]
    f0 = restrict_rf(f, var, 0)(xr)
    f1 = restrict_rf(f, var, 1)(xr)
    den = f1 - f0
    return span * (f(x) - f0) / den, span * f.derivative(x, var) / den


def sample_maps(theta_map, phi_map, mu, tau):
    """``(theta_l, phi_l, alpha)`` from normalized maps ``theta_map(mu) -> (theta_l, dtheta/dmu)``
    and ``phi_map(theta_l, u) -> (|phi_l|, d|phi_l|/du)``: u = |2 tau - 1|, the sign of phi_l
    from tau < 1/2, alpha = dtheta/dmu * 2 d|phi|/du * sin(theta_l), 0 where a clamp acts."""
    tl, dF = theta_map(mu)
    s = np.where(tau < 0.5, -1.0, 1.0)
    u = np.abs(2.0 * tau - 1.0)
    ok = (tl >= 0) & (tl <= HALF_PI)
    tl = np.clip(tl, 0.0, HALF_PI)
    ph, dG = phi_map(tl, u)
    ok &= (ph >= 0) & (ph <= np.pi)
    pl = s * np.clip(ph, 0.0, np.pi)
    return tl, pl, np.where(ok, dF * 2.0 * dG * np.sin(tl), 0.0)


def _certify_positive(poly: RationalFunction | None) -> bool:
    if poly is None:
        return False
    try:
        return bool(poly.certify_denominator(max_depth=12, max_boxes=20000).certified)
    except Exception:  # noqa: BLE001 - degenerate polynomial: not certified
        return False


def _verify_theta(F: RationalFunction) -> dict:
    tv, mu = verify_axes("theta")
    nv, nm = len(tv), len(mu)
    dmin_all, dmin_in, folds = np.inf, np.inf, 0
    end0 = end1 = None
    for chunk in np.array_split(tv, 8):
        X = np.stack(np.meshgrid(chunk, mu, indexing="ij"), -1)
        val, d = normalized_map(F, 1, X, HALF_PI)
        inside = (val > 0) & (val < HALF_PI)
        dmin_all = min(dmin_all, float(d.min()))
        if inside.any():
            dmin_in = min(dmin_in, float(d[inside].min()))
        folds += int(((d <= 0) & inside).sum())
        e0, e1 = float(val[:, 0].max()), float(val[:, -1].min())
        end0 = e0 if end0 is None else max(end0, e0)
        end1 = e1 if end1 is None else min(end1, e1)
    qcert = F.certify_denominator(max_depth=12)
    ok = bool(qcert.certified and folds == 0 and dmin_all > 0)
    cert0 = cert1 = True  # endpoints exact by construction (normalized map)
    return {"ok": ok, "grid": [nv, nm], "q_certified": bool(qcert.certified),
            "q_lower_bound": float(qcert.lower_bound) if qcert.certified else None,
            "monotone_grid": folds == 0, "fold_points": folds,
            "min_derivative_unclamped": dmin_in, "min_derivative_global": dmin_all,
            "max_value_at_mu0": end0, "min_value_at_mu1": end1,
            "covers_grid": bool(abs(end0) < 1e-9 and abs(end1 - HALF_PI) < 1e-9),
            "ends_certified": bool(cert0 and cert1)}


def _verify_phi(G: RationalFunction) -> dict:
    tv, tl, u = verify_axes("phi")
    nv, nt, nu = len(tv), len(tl), len(u)
    dmin_all, dmin_in, folds = np.inf, np.inf, 0
    end0, end1 = -np.inf, np.inf
    for a in tv:
        X = np.stack(np.meshgrid([a], tl, u, indexing="ij"), -1)[0]
        val, d = normalized_map(G, 2, X, np.pi)
        inside = (val > 0) & (val < np.pi)
        dmin_all = min(dmin_all, float(d.min()))
        if inside.any():
            dmin_in = min(dmin_in, float(d[inside].min()))
        folds += int(((d <= 0) & inside).sum())
        end0 = max(end0, float(val[:, 0].max()))
        end1 = min(end1, float(val[:, -1].min()))
    qcert = G.certify_denominator(max_depth=12)
    ok = bool(qcert.certified and folds == 0 and dmin_all > 0)
    cert0 = cert1 = True  # endpoints exact by construction (normalized map)
    return {"ok": ok, "grid": [nv, nt, nu], "q_certified": bool(qcert.certified),
            "q_lower_bound": float(qcert.lower_bound) if qcert.certified else None,
            "monotone_grid": folds == 0, "fold_points": folds,
            "min_derivative_unclamped": dmin_in, "min_derivative_global": dmin_all,
            "max_value_at_u0": end0, "min_value_at_u1": end1,
            "covers_grid": bool(abs(end0) < 1e-9 and abs(end1 - np.pi) < 1e-9),
            "ends_certified": bool(cert0 and cert1)}


# --------------------------------------------------------------------------------------------
def _grid_poly(exponents, coef, domain, axes, dvar=None) -> np.ndarray:
    """Chebyshev polynomial (or its derivative in ``dvar``) on the tensor grid ``axes``,
    shape ``tuple(len(a) for a in axes)``, by contracting one 1-D table per axis."""
    from .rational.basis import chebyshev_derivative_table, chebyshev_table

    exponents = np.asarray(exponents, int)
    kmax = exponents.max(axis=0)
    C = np.zeros(tuple(int(k) + 1 for k in kmax))
    np.add.at(C, tuple(exponents.T), np.asarray(coef, float))
    out = C
    for v, a in enumerate(axes):
        lo, hi = domain[v]
        t = (2.0 * np.asarray(a, float) - (lo + hi)) / (hi - lo)
        if v == dvar:
            T = chebyshev_derivative_table(t, int(kmax[v])) * (2.0 / (hi - lo))
        else:
            T = chebyshev_table(t, int(kmax[v]))
        # contract the leading coefficient axis with T (points x k); the new axis goes last
        out = np.tensordot(out, T[:, :int(kmax[v]) + 1], axes=([0], [1]))
    return out


def monotone_refit(f: RationalFunction, var: int, X, lower, upper, axes, span: float,
                   min_slope_frac: float = 1e-3, max_rounds: int = 30, batch: int = 2000,
                   coef_bound: float = 1e6, deadline: float | None = None):
    """Refit the numerator of ``f = P / Q`` with ``Q`` fixed so that ``f`` INCREASES in
    variable ``var`` on the grid ``axes`` (one 1-D array per variable), staying as close to the
    intervals ``[lower, upper]`` at ``X`` as that allows.

    With Q fixed, ``dR/dx_var = (P' Q - P Q') / Q**2`` has a numerator LINEAR in P's
    coefficients, so "R' >= s" at a grid point is the LP row ``(P' Q - P Q') >= s Q**2``, with
    ``s = min_slope_frac * span / (b - a)`` (``span``: the range the map covers, ``[a, b]``: the
    domain of ``var``). The LP maximises the smallest normalized interval margin delta (which
    may stay negative: the intervals are soft) under the slope rows (hard); rows are generated:
    start from a coarse sub-grid, add (at most ``batch`` per round) the grid points where the
    slope falls below ``s`` until none does. Always feasible when ``deg P >= deg Q + 1`` in ``var`` (``P = u Q``
    is increasing wherever Q > 0). Returns ``(RationalFunction, info)``; Q and hence the Q > 0
    certificate are unchanged. ``deadline`` (a ``time.perf_counter()`` value): past it the
    refit gives up (returns ``None`` with the reason in ``info["status"]``).
    """
    from scipy.optimize import linprog

    from .rational.lp import IncrementalLP
    from .rational.basis import chebyshev_basis, chebyshev_basis_derivative

    X = np.asarray(X, float)
    lower = np.asarray(lower, float)
    upper = np.asarray(upper, float)
    E, dom = f.num_exponents, f.domain
    w = np.maximum(upper - lower, 1e-12)
    B = chebyshev_basis(X, E, dom)
    Qx = f.denominator(X)
    scale = float(np.max(np.abs(f.num_coef))) or 1.0
    slope = min_slope_frac * span / (dom[var, 1] - dom[var, 0])
    G = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(axes))

    def slope_rows(pts):
        Q = f.denominator(pts)
        dQ = chebyshev_basis_derivative(pts, f.den_exponents, dom, var) @ f.den_coef
        A = chebyshev_basis_derivative(pts, E, dom, var) * Q[:, None] - chebyshev_basis(pts, E, dom) * dQ[:, None]
        return A, slope * Q ** 2

    Qg = _grid_poly(f.den_exponents, f.den_coef, dom, axes).ravel()
    dQg = _grid_poly(f.den_exponents, f.den_coef, dom, axes, var).ravel()
    rhs_g = slope * Qg ** 2

    def slopes(p):
        """Slope-row residuals at every grid point (separable tensor evaluation)."""
        P = _grid_poly(E, p, dom, axes).ravel()
        dP = _grid_poly(E, p, dom, axes, var).ravel()
        return dP * Qg - P * dQg - rhs_g

    idx = np.arange(len(G)).reshape([len(a) for a in axes])
    for v, a in enumerate(axes):   # a coarse sub-grid (about 9 x 17 x 17 points) to start from
        step = max(1, (len(a) - 1) // (16 if v == var else 8))
        idx = np.take(idx, np.unique(np.r_[np.arange(0, len(a), step), len(a) - 1]), axis=v)
    rows = idx.ravel()
    K = len(E)
    # variables: p (K, scaled by `scale`), delta; maximise delta
    c = np.zeros(K + 1)
    c[-1] = -1.0
    one = np.ones((len(X), 1))
    A_int = np.vstack([np.hstack([-B * scale / w[:, None], one]), np.hstack([B * scale / w[:, None], one])])
    b_int = np.concatenate([-lower * Qx, upper * Qx]) / np.concatenate([w, w])
    bounds = [(-coef_bound, coef_bound)] * K + [(None, 1.0)]
    info = {"rounds": 0, "slope_rows": 0, "min_slope": None, "delta": None}
    p = None
    new = rows
    A_parts, b_parts = [A_int], [b_int]     # stacked only if linprog has to solve from scratch
    # One live HiGHS model, slope rows appended each round (warm-started dual simplex); linprog
    # from scratch without the bindings or if a warm solve does not end optimal.
    lp = IncrementalLP(c, [b_[0] for b_ in bounds], [b_[1] for b_ in bounds]) if IncrementalLP.available else None
    if lp is not None:
        lp.add_rows(A_int, b_int)
    t0 = time.perf_counter()
    for rnd in range(max_rounds):
        if deadline is not None and time.perf_counter() > deadline:
            info.update(status=f"time limit reached after {rnd} rounds ({time.perf_counter() - t0:.0f} s)")
            return None, info
        A_s, r_s = slope_rows(G[new])          # only the rows added this round
        A_new = np.hstack([-A_s * scale, np.zeros((len(new), 1))])
        A_parts.append(A_new)
        b_parts.append(-r_s)
        x = None
        if lp is not None:
            lp.add_rows(A_new, -r_s)
            x = lp.solve()
        if x is None:
            res = linprog(c, A_ub=np.vstack(A_parts), b_ub=np.concatenate(b_parts), bounds=bounds, method="highs")
            if res.status != 0:
                info.update(status=res.message)
                return None, info
            x = res.x
        p = x[:K] * scale
        sl = slopes(p)
        bad = np.setdiff1d(np.flatnonzero(sl < 0.0), rows)
        info.update(rounds=rnd + 1, slope_rows=int(len(rows)), delta=float(x[-1]))
        if len(bad) == 0:
            break
        new = bad[np.argsort(sl[bad])[:batch]]
        rows = np.union1d(rows, new)
    out = RationalFunction(dom, E, p, f.den_exponents, f.den_coef, var_names=f.var_names)
    info["min_slope"] = float(np.min((sl + rhs_g) / Qg ** 2))   # dR/dx on the whole grid
    return out, info


# --------------------------------------------------------------------------------------------
@dataclass
class CDFFit:
    """Rational inverse CDFs of one material, with their verification and the table they fit.

    ``fallback`` True: the rational sampler must not be used; renderers use ``table``."""

    table: CDFTable
    table_params: dict
    theta: RationalFunction | None
    phi: RationalFunction | None
    verification: dict
    fallback: bool
    reason: str = ""
    fit_info: dict = field(default_factory=dict)
    name: str = ""
    source: dict = field(default_factory=lambda: {"file": "", "sha256": ""})

    rows: list | None = None   # "rows" layout: per table row (F_v, G_v) or None (table row)
    pieces: object = None      # "pieces" layout: fit.cdf_pieces.PieceMaps

    @property
    def layout(self) -> str:
        """``"global"`` (F(theta_v, mu), G(theta_v, theta_l, u)), ``"rows"`` (fit.cdf_rows) or
        ``"pieces"`` (fit.cdf_pieces)."""
        if self.pieces is not None:
            return "pieces"
        return "global" if self.rows is None else "rows"

    # Sampling (NumPy reference of the Warp sampler) ------------------------------------------
    def _theta_map(self, tv, mu):
        """(theta_l, dtheta_l/dmu) of the rational map; NaN on table rows (rows, pieces layouts)."""
        if self.pieces is not None:
            v = self.table.row(tv)
            t, d = self.pieces.theta_map(v, mu)
            tab = ~self.pieces.row_ok[v]
            return np.where(tab, np.nan, t), np.where(tab, np.nan, d)
        if self.rows is None:
            return normalized_map(self.theta, 1, np.stack([tv, mu], -1), HALF_PI)
        from .cdf_rows import normalized_row_map

        v = self.table.row(tv)
        t, d = np.full(mu.shape, np.nan), np.full(mu.shape, np.nan)
        for r in np.unique(v):
            if self.rows[r] is not None:
                k = v == r
                t[k], d[k] = normalized_row_map(self.rows[r][0], mu[k][:, None], HALF_PI)
        return t, d

    def _phi_map(self, tv, tl, u):
        if self.pieces is not None:
            v = self.table.row(tv)
            p, d = self.pieces.phi_map(v, self.pieces.theta_piece(v, np.nan_to_num(tl)), u)
            tab = ~self.pieces.row_ok[v]
            return np.where(tab, np.nan, p), np.where(tab, np.nan, d)
        if self.rows is None:
            return normalized_map(self.phi, 2, np.stack([tv, tl, u], -1), np.pi)
        from .cdf_rows import normalized_row_map

        v = self.table.row(tv)
        p, d = np.full(u.shape, np.nan), np.full(u.shape, np.nan)
        for r in np.unique(v):
            if self.rows[r] is not None:
                k = v == r
                p[k], d[k] = normalized_row_map(self.rows[r][1], np.stack([tl[k], u[k]], -1), np.pi)
        return p, d

    def inverse_theta(self, theta_v, mu) -> np.ndarray:
        """theta_l = the rational CDF^-1_v(mu) (rad); NaN on table rows of the rows layout."""
        tv, mu = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(mu, float))
        return self._theta_map(tv, mu)[0]

    def inverse_phi(self, theta_v, theta_l, u) -> np.ndarray:
        """|phi_l| = the rational CDF^-1_v(u | theta_l) (rad, u = |2 tau - 1|); NaN on table rows."""
        tv, tl, u = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_v, theta_l, u)))
        return self._phi_map(tv, tl, u)[0]

    def _table_rows(self, tv) -> np.ndarray:
        """True where the sample's row is sampled with the table (rows / pieces layout, failed row)."""
        if self.pieces is not None:
            return ~self.pieces.row_ok[self.table.row(tv)]
        if self.rows is None:
            return np.zeros(np.shape(tv), bool)
        ok = np.array([r is not None for r in self.rows])
        return ~ok[self.table.row(tv)]

    def sample(self, theta_v, mu, tau):
        """``(theta_l, phi_l, alpha)``; alpha = dtheta/dmu * dphi/dtau * sin(theta_l) (= 1/pdf
        in 1/sr^-1), 0 where a clamp is active. Rows layout: rows without a verified fit are
        sampled with the table (alpha = 1 / the table's pdf)."""
        if self.rows is None and self.pieces is None and (self.theta is None or self.phi is None):
            raise ValueError("no rational fit (fallback); use .table")
        tv, mu, tau = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(mu, float),
                                          np.asarray(tau, float))
        tl, pl, alpha = sample_maps(lambda m: self._theta_map(tv, m), lambda t, u: self._phi_map(tv, t, u),
                                    mu, tau)
        return table_where(self.table, self._table_rows(tv), tv, mu, tau, tl, pl, alpha)

    def theta_cdf(self, theta_v, theta_l, iters: int = 40) -> np.ndarray:
        """P(theta <= theta_l) under the rational sampler (bisection of the monotone F; the
        table's CDF on table rows)."""
        tv, t = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(theta_l, float))
        lo, hi = np.zeros(t.shape), np.ones(t.shape)
        for _ in range(iters):
            m = 0.5 * (lo + hi)
            below = self._theta_map(tv, m)[0] <= t
            lo, hi = np.where(below, m, lo), np.where(below, hi, m)
        out = 0.5 * (lo + hi)
        tab = self._table_rows(tv)
        if tab.any():
            edges = np.linspace(0.0, HALF_PI, self.table.n_t + 1)
            v = self.table.row(tv)
            for r in np.unique(v[tab]):
                k = tab & (v == r)
                out[k] = np.interp(t[k], edges, self.table.cdf_theta[r])
        return np.where(t >= HALF_PI, 1.0, np.where(t <= 0, 0.0, out))

    def phi_cdf_half(self, theta_v, theta_l, phi_abs, iters: int = 40) -> np.ndarray:
        """P(|phi| <= phi_abs | theta_l) under the rational sampler (bisection in u)."""
        tv, tl, p = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(theta_l, float),
                                        np.asarray(phi_abs, float))
        lo, hi = np.zeros(p.shape), np.ones(p.shape)
        for _ in range(iters):
            m = 0.5 * (lo + hi)
            below = self._phi_map(tv, tl, m)[0] <= p
            lo, hi = np.where(below, m, lo), np.where(below, hi, m)
        out = 0.5 * (lo + hi)
        tab = self._table_rows(tv)
        if tab.any():
            edges = np.linspace(0.0, np.pi, self.table.n_p + 1)
            v = self.table.row(tv)
            j = np.clip(np.floor(tl / (HALF_PI / self.table.n_t)), 0, self.table.n_t - 1).astype(np.intp)
            for r, c in {(int(a), int(b)) for a, b in zip(v[tab], j[tab])}:
                k = tab & (v == r) & (j == c)
                out[k] = np.interp(p[k], edges, self.table.cdf_phi[r, c])
        return np.where(p >= np.pi, 1.0, np.where(p <= 0, 0.0, out))

    # Persistence ------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        from .rational.coefficient_file import to_dict as model_to_dict
        from .rational.model import RationalModel, Variable

        def model(f, names, out, rng):
            if f is None:
                return None
            m = RationalModel(name=f"{self.name}:{out}", kind="function",
                              variables=[Variable(n, "1" if n in ("mu", "u") else "rad", "identity", tuple(d))
                                         for n, d in zip(names, f.domain)],
                              functions=[f], outputs=(out,), value_min=None, value_name=out,
                              value_unit="rad",
                              domain_policy={"outside": "clamp", "value": f"clamp to {rng}"})
            return model_to_dict(m)

        t = self.table
        return {
            "format": FORMAT, "version": VERSION, "name": self.name,
            "sampler": {
                "theta_l": "pi/2 (F(theta_v, mu) - F(theta_v, 0)) / (F(theta_v, 1) - F(theta_v, 0))",
                "phi_l": "sign(tau - 1/2) pi (G(theta_v, theta_l, u) - G(.., 0)) / (G(.., 1) - G(.., 0)), u = |2 tau - 1|",
                "alpha": "dtheta_l/dmu * dphi_l/dtau * sin(theta_l)",
                "phi_origin": "azimuth of the view direction",
                "rows": "layout 'rows': row v = floor(theta_v / (pi/2) * n_v) uses F_v(mu), G_v(theta_l, u) "
                        "in the same formulas; a null row is sampled with the table",
                "pieces": "layout 'pieces': rational-quadratic pieces uniform in mu / u, rebuilt from "
                          "table_data by fit.cdf_pieces.build_pieces(n_mu, n_u); rows with row_ok false "
                          "are sampled with the table",
            },
            "table": dict(self.table_params),
            "table_data": {"theta_v": t.theta_v.tolist(), "cdf_theta": t.cdf_theta.tolist(),
                           "cdf_phi": t.cdf_phi.tolist(), "row_fallback": t.row_fallback.tolist(),
                           "eps": t.eps, "albedo": t.albedo.tolist()},
            "theta": model(self.theta, ("theta_v", "mu"), "theta_l", "[0, pi/2]"),
            "phi": model(self.phi, ("theta_v", "theta_l", "u"), "phi_abs", "[0, pi]"),
            "layout": self.layout,
            "pieces": None if self.pieces is None else {
                "n_mu": self.pieces.n_mu, "n_u": self.pieces.n_u,
                "row_ok": [bool(x) for x in self.pieces.row_ok]},
            "rows": None if self.rows is None else [
                None if r is None else {"theta": model(r[0], ("mu",), "theta_l", "[0, pi/2]"),
                                        "phi": model(r[1], ("theta_l", "u"), "phi_abs", "[0, pi]")}
                for r in self.rows],
            "verification": _jsonable(self.verification),
            "fallback": bool(self.fallback),
            "reason": self.reason,
            "fit": _jsonable(self.fit_info),
            "source": dict(self.source),
        }

    def save(self, path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), allow_nan=False) + "\n", encoding="utf-8")


def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return _jsonable(o.tolist())
    if isinstance(o, (bool, np.bool_)):
        return bool(o)
    if isinstance(o, (int, np.integer)):
        return int(o)
    if isinstance(o, (float, np.floating)):
        f = float(o)
        return f if np.isfinite(f) else None
    return o


def from_dict(d: dict, path=None) -> CDFFit:
    from .rational.coefficient_file import from_dict as model_from_dict

    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise BRDFFileError(path, f"not an {FORMAT} file")
    if d.get("version") not in (1, VERSION):
        raise BRDFFileError(path, f"unsupported {FORMAT} version {d.get('version')!r} (this reader knows {VERSION})")
    try:
        td = d["table_data"]
        table = CDFTable(theta_v=np.asarray(td["theta_v"], float), cdf_theta=np.asarray(td["cdf_theta"], float),
                         cdf_phi=np.asarray(td["cdf_phi"], float),
                         row_fallback=np.asarray(td["row_fallback"], bool), eps=float(td["eps"]),
                         albedo=np.asarray(td["albedo"], float))
        theta = model_from_dict(d["theta"], path).functions[0] if d.get("theta") else None
        phi = model_from_dict(d["phi"], path).functions[0] if d.get("phi") else None
        rows = None
        if d.get("layout", "global") == "rows":
            rows = [None if r is None else (model_from_dict(r["theta"], path).functions[0],
                                            model_from_dict(r["phi"], path).functions[0])
                    for r in d["rows"]]
            if len(rows) != table.n_v:
                raise ValueError(f"{len(rows)} row fits for {table.n_v} table rows")
        pieces = None
        if d.get("layout", "global") == "pieces":
            from .cdf_pieces import build_pieces, verify_pieces

            pd = d["pieces"]
            if len(pd["row_ok"]) != table.n_v:
                raise ValueError(f"{len(pd['row_ok'])} row flags for {table.n_v} table rows")
            pieces = build_pieces(table, int(pd["n_mu"]), int(pd["n_u"]), row_ok=pd["row_ok"])
            bad = ~np.asarray(verify_pieces(pieces)["rows"]) & pieces.row_ok
            if bad.any():
                raise ValueError(f"pieces of rows {np.flatnonzero(bad).tolist()} fail verification")
        fb = bool(d["fallback"])
        if not fb and rows is None and pieces is None and (theta is None or phi is None):
            raise ValueError("no fallback but rational functions missing")
        return CDFFit(table=table, table_params=dict(d.get("table", {})), theta=theta, phi=phi,
                      verification=dict(d.get("verification", {})), fallback=fb,
                      reason=str(d.get("reason", "")), fit_info=dict(d.get("fit", {})),
                      name=str(d.get("name", "")), source=dict(d.get("source", {})), rows=rows,
                      pieces=pieces)
    except BRDFFileError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise BRDFFileError(path, f"invalid {FORMAT} file ({e.__class__.__name__}: {e})") from None


def load(path) -> CDFFit:
    path = Path(path)
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BRDFFileError(path, "no such file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise BRDFFileError(path, f"cannot read CDF file ({e.__class__.__name__}: {e})") from None
    return from_dict(d, path)


# --------------------------------------------------------------------------------------------
DEFAULTS = dict(n_v=32, n_t=64, n_p=64, sub=3, eps=0.02, noise=1e-6)
TIME_LIMIT_S = 180.0   # default bound on fit_cdf's fitting time (s)


def table_only(evaluate, table_params: dict | None = None, reason: str = "table only", name: str = "",
               source: dict | None = None) -> CDFFit:
    """A :class:`CDFFit` with the tables and no rational fit (``fallback`` True: the tabulated
    samplers use it, a rational sampler falls back to them)."""
    params = dict(DEFAULTS, **(table_params or {}))
    return CDFFit(table=tabulate(evaluate, **params), table_params=params, theta=None, phi=None,
                  verification={}, fallback=True, reason=reason, name=name,
                  source=source or {"file": "", "sha256": ""})


def fit_theta(table: CDFTable, tol: float = 0.03, n_theta_v: int = 0, n_mu: int = 33,
              max_degree: int = 10, over=(-0.01, 0.01), time_limit: float | None = None):
    """Fit F(theta_v, mu) ~ CDF^-1_v(mu). Returns (FitResult, data info)."""
    from .rational.fitter import IntervalRationalFitter

    tv = np.concatenate([[0.0], table.theta_v, [HALF_PI]]) if n_theta_v <= 0 else np.linspace(0, HALF_PI, n_theta_v)
    mu = _cheb_points(n_mu)
    Y = inverse_cdf_theta(table, tv, mu)
    lo, hi = _monotone_intervals(Y, tol, 0.0, HALF_PI, over)
    X = np.stack(np.meshgrid(tv, mu, indexing="ij"), -1).reshape(-1, 2)
    f = IntervalRationalFitter(max_degree=max_degree, domain=[[0, HALF_PI], [0, 1]], time_limit=time_limit)
    r = f.fit(X, y=Y.ravel(), lower=lo.ravel(), upper=hi.ravel())
    return r, {"points": int(len(X)), "tol_rad": tol, "n_mu": n_mu, "n_theta_v": len(tv)}, (X, lo.ravel(), hi.ravel())


def fit_phi(table: CDFTable, tol: float = 0.15, n_theta_v: int = 9, n_theta_l: int = 9, degrees=(6, 4),
            n_u: int = 9, max_degree: int = 8, over=(-0.02, 0.02), time_limit: float | None = None):
    """Fit G(theta_v, theta_l, u) ~ |phi_l| = CDF^-1_v(u | theta_l) (half range).

    Fixed total degrees (6, 4) by default: the fitter's degree search on the trivariate data
    takes minutes (measured: 540 s without reaching a certified fit on vch_golden_yellow), so
    the default fits one degree pair and returns the least-violating fit when the intervals
    cannot all be met -- accuracy only affects variance; monotonicity, covering and Q > 0 are
    verified afterwards and decide the fallback. ``degrees=None`` runs the full search."""
    from .rational.fitter import IntervalRationalFitter

    tv = np.linspace(0, HALF_PI, n_theta_v)
    tl = np.linspace(0, HALF_PI, n_theta_l)
    u = _cheb_points(n_u)
    Y = inverse_cdf_phi(table, tv, tl, u)
    lo, hi = _monotone_intervals(Y, tol, 0.0, np.pi, over)
    X = np.stack(np.meshgrid(tv, tl, u, indexing="ij"), -1).reshape(-1, 3)
    f = IntervalRationalFitter(max_degree=max_degree, domain=[[0, HALF_PI], [0, HALF_PI], [0, 1]], degrees=degrees, max_iter=25,
                               time_limit=time_limit)
    r = f.fit(X, y=Y.ravel(), lower=lo.ravel(), upper=hi.ravel())
    return r, {"points": int(len(X)), "tol_rad": tol, "grid": [n_theta_v, n_theta_l, n_u]}, (X, lo.ravel(), hi.ravel())


def _summary(r) -> dict:
    return {"num_degree": r.num_degree, "den_degree": r.den_degree, "n_coefficients": r.n_coefficients,
            "feasible": bool(r.feasible), "valid": bool(r.valid), "time_s": r.time_s,
            "max_error_ratio": r.max_error_ratio, "message": r.message}


def _refit(f, var, data, span, verify, log, what, deadline=None):
    """Monotone refit of a folding fit on its verification grid; returns (f, verification, info)."""
    X, lo, hi = data
    t0 = time.perf_counter()
    g, info = monotone_refit(f, var, X, lo, hi, verify_axes(what), span, deadline=deadline)
    info["time_s"] = time.perf_counter() - t0
    if g is None:
        log(f"  {what}: monotone refit failed ({info.get('status')})")
        return f, verify(f), info
    v = verify(g)
    log(f"  {what}: monotone refit (Q kept, numerator refitted under slope >= 0 rows on the "
        f"verification grid): {info['rounds']} rounds, {info['slope_rows']} slope rows, margin "
        f"{info['delta']:.3g}, {info['time_s']:.1f} s, verified {v['ok']}")
    return g, v, info


def fit_cdf(evaluate, name: str = "", table: CDFTable | None = None, table_params: dict | None = None,
            theta_kw: dict | None = None, phi_kw: dict | None = None, refinements: int = 1,
            log=None, source: dict | None = None, monotone: bool = True,
            time_limit_s: float | None = TIME_LIMIT_S, layout: str = "pieces",
            rows_kw: dict | None = None, pieces_kw: dict | None = None) -> CDFFit:
    """Tabulate (unless ``table`` is given), fit both inverse CDFs, verify, decide fallback.

    Each refinement round that fails verification doubles the data density along the CDF
    variable (tighter monotone intervals) and halves the tolerance. With ``monotone`` (default)
    a fit whose Q is certified but that folds is first repaired by :func:`monotone_refit` on the
    verification grid (numerator refitted, Q kept) and verified again. ``log(str)`` reports.

    ``time_limit_s`` bounds the fitting time of the fitted layouts ("rows", "global";
    tabulation excluded): fits and refits stop when it is reached, and whatever is not verified
    by then falls back (the reason says so). The "pieces" layout fits nothing and has no time
    limit (1-25 s per material, mostly its variance gate).

    ``layout``: ``"pieces"`` (default; :mod:`fit.cdf_pieces`, monotone rational-quadratic
    pieces uniform in mu and u per table row, built from the table (no fitting), rows
    above the variance gate sampled with the table; ``pieces_kw`` tunes it), ``"rows"``
    (:mod:`fit.cdf_rows`, one univariate F_v and one bivariate G_v per table row fitted with
    the interval fitter, rows that fail verification sampled with the table; ``rows_kw`` tunes
    it) or ``"global"`` (the paper's F(theta_v, mu), G(theta_v, theta_l, u); ``theta_kw``,
    ``phi_kw``, ``refinements``, ``monotone`` apply to it).
    A sharp lobe can otherwise take many minutes (measured, near-mirror Blinn-Phong n = 5000:
    the theta refit alone ran 233 s with its LP re-solved from scratch every round)."""
    log = log or (lambda s: None)
    params = dict(DEFAULTS, **(table_params or {}))
    if table is None:
        table = tabulate(evaluate, **params)
    theta_kw = dict(theta_kw or {})
    phi_kw = dict(phi_kw or {})
    info: dict = {"fitter": "fit.fitter.IntervalRationalFitter", "rounds": []}
    t0 = time.perf_counter()
    deadline = None if time_limit_s is None else t0 + float(time_limit_s)

    def left():
        return None if deadline is None else max(deadline - time.perf_counter(), 0.0)

    def late():
        return deadline is not None and time.perf_counter() > deadline

    if layout == "rows":
        return _fit_cdf_rows(table, params, name, source, log, deadline, time_limit_s, rows_kw, t0, evaluate)
    if layout == "pieces":
        return _fit_cdf_pieces(table, params, name, source, log, pieces_kw, evaluate)
    if layout != "global":
        raise ValueError(f"layout must be 'pieces', 'rows' or 'global', not {layout!r}")
    F = G = None
    vt = vp = {"ok": False}
    for rnd in range(refinements + 1):
        if not vt.get("ok") and not late():
            rt, dt, data_t = fit_theta(table, **theta_kw, time_limit=left())
            F = rt.function
            vt = _verify_theta(F) if F is not None else {"ok": False, "error": "no fit"}
            info["theta"] = dict(_summary(rt), data=dt)
            log(f"  theta fit (round {rnd}): degrees ({rt.num_degree}, {rt.den_degree}), "
                f"{rt.n_coefficients} coefficients, {rt.time_s:.1f} s, verified {vt['ok']}")
            if F is not None and vt.get("q_certified") and not vt.get("ok") and monotone and not late():
                F, vt, info["theta"]["monotone_refit"] = _refit(F, 1, data_t, HALF_PI, _verify_theta, log,
                                                                "theta", deadline)
        if not vp.get("ok") and not late():
            rp, dp, data_p = fit_phi(table, **phi_kw, time_limit=left())
            G = rp.function
            vp = _verify_phi(G) if G is not None else {"ok": False, "error": "no fit"}
            info["phi"] = dict(_summary(rp), data=dp)
            log(f"  phi fit (round {rnd}): degrees ({rp.num_degree}, {rp.den_degree}), "
                f"{rp.n_coefficients} coefficients, {rp.time_s:.1f} s, verified {vp['ok']}")
            if G is not None and vp.get("q_certified") and not vp.get("ok") and monotone and not late():
                G, vp, info["phi"]["monotone_refit"] = _refit(G, 2, data_p, np.pi, _verify_phi, log,
                                                              "phi", deadline)
        info["rounds"].append({"theta_ok": vt.get("ok"), "phi_ok": vp.get("ok")})
        if (vt.get("ok") and vp.get("ok")) or late():
            break
        theta_kw["n_mu"] = 2 * theta_kw.get("n_mu", 33) - 1
        theta_kw["tol"] = 0.5 * theta_kw.get("tol", 0.03)
        phi_kw["n_u"] = 2 * phi_kw.get("n_u", 9) - 1
        phi_kw["tol"] = 0.5 * phi_kw.get("tol", 0.15)
    info["time_limit_s"] = time_limit_s
    info["time_limit_reached"] = bool(late())
    info["time_s"] = time.perf_counter() - t0
    reasons = []
    for what, v in (("theta", vt), ("phi", vp)):
        if not v.get("ok"):
            bad = [k for k in ("q_certified", "monotone_grid", "covers_grid", "ends_certified") if v.get(k) is False]
            reasons.append(f"{what}: " + (", ".join(f"not {b}" for b in bad) or v.get("error", "failed")))
    if reasons and info["time_limit_reached"]:
        reasons.append(f"fitting time limit {time_limit_s:g} s reached")
    fb = bool(reasons)
    return CDFFit(table=table, table_params=params, theta=F, phi=G,
                  verification={"theta": vt, "phi": vp}, fallback=fb,
                  reason="; ".join(reasons) if fb else "verified: monotone, covering, no poles",
                  fit_info=info, name=name, source=source or {"file": "", "sha256": ""})


def _fit_cdf_rows(table, params, name, source, log, deadline, time_limit_s, rows_kw, t0, evaluate) -> CDFFit:
    from .cdf_rows import fit_rows

    rows, info = fit_rows(table, log=log, deadline=deadline, evaluate=evaluate, **(rows_kw or {}))
    info.update(layout="rows", fitter="fit.fitter.IntervalRationalFitter", time_limit_s=time_limit_s,
                time_limit_reached=bool(deadline is not None and time.perf_counter() > deadline),
                time_s=time.perf_counter() - t0)
    n_ok = info["verified_rows"]
    fb = n_ok == 0
    why = {r.get("reason", "?") for r, f in zip(info["rows"], rows) if f is None}
    reason = _rows_reason(n_ok, info["n_rows"], why, "verified monotone, covering, no poles")
    if fb and info["time_limit_reached"]:
        reason += f" (fitting time limit {time_limit_s:g} s reached)"
    log(f"  {reason}")
    return CDFFit(table=table, table_params=params, theta=None, phi=None,
                  verification={"rows": [r.get("verification", {}) for r in info["rows"]]},
                  fallback=fb, reason=reason, fit_info=info, name=name,
                  source=source or {"file": "", "sha256": ""}, rows=None if fb else rows)


def _rows_reason(n_ok: int, n: int, why, all_ok: str) -> str:
    """The fit's reason for the per-row layouts: how many of the ``n`` view rows are rational
    and why the others are sampled with the table (``why``: their reasons)."""
    why = "; ".join(sorted(why))
    if n_ok == 0:
        return f"no row rational ({why})"
    if n_ok < n:
        return f"rational on {n_ok}/{n} view rows; the other {n - n_ok} rows are sampled with the table ({why})"
    return f"rational on all {n} view rows: {all_ok}"


def _fit_cdf_pieces(table, params, name, source, log, pieces_kw, evaluate) -> CDFFit:
    from .cdf_pieces import fit_pieces

    pm, info = fit_pieces(table, evaluate, log=log, **(pieces_kw or {}))
    info.update(layout="pieces", construction="fit.cdf_pieces (monotone rational-quadratic pieces)")
    n_ok = info["verified_rows"]
    why = {r.get("reason", "?") for r in info["rows"] if not r["ok"]}
    reason = _rows_reason(n_ok, info["n_rows"], why, "monotone, covering, no poles (by construction, checked)")
    log(f"  {reason}")
    return CDFFit(table=table, table_params=params, theta=None, phi=None,
                  verification={"pieces": info["verification"]}, fallback=n_ok == 0, reason=reason,
                  fit_info=info, name=name, source=source or {"file": "", "sha256": ""},
                  pieces=None if n_ok == 0 else pm)


def _reverified(fit: CDFFit, n_ok: int, n: int) -> CDFFit:
    """``fit`` with the fallback flag and reason of a per-row layout after :func:`verify`."""
    fit.fallback = n_ok == 0
    fit.reason = f"rational on {n_ok}/{n} view rows (others sampled with the table)" if n_ok else "no row rational"
    return fit


def verify(fit: CDFFit) -> CDFFit:
    """Re-run the verification of ``fit`` (e.g. after editing coefficients); updates fallback.
    Rows layout: a row that fails is dropped to the table (``fit.rows[v] = None``); pieces
    layout: its row flag is cleared."""
    if fit.pieces is not None:
        from .cdf_pieces import verify_pieces

        ver = verify_pieces(fit.pieces)
        fit.pieces.row_ok &= np.asarray(ver["rows"], bool)
        n_ok = int(fit.pieces.row_ok.sum())
        fit.verification = {"pieces": {k: ver[k] for k in ("ok", "failures")}}
        return _reverified(fit, n_ok, fit.table.n_v)
    if fit.rows is not None:
        from .cdf_rows import verify_row

        vs = []
        for v, r in enumerate(fit.rows):
            vs.append(verify_row(*r) if r is not None else {"ok": False})
            if r is not None and not vs[-1]["ok"]:
                fit.rows[v] = None
        n_ok = sum(r is not None for r in fit.rows)
        fit.verification = {"rows": vs}
        return _reverified(fit, n_ok, len(fit.rows))
    vt = _verify_theta(fit.theta) if fit.theta is not None else {"ok": False}
    vp = _verify_phi(fit.phi) if fit.phi is not None else {"ok": False}
    fit.verification = {"theta": vt, "phi": vp}
    reasons = [f"{w} verification failed" for w, v in (("theta", vt), ("phi", vp)) if not v["ok"]]
    fit.fallback = bool(reasons)
    fit.reason = "; ".join(reasons) if reasons else "verified: monotone, covering, no poles"
    return fit


def file_source(path) -> dict:
    p = Path(path)
    h = hashlib.sha256(p.read_bytes()).hexdigest()
    return {"file": p.name, "sha256": h}
