"""Bernstein forms of Chebyshev polynomials on a box: the Q > 0 certificates.

:func:`bernstein_coefficients` converts a Chebyshev polynomial (:mod:`fit.rational.basis`)
exactly (rational arithmetic) into tensor Bernstein coefficients on the box ``[-1, 1]^n``; if
they are all positive, the polynomial is > 0 on the whole box (convex-hull property).
:func:`certify_positive` does the same in float64 with a rigorous rounding-error bound (fast) and
subdivides the box (de Casteljau at the midpoints, :func:`de_casteljau_split`) where the
coefficients are not conclusive; its result is a :class:`PositivityCertificate`.
:func:`subdivision_matrix` is the linear map from Chebyshev coefficients to the Bernstein
coefficients on a regular split of the box (the fitter's Q >= q_min rows).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache
from math import comb

import numpy as np


# --------------------------------------------------------------------------------------------
# Chebyshev -> Bernstein conversion
# --------------------------------------------------------------------------------------------
@lru_cache(maxsize=None)
def _cheb_to_bernstein_matrix(n: int) -> tuple:
    """M[i][k] = i-th Bernstein coefficient (degree n, on t in [-1, 1]) of T_k, as Fractions."""
    # Monomial coefficients (in t) of T_k, exact integers.
    mono = [[1], [0, 1]]
    for k in range(2, n + 1):
        a = [0] + [2 * c for c in mono[k - 1]]
        b = mono[k - 2] + [0] * (len(a) - len(mono[k - 2]))
        mono.append([x - y for x, y in zip(a, b)])
    mono = mono[: n + 1]
    cols = []
    for k in range(n + 1):
        # substitute t = 2 s - 1, s in [0, 1]: coefficients in s.
        s_coef = [0] * (n + 1)
        for j, c in enumerate(mono[k]):
            if c == 0:
                continue
            for m in range(j + 1):  # (2s - 1)^j = sum_m C(j, m) (2s)^m (-1)^(j-m)
                s_coef[m] += c * comb(j, m) * (2 ** m) * (-1) ** (j - m)
        # monomial in s -> Bernstein of degree n: b_i = sum_{m <= i} C(i, m) / C(n, m) a_m
        cols.append([sum((Fraction(comb(i, m), comb(n, m)) * s_coef[m] for m in range(i + 1)),
                         Fraction(0)) for i in range(n + 1)])
    return tuple(tuple(cols[k][i] for k in range(n + 1)) for i in range(n + 1))


def bernstein_coefficients(exponents, coefficients) -> np.ndarray:
    """Exact tensor Bernstein coefficients (object array of Fractions) of a Chebyshev polynomial
    on ``[-1, 1]^n``, with per-variable degrees ``max(E[:, v])``."""
    exponents = np.asarray(exponents, dtype=np.int64)
    degs = exponents.max(axis=0)
    arr = np.empty(tuple(int(d) + 1 for d in degs), dtype=object)
    arr.fill(Fraction(0))
    for e, c in zip(exponents, coefficients):
        arr[tuple(e)] += Fraction(float(c))
    for v, n in enumerate(degs):
        m = np.array(_cheb_to_bernstein_matrix(int(n)), dtype=object)
        arr = np.moveaxis(np.tensordot(m, np.moveaxis(arr, v, 0), axes=(1, 0)), 0, v)
    return arr


def bernstein_coefficients_float(exponents, coefficients):
    """Tensor Bernstein coefficients in float64 and a rigorous bound on their rounding error.

    The 1-D conversion matrices are exact rationals rounded once to float64.
    """
    exponents = np.asarray(exponents, dtype=np.int64)
    degs = exponents.max(axis=0)
    arr = np.zeros(tuple(int(d) + 1 for d in degs))
    for e, c in zip(exponents, coefficients):
        arr[tuple(e)] += float(c)
    absarr = np.abs(arr)
    k = 0
    for v, n in enumerate(degs):
        m = np.array(_cheb_to_bernstein_matrix(int(n)), dtype=float)
        arr = np.moveaxis(np.tensordot(m, np.moveaxis(arr, v, 0), axes=(1, 0)), 0, v)
        absarr = np.moveaxis(np.tensordot(np.abs(m), np.moveaxis(absarr, v, 0), axes=(1, 0)), 0, v)
        k += int(n) + 2
    err = 4.0 * (k + 2) * np.finfo(float).eps * float(absarr.max())
    return arr, err


# --------------------------------------------------------------------------------------------
# Subdivision
# --------------------------------------------------------------------------------------------
def de_casteljau_split(arr: np.ndarray, axis: int):
    """Bernstein coefficients (float) of the two halves of the box split at the midpoint of
    ``axis`` (de Casteljau): ``(left, right)``, each of the shape of ``arr``."""
    a = np.moveaxis(arr, axis, 0)
    n = a.shape[0] - 1
    rows = a.copy()
    left = np.empty_like(a)
    right = np.empty_like(a)
    left[0], right[n] = rows[0], rows[n]
    for k in range(1, n + 1):
        rows = 0.5 * (rows[:-1] + rows[1:])
        left[k] = rows[0]
        right[n - k] = rows[-1]
    return np.moveaxis(left, 0, axis), np.moveaxis(right, 0, axis)


def _split_regular(b: np.ndarray, axis: int, parts: int) -> list:
    """Bernstein coefficients on ``parts`` equal sub-intervals of ``axis`` (parts = 1, 2, 4, ...)."""
    out = [b]
    while len(out) < parts:
        new = []
        for x in out:
            new.extend(de_casteljau_split(x, axis))
        out = new
    return out


def subdivision_matrix(exponents, parts: int) -> np.ndarray:
    """Linear map from the coefficients of a Chebyshev polynomial with the exponent rows
    ``exponents`` (one column per row) to its tensor Bernstein coefficients (per-variable
    degrees ``max(E[:, v])``) on every sub-box of a regular split of the box into ``parts``
    (1, 2, 4, ...) equal parts per axis: shape ``(n_sub_boxes * n_bernstein, len(exponents))``.

    Constraining these to be >= q_min makes the polynomial >= q_min on the whole box."""
    exponents = np.asarray(exponents, dtype=np.int64)
    blocks = []
    for j in range(len(exponents)):
        unit = np.zeros(len(exponents))
        unit[j] = 1.0
        full, _ = bernstein_coefficients_float(exponents, unit)
        pieces = [full]
        for axis in range(full.ndim):
            new = []
            for piece in pieces:
                new.extend(_split_regular(piece, axis, parts))
            pieces = new
        blocks.append(np.concatenate([p_.reshape(-1) for p_ in pieces]))
    return np.stack(blocks, axis=1)


# --------------------------------------------------------------------------------------------
# Certificates
# --------------------------------------------------------------------------------------------
@dataclass
class PositivityCertificate:
    """Result of :func:`certify_positive` (and
    :meth:`fit.rational.function.RationalFunction.certify_denominator`).

    ``certified`` True means Q > 0 on the whole domain box, proved by Bernstein coefficients
    that exceed their rounding-error bound on every sub-box of a midpoint subdivision. ``lower_bound`` is a proven lower bound of Q on the box (min over leaves of the
    smallest Bernstein coefficient) when certified.
    """

    certified: bool
    lower_bound: float
    n_boxes: int
    max_depth: int
    #: why a certificate failed: a point of the box where Q <= 0, or the subdivision limits
    reason: str = ""
    method: str = ("Bernstein coefficients (exact rational conversion matrices, float64 with a rigorous "
                   "rounding-error bound) with midpoint subdivision")


def certify_positive(exponents, coefficients, max_depth: int = 12,
                     max_boxes: int = 20000) -> PositivityCertificate:
    """Prove that the Chebyshev polynomial ``sum_j c_j prod_v T_{E[j, v]}(t_v)`` is > 0 on the
    whole box ``[-1, 1]^n`` (or fail to).

    The Chebyshev coefficients are converted to tensor Bernstein coefficients on the box with
    a conversion matrix computed exactly (rational arithmetic) and applied in float64 together
    with a rigorous bound on the rounding error (``4 (k + 2) eps`` times the same product
    with absolute values, ``k`` = number of accumulated terms). A box whose coefficients
    all exceed the error bound is proven positive (convex-hull property of the Bernstein
    form); a box whose corner coefficient (= a value of Q) is <= -bound proves Q <= 0
    somewhere and the certificate fails; otherwise the box is split at the midpoint
    (de Casteljau, axis ``depth mod n_vars``; each split adds ``(deg + 1) eps max|b|`` to
    the bound) up to ``max_depth`` levels.
    """
    b, err = bernstein_coefficients_float(exponents, coefficients)
    stack = [(b, err, 0)]
    lower = np.inf
    n_boxes = 0
    depth_seen = 0
    eps = np.finfo(float).eps
    while stack:
        a, e, depth = stack.pop()
        n_boxes += 1
        depth_seen = max(depth_seen, depth)
        if a.min() - e > 0:
            lower = min(lower, float(a.min() - e))
            continue
        corners = [a[c] for c in itertools.product(*((0, s - 1) for s in a.shape))]
        if min(corners) + e <= 0:
            return PositivityCertificate(False, float("nan"), n_boxes, depth_seen,
                                         "Q <= 0 at a corner of a sub-box: the denominator has a zero "
                                         "(a pole) or changes sign on the domain")
        if depth >= max_depth or n_boxes + len(stack) > max_boxes:
            return PositivityCertificate(False, float("nan"), n_boxes, depth_seen,
                                         f"Q > 0 could not be proven within {max_depth} subdivision levels "
                                         f"and {max_boxes} sub-boxes (Q comes too close to 0)")
        axis = depth % a.ndim
        left, right = de_casteljau_split(a, axis)
        e2 = e + (a.shape[axis] + 1) * eps * float(np.abs(a).max())
        stack.append((left, e2, depth + 1))
        stack.append((right, e2, depth + 1))
    return PositivityCertificate(True, float(lower), n_boxes, depth_seen)
