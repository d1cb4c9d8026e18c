"""Multivariate rational functions ``R(x) = P(x) / Q(x)`` in a tensor Chebyshev basis.

Each variable ``x_v`` has a domain ``[a_v, b_v]`` mapped affinely onto ``[-1, 1]``::

    t_v = (2 x_v - (a_v + b_v)) / (b_v - a_v)

and a term with exponent row ``e = (e_1, ..., e_n)`` is the product ``T_{e_1}(t_1) ... T_{e_n}(t_n)``
of Chebyshev polynomials of the first kind (``T_0 = 1``, ``T_1 = t``,
``T_{k+1} = 2 t T_k - T_{k-1}``). The numerator and the denominator each store an explicit
``(n_terms, n_vars)`` integer exponent list and a coefficient vector, so code generators can
unroll the sums::

    P(x) = sum_j p_j prod_v T_{E_P[j, v]}(t_v),   Q(x) = sum_j q_j prod_v T_{E_Q[j, v]}(t_v)

Evaluation is vectorised over leading axes: ``x`` has shape ``(..., n_vars)`` (a 1-variable
function also accepts ``(...)``). Outside the domain the polynomials are simply extrapolated
(``|t| > 1``); clamping policies belong to the caller (see :mod:`fit.coefficients`).

Q > 0 certificates: :func:`bernstein_coefficients` converts a Chebyshev polynomial exactly
(rational arithmetic) into tensor Bernstein coefficients on the box; if they are all positive,
Q > 0 on the whole box. :meth:`RationalFunction.certify_denominator` does the same in float64
with a rigorous rounding-error bound (fast) and subdivides the box (de Casteljau at the
midpoints) where the coefficients are not conclusive.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from fractions import Fraction
from functools import lru_cache
from math import comb

import numpy as np

__all__ = [
    "total_degree_exponents", "tensor_exponents", "chebyshev_basis", "chebyshev_basis_derivative",
    "RationalFunction", "RationalRGB", "bernstein_coefficients", "PositivityCertificate",
]


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


def _cheb_table(t: np.ndarray, kmax: int) -> np.ndarray:
    """T_0..T_kmax at t: shape t.shape + (kmax + 1,)."""
    out = np.empty(t.shape + (kmax + 1,))
    out[..., 0] = 1.0
    if kmax >= 1:
        out[..., 1] = t
    for k in range(2, kmax + 1):
        out[..., k] = 2.0 * t * out[..., k - 1] - out[..., k - 2]
    return out


def _cheb_deriv_table(t: np.ndarray, kmax: int) -> np.ndarray:
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
        out *= _cheb_table(t[..., v], kmax)[..., exponents[:, v]]
    return out


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
            out *= scale * _cheb_deriv_table(t[..., v], kmax)[..., exponents[:, v]]
        elif kmax > 0:
            out *= _cheb_table(t[..., v], kmax)[..., exponents[:, v]]
    return out


# --------------------------------------------------------------------------------------------
# Exact Chebyshev -> Bernstein conversion (certificates)
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


def _de_casteljau_split_float(arr: np.ndarray, axis: int):
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


def _de_casteljau_split(arr: np.ndarray, axis: int):
    """Split Bernstein coefficients at the midpoint of ``axis`` (exact for Fractions)."""
    a = np.moveaxis(arr, axis, 0)
    n = a.shape[0] - 1
    rows = [a[i] for i in range(n + 1)]
    left, right = [rows[0]], [rows[n]]
    for _ in range(n):
        rows = [(rows[i] + rows[i + 1]) / 2 for i in range(len(rows) - 1)]
        left.append(rows[0])
        right.append(rows[-1])
    left = np.moveaxis(np.array(left, dtype=object), 0, axis)
    right = np.moveaxis(np.array(right[::-1], dtype=object), 0, axis)
    return left, right


@dataclass
class PositivityCertificate:
    """Result of :meth:`RationalFunction.certify_denominator`.

    ``certified`` True means Q > 0 on the whole domain box, proved by Bernstein coefficients
    that exceed their rounding-error bound on every sub-box of a midpoint subdivision. ``lower_bound`` is a proven lower bound of Q on the box (min over leaves of the
    smallest Bernstein coefficient) when certified.
    """

    certified: bool
    lower_bound: float
    n_boxes: int
    max_depth: int
    method: str = ("Bernstein coefficients (exact rational conversion matrices, float64 with a rigorous "
                   "rounding-error bound) with midpoint subdivision")


# --------------------------------------------------------------------------------------------
# RationalFunction
# --------------------------------------------------------------------------------------------
@dataclass
class RationalFunction:
    """``R = P / Q`` in the tensor Chebyshev basis on a box domain.

    Parameters
    ----------
    domain : array (n_vars, 2)
        ``[a_v, b_v]`` per variable, mapped onto ``[-1, 1]``.
    num_exponents, den_exponents : int arrays (n_p, n_vars), (n_q, n_vars)
    num_coef, den_coef : float arrays (n_p,), (n_q,)
    """

    domain: np.ndarray
    num_exponents: np.ndarray
    num_coef: np.ndarray
    den_exponents: np.ndarray
    den_coef: np.ndarray
    basis: str = "chebyshev"
    var_names: tuple = field(default=())

    def __post_init__(self):
        self.domain = np.asarray(self.domain, dtype=np.float64).reshape(-1, 2)
        n = self.domain.shape[0]
        self.num_exponents = np.asarray(self.num_exponents, dtype=np.int64).reshape(-1, n)
        self.den_exponents = np.asarray(self.den_exponents, dtype=np.int64).reshape(-1, n)
        self.num_coef = np.asarray(self.num_coef, dtype=np.float64).reshape(-1)
        self.den_coef = np.asarray(self.den_coef, dtype=np.float64).reshape(-1)
        if self.basis != "chebyshev":
            raise ValueError(f"unsupported basis {self.basis!r}")
        if len(self.num_coef) != len(self.num_exponents) or len(self.den_coef) != len(self.den_exponents):
            raise ValueError("coefficient and exponent counts differ")
        if len(self.den_coef) == 0:
            raise ValueError("the denominator needs at least one term")
        if np.any(self.domain[:, 1] <= self.domain[:, 0]):
            raise ValueError("each domain needs a < b")
        if np.any(self.num_exponents < 0) or np.any(self.den_exponents < 0):
            raise ValueError("negative exponent")
        if not self.var_names:
            self.var_names = tuple(f"x{v}" for v in range(n))

    # Shape information ---------------------------------------------------------------------
    @property
    def n_vars(self) -> int:
        return self.domain.shape[0]

    @property
    def n_coefficients(self) -> int:
        """Number of stored coefficients (numerator + denominator)."""
        return len(self.num_coef) + len(self.den_coef)

    @property
    def num_degrees(self) -> tuple:
        """Per-variable maximum exponent of the numerator."""
        return tuple(int(d) for d in self.num_exponents.max(axis=0)) if len(self.num_coef) else (0,) * self.n_vars

    @property
    def den_degrees(self) -> tuple:
        return tuple(int(d) for d in self.den_exponents.max(axis=0))

    @property
    def num_total_degree(self) -> int:
        return int(self.num_exponents.sum(axis=1).max()) if len(self.num_coef) else 0

    @property
    def den_total_degree(self) -> int:
        return int(self.den_exponents.sum(axis=1).max())

    # Evaluation ------------------------------------------------------------------------------
    def numerator(self, x) -> np.ndarray:
        return chebyshev_basis(x, self.num_exponents, self.domain) @ self.num_coef

    def denominator(self, x) -> np.ndarray:
        return chebyshev_basis(x, self.den_exponents, self.domain) @ self.den_coef

    def __call__(self, x) -> np.ndarray:
        """R(x) for ``x`` of shape ``(..., n_vars)``; returns shape ``(...)``."""
        return self.numerator(x) / self.denominator(x)

    def derivative(self, x, var: int = 0) -> np.ndarray:
        """dR/dx_var = (dP/dx - R dQ/dx) / Q, analytic."""
        p = self.numerator(x)
        q = self.denominator(x)
        dp = chebyshev_basis_derivative(x, self.num_exponents, self.domain, var) @ self.num_coef
        dq = chebyshev_basis_derivative(x, self.den_exponents, self.domain, var) @ self.den_coef
        r = p / q
        return (dp - r * dq) / q

    def gradient(self, x) -> np.ndarray:
        """All partial derivatives, shape ``(..., n_vars)``."""
        return np.stack([self.derivative(x, v) for v in range(self.n_vars)], axis=-1)

    # Transformations --------------------------------------------------------------------------
    def scaled(self, factor: float) -> "RationalFunction":
        """``factor * R`` (numerator scaled)."""
        return RationalFunction(self.domain, self.num_exponents, self.num_coef * factor,
                                self.den_exponents, self.den_coef.copy(), self.basis, self.var_names)

    def normalized(self) -> "RationalFunction":
        """Same function with the denominator's constant coefficient 1 (if it has one, > 0)."""
        k = np.flatnonzero(~self.den_exponents.any(axis=1))
        if len(k) == 0 or self.den_coef[k[0]] == 0:
            return self
        s = self.den_coef[k[0]]
        return RationalFunction(self.domain, self.num_exponents, self.num_coef / s,
                                self.den_exponents, self.den_coef / s, self.basis, self.var_names)

    def grid(self, n: int = 64) -> np.ndarray:
        """Points of a regular ``n^n_vars`` grid on the domain (including the boundary), ``(N, n_vars)``."""
        axes = [np.linspace(a, b, n) for a, b in self.domain]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, self.n_vars)

    # Certificates ----------------------------------------------------------------------------
    def certify_denominator(self, max_depth: int = 12, max_boxes: int = 20000) -> PositivityCertificate:
        """Prove Q > 0 on the whole domain box (or fail to).

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
        b, err = bernstein_coefficients_float(self.den_exponents, self.den_coef)
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
            if min(corners) + e <= 0 or depth >= max_depth or n_boxes + len(stack) > max_boxes:
                return PositivityCertificate(False, float("nan"), n_boxes, depth_seen)
            axis = depth % a.ndim
            left, right = _de_casteljau_split_float(a, axis)
            e2 = e + (a.shape[axis] + 1) * eps * float(np.abs(a).max())
            stack.append((left, e2, depth + 1))
            stack.append((right, e2, depth + 1))
        return PositivityCertificate(True, float(lower), n_boxes, depth_seen)

    # Serialisation helpers --------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {
            "basis": self.basis,
            "domain": self.domain.tolist(),
            "numerator": {"exponents": self.num_exponents.tolist(), "coefficients": self.num_coef.tolist()},
            "denominator": {"exponents": self.den_exponents.tolist(), "coefficients": self.den_coef.tolist()},
            "num_degrees": list(self.num_degrees),
            "den_degrees": list(self.den_degrees),
        }

    @classmethod
    def from_dict(cls, d: dict, var_names=()) -> "RationalFunction":
        return cls(domain=d["domain"],
                   num_exponents=d["numerator"]["exponents"], num_coef=d["numerator"]["coefficients"],
                   den_exponents=d["denominator"]["exponents"], den_coef=d["denominator"]["coefficients"],
                   basis=d.get("basis", "chebyshev"), var_names=tuple(var_names))


@dataclass
class RationalRGB:
    """One :class:`RationalFunction` per colour channel (R, G, B)."""

    channels: list

    def __post_init__(self):
        self.channels = list(self.channels)
        if len(self.channels) != 3:
            raise ValueError("RationalRGB needs exactly three channels")

    def __getitem__(self, i) -> RationalFunction:
        return self.channels[i]

    def __iter__(self):
        return iter(self.channels)

    def __call__(self, x) -> np.ndarray:
        """Shape ``(..., 3)``."""
        return np.stack([c(x) for c in self.channels], axis=-1)

    def derivative(self, x, var: int = 0) -> np.ndarray:
        return np.stack([c.derivative(x, var) for c in self.channels], axis=-1)

    @property
    def n_coefficients(self) -> int:
        return sum(c.n_coefficients for c in self.channels)
