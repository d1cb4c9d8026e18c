"""The tensor Chebyshev basis of the rational functions: exponent lists, basis matrices and the
1-D tables of T_k and dT_k/dt.

Each variable ``x_v`` has a domain ``[a_v, b_v]`` mapped affinely onto ``[-1, 1]``::

    t_v = (2 x_v - (a_v + b_v)) / (b_v - a_v)

and a term with exponent row ``e = (e_1, ..., e_n)`` is the product ``T_{e_1}(t_1) ... T_{e_n}(t_n)``
of Chebyshev polynomials of the first kind (``T_0 = 1``, ``T_1 = t``,
``T_{k+1} = 2 t T_k - T_{k-1}``). Exponent lists are integer arrays ``(n_terms, n_vars)``; points
are ``(..., n_vars)`` (a 1-variable basis also accepts ``(...)``). Outside the domain the
polynomials are simply extrapolated (``|t| > 1``).
"""
from __future__ import annotations

import itertools

import numpy as np


# --------------------------------------------------------------------------------------------
# Exponent lists
# --------------------------------------------------------------------------------------------
def total_degree_exponents(n_vars: int, degree: int) -> np.ndarray:
    """All exponent rows with ``sum(e) <= degree``, ordered by total degree then lexicographically
    (descending on the first variable). Shape ``(comb(degree + n_vars, n_vars), n_vars)``."""
    if degree < 0:
        return np.zeros((0, n_vars), dtype=np.int64)
    rows = []
    for d in range(degree + 1):
        rows.extend(e for e in itertools.product(range(d, -1, -1), repeat=n_vars) if sum(e) == d)
    return np.array(rows, dtype=np.int64).reshape(-1, n_vars)


def tensor_exponents(degrees) -> np.ndarray:
    """All exponent rows with ``e_v <= degrees[v]`` (tensor-product degrees), ordered by total
    degree then lexicographically. Shape ``(prod(degrees + 1), n_vars)``."""
    degrees = [int(d) for d in np.atleast_1d(degrees)]
    rows = list(itertools.product(*(range(d + 1) for d in degrees)))
    rows.sort(key=lambda e: (sum(e), tuple(-x for x in e)))
    return np.array(rows, dtype=np.int64).reshape(-1, len(degrees))


# --------------------------------------------------------------------------------------------
# Basis evaluation
# --------------------------------------------------------------------------------------------
def _to_unit(x: np.ndarray, domain: np.ndarray) -> np.ndarray:
    a, b = domain[:, 0], domain[:, 1]
    return (2.0 * x - (a + b)) / (b - a)


def chebyshev_table(t: np.ndarray, kmax: int) -> np.ndarray:
    """T_0..T_kmax at t: shape t.shape + (kmax + 1,) (:func:`_chebyshev_rows`, transposed)."""
    t = np.asarray(t, dtype=np.float64)
    rows = _chebyshev_rows(t.reshape(-1), kmax)
    return np.ascontiguousarray(rows.T).reshape(t.shape + (kmax + 1,))


def _chebyshev_rows(t: np.ndarray, kmax: int) -> np.ndarray:
    """T_0..T_kmax at the points ``t`` (N,) by the three-term recurrence: shape (kmax + 1, N),
    each row contiguous."""
    out = np.empty((kmax + 1, t.shape[0]))
    out[0] = 1.0
    if kmax >= 1:
        out[1] = t
    for k in range(2, kmax + 1):
        np.multiply(t, out[k - 1], out=out[k])
        out[k] *= 2.0
        out[k] -= out[k - 2]
    return out


def chebyshev_derivative_table(t: np.ndarray, kmax: int) -> np.ndarray:
    """dT_k/dt = k U_{k-1}(t) for k = 0..kmax: shape t.shape + (kmax + 1,)."""
    out = np.zeros(t.shape + (kmax + 1,))
    if kmax >= 1:
        u_prev = np.zeros_like(t)      # U_{-1}
        u = np.ones_like(t)            # U_0
        for k in range(1, kmax + 1):
            out[..., k] = k * u
            u_prev, u = u, 2.0 * t * u - u_prev
    return out


def _as_points(x, n_vars: int) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if n_vars == 1 and (x.ndim == 0 or x.shape[-1] != 1):
        x = x[..., None]
    if x.shape[-1] != n_vars:
        raise ValueError(f"expected points with last axis {n_vars}, got shape {x.shape}")
    return x


def chebyshev_basis(x, exponents, domain) -> np.ndarray:
    """Basis matrix ``B[..., j] = prod_v T_{E[j, v]}(t_v)``; ``x`` is ``(..., n_vars)``."""
    exponents = np.asarray(exponents, dtype=np.int64)
    domain = np.asarray(domain, dtype=np.float64).reshape(-1, 2)
    n_vars = domain.shape[0]
    t = _to_unit(_as_points(x, n_vars), domain)
    out = np.ones(t.shape[:-1] + (exponents.shape[0],))
    if exponents.shape[0] == 0:
        return out
    for v in range(n_vars):
        kmax = int(exponents[:, v].max())
        if kmax == 0:
            continue
        out *= chebyshev_table(t[..., v], kmax)[..., exponents[:, v]]
    return out


def chebyshev_series(x, exponents, domain, coef) -> np.ndarray:
    """``sum_j coef[j] prod_v T_{E[j, v]}(t_v)`` at ``x`` (``(..., n_vars)``): the value of
    ``chebyshev_basis(x, exponents, domain) @ coef`` (shape ``(...)``) without the basis matrix.
    The coefficients are scattered into a dense ``(k_1 + 1, ..., k_n + 1)`` tensor (``k_v`` the
    highest exponent of variable ``v``) contracted one variable at a time against its Chebyshev
    table: a matrix product for the first variable, products and sums over the others (the
    basis matrix gathers ``n_terms`` columns per variable: 6.2-12.2x slower on the shipped 2-D
    fits, ``benchmarks/bench_numpy_eval.py``). Equal to the basis-matrix form within rounding
    (sums in another order)."""
    exponents = np.asarray(exponents, dtype=np.int64)
    coef = np.asarray(coef, dtype=np.float64).reshape(-1)
    domain = np.asarray(domain, dtype=np.float64).reshape(-1, 2)
    n_vars = domain.shape[0]
    t = _to_unit(_as_points(x, n_vars), domain)
    lead = t.shape[:-1]
    if exponents.shape[0] == 0:
        return np.zeros(lead)
    kmax = exponents.max(axis=0)
    dense = np.zeros(tuple(int(k) + 1 for k in kmax))
    np.add.at(dense, tuple(exponents.T), coef)
    flat = np.ascontiguousarray(t.reshape(-1, n_vars).T)          # (n_vars, N)
    n = flat.shape[1]
    k0 = int(kmax[0]) + 1
    acc = dense.reshape(k0, -1).T @ _chebyshev_rows(flat[0], k0 - 1)   # (rest, N)
    for v in range(1, n_vars):
        kv = int(kmax[v]) + 1
        acc = np.einsum("krn,kn->rn", acc.reshape(kv, -1, n), _chebyshev_rows(flat[v], kv - 1))
    return acc.reshape(lead)


def chebyshev_basis_derivative(x, exponents, domain, var: int) -> np.ndarray:
    """Partial derivative of :func:`chebyshev_basis` with respect to ``x[..., var]``."""
    exponents = np.asarray(exponents, dtype=np.int64)
    domain = np.asarray(domain, dtype=np.float64).reshape(-1, 2)
    n_vars = domain.shape[0]
    t = _to_unit(_as_points(x, n_vars), domain)
    out = np.ones(t.shape[:-1] + (exponents.shape[0],))
    if exponents.shape[0] == 0:
        return out * 0.0
    for v in range(n_vars):
        kmax = int(exponents[:, v].max())
        if v == var:
            scale = 2.0 / (domain[v, 1] - domain[v, 0])
            out *= scale * chebyshev_derivative_table(t[..., v], kmax)[..., exponents[:, v]]
        elif kmax > 0:
            out *= chebyshev_table(t[..., v], kmax)[..., exponents[:, v]]
    return out
