"""Monotone repair of a rational inverse CDF (the paper's "global" layout,
:mod:`fit.sampling.global_layout`): refit the numerator of ``f = P / Q`` with ``Q`` fixed so that
``f`` increases in its CDF variable on a dense grid (:func:`monotone_refit`).

With Q fixed, the Q > 0 certificate is unchanged, and ``dR/dx = (P' Q - P Q') / Q**2`` has a
numerator linear in P's coefficients: "slope >= s" at a grid point is one LP row. Grid values of
the polynomials are evaluated separably (:func:`_grid_poly`, one 1-D Chebyshev table per axis).
"""
from __future__ import annotations

import time

import numpy as np
from scipy.optimize import linprog

from ..rational.basis import (chebyshev_basis, chebyshev_basis_derivative, chebyshev_derivative_table,
                              chebyshev_table)
from ..rational.function import RationalFunction
from ..rational.lp import IncrementalLP


def _grid_poly(exponents, coef, domain, axes, dvar=None) -> np.ndarray:
    """Chebyshev polynomial (or its derivative in ``dvar``) on the tensor grid ``axes``,
    shape ``tuple(len(a) for a in axes)``, by contracting one 1-D table per axis."""
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
