"""One interval-fitting problem on fixed data: the points, their intervals and the rows of the
LP of :mod:`fit.rational.fitter`.

For fixed degrees this is linear in the coefficients when ``Q > 0`` (Salazar Celis, Cuyt,
Verdonk 2007, as used by the Rational BRDF paper). Each constraint row is divided by the
interval width ``w_i = u_i - l_i``, and the LP (scipy.optimize.linprog, HiGHS)

    maximise  delta
    subject to  (P(x_i) - l_i Q(x_i)) / w_i >= delta,   (u_i Q(x_i) - P(x_i)) / w_i >= delta,
                Q >= q_min on the box: Bernstein coefficients of Q on a regular split of the
                box >= q_min (``bernstein_split`` > 0; this implies Q >= q_min at every data and
                grid point, so those rows are only added for data points outside the box), or
                Q(x_i) >= q_min and Q(g) >= q_min on a grid g (``bernstein_split`` = 0),
                q_0 = 1  (constant Chebyshev coefficient: the Chebyshev-weighted mean of Q),
                |coefficients| <= coef_bound,  delta <= 1

is solved by the fitter by constraint generation on growing subsets of its rows.

:class:`IntervalProblem` holds the (finite, validated) points ``X`` ``(N, n_vars)``, intervals
``[lo, hi]``, centre values ``y``, the domain box ``(n_vars, 2)``, the Chebyshev basis matrix of
the points for every exponent row up to the largest degree, and builds the LP rows of a degree
pair (numerator columns ``cp``, denominator columns ``cq`` into that exponent list):

* interval rows of constraint ids ``2 i`` (lower side of point i) and ``2 i + 1`` (upper side),
  divided by the interval width and by the value scale;
* ``Q >= q_min`` rows: the Bernstein coefficients of Q on a regular split of the box
  (``bernstein_split`` > 0, which implies Q >= q_min everywhere on the box) or Q on a
  Chebyshev-spaced grid, plus extra rows added by the certification;
* the LP solved from scratch with ``scipy.optimize.linprog`` (the incremental model is
  :class:`fit.rational.lp.DegreePairLP`), and the slack of every constraint.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

from .basis import chebyshev_basis
from .bernstein import subdivision_matrix
from .function import RationalFunction


def finite_data(X, lower, upper, y, domain):
    """``(X, lower, upper, y, domain)`` ready for :class:`IntervalProblem`: ``X`` ``(N, n_vars)``
    and the intervals as float arrays, rows with a non-finite value dropped, ``y`` the interval
    centres when not given, zero-width intervals widened by a relative ulp-level epsilon, and
    ``domain`` (None: the bounding box of the points). ValueError when no finite point is left or
    an interval has upper < lower."""
    lower = np.asarray(lower, float).reshape(-1)
    upper = np.asarray(upper, float).reshape(-1)
    yc = 0.5 * (lower + upper) if y is None else np.asarray(y, float).reshape(-1)
    ok = np.all(np.isfinite(X), axis=1) & np.isfinite(lower) & np.isfinite(upper) & np.isfinite(yc)
    X, lower, upper, yc = X[ok], lower[ok], upper[ok], yc[ok]
    if len(X) == 0:
        raise ValueError("no finite data point")
    if np.any(upper < lower):
        raise ValueError("an interval has upper < lower")
    # Zero-width intervals cannot be normalised: widen by a relative ulp-level epsilon.
    w0 = upper - lower
    tiny = 1e-12 * np.maximum(np.abs(lower) + np.abs(upper), 1e-300)
    lower = np.where(w0 <= tiny, lower - tiny, lower)
    upper = np.where(w0 <= tiny, upper + tiny, upper)
    if domain is None:
        domain = np.stack([X.min(axis=0), X.max(axis=0)], axis=1)
        same = domain[:, 1] <= domain[:, 0]
        domain[same, 1] = domain[same, 0] + 1.0
    return X, lower, upper, yc, domain


class IntervalProblem:
    """Data and LP rows of one interval fit (see the module docstring).

    ``exponents``: every exponent row the degree pairs may use (the columns ``cp``/``cq`` of the
    LP rows index it); ``q_grid``: points per axis of the ``Q >= q_min`` grid (default 65 / 17 / 7
    for 1 / 2 / 3+ variables)."""

    def __init__(self, X, lower, upper, y, domain, exponents, q_min: float, coef_bound: float,
                 q_grid: int | None, bernstein_split: int):
        self.n_vars = X.shape[1]
        self.domain = domain
        self.X, self.lo, self.hi, self.y = X, lower, upper, y
        self.w = upper - lower
        self.scale = float(max(np.max(np.abs(lower)), np.max(np.abs(upper)), 1e-300))
        self.q_min, self.coef_bound, self.bernstein_split = q_min, coef_bound, bernstein_split
        self.E = exponents
        self._index = {tuple(e): k for k, e in enumerate(self.E)}
        self.B = chebyshev_basis(X, self.E, domain)
        ng = q_grid or {1: 65, 2: 17}.get(self.n_vars, 7)
        axes = [np.cos(np.linspace(np.pi, 0.0, ng)) * 0.5 * (b - a) + 0.5 * (a + b) for a, b in domain]
        G = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, self.n_vars)
        self.BG = chebyshev_basis(G, self.E, domain)
        self._bern_cache = {}
        self.subset0 = self._initial_subset()
        a, b = domain[:, 0], domain[:, 1]
        self.outside = np.any((X < a) | (X > b), axis=1)

    def columns(self, exponents) -> np.ndarray:
        """Indices of the exponent rows ``exponents`` in the problem's exponent list."""
        return np.array([self._index[tuple(e)] for e in exponents], dtype=np.intp)

    def function(self, cp, cq, p, q) -> RationalFunction:
        """The rational function of LP coefficients ``p`` (scaled), ``q`` on columns cp, cq."""
        return RationalFunction(self.domain, self.E[cp], p * self.scale, self.E[cq], q)

    def _initial_subset(self) -> np.ndarray:
        """Well-spread starting points: one per Chebyshev-spaced cell, plus extreme values."""
        N = len(self.X)
        k = {1: 48, 2: 14, 3: 6}.get(self.n_vars, 4)
        a, b = self.domain[:, 0], self.domain[:, 1]
        t = np.clip((2 * self.X - (a + b)) / (b - a), -1, 1)
        s = np.arccos(-t) / np.pi                      # Chebyshev-spread coordinate in [0, 1]
        cell = np.minimum((s * k).astype(np.int64), k - 1)
        key = np.ravel_multi_index(cell.T, (k,) * self.n_vars)
        centre = (cell + 0.5) / k
        dist = np.sum((s - centre) ** 2, axis=1)
        order = np.lexsort((dist, key))
        first = np.ones(N, bool)
        first[1:] = key[order][1:] != key[order][:-1]
        idx = set(order[first].tolist())
        for arr in (self.y, -self.y, self.w, -self.w):
            idx.update(np.argsort(arr)[:4].tolist())
        return np.array(sorted(idx), dtype=np.intp)

    def _bernstein_rows(self, cq) -> np.ndarray:
        """Linear map q -> Bernstein coefficients of Q on each sub-box of a regular split of the
        box (``bernstein_split`` parts per axis); rows of shape ``(n_rows, len(E))``.

        Constraining them to be >= q_min makes Q >= q_min on the whole box by construction."""
        key = tuple(cq)
        if key not in self._bern_cache:
            M = subdivision_matrix(self.E[cq], self.bernstein_split)   # (n_rows, len(cq))
            rows = np.zeros((M.shape[0], len(self.E)))
            rows[:, cq] = M
            self._bern_cache[key] = rows
        return self._bern_cache[key]

    def static_q_rows(self, cq, qrows) -> np.ndarray:
        """Q >= q_min rows that do not depend on the data subset: the Bernstein rows (which
        imply Q >= q_min on the whole box) or, without them, the grid; plus the extra rows."""
        parts = [self._bernstein_rows(cq)[:, cq]] if self.bernstein_split else [self.BG[:, cq]]
        if len(qrows):
            parts.append(qrows[:, cq])
        return np.vstack(parts)

    def point_rows(self, cp, cq, cons):
        """LP rows of the constraints ``cons`` (id ``2 i`` = lower side of point i, ``2 i + 1``
        = its upper side) and the Q >= q_min rows of their points. With Bernstein rows, Q >= q_min
        already holds on the whole box, so data Q rows are only kept for points outside it (the
        LP feasible set is unchanged)."""
        rows, upper = cons // 2, (cons % 2).astype(bool)
        Bp = self.B[np.ix_(rows, cp)]
        Bq = self.B[np.ix_(rows, cq)]
        ws = self.w[rows][:, None] / self.scale
        bound = np.where(upper, self.hi[rows], self.lo[rows])[:, None] / self.scale
        sign = np.where(upper, 1.0, -1.0)[:, None]
        # lower: -(P - l Q)/w + delta <= 0;  upper: -(u Q - P)/w + delta <= 0
        A = np.hstack([sign * Bp / ws, -sign * bound * Bq / ws, np.ones((len(rows), 1))])
        Qd = Bq[self.outside[rows]] if self.bernstein_split else Bq
        return A, Qd

    def solve_lp(self, cp, cq, rows, qrows):
        """LP on the constraints ``rows`` (ids as in :meth:`point_rows`) and extra Q rows, solved
        from scratch; returns (p, q, delta) or None."""
        npv, nqv = len(cp), len(cq)
        A1, Qd = self.point_rows(cp, cq, rows)
        Q_rows = np.vstack([Qd, self.static_q_rows(cq, qrows)])
        A3 = np.hstack([np.zeros((len(Q_rows), npv)), -Q_rows, np.zeros((len(Q_rows), 1))])
        A = np.vstack([A1, A3])
        b = np.concatenate([np.zeros(len(rows)), -self.q_min * np.ones(len(Q_rows))])
        c = np.zeros(npv + nqv + 1)
        c[-1] = -1.0
        bounds = [(-self.coef_bound, self.coef_bound)] * (npv + nqv) + [(-1e3, 1.0)]
        bounds[npv] = (1.0, 1.0)                              # q_0 = 1 (cq[0] is the constant term)
        res = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method="highs")
        if res.status != 0 or res.x is None:
            return None
        z = res.x
        return z[:npv], z[npv:npv + nqv], float(z[-1])

    def slack(self, cp, cq, p, q):
        """Normalised slack of every constraint, ``(P - l Q) / w`` at id ``2 i`` and
        ``(u Q - P) / w`` at ``2 i + 1`` (LP units; negative = violated), and P, Q at the points."""
        P = self.B[:, cp] @ p * self.scale
        Q = self.B[:, cq] @ q
        s = np.empty(2 * len(P))
        s[0::2] = (P - self.lo * Q) / self.w
        s[1::2] = (self.hi * Q - P) / self.w
        return s, P, Q
