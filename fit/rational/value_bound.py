"""A proven upper bound of a rational function P/Q on its whole box, where Q > 0 is certified.

:func:`bound_ratio` answers "is P/Q <= limit everywhere on ``[-1, 1]^n``?" with a proof either
way, or says that it could not decide within its budget:

* **proven bounded**: on every sub-box of a midpoint subdivision, the largest Bernstein
  coefficient of P (plus its rounding-error bound) divided by the smallest Bernstein
  coefficient of Q (minus its bound, > 0) is <= ``limit``. By the convex-hull property of the
  Bernstein form, P <= max b_P and Q >= min b_Q > 0 on the sub-box, so P/Q <= their ratio. The
  first test is cheaper still: |T_k| <= 1 on [-1, 1], so |P| <= sum |p_j| on the whole box,
  and Q >= the certificate's lower bound;
* **proven above**: a corner of a sub-box (a corner Bernstein coefficient is the polynomial's
  value there) where P/Q > ``limit`` even with the rounding-error bounds against it; the
  corner is returned as the witness, in the box's [-1, 1] coordinates;
* **undecided**: the subdivision reached ``max_depth`` levels or ``max_boxes`` sub-boxes; the
  caller refuses the file (a bound that cannot be proven cheaply is not trusted).

The conversion to Bernstein form and the error bounds are those of the Q > 0 certificate
(:mod:`fit.rational.bernstein`).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from .bernstein import bernstein_coefficients_float, de_casteljau_split


@dataclass
class RatioBound:
    """Result of :func:`bound_ratio`. ``bounded``: P/Q <= limit proven on the whole box
    (``bound``: the largest proven sub-box bound, <= limit). Otherwise ``witness`` is a point of
    ``[-1, 1]^n`` where P/Q = ``value`` > limit, or None when undecided (``reason`` says why).
    ``work``: Bernstein coefficients examined (for the caller's budget)."""

    bounded: bool
    bound: float = float("nan")
    witness: tuple | None = None
    value: float = float("nan")
    reason: str = ""
    work: int = 0


def bound_ratio(num_exponents, num_coef, den_exponents, den_coef, limit: float, q_lower: float,
                max_boxes: int = 4096, max_depth: int = 24) -> RatioBound:
    """Prove ``P/Q <= limit`` on ``[-1, 1]^n`` (Chebyshev polynomials given by exponent rows
    (m, n) and coefficients (m,)), or find a point where it is not (module docstring).
    ``q_lower`` > 0 is a proven lower bound of Q on the box (the Q > 0 certificate's)."""
    num_coef = np.asarray(num_coef, float)
    if len(num_coef) == 0:
        return RatioBound(True, 0.0)
    if q_lower > 0 and float(np.abs(num_coef).sum()) / q_lower <= limit:
        return RatioBound(True, float(np.abs(num_coef).sum()) / q_lower)
    n = np.asarray(den_exponents).shape[1]
    bp, ep = bernstein_coefficients_float(num_exponents, num_coef)
    bq, eq = bernstein_coefficients_float(den_exponents, den_coef)
    axes = [v for v in range(n) if bp.shape[v] > 1 or bq.shape[v] > 1] or [0]
    eps = np.finfo(float).eps
    stack = [(bp, ep, bq, eq, 0, np.full(n, -1.0), np.full(n, 1.0))]
    best, boxes, work = 0.0, 0, 0
    while stack:
        p, e_p, q, e_q, depth, lo, hi = stack.pop()
        boxes += 1
        work += p.size + q.size
        pmax, qmin = float(p.max()) + e_p, float(q.min()) - e_q
        if pmax <= 0:
            continue
        if qmin > 0 and pmax / qmin <= limit:
            best = max(best, pmax / qmin)
            continue
        for c in itertools.product((0, 1), repeat=n):
            ip = tuple(c[v] * (p.shape[v] - 1) for v in range(n))
            iq = tuple(c[v] * (q.shape[v] - 1) for v in range(n))
            pv, qv = float(p[ip]), float(q[iq])
            if qv - e_q > 0 and (pv - e_p) / (qv + e_q) > limit:
                point = tuple(float(hi[v] if c[v] else lo[v]) for v in range(n))
                return RatioBound(False, witness=point, value=pv / qv, work=work)
        if depth >= max_depth or boxes + len(stack) >= max_boxes:
            return RatioBound(False, reason=f"P/Q <= {limit:.6g} could not be proven within {max_depth} "
                                            f"subdivision levels and {max_boxes} sub-boxes", work=work)
        axis = axes[depth % len(axes)]
        mid = 0.5 * (lo[axis] + hi[axis])
        pl, pr = de_casteljau_split(p, axis)
        ql, qr = de_casteljau_split(q, axis)
        e_p2 = e_p + (p.shape[axis] + 1) * eps * float(np.abs(p).max())
        e_q2 = e_q + (q.shape[axis] + 1) * eps * float(np.abs(q).max())
        lo_r, hi_l = lo.copy(), hi.copy()
        lo_r[axis], hi_l[axis] = mid, mid
        stack.append((pl, e_p2, ql, e_q2, depth + 1, lo, hi_l))
        stack.append((pr, e_p2, qr, e_q2, depth + 1, lo_r, hi))
    return RatioBound(True, best, work=work)
