"""Multivariate rational functions ``R(x) = P(x) / Q(x)`` in a tensor Chebyshev basis.

Each variable ``x_v`` has a domain ``[a_v, b_v]`` mapped affinely onto ``[-1, 1]``::

    t_v = (2 x_v - (a_v + b_v)) / (b_v - a_v)

and a term with exponent row ``e = (e_1, ..., e_n)`` is the product ``T_{e_1}(t_1) ... T_{e_n}(t_n)``
of Chebyshev polynomials of the first kind (:mod:`fit.rational.basis`). The numerator and the
denominator each store an explicit ``(n_terms, n_vars)`` integer exponent list and a
coefficient vector, so code generators can unroll the sums::

    P(x) = sum_j p_j prod_v T_{E_P[j, v]}(t_v),   Q(x) = sum_j q_j prod_v T_{E_Q[j, v]}(t_v)

Evaluation is vectorised over leading axes: ``x`` has shape ``(..., n_vars)`` (a 1-variable
function also accepts ``(...)``). Outside the domain the polynomials are simply extrapolated
(``|t| > 1``); clamping policies belong to the caller (see :mod:`fit.rational.model`).

Q > 0 certificates: :meth:`RationalFunction.certify_denominator` proves Q > 0 on the whole box
with Bernstein coefficients (:mod:`fit.rational.bernstein`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .basis import chebyshev_basis_derivative, chebyshev_series
from .bernstein import PositivityCertificate, certify_positive

__all__ = ["RationalFunction", "RationalRGB"]


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
        """P(x) for ``x`` of shape ``(..., n_vars)``; returns shape ``(...)``."""
        return chebyshev_series(x, self.num_exponents, self.domain, self.num_coef)

    def denominator(self, x) -> np.ndarray:
        """Q(x) for ``x`` of shape ``(..., n_vars)``; returns shape ``(...)``."""
        return chebyshev_series(x, self.den_exponents, self.domain, self.den_coef)

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
        """Prove Q > 0 on the whole domain box (or fail to): :func:`fit.rational.bernstein.certify_positive`
        of the denominator (Bernstein coefficients with a rigorous float64 rounding-error bound,
        midpoint subdivision up to ``max_depth`` levels)."""
        return certify_positive(self.den_exponents, self.den_coef, max_depth, max_boxes)

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
