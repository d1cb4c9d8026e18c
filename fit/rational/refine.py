"""The second stage of a two-stage rational fit: the smallest weighted squared error inside
relaxed intervals (a quadratic program, HiGHS).

The interval LP (:mod:`fit.rational.fitter`) answers "is there a P/Q within these intervals?"
and, at the smallest tolerance met, its solution equi-oscillates: most points sit near the bound,
so its average error is close to the bound. This stage keeps a bound and lowers the average:
given the degrees (the exponent lists of a first-stage function ``f0`` with Q > 0), intervals
``[lo_i, hi_i]`` at the data points ``U_i`` (typically the first stage's tolerance relaxed by a
factor, so that there is room) and objective points ``V_j`` with targets ``t_j`` and weights
``w_j >= 0``, it solves

    minimise   sum_j w_j ((P(V_j) - t_j Q(V_j)) / Q_prev(V_j))^2      (Sanathanan-Koerner)
    subject to lo_i Q(U_i) <= P(U_i) <= hi_i Q(U_i)    at every data point,
               Bernstein coefficients of Q >= q_min on a regular split of the box (Q > 0
               on the whole box by construction), q_0 = 1, |coefficients| <= coef_bound,

``Q_prev`` the previous iterate's denominator (first: ``f0``'s): ``(P - t Q) / Q_prev`` tends
to ``R - t`` as the iteration settles. ``w_j`` may be updated between iterations by the
caller's ``reweight(R_prev(V), t)`` (secant weights that turn an error in a transformed value,
e.g. ``log rho``, into an error in the value). The interval rows are generated: the QP starts
with the rows where ``f0`` is closest to its intervals and adds the violated ones until every
data point is inside (float64 check), each row kept ``margin`` (1e-5 of the interval width, in
units of Q) inside so that the solver's feasibility tolerance cannot put a point outside.

How the QP is solved: the objective is whitened (QR of the weighted objective matrix with a ridge
of 1e-10, ``y = R z + c``), so that it reads ``min |y|^2`` under linear rows, a least-distance
problem, solved as one non-negative least-squares problem (Lawson and Hanson, *Solving Least
Squares Problems*, ch. 23; :func:`scipy.optimize.nnls`, at most ``20 n`` iterations), with HiGHS's
QP solver as the fallback (at most ``qp_iterations`` QP iterations, a count, so that the result
does not depend on the machine's load; no time limit by default: a wall-clock one, ``qp_time``,
would make a QP that a loaded machine slows fail where it succeeds on a quiet one, and the
iteration count already ends it). HiGHS's active-set QP on the raw Hessian stalled (57 s, then a time limit or a solve
error, on pieces of satin_rosaline); the NNLS form takes 0.02-0.15 s per solve there. Every loop
here stops on a count (``iterations``, ``max_rounds``, the NNLS and QP iteration limits).

Result: a :class:`fit.rational.function.RationalFunction` of the same exponents, or None when
the QP did not end optimal, a data point is still outside its interval after the rounds, or
Q > 0 is not certified (exact Bernstein coefficients): the caller keeps ``f0`` then. Nothing
is guaranteed between the data points beyond what the caller checks.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular
from scipy.optimize import nnls

from .basis import chebyshev_basis
from .bernstein import subdivision_matrix
from .function import RationalFunction
from .lp import new_model

try:   # the same HiGHS bindings as fit.rational.lp (the fallback QP solver only)
    import highspy as _hs
except ImportError:  # pragma: no cover
    _hs = None

available = _hs is not None


def _least_distance_nnls(G, h):
    """``argmin |y|^2`` s.t. ``G y >= h`` by the least-distance algorithm of Lawson and Hanson
    (Solving Least Squares Problems, ch. 23: one non-negative least-squares problem on
    ``[G'; h']``, rows normalised), or a reason (str) when it reports the rows infeasible."""
    norm = np.maximum(np.linalg.norm(G, axis=1), 1e-300)
    E = np.vstack([(G / norm[:, None]).T, (h / norm)[None, :]])
    f = np.zeros(E.shape[0])
    f[-1] = 1.0
    try:
        u, _ = nnls(E, f, maxiter=20 * E.shape[1])
    except RuntimeError as e:          # iteration limit
        return f"NNLS: {e}"
    r = E @ u - f
    if abs(r[-1]) < 1e-12:
        return "NNLS: constraints infeasible"
    return -r[:-1] / r[-1]


def _least_distance(G, h, iteration_limit, time_limit=None):
    """``argmin |y|^2`` s.t. ``G y >= h`` (HiGHS QP with the identity Hessian: the objective is
    whitened by the caller, which keeps the active-set solver well conditioned), or the model
    status (str) when it does not end optimal within ``iteration_limit`` QP iterations (the
    rule: a count, the same on any machine) or, only when a caller sets one, ``time_limit``
    wall-clock seconds (None: none)."""
    m, n = G.shape
    hs = new_model()
    hs.setOptionValue("qp_iteration_limit", int(iteration_limit))
    if time_limit is not None:
        hs.setOptionValue("time_limit", float(time_limit))
    hs.addVars(n, np.full(n, -np.inf), np.full(n, np.inf))
    G = np.ascontiguousarray(G, np.float64)
    hs.addRows(m, np.ascontiguousarray(h, np.float64), np.full(m, np.inf), m * n,
               (np.arange(m) * n).astype(np.int32), np.tile(np.arange(n, dtype=np.int32), m), G.reshape(-1))
    hs.passHessian(n, n, _hs.HessianFormat.kTriangular, np.arange(n, dtype=np.int32),
                   np.arange(n, dtype=np.int32), np.full(n, 2.0))
    hs.run()
    status = hs.getModelStatus()
    if status != _hs.HighsModelStatus.kOptimal:
        return str(status)
    return np.asarray(hs.getSolution().col_value, np.float64)


def refine(f0: RationalFunction, U, lo, hi, V, t, w, *, iterations: int = 3, reweight=None,
           q_min: float = 1e-4, bernstein_split: int = 2, max_rounds: int = 12, qp_time: float | None = None,
           certify_depth: int = 12, margin: float = 1e-5, sums=None, qp_iterations: int = 20000):
    """The weighted-least-squares function inside ``[lo, hi]`` (module docstring).

    ``f0``: first-stage function (its exponents and domain are kept; Q > 0 on the box);
    ``U`` ``(N, n_vars)`` data points (the variables ``f0`` reads), ``lo``/``hi`` ``(N,)`` their
    intervals (values of ``R``); ``V`` ``(M, n_vars)`` objective points, ``t`` ``(M,)`` targets,
    ``w`` ``(M,)`` weights; ``reweight(R(V), t) -> w`` (optional) between iterations.
    ``iterations``: Sanathanan-Koerner iterations; ``max_rounds``: constraint-generation rounds
    per iteration; ``qp_iterations``: QP iterations of the HiGHS fallback per QP (the budget);
    ``qp_time``: a wall-clock limit per QP (seconds; None, the default: none, the iteration
    count ends a QP; a QP that reaches it fails, ``info["reason"]`` says so, and the result then
    depends on the machine's load); ``margin``: see the module
    docstring. ``sums`` (optional): squared **sums** of residuals added to the objective (e.g. a
    directional albedo, :mod:`fit.rational.albedo3d`), ``(W, t2, groups, slope)``: points ``W``
    ``(K, n_vars)`` with targets ``t2`` ``(K,)``, ``groups`` a list of ``(idx, coef, const,
    weight)`` each adding ``weight * (sum_j coef_j slope_j (P(W_j) - t2_j Q(W_j)) / Q_prev(W_j)
    + const)^2`` (linearised ``sum_j coef_j (value_j - target_j) + const``; ``weight`` in the
    units of ``w``), ``slope(R, t2)`` the value's slope per unit of ``R`` (a secant), taken at the
    previous iterate. Returns ``(function, info)``: ``function`` None when the stage fails
    (``info["reason"]``; the caller keeps ``f0``)."""
    U, V = np.asarray(U, np.float64), np.asarray(V, np.float64)
    lo, hi, t, w = (np.asarray(a, np.float64).reshape(-1) for a in (lo, hi, t, w))
    if len(t) == 0 or not np.sum(np.maximum(w, 0.0)) > 0:
        return None, {"reason": "no objective point with a positive weight"}
    try:
        return _refine(f0, U, lo, hi, V, t, w, iterations, reweight, q_min, bernstein_split, max_rounds,
                       (int(qp_iterations), None if qp_time is None else float(qp_time)), certify_depth, margin, sums)
    except np.linalg.LinAlgError as e:
        return None, {"reason": f"linear algebra: {e}"}


def _sum_rows(sums, z, npv, fixed, Wp, Wq, scale):
    """The rows of the objective's squared sums (``sums`` of :func:`refine`) at coefficients ``z``
    (slopes and ``Q_prev`` from ``z``), each times ``sqrt(weight * scale)``; None when a
    ``Q_prev`` is not positive."""
    _, t2, groups, slope = sums
    qp = Wq @ z[npv:]
    if np.any(qp <= 0):
        return None
    sl = slope((Wp @ z[:npv]) / qp, t2)
    rows = []
    for idx, coef, const, weight in groups:
        idx = np.asarray(idx, np.intp)
        cj = (np.asarray(coef, np.float64) * sl[idx] / qp[idx])[:, None]
        row = np.concatenate([np.sum(cj * Wp[idx], axis=0), -np.sum(cj * t2[idx, None] * Wq[idx], axis=0)])
        row[fixed] += float(const)
        rows.append(np.sqrt(max(float(weight), 0.0) * scale) * row)
    return np.array(rows).reshape(len(rows), len(z))


def _refine(f0, U, lo, hi, V, t, w, iterations, reweight, q_min, bernstein_split, max_rounds, qp_limits,
            certify_depth, margin, sums=None):
    Ep, Eq, dom = f0.num_exponents, f0.den_exponents, f0.domain
    npv, nqv = len(Ep), len(Eq)
    k0 = int(np.flatnonzero(np.all(Eq == 0, axis=1))[0])
    Bp, Bq = chebyshev_basis(U, Ep, dom), chebyshev_basis(U, Eq, dom)
    Vp, Vq = chebyshev_basis(V, Ep, dom), chebyshev_basis(V, Eq, dom)
    if sums is not None:
        sums = (np.asarray(sums[0], np.float64), np.asarray(sums[1], np.float64).reshape(-1)) + tuple(sums[2:])
        Wp, Wq = chebyshev_basis(sums[0], Ep, dom), chebyshev_basis(sums[0], Eq, dom)
    M = subdivision_matrix(Eq, bernstein_split)               # Bernstein coefficients of Q (rows, nqv)
    qrows = np.hstack([np.zeros((len(M), npv)), M])
    width = np.maximum(hi - lo, 1e-300)
    # interval rows, divided by the width: (P - lo Q) / width >= margin, (hi Q - P) / width >= margin
    # (the margin absorbs the QP solver's feasibility tolerance: the float64 check below is exact)
    rl = np.hstack([Bp, -lo[:, None] * Bq]) / width[:, None]   # (P - lo Q)/w  >= 0
    ru = np.hstack([-Bp, hi[:, None] * Bq]) / width[:, None]   # (hi Q - P)/w >= 0
    z = np.concatenate([f0.num_coef, f0.den_coef / f0.den_coef[k0]])
    z[:npv] /= f0.den_coef[k0]
    fixed = npv + k0                                          # q_0 = 1
    free = np.delete(np.arange(npv + nqv), fixed)
    # start with the rows where f0 is closest to its intervals (both sides of the 4 n_coef tightest)
    s0 = np.minimum(rl @ z, ru @ z)
    active = set(np.argsort(s0)[:4 * (npv + nqv)].tolist())
    q_prev = Vq @ z[npv:]
    info = {"rounds": 0, "qp": 0}
    for it in range(max(int(iterations), 1)):
        if np.any(q_prev <= 0):
            return None, dict(info, reason="Q_prev not positive at an objective point")
        wscale = 1.0 / max(float(np.mean(np.maximum(w, 0.0))), 1e-300)
        wn = np.maximum(w, 0.0) * wscale                                           # scale-free objective
        A = np.hstack([Vp, -t[:, None] * Vq]) * (np.sqrt(wn) / q_prev)[:, None]
        if sums is not None:
            S = _sum_rows(sums, z, npv, fixed, Wp, Wq, wscale)
            if S is None:
                return None, dict(info, reason="Q_prev not positive at a point of a sum")
            A = np.vstack([A, S])
        # whiten: |A z|^2 = |R z_f + c|^2 + const with z_f the free coefficients (q_0 = 1 fixed),
        # y = R z_f + c; a ridge of 1e-10 of the mean squared column norm keeps R invertible
        lam = 1e-10 * float(np.sum(A[:, free] ** 2)) / len(free)
        Qm, Rm = np.linalg.qr(np.vstack([A[:, free], np.sqrt(lam) * np.eye(len(free))]))
        c = Qm.T @ np.concatenate([A[:, fixed], np.zeros(len(free))])
        z_new = None
        for _ in range(max_rounds):
            idx = np.array(sorted(active), dtype=np.intp)
            C = np.vstack([rl[idx], ru[idx], qrows])
            lo_r = np.concatenate([np.full(2 * len(idx), margin), np.full(len(M), q_min)])
            G = solve_triangular(Rm, C[:, free].T, trans="T").T         # C_f R^-1
            hh = lo_r - C[:, fixed] + G @ c
            y = _least_distance_nnls(G, hh)
            if available and (isinstance(y, str) or np.any(G @ y < hh - 1e-9 * (1.0 + np.abs(hh)))):
                y = _least_distance(G, hh, *qp_limits)      # HiGHS when NNLS fails or is inexact
            info["qp"] += 1
            if isinstance(y, str):
                return None, dict(info, reason=f"QP not optimal ({y})")
            z_try = z.copy()
            z_try[free] = solve_triangular(Rm, y - c)
            sl = np.minimum(rl @ z_try, ru @ z_try)
            bad = np.flatnonzero(sl < 0.0)
            info["rounds"] += 1
            if len(bad) == 0:
                z_new = z_try
                break
            new = np.setdiff1d(bad[np.argsort(sl[bad])][:max(2 * (npv + nqv), 64)], idx)
            if len(new) == 0:       # violated rows already in the QP: tolerance of the solver
                z_new = None
                break
            active.update(new.tolist())
        if z_new is None:
            break
        z = z_new
        q_prev = Vq @ z[npv:]
        if reweight is not None:
            w = np.asarray(reweight((Vp @ z[:npv]) / q_prev, t), np.float64)
        info["iterations"] = it + 1
    if info.get("iterations") is None:
        return None, dict(info, reason="no feasible QP solution within the rounds")
    f = RationalFunction(dom, Ep, z[:npv], Eq, z[npv:])
    R = f(U)
    if not (np.all(np.isfinite(R)) and np.all(R >= lo) and np.all(R <= hi)):
        # float64 check on the final function: a point outside by rounding is a failure
        return None, dict(info, reason="a data point outside its interval after the QP")
    cert = f.certify_denominator(max_depth=certify_depth)
    if not cert.certified:
        return None, dict(info, reason="Q > 0 not certified")
    info["certificate"] = cert
    return f, info
