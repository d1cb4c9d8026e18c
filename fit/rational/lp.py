"""Incremental linear programs for the interval fitter (:mod:`fit.rational.fitter`).

:class:`IncrementalLP` is one live HiGHS model: rows are appended over time and every re-solve
is a dual simplex warm-started from the previous optimal basis. It uses HiGHS's official
Python bindings (``highspy``, a declared dependency), else SciPy's bundled private copy;
without either, ``IncrementalLP.available`` is False and callers solve every round from
scratch with ``scipy.optimize.linprog`` (same LP, same result, slower).

:class:`DegreePairLP` is the fitter's LP for one (numerator, denominator) degree pair, grown by
constraint generation: variables ``(p, q, delta)``, maximise ``delta``, ``q_0 = 1``,
``|coefficients| <= coef_bound``, ``-1e3 <= delta <= 1``, rows ``Q >= q_min`` and the interval
rows of the data points added so far.

Every HiGHS model of the fitter is made by :func:`new_model`: quiet (no copyright banner, no
solver log) unless :func:`set_verbose` asked for HiGHS's log (``rbrdf-fit ... --verbose``).
HiGHS writes its banner on a model's first logged call unless ``output_flag`` is off by then,
and highspy's ``Highs`` class makes such a call in its constructor (it installs its callback),
so models are made from the raw binding ``highspy._core._Highs`` with ``output_flag`` set
first.
"""
from __future__ import annotations

import numpy as np

# Incremental LP (add rows, warm-started dual simplex) through HiGHS's official Python bindings
# (`highspy`, a declared dependency); SciPy's bundled private copy is the second choice; without
# either, every round is solved from scratch with `linprog` (same LP, same result, slower).
try:
    import highspy as _hs
    from highspy import _core as _hs_core

    _HighsModel, _HighsStatus = _hs_core._Highs, _hs.HighsModelStatus
except Exception:  # pragma: no cover
    try:
        from scipy.optimize._highspy import _core as _hs

        _HighsModel, _HighsStatus = _hs._Highs, _hs.HighsModelStatus
    except Exception:
        _HighsModel = _HighsStatus = None

_HIGHS_OPTIONS: dict = {}   # extra HiGHS options for the incremental model (defaults measured best)
_VERBOSE = False            # HiGHS's banner and log on stdout (set_verbose)


def set_verbose(on: bool) -> None:
    """Let the HiGHS models made from now on print HiGHS's banner and solver log (stdout)."""
    global _VERBOSE
    _VERBOSE = bool(on)


def new_model():
    """A new, empty HiGHS model (the raw binding), quiet unless :func:`set_verbose` is on:
    ``output_flag`` and ``log_to_console`` are set before any other call, which keeps HiGHS's
    copyright banner from being printed. None without HiGHS's bindings."""
    if _HighsModel is None:
        return None
    h = _HighsModel()
    h.setOptionValue("output_flag", _VERBOSE)
    h.setOptionValue("log_to_console", _VERBOSE)
    return h


class IncrementalLP:
    """``min cost . x`` s.t. ``A x <= ub`` (rows added over time), ``lo <= x <= hi``, as one live
    HiGHS model: every :meth:`solve` after :meth:`add_rows` is a warm-started dual simplex from
    the previous basis. Needs HiGHS's Python bindings (``available``); callers fall back to
    ``linprog`` from scratch without them, or when :meth:`solve` returns None (not optimal)."""

    available = _HighsModel is not None

    def __init__(self, cost, lo, hi):
        self.nv = len(cost)
        h = new_model()
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


class DegreePairLP:
    """One HiGHS model per degree pair, grown by constraint generation.

    Same LP as :meth:`fit.rational.problem.IntervalProblem.solve_lp` (identical rows and
    bounds), but rows are added to the live model so every re-solve is a warm-started dual
    simplex from the previous basis instead of a solve from scratch. ``n_p``, ``n_q``: numbers
    of numerator and denominator coefficients; ``q_rows``: the initial ``Q >= q_min`` rows
    (``(k, n_q)``, acting on q).
    """

    def __init__(self, n_p: int, n_q: int, coef_bound: float, q_min: float, q_rows):
        self.npv, self.nqv = n_p, n_q
        self.q_min = q_min
        self.nv = self.npv + self.nqv + 1
        lo = np.full(self.nv, -coef_bound)
        hi = np.full(self.nv, coef_bound)
        lo[self.npv] = hi[self.npv] = 1.0                   # q_0 = 1
        lo[-1], hi[-1] = -1e3, 1.0
        cost = np.zeros(self.nv)
        cost[-1] = -1.0
        self.lp = IncrementalLP(cost, lo, hi)
        self._add_q(q_rows)

    def _add_q(self, Qr):
        A = np.hstack([np.zeros((len(Qr), self.npv)), -Qr, np.zeros((len(Qr), 1))])
        self.lp.add_rows(A, np.full(len(Qr), -self.q_min))

    def add_points(self, A, Qd):
        """Append interval rows ``A`` (``A z <= 0``, z = (p, q, delta)) and the ``Q >= q_min``
        rows ``Qd`` of their points (may be empty)."""
        self.lp.add_rows(A, np.zeros(len(A)))
        if len(Qd):
            self._add_q(Qd)

    def solve(self):
        """``(p, q, delta)`` at the optimum, or None if HiGHS did not end optimal."""
        z = self.lp.solve()
        if z is None:
            return None
        return z[:self.npv], z[self.npv:self.npv + self.nqv], float(z[-1])
