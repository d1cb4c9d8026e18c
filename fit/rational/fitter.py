"""Interval-constraint rational fitting (linear programming), its error guaranteed at the data points.

Given points ``x_i`` and intervals ``[l_i, u_i]`` (from a tolerance or a cluster spread), find
``R = P / Q`` in the Chebyshev basis (:mod:`fit.rational.function`) with

    l_i <= R(x_i) <= u_i  for every i      and      Q > 0 on the whole domain box.

For fixed degrees this is linear in the coefficients when ``Q > 0`` (Salazar Celis, Cuyt,
Verdonk 2007, as used by the Rational BRDF paper): an LP that maximises the smallest normalised
interval margin ``delta`` under ``Q >= q_min`` on the box (:mod:`fit.rational.problem` states it
and builds its rows). It is solved by *constraint generation*: start from a small well-spread subset of the points
(Chebyshev-spread cells plus the extreme values), evaluate all points, add the worst violators,
repeat until no point is outside its interval. Since the subset LP is a relaxation, ``delta <= 0``
on a subset proves the degrees infeasible for the whole data set (fast rejection). The rounds
of one degree pair share one HiGHS model (:class:`fit.rational.lp.DegreePairLP`): new rows are
appended and the dual simplex restarts from the previous optimal basis (falls back to
``linprog`` from scratch if the bindings are missing or a warm solve does not end optimal).

The degree search (:mod:`fit.rational.degree_search`) walks the (numerator, denominator) plane
(an optional ``start_degrees`` pair is tried first); the result is the feasible fit with the
FEWEST coefficients (ties: lower denominator degree).

Guarantees of a result with ``valid`` True:
* every data point was evaluated in float64 after the fit and lies in its interval
  (``max_violation <= 0``);
* Q > 0 on the whole domain box, proved by exact (rational-arithmetic) Bernstein coefficients
  with midpoint subdivision (:meth:`fit.rational.function.RationalFunction.certify_denominator`).
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

from .basis import chebyshev_basis, tensor_exponents, total_degree_exponents
from .bernstein import PositivityCertificate
from .degree_search import search_degrees
from .function import RationalFunction
from .lp import DegreePairLP, IncrementalLP
from .problem import IntervalProblem, finite_data

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
        feasible. Small values mark hard data: :func:`fit.rational.brdf_fit.fit_brdf` ranks its colour
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
        X, lower, upper, yc, domain = finite_data(X, lower, upper, y, self.domain)
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
        dmax = max(self.max_degree, self.max_den_degree)
        if self.degrees is not None:
            dmax = max(dmax, *self.degrees)
        self._p = IntervalProblem(X, lower, upper, y, domain, self._exponents(dmax), self.q_min,
                                  self.coef_bound, self.q_grid, self.bernstein_split)
        self._extra_q = np.zeros((0, len(self._p.E)))
        self._lp_count = 0

    def _cols(self, d: int) -> np.ndarray:
        return self._p.columns(self._exponents(d))

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
        pb = self._p
        rows = np.sort(np.concatenate([2 * pb.subset0, 2 * pb.subset0 + 1]))
        qrows = self._extra_q
        lp0 = self._lp_count
        batch = max(int(self._batch_mult * (len(cp) + len(cq))), 16)
        best = None
        sess = None
        if IncrementalLP.available and self.incremental:
            sess = DegreePairLP(len(cp), len(cq), self.coef_bound, self.q_min, pb.static_q_rows(cq, qrows))
            sess.add_points(*pb.point_rows(cp, cq, rows))
        for _ in range(self.max_iter if max_rounds is None else int(max_rounds)):
            if best is not None and self._out_of_time():
                break
            sol = None
            if sess is not None:
                self._lp_count += 1
                sol = sess.solve()
            if sol is None:   # no incremental model, or it did not reach optimality: solve afresh
                self._lp_count += 1
                sol = pb.solve_lp(cp, cq, rows, qrows)
            if sol is None:
                return _Attempt(m, n, None, None, -np.inf, False, True, np.inf, len(rows),
                                self._lp_count - lp0)
            p, q, delta = sol
            slack, P, Q = pb.slack(cp, cq, p, q)
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
                sess.add_points(*pb.point_rows(cp, cq, np.sort(worst)))
        best.n_lp = self._lp_count - lp0
        return best

    def _try_pair(self, m: int, n: int) -> _Attempt:
        """Constraint generation for ``(m, n)``, certified (Q > 0) when feasible."""
        att = self._fit_pair(m, n)
        return self._make_certified(att) if att.feasible else att

    def _search(self):
        """Fewest-coefficient feasible pair (:func:`fit.rational.degree_search.search_degrees`);
        returns (attempt, tried). Without a feasible pair: the converged least-violation fit at
        the largest degrees (``best_effort``), else the least-violating attempt tried."""
        M, N = self.max_degree, self.max_den_degree
        best, cache, tried = search_degrees(self._try_pair, self._ncoef, M, N, self.start_degrees,
                                            self._out_of_time, self.progress)
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
        return self._p.function(self._cols(att.m), self._cols(att.n), att.p, att.q)

    def _make_certified(self, att: _Attempt) -> _Attempt:
        """Certify Q > 0; if that fails, add Q >= q_min where Q is smallest and refit."""
        for _ in range(6):
            f = self._function(att)
            cert = f.certify_denominator(max_depth=self.certify_depth)
            att.certificate = cert
            if cert.certified:
                return att
            ng = {1: 4097, 2: 257}.get(self.n_vars, 41)
            axes = [np.linspace(a, b, ng) for a, b in self._p.domain]
            D = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, self.n_vars)
            BD = chebyshev_basis(D, self._p.E, self._p.domain)
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
        pb = self._p
        if att.p is None:
            return FitResult(None, att.m, att.n, False, None, -np.inf, np.inf, np.inf, len(pb.X),
                             att.n_constraints, self._lp_count, time.perf_counter() - t0, tried,
                             "no LP solution" + (f"; time limit {self.time_limit:g} s reached"
                                                 if self._out_of_time() else ""))
        f = self._function(att)
        cert = getattr(att, "certificate", None)
        if cert is None:
            cert = f.certify_denominator(max_depth=self.certify_depth)
        R = f(pb.X)
        # Independent float64 check on the final function.
        viol = np.max(np.maximum(pb.lo - R, R - pb.hi) / pb.w)
        half = 0.5 * pb.w
        ratio = float(np.max(np.abs(R - pb.y) / half))
        feasible = bool(viol <= 0 and np.all(np.isfinite(R)))
        msg = ("feasible" if feasible else "no feasible degree pair up to the maximum degree; "
               "returning the least-violating fit") + (
            f"; time limit {self.time_limit:g} s reached" if self._out_of_time() else "") + (
            "; Q > 0 certified" if cert.certified else "; Q > 0 NOT certified")
        return FitResult(f, att.m, att.n, feasible, cert, att.delta, float(viol), ratio, len(pb.X),
                         att.n_constraints, self._lp_count, time.perf_counter() - t0, tried, msg)
