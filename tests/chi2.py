"""The reusable sampling checks of the test suite (after Mitsuba 3's ``chi2.py``): a chi-square
test of sampled light directions against the cell probabilities of a density, three ways of
computing those probabilities, and the unbiasedness check against quadrature.

Cells are (theta_l, phi_l) rectangles: theta_l in [0, pi/2] (``t_edges``), phi_l in [-pi, pi]
measured from the view's azimuth (``p_edges``); angles in radians, densities in 1/sr.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from fit.formats.colour import LUMINANCE
from fit.projection.albedo import directional_albedo

MIN_EXPECTED = 5.0


def edges(n_t: int, n_p: int):
    """``n_t`` equal theta_l cells on [0, pi/2] and ``n_p`` equal phi_l cells on [-pi, pi]."""
    return np.linspace(0.0, np.pi / 2, n_t + 1), np.linspace(-np.pi, np.pi, n_p + 1)


def chi2_pvalue(counts, probs, n: int) -> float:
    """Pearson chi-square p-value of ``counts`` against ``n * probs`` (probabilities
    renormalised); cells expected below :data:`MIN_EXPECTED` are pooled into one. Samples in a
    cell of zero probability fail at once."""
    p = np.asarray(probs, float).ravel()
    exp = p / p.sum() * n
    obs = np.asarray(counts, float).ravel()
    low = exp < MIN_EXPECTED
    e = np.append(exp[~low], exp[low].sum())
    o = np.append(obs[~low], obs[low].sum())
    keep = e > 0
    assert o[~keep].sum() == 0, "samples in cells of zero probability"
    stat = float(np.sum((o[keep] - e[keep]) ** 2 / e[keep]))
    return float(chi2.sf(stat, max(int(keep.sum()) - 1, 1)))


def histogram(theta_l, phi_l, t_edges, p_edges):
    return np.histogram2d(theta_l, phi_l, bins=[t_edges, p_edges])[0]


def pdf_cell_probs(pdf, t_edges, p_edges, sub: int = 24):
    """Cell probabilities of a density ``pdf(wi (N, 3)) -> (N,)`` (1/sr): midpoint quadrature in
    solid angle on ``sub`` x ``sub`` points per cell (exact for a table's density when the cells
    are unions of table cells: pdf sin(theta) is constant on those)."""
    from fit.formats.angles import spherical_to_direction

    n_t, n_p = len(t_edges) - 1, len(p_edges) - 1
    t = t_edges[0] + (np.arange(n_t * sub) + 0.5) / (n_t * sub) * (t_edges[-1] - t_edges[0])
    p = p_edges[0] + (np.arange(n_p * sub) + 0.5) / (n_p * sub) * (p_edges[-1] - p_edges[0])
    tt, pp = np.meshgrid(t, p, indexing="ij")
    dens = np.asarray(pdf(spherical_to_direction(tt, pp).reshape(-1, 3)), float).reshape(tt.shape)
    cell = dens * np.sin(tt) * (t[1] - t[0]) * (p[1] - p[0])
    return cell.reshape(n_t, sub, n_p, sub).sum(axis=(1, 3))


def map_cell_probs(cdf, theta_v: float, t_edges, p_edges, nq: int = 64):
    """Exact cell probabilities of a :class:`fit.sampling.cdf_file.CDFFit`'s own sampler (its
    monotone maps; table rows included) from its CDFs: P(theta cell) from ``theta_cdf``, then
    the conditional phi mass at ``nq`` theta_l quantiles inside it from ``phi_cdf_half``
    (symmetric in phi, mass 1/2 per side). The CDFs are bisections: each is called once, on
    every point at once."""
    n_t, n_p = len(t_edges) - 1, len(p_edges) - 1
    mu_e = cdf.theta_cdf(theta_v, t_edges)
    # nq theta_l quantiles inside every theta cell: (n_t, nq)
    mu = mu_e[:-1, None] + (np.arange(nq) + 0.5)[None, :] / nq * (mu_e[1:] - mu_e[:-1])[:, None]
    tl = cdf.sample(np.full(mu.size, theta_v), mu.ravel(), np.full(mu.size, 0.75))[0].reshape(n_t, nq)
    # each phi cell's mass from the CDF of |phi| at its ends (a cell across 0 takes both sides)
    ends = []
    for lo, hi in zip(p_edges[:-1], p_edges[1:]):
        ends.append((hi, lo, -1.0) if lo >= 0 else (-lo, -hi, -1.0) if hi <= 0 else (hi, -lo, 1.0))
    x = np.unique([e for a, b, _ in ends for e in (a, b)])
    C = cdf.phi_cdf_half(theta_v, tl[:, :, None], x[None, None, :])      # (n_t, nq, len(x))
    probs = np.zeros((n_t, n_p))
    for b, (x1, x2, sign) in enumerate(ends):
        pr = 0.5 * (C[:, :, np.searchsorted(x, x1)] + sign * C[:, :, np.searchsorted(x, x2)])
        probs[:, b] = (mu_e[1:] - mu_e[:-1]) * pr.mean(axis=1)
    return probs


def _overlap(lo, hi, e):
    """Length of [lo, hi] inside each interval of ``e``."""
    return np.clip(np.minimum(hi, e[1:]) - np.maximum(lo, e[:-1]), 0, None)


def table_cell_probs(table, theta_v: float, t_edges, p_edges):
    """Exact cell probabilities of a :class:`fit.sampling.table.CDFTable`'s sampler for cells
    not aligned with its own, from its CDF arrays alone (piecewise-uniform density inside each
    table cell)."""
    v = table.row(theta_v)
    m_t = np.diff(table.cdf_theta[v])            # (n_t,)
    m_p = np.diff(table.cdf_phi[v], axis=1)      # (n_t, n_p) over |phi|
    t_fine = np.linspace(0, np.pi / 2, table.n_t + 1)
    p_fine = np.linspace(0, np.pi, table.n_p + 1)
    probs = np.zeros((len(t_edges) - 1, len(p_edges) - 1))
    for a in range(probs.shape[0]):
        ft = _overlap(t_edges[a], t_edges[a + 1], t_fine) / np.diff(t_fine)
        for b in range(probs.shape[1]):
            lo, hi = p_edges[b], p_edges[b + 1]
            fp = (_overlap(max(lo, 0), max(hi, 0), p_fine) + _overlap(max(-hi, 0), max(-lo, 0), p_fine)) / np.diff(p_fine)
            probs[a, b] = np.sum(m_t[:, None] * ft[:, None] * 0.5 * m_p * fp[None, :])
    return probs


def assert_unbiased(evaluate, theta_v: float, wi, wo, weight, label="", rel: float = 0.0, quadrature=None):
    """The estimator ``f cos(theta_l) * weight`` (luminance; ``evaluate(wi, wo) -> (N, 3)``)
    of the integral of f cos over the light (view ``wo`` fixed at ``theta_v``) agrees with
    midpoint quadrature within 3 sigma + twice the quadrature's own uncertainty (difference of
    two resolutions) + ``rel`` of the value. ``quadrature``: ``quadrature_albedo(evaluate,
    theta_v)`` when the caller has it (None: computed here)."""
    wi = np.asarray(wi, float)
    est = (np.asarray(evaluate(wi, wo), float) @ LUMINANCE) * np.maximum(wi[:, 2], 0.0) * weight
    m, se = est.mean(), est.std() / np.sqrt(len(est))
    q, dq = quadrature_albedo(evaluate, theta_v) if quadrature is None else quadrature
    assert abs(m - q) < 3 * se + 2 * dq + rel * abs(q) + 1e-6, (label, m, q, se, dq)


def quadrature_albedo(evaluate, theta_v: float):
    """Luminance of the integral of f cos over the light (view at ``theta_v``, radians) by
    midpoint quadrature on two resolutions: ``(value of the finer, |difference|)``."""
    swap = lambda a, b: evaluate(b, a)  # noqa: E731  (directional_albedo integrates its 2nd argument)
    q1 = directional_albedo(swap, theta_v) @ LUMINANCE
    q2 = directional_albedo(swap, theta_v, 180, 720) @ LUMINANCE
    return float(q2), float(abs(q2 - q1))
