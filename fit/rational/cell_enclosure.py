"""Bernstein enclosures of a rational function on many sub-boxes of its box at once, for
:mod:`fit.rational.proved_bound`.

:class:`Enclosure` holds P and Q of one :class:`fit.rational.function.RationalFunction` in tensor
Bernstein form on its box ``[-1, 1]^n`` (common per-variable degrees, float64 with a rigorous
rounding-error bound, :func:`fit.rational.bernstein.bernstein_coefficients_float`). On a sub-box
the coefficients are restricted by de Casteljau (a matrix of convex weights per axis, with a
rounding-error bound added per axis), and where every coefficient of Q is proved > 0:

* :meth:`Enclosure.ratio` encloses P/Q: a rational Bezier form, so P/Q on the sub-box lies between
  the smallest and largest ratio ``b_P,i / b_Q,i``;
* :meth:`Enclosure.ratio_minus` encloses ``P/Q - l`` with ``l`` multilinear on the sub-box (given
  by its corner values): ``P - l Q`` is a polynomial of one degree more per variable, its
  Bernstein coefficients on the sub-box are exact combinations of those of P and Q (the product
  of a degree-1 and a degree-n Bernstein basis is a degree n + 1 one), and Q raised to the same
  degrees; so ``(P - l Q) / Q`` lies between the smallest and largest ratio of those. Because the
  two terms are enclosed together, the width of this enclosure shrinks like the square of the
  sub-box's size where ``P/Q - l`` is smooth, while bounding ``P/Q`` and ``l`` separately keeps
  the variation of both (of the order of the sub-box's size).
"""
from __future__ import annotations

import itertools

import numpy as np

from .bernstein import bernstein_coefficients_float

EPS = np.finfo(float).eps


def _casteljau(a, t, left: bool):
    """Bernstein coefficients (axis 1 of ``a`` (N, n+1, K)) of the part left (right) of the
    parameter ``t`` (N,) in [0, 1] of each row's interval."""
    n = a.shape[1] - 1
    out = np.empty_like(a)
    rows = a
    tt = t[:, None, None]
    out[:, 0 if left else n] = rows[:, 0 if left else n]
    for k in range(1, n + 1):
        rows = (1.0 - tt) * rows[:, :-1] + tt * rows[:, 1:]
        if left:
            out[:, k] = rows[:, 0]
        else:
            out[:, n - k] = rows[:, -1]
    return out


def _restriction(n: int, lo, hi) -> np.ndarray:
    """``A`` (N, n+1, n+1): Bernstein coefficients on ``[lo, hi]`` (subsets of [0, 1]) are
    ``A @ b`` of those ``b`` on [0, 1]; each row of ``A`` holds convex weights."""
    eye = np.broadcast_to(np.eye(n + 1), (len(lo), n + 1, n + 1)).copy()
    a = _casteljau(eye, hi, left=True)                       # on [0, hi]
    tau = np.where(hi > 0, lo / np.where(hi > 0, hi, 1.0), 0.0)
    return _casteljau(a, np.clip(tau, 0.0, 1.0), left=False)  # on [lo, hi]


def restrict(b, err, s_lo, s_hi):
    """Tensor Bernstein coefficients ``b`` on [0, 1]^n restricted to each box ``[s_lo, s_hi]``
    (N, n): ``(N, *b.shape)`` and the error bound per box (N,)."""
    n_vars, N = b.ndim, len(s_lo)
    out = np.broadcast_to(b, (N,) + b.shape)
    e = np.full(N, float(err))
    for v in range(n_vars):
        deg = b.shape[v] - 1
        if deg == 0:
            continue
        A = _restriction(deg, s_lo[:, v], s_hi[:, v])
        # axis v first, the others flattened: one (deg+1, deg+1) @ (deg+1, rest) product per box
        # (a batched matmul: restrict took 1.6x as long with numpy.einsum, 2,000 boxes of degrees (5, 5, 3))
        o = np.ascontiguousarray(np.moveaxis(out, v + 1, 1))
        shape = o.shape
        out = np.moveaxis(np.matmul(A, o.reshape(N, deg + 1, -1)).reshape(shape), 1, v + 1)
        # convex weights: |A b - fl(A b)| <= (deg + 2) eps max|b| per level in any order of the
        # sum, the weights' own rounding (2 deg levels of de Casteljau) as much again; doubled
        # for safety
        e = e + 4.0 * (2 * deg + 4) * EPS * np.abs(out).reshape(len(s_lo), -1).max(axis=1) + 2 * e * deg * EPS
    return out, e


def _ratio_range(P, ep, Q, eq):
    """``(lo, hi)`` (N,): the smallest and largest ratio of the coefficients ``P`` (N, K) over
    ``Q`` (N, K), each within its error bound ``ep``, ``eq`` (N,); ``(-inf, inf)`` where a
    coefficient of Q is not proved > 0."""
    ql, qh = Q - eq[:, None], Q + eq[:, None]
    pl, ph = P - ep[:, None], P + ep[:, None]
    ok = ql.min(axis=1) > 0
    qls = np.where(ql > 0, ql, 1.0)
    lo = np.where(pl >= 0, pl / qh, pl / qls).min(axis=1)
    hi = np.where(ph >= 0, ph / qls, ph / qh).max(axis=1)
    return (np.where(ok, lo - 4 * EPS * np.abs(lo), -np.inf),
            np.where(ok, hi + 4 * EPS * np.abs(hi), np.inf))


def _raise_degree(lo, hi, ax: int):
    """``B_0^1 lo + B_1^1 hi`` along axis ``ax``: ``lo`` and ``hi`` hold Bernstein coefficients of
    degree n there, the result those of degree n + 1 (``B_0^1 B_k^n = (n+1-k)/(n+1) B_k^(n+1)``,
    ``B_1^1 B_k^n = (k+1)/(n+1) B_(k+1)^(n+1)``, convex weights)."""
    n = lo.shape[ax] - 1
    k = np.arange(n + 1, dtype=np.float64)
    shp = [1] * lo.ndim
    shp[ax] = n + 1
    wl = ((n + 1 - k) / (n + 1)).reshape(shp)
    wh = ((k + 1) / (n + 1)).reshape(shp)
    pad = [(0, 0)] * lo.ndim
    pad_l, pad_h = list(pad), list(pad)
    pad_l[ax], pad_h[ax] = (0, 1), (1, 0)
    return np.pad(lo * wl, pad_l) + np.pad(hi * wh, pad_h)


def _elevate(Q, n_vars: int):
    """``Q`` (N, *shape): Bernstein coefficients per box; returns those of the same polynomials
    one degree higher in every variable (N, *shape + 1): :func:`_times_linear` with every
    corner's polynomial ``Q`` (the corner basis sums to 1), the same operations on 2^n times
    fewer numbers, the same results to the last bit."""
    out = Q
    for v in range(n_vars):
        out = _raise_degree(out, out, v + 1)
    return out


def _times_linear(R, n_vars: int):
    """``R`` (N, 2, ..., 2, *shape): per corner of the box (one axis of size 2 per variable,
    low / high side) the Bernstein coefficients of a polynomial ``R_c``; returns those of
    ``sum_c B_c R_c`` (N, *shape + 1), ``B_c`` the multilinear basis function of corner c (1 at
    c, 0 at the other corners), one variable at a time (:func:`_raise_degree`)."""
    out = R
    for _ in range(n_vars):
        # variable v's corner axis is axis 1 (those before it are taken out); once it is taken
        # out too, variable v's degree axis is axis n_vars
        out = _raise_degree(out[:, 0], out[:, 1], n_vars)
    return out


class Enclosure:
    """P and Q of one :class:`fit.rational.function.RationalFunction` in Bernstein form on its
    box, common degrees (module docstring); sub-boxes are given in the box's [-1, 1]^n."""

    def __init__(self, fn):
        degs = np.maximum(fn.num_exponents.max(axis=0) if len(fn.num_coef) else 0, fn.den_exponents.max(axis=0))
        pad = degs[None, :]
        self.bp, self.ep = bernstein_coefficients_float(np.vstack([fn.num_exponents, pad]),
                                                        np.append(fn.num_coef, 0.0))
        self.bq, self.eq = bernstein_coefficients_float(np.vstack([fn.den_exponents, pad]),
                                                        np.append(fn.den_coef, 0.0))
        self.fn = fn
        self.n_vars = self.bp.ndim

    def _on(self, t_lo, t_hi):
        a, b = 0.5 * (t_lo + 1.0), 0.5 * (t_hi + 1.0)
        P, ep = restrict(self.bp, self.ep, a, b)
        Q, eq = restrict(self.bq, self.eq, a, b)
        return P, ep, Q, eq

    def _chunk(self) -> int:
        return max(64, 2 ** 21 // (self.bp.size * 2 ** self.n_vars * 2))

    def ratio(self, t_lo, t_hi):
        """``(r_lo, r_hi)`` (N,): proved bounds of P/Q on each box ``[t_lo, t_hi]`` (N, n) of
        [-1, 1]^n; ``(-inf, inf)`` where Q's coefficients are not all proved > 0."""
        rl, rh = np.empty(len(t_lo)), np.empty(len(t_lo))
        step = 4 * self._chunk()
        for i in range(0, len(t_lo), step):
            sl = slice(i, i + step)
            P, ep, Q, eq = self._on(t_lo[sl], t_hi[sl])
            rl[sl], rh[sl] = _ratio_range(P.reshape(len(P), -1), ep, Q.reshape(len(Q), -1), eq)
        return rl, rh

    def ratio_minus(self, t_lo, t_hi, ell):
        """``(d_lo, d_hi)`` (N,): proved bounds of ``P/Q - l`` on each box ``[t_lo, t_hi]``
        (N, n) of [-1, 1]^n, ``l`` the multilinear function with the corner values ``ell``
        (N, 2^n) (corner k: bit v of k, most significant first, is the high side of axis v);
        ``(-inf, inf)`` where Q's coefficients are not all proved > 0."""
        n = self.n_vars
        dl, dh = np.empty(len(t_lo)), np.empty(len(t_lo))
        step = self._chunk()
        for i in range(0, len(t_lo), step):
            sl = slice(i, i + step)
            P, ep, Q, eq = self._on(t_lo[sl], t_hi[sl])
            N = len(P)
            L = np.asarray(ell[sl], np.float64).reshape((N,) + (2,) * n + (1,) * n)
            Pc = P.reshape((N,) + (1,) * n + P.shape[1:])
            Qc = Q.reshape((N,) + (1,) * n + Q.shape[1:])
            D = _times_linear(Pc - L * Qc, n).reshape(N, -1)
            Qe = _elevate(Q, n).reshape(N, -1)
            lmax = np.abs(L).reshape(N, -1).max(axis=1)
            pmax = np.abs(P).reshape(N, -1).max(axis=1)
            qmax = np.abs(Q).reshape(N, -1).max(axis=1)
            # P - l_c Q: the errors of P and Q, and the rounding of the product and difference;
            # the elevation (convex weights, 2 operations per variable) as much per variable
            e_d = ep + lmax * eq + (4 * n + 8) * EPS * (pmax + 2 * lmax * qmax)
            e_q = eq + (4 * n + 8) * EPS * qmax
            dl[sl], dh[sl] = _ratio_range(D, e_d, Qe, e_q)
        return dl, dh


def corner_bits(n: int) -> np.ndarray:
    """(2^n, n): the corner order of :meth:`Enclosure.ratio_minus`."""
    return np.array(list(itertools.product((0, 1), repeat=n)), bool)
