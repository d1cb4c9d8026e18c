"""Interval-constraint rational fitting with a guaranteed error (linear programming).

Given points ``x_i`` and intervals ``[l_i, u_i]`` (from a tolerance or a cluster spread), find
``R = P / Q`` in the Chebyshev basis (:mod:`fit.rational`) with

    l_i <= R(x_i) <= u_i  for every i      and      Q > 0 on the whole domain box.

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

is solved by *constraint generation*: start from a small well-spread subset of the points
(Chebyshev-spread cells plus the extreme values), evaluate all points, add the worst violators,
repeat until no point is outside its interval. Since the subset LP is a relaxation, ``delta <= 0``
on a subset proves the degrees infeasible for the whole data set (fast rejection). The rounds
of one degree pair share one HiGHS model (SciPy's bindings): new rows are appended and the dual
simplex restarts from the previous optimal basis (falls back to ``linprog`` from scratch if the
bindings are missing or a warm solve does not end optimal).

The degree search walks the (numerator, denominator) plane: feasibility is monotone in both
degrees, so for each denominator degree n, from the largest down, a binary search finds the
smallest feasible numerator degree m; only pairs with fewer coefficients than the best found so
far are tried, and m never goes below the smallest feasible m of a higher denominator degree. An optional ``start_degrees``
pair (e.g. the previous colour channel's degrees) is tried first: if feasible it is the initial
best, which prunes most of the walk without changing its result. The result
is the feasible fit with the FEWEST coefficients (ties: lower denominator degree).

Guarantees of a result with ``valid`` True:
* every data point was evaluated in float64 after the fit and lies in its interval
  (``max_violation <= 0``);
* Q > 0 on the whole domain box, proved by exact (rational-arithmetic) Bernstein coefficients
  with midpoint subdivision (:meth:`fit.rational.RationalFunction.certify_denominator`).
  During the fit, Q >= q_min is enforced on a grid; if the certificate fails, the points where Q
  is smallest on a dense grid are added and the LP is solved again.

If no degree up to ``max_degree`` is feasible, the least-violating fit at the largest degrees is
returned with ``feasible=False`` and its measured error (never flagged valid).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from math import comb

import numpy as np
from scipy.optimize import linprog

# Incremental LP (add rows, warm-started dual simplex) through HiGHS's official Python bindings
# (`highspy`, a declared dependency); SciPy's bundled private copy is the second choice; without
# either, every round is solved from scratch with `linprog` (same LP, same result, slower).
try:
    import highspy as _hs

    _HighsModel, _HighsStatus = _hs.Highs, _hs.HighsModelStatus
except Exception:  # pragma: no cover
    try:
        from scipy.optimize._highspy import _core as _hs

        _HighsModel, _HighsStatus = _hs._Highs, _hs.HighsModelStatus
    except Exception:
        _HighsModel = _HighsStatus = None
_highs = _HighsModel  # truthy when incremental solves are available

from .rational import (PositivityCertificate, RationalFunction, _de_casteljau_split_float,
                       bernstein_coefficients_float, chebyshev_basis, tensor_exponents,
                       total_degree_exponents)


def _elevate(b: np.ndarray, shape) -> np.ndarray:
    """Degree-elevate tensor Bernstein coefficients to ``shape`` (exact formula, float64)."""
    for axis, target in enumerate(shape):
        while b.shape[axis] < target:
            a = np.moveaxis(b, axis, 0)
            n = a.shape[0] - 1
            out = np.empty((n + 2,) + a.shape[1:])
            out[0], out[n + 1] = a[0], a[n]
            for i in range(1, n + 1):
                out[i] = i / (n + 1) * a[i - 1] + (1 - i / (n + 1)) * a[i]
            b = np.moveaxis(out, 0, axis)
    return b


def _split_regular(b: np.ndarray, axis: int, parts: int) -> list:
    """Bernstein coefficients on ``parts`` equal sub-intervals of ``axis`` (parts = 1, 2, 4, ...)."""
    out = [b]
    while len(out) < parts:
        new = []
        for x in out:
            new.extend(_de_casteljau_split_float(x, axis))
        out = new
    return out

__all__ = ["intervals_from_tolerance", "intervals_from_spread", "FitResult", "IntervalRationalFitter"]


# --------------------------------------------------------------------------------------------
# Intervals
# --------------------------------------------------------------------------------------------
def intervals_from_tolerance(y, tol: float, abs_floor: float = 0.0):
    """``[y - e, y + e]`` with ``e = max(tol |y|, abs_floor)``.

    The absolute floor keeps zero (or clamped-to-zero) values feasible: with ``abs_floor > 0``
    every interval has a positive width.
    """
    y = np.asarray(y, dtype=np.float64)
    e = np.maximum(tol * np.abs(y), abs_floor)
    return y - e, y + e


def intervals_from_spread(y, std, k: float = 2.0, abs_floor: float = 0.0, tol_min: float = 0.0):
    """``[y - e, y + e]`` with ``e = max(k std, tol_min |y|, abs_floor)`` (cluster spread)."""
    y = np.asarray(y, dtype=np.float64)
    e = np.maximum(np.maximum(k * np.asarray(std, float), tol_min * np.abs(y)), abs_floor)
    return y - e, y + e


# --------------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------------
@dataclass
class FitResult:
    """Outcome of a fit.

    ``function`` is R = P/Q on the fitted domain, in the units of the intervals.
    ``feasible``: all data points inside their intervals (checked in float64 after the fit).
    ``certificate``: proof of Q > 0 on the box (see :class:`PositivityCertificate`).
    ``valid`` = feasible and certified: the only state in which the error guarantee holds.
    ``max_violation``: max over points of ``max(l - R, R - u) / w`` (<= 0 when feasible).
    ``max_error_ratio``: max over points of ``|R - y| / e`` where ``e`` = half-width
    (<= 1 when feasible and the intervals are symmetric).
    """

    function: RationalFunction | None
    num_degree: int
    den_degree: int
    feasible: bool
    certificate: PositivityCertificate | None
    delta: float
    max_violation: float
    max_error_ratio: float
    n_points: int
    n_constraints: int
    n_lp: int
    time_s: float
    tried: list = field(default_factory=list)
    message: str = ""

    @property
    def valid(self) -> bool:
        return bool(self.feasible and self.certificate is not None and self.certificate.certified)

    @property
    def n_coefficients(self) -> int:
        return self.function.n_coefficients if self.function is not None else 0

    def __call__(self, x):
        return self.function(x)


@dataclass
class _Attempt:
    m: int
    n: int
    p: np.ndarray | None
    q: np.ndarray | None
    delta: float
    feasible: bool          # all points inside (float check)
    infeasible_proof: bool  # LP on a subset had delta <= 0
    max_violation: float
    n_constraints: int
    n_lp: int
    certificate: PositivityCertificate | None = None



_HIGHS_OPTIONS: dict = {}   # extra HiGHS options for the incremental model (defaults measured best)


class IncrementalLP:
    """``min cost . x`` s.t. ``A x <= ub`` (rows added over time), ``lo <= x <= hi``, as one live
    HiGHS model: every :meth:`solve` after :meth:`add_rows` is a warm-started dual simplex from
    the previous basis. Needs HiGHS's Python bindings (``available``); callers fall back to
    ``linprog`` from scratch without them, or when :meth:`solve` returns None (not optimal)."""

    available = _HighsModel is not None

    def __init__(self, cost, lo, hi):
        self.nv = len(cost)
        h = _HighsModel()
        h.setOptionValue("output_flag", False)
        for k_, v_ in _HIGHS_OPTIONS.items():
            h.setOptionValue(k_, v_)
        lo = np.array([-np.inf if v is None else v for v in lo], dtype=np.float64)
        hi = np.array([np.inf if v is None else v for v in hi], dtype=np.float64)
        h.addVars(self.nv, lo, hi)
        h.changeColsCost(self.nv, np.arange(self.nv, dtype=np.int32), np.asarray(cost, dtype=np.float64))
        self.h = h

    def add_rows(self, A, ub):
        m = A.shape[0]
        if m == 0:
            return
        A = np.ascontiguousarray(A, dtype=np.float64)
        starts = (np.arange(m, dtype=np.int32) * self.nv).astype(np.int32)
        idx = np.tile(np.arange(self.nv, dtype=np.int32), m)
        self.h.addRows(m, np.full(m, -np.inf), np.ascontiguousarray(ub, dtype=np.float64),
                       m * self.nv, starts, idx, A.reshape(-1))

    def solve(self):
        """The optimal x, or None if HiGHS did not end optimal."""
        self.h.run()
        if self.h.getModelStatus() != _HighsStatus.kOptimal:
            return None
        return np.asarray(self.h.getSolution().col_value, dtype=np.float64)


class _LPSession:
    """One HiGHS model per degree pair, grown by constraint generation.

    Same LP as :meth:`IntervalRationalFitter._solve_lp` (identical rows and bounds), but rows are
    added to the live model so every re-solve is a warm-started dual simplex from the previous
    basis instead of a solve from scratch.
    """

    def __init__(self, fitter, cp, cq, qrows):
        self.f, self.cp, self.cq = fitter, cp, cq
        self.npv, self.nqv = len(cp), len(cq)
        self.nv = self.npv + self.nqv + 1
        lo = np.full(self.nv, -fitter.coef_bound)
        hi = np.full(self.nv, fitter.coef_bound)
        lo[self.npv] = hi[self.npv] = 1.0                   # q_0 = 1
        lo[-1], hi[-1] = -1e3, 1.0
        cost = np.zeros(self.nv)
        cost[-1] = -1.0
        self.lp = IncrementalLP(cost, lo, hi)
        self._add_q(fitter._static_q_rows(cq, qrows))

    def _add_q(self, Qr):
        A = np.hstack([np.zeros((len(Qr), self.npv)), -Qr, np.zeros((len(Qr), 1))])
        self.lp.add_rows(A, np.full(len(Qr), -self.f.q_min))

    def add_points(self, rows):
        A, Qd = self.f._point_rows(self.cp, self.cq, rows)
        self.lp.add_rows(A, np.zeros(len(rows)))
        if len(Qd):
            self._add_q(Qd)

    def solve(self):
        self.f._lp_count += 1
        z = self.lp.solve()
        if z is None:
            return None
        return z[:self.npv], z[self.npv:self.npv + self.nqv], float(z[-1])


# --------------------------------------------------------------------------------------------
# Fitter
# --------------------------------------------------------------------------------------------
class IntervalRationalFitter:
    """Fit the rational function with the fewest coefficients inside given intervals.

    Parameters
    ----------
    tol, abs_floor : intervals ``y +- max(tol |y|, abs_floor)`` when :meth:`fit` gets ``y``.
    max_degree : largest numerator and denominator (total) degree tried.
    max_den_degree : largest denominator degree (default ``max_degree``).
    degree_kind : ``"total"`` (sum of exponents <= d) or ``"tensor"`` (each exponent <= d).
    domain : ``(n_vars, 2)`` box; default: the bounding box of the points.
    q_min : lower bound enforced on Q (with q_0 = 1) at grid and data points.
    q_grid : points per axis of the Q >= q_min grid (default 33 / 33 / 9 for 1 / 2 / 3 vars).
    degrees : optional fixed ``(m, n)``; skips the search.
    progress : optional callable ``progress(event: dict)`` called after each degree pair.
    start_degrees : optional ``(m, n)`` tried first in the search (e.g. the degrees of another
        colour channel); if feasible it prunes the search, which still returns the
        fewest-coefficient pair.
    incremental : grow one HiGHS model per degree pair (warm-started re-solves) instead of
        solving every constraint-generation LP from scratch (same LP, same result).
    best_effort : when no degree pair is feasible, converge the least-violation LP at the
        largest degrees for the flagged result (False: return the unconverged attempt; callers
        that only need to know "infeasible" skip that cost).
    time_limit : seconds; when exceeded, the search stops trying new degree pairs and the
        running pair stops its rounds. The result is then the best found so far (valid only if
        it passed every check; the message says the limit was reached).
    """

    _batch_mult = 2.0   # violators added per constraint-generation round, per coefficient

    def __init__(self, tol: float = 0.05, abs_floor: float = 0.0, max_degree: int = 10,
                 max_den_degree: int | None = None, degree_kind: str = "total", domain=None,
                 q_min: float = 1e-4, q_grid: int | None = None, degrees=None,
                 coef_bound: float = 1e6, max_iter: int = 60, certify_depth: int = 12,
                 progress=None, delta_min: float = 1e-10, bernstein_split: int = 2,
                 incremental: bool = True, start_degrees=None, best_effort: bool = True,
                 time_limit: float | None = None):
        if degree_kind not in ("total", "tensor"):
            raise ValueError("degree_kind must be 'total' or 'tensor'")
        self.tol = float(tol)
        self.abs_floor = float(abs_floor)
        self.max_degree = int(max_degree)
        self.max_den_degree = self.max_degree if max_den_degree is None else int(max_den_degree)
        self.degree_kind = degree_kind
        self.domain = None if domain is None else np.asarray(domain, float).reshape(-1, 2)
        self.q_min = float(q_min)
        self.q_grid = q_grid
        self.degrees = degrees
        self.coef_bound = float(coef_bound)
        self.max_iter = int(max_iter)
        self.certify_depth = int(certify_depth)
        self.progress = progress
        self.delta_min = float(delta_min)
        self.bernstein_split = int(bernstein_split)
        self.incremental = bool(incremental)
        self.start_degrees = start_degrees
        self.best_effort = bool(best_effort)
        self.time_limit = None if time_limit is None else float(time_limit)

    # Public API ----------------------------------------------------------------------------
    def fit(self, X, y=None, lower=None, upper=None) -> FitResult:
        """Fit points ``X`` (``(N, n_vars)`` or ``(N,)``) with values ``y`` (intervals from
        ``tol``/``abs_floor``) or explicit ``lower``/``upper``. Non-finite rows are ignored."""
        t0 = time.perf_counter()
        self._prepare(X, y, lower, upper)
        if self.degrees is not None:
            m, n = (int(d) for d in self.degrees)
            att = self._fit_pair(m, n)
            if att.feasible:
                att = self._make_certified(att)
            else:
                att = self._fit_pair(m, n, converge=True)
            tried = [(m, n, att.feasible, self._ncoef(m, n))]
            best = att
        else:
            best, tried = self._search()
        return self._finish(best, tried, t0)

    def proves_infeasible(self, X, degrees, y=None, lower=None, upper=None, max_rounds: int = 6) -> bool:
        """True if at most ``max_rounds`` constraint-generation rounds prove that no rational
        function of ``degrees = (m, n)`` meets every interval (the LP on a subset of the points
        has no positive margin). False means "not refuted" (feasible, or not proved in time).
        A cheap pre-check: feasibility is monotone in both degrees."""
        self._prepare(X, y, lower, upper)
        m, n = (int(d) for d in degrees)
        att = self._fit_pair(m, n, max_rounds=max_rounds)
        return bool(att.infeasible_proof and not att.feasible)

    def subset_margin(self, X, degrees, y=None, lower=None, upper=None, rounds: int = 1) -> float:
        """Margin delta of the LP after ``rounds`` constraint-generation rounds at ``degrees``.

        An upper bound on the margin any rational function of these degrees can reach on all
        points (the LP on a subset is a relaxation), returned as ``inf`` when the fit is already
        feasible. Small values mark hard data: :func:`fit.brdf_fit.fit_brdf` ranks its colour
        channels with one round (measured on the six RGL materials at cores of 60/50/40 deg: the
        channel with the lowest one-round margin was refuted whenever any was)."""
        self._prepare(X, y, lower, upper)
        m, n = (int(d) for d in degrees)
        att = self._fit_pair(m, n, max_rounds=rounds)
        return float("inf") if att.feasible else float(att.delta)

    def _out_of_time(self) -> bool:
        return self.time_limit is not None and time.perf_counter() - self._t0 > self.time_limit

    def _prepare(self, X, y, lower, upper):
        self._t0 = time.perf_counter()
        X = np.asarray(X, dtype=np.float64)
        if X.ndim == 1:
            X = X[:, None]
        if lower is None or upper is None:
            if y is None:
                raise ValueError("give y or lower and upper")
            lower, upper = intervals_from_tolerance(y, self.tol, self.abs_floor)
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

        domain = self.domain
        if domain is None:
            domain = np.stack([X.min(axis=0), X.max(axis=0)], axis=1)
            same = domain[:, 1] <= domain[:, 0]
            domain[same, 1] = domain[same, 0] + 1.0
        self._setup(X, lower, upper, yc, domain)

    # Internals -----------------------------------------------------------------------------
    def _exponents(self, d: int) -> np.ndarray:
        if self.degree_kind == "total":
            return total_degree_exponents(self.n_vars, d)
        return tensor_exponents([d] * self.n_vars)

    def _nterms(self, d: int) -> int:
        return comb(d + self.n_vars, self.n_vars) if self.degree_kind == "total" else (d + 1) ** self.n_vars

    def _ncoef(self, m: int, n: int) -> int:
        return self._nterms(m) + self._nterms(n)

    def _setup(self, X, lower, upper, y, domain):
        self.n_vars = X.shape[1]
        self._domain = domain
        self._X, self._lo, self._hi, self._y = X, lower, upper, y
        self._w = upper - lower
        self._scale = float(max(np.max(np.abs(lower)), np.max(np.abs(upper)), 1e-300))
        dmax = max(self.max_degree, self.max_den_degree)
        if self.degrees is not None:
            dmax = max(dmax, *self.degrees)
        self._E = self._exponents(dmax)
        self._index = {tuple(e): k for k, e in enumerate(self._E)}
        self._B = chebyshev_basis(X, self._E, domain)
        ng = self.q_grid or {1: 65, 2: 17}.get(self.n_vars, 7)
        axes = [np.cos(np.linspace(np.pi, 0.0, ng)) * 0.5 * (b - a) + 0.5 * (a + b) for a, b in domain]
        G = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, self.n_vars)
        self._G = G
        self._BG = chebyshev_basis(G, self._E, domain)
        self._bern_cache = {}
        self._extra_q = np.zeros((0, len(self._E)))
        self._subset0 = self._initial_subset()
        a, b = domain[:, 0], domain[:, 1]
        self._outside = np.any((X < a) | (X > b), axis=1)
        self._lp_count = 0

    def _cols(self, d: int) -> np.ndarray:
        return np.array([self._index[tuple(e)] for e in self._exponents(d)], dtype=np.intp)

    def _initial_subset(self) -> np.ndarray:
        """Well-spread starting points: one per Chebyshev-spaced cell, plus extreme values."""
        N = len(self._X)
        k = {1: 48, 2: 14, 3: 6}.get(self.n_vars, 4)
        a, b = self._domain[:, 0], self._domain[:, 1]
        t = np.clip((2 * self._X - (a + b)) / (b - a), -1, 1)
        s = np.arccos(-t) / np.pi                      # Chebyshev-spread coordinate in [0, 1]
        cell = np.minimum((s * k).astype(np.int64), k - 1)
        key = np.ravel_multi_index(cell.T, (k,) * self.n_vars)
        centre = (cell + 0.5) / k
        dist = np.sum((s - centre) ** 2, axis=1)
        order = np.lexsort((dist, key))
        first = np.ones(N, bool)
        first[1:] = key[order][1:] != key[order][:-1]
        idx = set(order[first].tolist())
        for arr in (self._y, -self._y, self._w, -self._w):
            idx.update(np.argsort(arr)[:4].tolist())
        return np.array(sorted(idx), dtype=np.intp)

    def _bernstein_rows(self, cq) -> np.ndarray:
        """Linear map q -> Bernstein coefficients of Q on each sub-box of a regular split of the
        box (``bernstein_split`` parts per axis); rows of shape ``(n_rows, len(E))``.

        Constraining them to be >= q_min makes Q >= q_min on the whole box by construction."""
        key = tuple(cq)
        if key not in self._bern_cache:
            E = self._E[cq]
            splits = self.bernstein_split
            blocks = []
            for j in range(len(cq)):
                unit = np.zeros(len(cq))
                unit[j] = 1.0
                b, _ = bernstein_coefficients_float(E, unit)
                # pad to full degrees so every column has the same shape
                full = np.zeros(tuple(int(d) + 1 for d in E.max(axis=0)))
                full[tuple(slice(0, s_) for s_ in b.shape)] = b if b.shape == full.shape else 0.0
                if b.shape != full.shape:
                    full = _elevate(b, full.shape)
                parts = [full]
                for axis in range(full.ndim):
                    new = []
                    for part in parts:
                        new.extend(_split_regular(part, axis, splits))
                    parts = new
                blocks.append(np.concatenate([p_.reshape(-1) for p_ in parts]))
            M = np.stack(blocks, axis=1)                      # (n_rows, len(cq))
            rows = np.zeros((M.shape[0], len(self._E)))
            rows[:, cq] = M
            self._bern_cache[key] = rows
        return self._bern_cache[key]

    def _static_q_rows(self, cq, qrows) -> np.ndarray:
        """Q >= q_min rows that do not depend on the data subset: the Bernstein rows (which
        imply Q >= q_min on the whole box) or, without them, the grid; plus the extra rows."""
        parts = [self._bernstein_rows(cq)[:, cq]] if self.bernstein_split else [self._BG[:, cq]]
        if len(qrows):
            parts.append(qrows[:, cq])
        return np.vstack(parts)

    def _point_rows(self, cp, cq, cons):
        """LP rows of the constraints ``cons`` (id ``2 i`` = lower side of point i, ``2 i + 1``
        = its upper side) and the Q >= q_min rows of their points. With Bernstein rows, Q >= q_min
        already holds on the whole box, so data Q rows are only kept for points outside it (the
        LP feasible set is unchanged)."""
        rows, upper = cons // 2, (cons % 2).astype(bool)
        Bp = self._B[np.ix_(rows, cp)]
        Bq = self._B[np.ix_(rows, cq)]
        ws = self._w[rows][:, None] / self._scale
        bound = np.where(upper, self._hi[rows], self._lo[rows])[:, None] / self._scale
        sign = np.where(upper, 1.0, -1.0)[:, None]
        # lower: -(P - l Q)/w + delta <= 0;  upper: -(u Q - P)/w + delta <= 0
        A = np.hstack([sign * Bp / ws, -sign * bound * Bq / ws, np.ones((len(rows), 1))])
        Qd = Bq[self._outside[rows]] if self.bernstein_split else Bq
        return A, Qd

    def _solve_lp(self, cp, cq, rows, qrows):
        """LP on the constraints ``rows`` (ids as in :meth:`_point_rows`) and extra Q rows;
        returns (p, q, delta) or None."""
        npv, nqv = len(cp), len(cq)
        A1, Qd = self._point_rows(cp, cq, rows)
        Q_rows = np.vstack([Qd, self._static_q_rows(cq, qrows)])
        A3 = np.hstack([np.zeros((len(Q_rows), npv)), -Q_rows, np.zeros((len(Q_rows), 1))])
        A = np.vstack([A1, A3])
        b = np.concatenate([np.zeros(len(rows)), -self.q_min * np.ones(len(Q_rows))])
        c = np.zeros(npv + nqv + 1)
        c[-1] = -1.0
        bounds = [(-self.coef_bound, self.coef_bound)] * (npv + nqv) + [(-1e3, 1.0)]
        bounds[npv] = (1.0, 1.0)                              # q_0 = 1 (cq[0] is the constant term)
        self._lp_count += 1
        res = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method="highs")
        if res.status != 0 or res.x is None:
            return None
        z = res.x
        return z[:npv], z[npv:npv + nqv], float(z[-1])

    def _slack(self, cp, cq, p, q):
        """Normalised slack of every constraint, ``(P - l Q) / w`` at id ``2 i`` and
        ``(u Q - P) / w`` at ``2 i + 1`` (LP units; negative = violated), and P, Q at the points."""
        P = self._B[:, cp] @ p * self._scale
        Q = self._B[:, cq] @ q
        s = np.empty(2 * len(P))
        s[0::2] = (P - self._lo * Q) / self._w
        s[1::2] = (self._hi * Q - P) / self._w
        return s, P, Q

    def _fit_pair(self, m: int, n: int, converge: bool = False, max_rounds: int | None = None) -> _Attempt:
        """Constraint generation for one degree pair.

        Stops as soon as every point is inside its interval with Q > 0 (feasible), or when the
        subset LP proves infeasibility (delta <= delta_min). With ``converge`` (used for the
        flagged best fit) it continues until the least-violation LP converges. At most
        ``max_rounds`` rounds (default ``max_iter``).
        """
        cp, cq = self._cols(m), self._cols(n)
        # Constraint ids: both sides of the initial points; later only the violated side of a
        # point is added (the other side is rarely active: half the rows, same LP optimum).
        rows = np.sort(np.concatenate([2 * self._subset0, 2 * self._subset0 + 1]))
        qrows = self._extra_q
        lp0 = self._lp_count
        batch = max(int(self._batch_mult * (len(cp) + len(cq))), 16)
        best = None
        sess = None
        if _highs is not None and self.incremental:
            sess = _LPSession(self, cp, cq, qrows)
            sess.add_points(rows)
        for _ in range(self.max_iter if max_rounds is None else int(max_rounds)):
            if best is not None and self._out_of_time():
                break
            sol = sess.solve() if sess is not None else None
            if sol is None:   # no incremental model, or it did not reach optimality: solve afresh
                sol = self._solve_lp(cp, cq, rows, qrows)
            if sol is None:
                return _Attempt(m, n, None, None, -np.inf, False, True, np.inf, len(rows),
                                self._lp_count - lp0)
            p, q, delta = sol
            slack, P, Q = self._slack(cp, cq, p, q)
            viol = -np.min(slack) if np.all(Q > 0) else np.inf
            att = _Attempt(m, n, p, q, delta, bool(viol <= 0 and np.all(Q > 0)), delta <= self.delta_min,
                           float(viol), len(rows), self._lp_count - lp0)
            if best is None or att.max_violation < best.max_violation:
                best = att
            if att.feasible:
                return att
            if att.infeasible_proof and not converge:
                return att
            # Worst violated constraints relative to the current LP level, not yet in the LP.
            bad = np.flatnonzero(slack < min(delta, 0.0) - 1e-9 * max(1.0, abs(delta)))
            if len(bad) == 0:
                bad = np.flatnonzero(slack < 0)
            bad = np.setdiff1d(bad, rows)
            if len(bad) == 0:
                break
            worst = bad[np.argsort(slack[bad])[:batch]]
            rows = np.union1d(rows, worst)
            if sess is not None:
                sess.add_points(np.sort(worst))
        best.n_lp = self._lp_count - lp0
        return best

    def _search(self):
        """Fewest-coefficient feasible pair; returns (attempt, tried)."""
        tried = []
        cache: dict = {}
        M, N = self.max_degree, self.max_den_degree

        def feas(m, n):
            if (m, n) not in cache and self._out_of_time():
                return False                   # not tried: the result says the limit was hit
            if (m, n) not in cache:
                att = self._fit_pair(m, n)
                att = self._make_certified(att) if att.feasible else att
                cache[(m, n)] = att
                tried.append((m, n, att.feasible, self._ncoef(m, n)))
                if self.progress is not None:
                    self.progress({"m": m, "n": n, "feasible": att.feasible,
                                   "n_coefficients": self._ncoef(m, n)})
            return cache[(m, n)].feasible

        def better(m, n, ref):
            k, kr = self._ncoef(m, n), self._ncoef(ref.m, ref.n)
            return k < kr or (k == kr and n < ref.n)

        best = None
        hint = None
        if self.start_degrees is not None:
            hm, hn = (int(d) for d in self.start_degrees)
            if 0 <= hm <= M and 0 <= hn <= N:
                hint = (hm, hn)
                # A feasible hint (e.g. the previous colour channel's degrees) bounds the
                # coefficient count from the start; the walk below still visits every pair that
                # could beat it (ties: lower denominator degree), so the result is unchanged.
                if feas(hm, hn):
                    best = cache[(hm, hn)]
                elif hm < M and feas(hm + 1, hn):
                    # One numerator degree more usually suffices for a sibling channel: a
                    # feasible pair early prunes the walk (which still finds the fewest).
                    best = cache[(hm + 1, hn)]
        # Walk the denominator degree DOWN from N. The smallest feasible numerator degree
        # m_min(n) does not decrease when n decreases (monotonicity), so after n the search for
        # n - 1 starts at m_min(n): one or two pairs per lower n, most of them cheap refutations.
        # (Walking n upwards from 0 starts at m = M, the most expensive feasible LPs; measured
        # on satin_rosaline's red core: 16 pairs, 10.9 s up; 6 pairs, 3.3 s down.)
        m_lo = 0
        for n in range(N, -1, -1):
            if hint is not None and n <= hint[1] and not cache[hint].feasible:
                m_lo = max(m_lo, hint[0] + 1)        # (m <= hm, n <= hn) infeasible
            if best is None:
                lo, hi = m_lo, M + 1                 # hi = M + 1: nothing known feasible yet
            else:
                m_cap = M if n < best.n else min(M, best.m)
                while m_cap >= m_lo and not better(m_cap, n, best):
                    m_cap -= 1
                if m_cap < m_lo:
                    continue                         # no pair at this n beats the best
                if not feas(m_cap, n):
                    m_lo = m_cap + 1                 # m_min(n) > m_cap, and m_min(n - 1) too
                    continue
                lo, hi = m_lo, m_cap
            while lo < hi:                           # smallest feasible m in [lo, hi]
                mid = (lo + hi) // 2
                if feas(mid, n):
                    hi = mid
                else:
                    lo = mid + 1
            m_lo = lo
            if lo > M:
                continue                             # nothing feasible at this n
            cand = cache[(lo, n)]
            if best is None or better(lo, n, best):
                best = cand
        if best is None:
            if self.best_effort and not self._out_of_time():
                best = self._fit_pair(M, N, converge=True)
                tried.append((M, N, best.feasible, self._ncoef(M, N)))
            elif cache:   # the caller only needs to know that nothing is feasible: no converged fit
                best = cache.get((M, N)) or min(cache.values(), key=lambda a: a.max_violation)
            else:
                best = _Attempt(M, N, None, None, -np.inf, False, False, np.inf, 0, 0)
        return best, tried

    def _function(self, att: _Attempt) -> RationalFunction:
        cp, cq = self._cols(att.m), self._cols(att.n)
        return RationalFunction(self._domain, self._E[cp], att.p * self._scale, self._E[cq], att.q)

    def _make_certified(self, att: _Attempt) -> _Attempt:
        """Certify Q > 0; if that fails, add Q >= q_min where Q is smallest and refit."""
        for _ in range(6):
            f = self._function(att)
            cert = f.certify_denominator(max_depth=self.certify_depth)
            att.certificate = cert
            if cert.certified:
                return att
            ng = {1: 4097, 2: 257}.get(self.n_vars, 41)
            axes = [np.linspace(a, b, ng) for a, b in self._domain]
            D = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, self.n_vars)
            BD = chebyshev_basis(D, self._E, self._domain)
            Qd = BD[:, self._cols(att.n)] @ att.q
            worst = np.argsort(Qd)[:8]
            self._extra_q = np.vstack([self._extra_q, BD[worst]])
            new = self._fit_pair(att.m, att.n)
            if not new.feasible:
                new.certificate = None
                return new
            att = new
        att.certificate = self._function(att).certify_denominator(max_depth=self.certify_depth)
        return att

    def _finish(self, att: _Attempt, tried, t0) -> FitResult:
        if att.p is None:
            return FitResult(None, att.m, att.n, False, None, -np.inf, np.inf, np.inf, len(self._X),
                             att.n_constraints, self._lp_count, time.perf_counter() - t0, tried,
                             "no LP solution" + (f"; time limit {self.time_limit:g} s reached"
                                                 if self._out_of_time() else ""))
        f = self._function(att)
        cert = getattr(att, "certificate", None)
        if cert is None:
            cert = f.certify_denominator(max_depth=self.certify_depth)
        R = f(self._X)
        # Independent float64 check on the final function.
        viol = np.max(np.maximum(self._lo - R, R - self._hi) / self._w)
        half = 0.5 * self._w
        ratio = float(np.max(np.abs(R - self._y) / half))
        feasible = bool(viol <= 0 and np.all(np.isfinite(R)))
        msg = ("feasible" if feasible else "no feasible degree pair up to the maximum degree; "
               "returning the least-violating fit") + (
            f"; time limit {self.time_limit:g} s reached" if self._out_of_time() else "") + (
            "; Q > 0 certified" if cert.certified else "; Q > 0 NOT certified")
        return FitResult(f, att.m, att.n, feasible, cert, att.delta, float(viol), ratio, len(self._X),
                         att.n_constraints, self._lp_count, time.perf_counter() - t0, tried, msg)
