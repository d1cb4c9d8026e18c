"""What the rational sampling layouts share: the endpoint-normalized maps of a rational
function and the map from uniform ``(mu, tau)`` to a light direction and its weight.

A sampler maps uniform ``(mu, tau)`` in [0, 1]^2 to a light direction by

    theta_l = clamp(theta_map(mu), 0, pi/2)
    u = |2 tau - 1|,  phi_l = sign(tau - 1/2) * clamp(phi_map(theta_l, u), 0, pi)

(phi_l measured from the view's azimuth, in [-pi, pi]; the sampled density is symmetric in
phi_l). The derivative estimator (eq. 3-4 of the paper's supplementary text) weights a sample
by ``alpha = dtheta_l/dmu * dphi_l/dtau * sin(theta_l)`` in place of 1 / pdf; ``alpha = 0``
where a clamp is active (those samples contribute 0). All angles in radians.
"""
from __future__ import annotations

import numpy as np

from ..formats.angles import HALF_PI
from ..rational.function import RationalFunction


def restrict_rf(f: RationalFunction, var: int, value: float) -> RationalFunction:
    """``f`` with variable ``var`` fixed to the lower (value 0) or upper (value 1) end of its
    domain, as a rational function of the remaining variables (exact: T_k(+-1) = (+-1)^k)."""
    t = -1.0 if value == 0 else 1.0
    keep = [v for v in range(f.n_vars) if v != var]

    def collapse(ex, co):
        terms: dict = {}
        for e, c in zip(ex, co):
            key = tuple(int(e[k]) for k in keep)
            terms[key] = terms.get(key, 0.0) + c * t ** int(e[var])
        E = np.array(list(terms), dtype=np.int64).reshape(-1, len(keep))
        return E, np.array(list(terms.values()), float)

    ne, nc = collapse(f.num_exponents, f.num_coef)
    de, dc = collapse(f.den_exponents, f.den_coef)
    return RationalFunction(f.domain[keep], ne, nc, de, dc)


def normalized_map(f: RationalFunction, var: int, x, span: float):
    """``(value, derivative)`` of the endpoint-normalized map
    ``span * (f(x) - f(x|var=lo)) / (f(x|var=hi) - f(x|var=lo))`` (exact endpoints 0 and span)."""
    x = np.asarray(x, float)
    keep = [v for v in range(f.n_vars) if v != var]
    xr = x[..., keep]
    f0 = restrict_rf(f, var, 0)(xr)
    f1 = restrict_rf(f, var, 1)(xr)
    den = f1 - f0
    return span * (f(x) - f0) / den, span * f.derivative(x, var) / den


def sample_maps(theta_map, phi_map, mu, tau):
    """``(theta_l, phi_l, alpha)`` from normalized maps ``theta_map(mu) -> (theta_l, dtheta/dmu)``
    and ``phi_map(theta_l, u) -> (|phi_l|, d|phi_l|/du)``: u = |2 tau - 1|, the sign of phi_l
    from tau < 1/2, alpha = dtheta/dmu * 2 d|phi|/du * sin(theta_l), 0 where a clamp acts."""
    tl, dF = theta_map(mu)
    s = np.where(tau < 0.5, -1.0, 1.0)
    u = np.abs(2.0 * tau - 1.0)
    ok = (tl >= 0) & (tl <= HALF_PI)
    tl = np.clip(tl, 0.0, HALF_PI)
    ph, dG = phi_map(tl, u)
    ok &= (ph >= 0) & (ph <= np.pi)
    pl = s * np.clip(ph, 0.0, np.pi)
    return tl, pl, np.where(ok, dF * 2.0 * dG * np.sin(tl), 0.0)
