"""Tabulated sampling densities of rho(v, l) cos(theta_l) and their inverse CDFs.

For a view direction at polar angle ``theta_v`` (azimuth 0), a light direction is written
``(theta_l, phi_l)`` with ``phi_l`` measured from the view's azimuth (isotropy). The sampling
density in solid angle is factored as

    pdf(l) = p_theta(theta_l) * p_phi(phi_l | theta_l) / sin(theta_l)

with ``p_theta`` a density per radian on [0, pi/2] and ``p_phi`` a density per radian on
[-pi, pi], symmetric in phi_l (only [0, pi] is tabulated). Both are piecewise constant on a
regular (theta_l, phi_l) grid of cells; the cell masses are integrals of the luminance of
``rho * cos(theta_l) * sin(theta_l)`` by a midpoint rule with ``sub x sub`` points per cell.

Each theta_v row is a mixture ``(1 - eps) * BRDF part + eps * cosine part`` (cosine-weighted
hemisphere discretized on the same cells), so every direction of the upper hemisphere has a
positive density: the estimators stay unbiased even where the table misses a thin lobe. Rows
whose BRDF mass is zero or below ``noise`` times the largest row mass (grazing views, black
materials) fall back to the pure cosine part; they are listed in ``row_fallback``.

Arrays: ``theta_v`` (n_v,) row angles (bin centres on [0, pi/2)); ``cdf_theta`` (n_v, n_t + 1);
``cdf_phi`` (n_v, n_t, n_p + 1) over phi in [0, pi]. Angles are in radians.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..formats.angles import spherical_to_direction
from ..formats.colour import LUMINANCE
from ..limits import (
    MAX_CDF_CELLS,
    MAX_CDF_PHI_CELLS,
    MAX_CDF_ROWS,
    MAX_CDF_THETA_CELLS,
    check_memory,
)
from ..progress import report

TABULATE_STAGE = "tabulating the CDFs"   # the progress stage of tabulate
#: Version of the tabulation (:func:`tabulate`): bump it whenever a change makes ``tabulate``
#: return other arrays for the same arguments (the stored tables of
#: :mod:`warp_rbrdf.techniques.table_cache` are keyed on it, not on this file's bytes).
TABULATION_VERSION = 1


@dataclass
class CDFTable:
    theta_v: np.ndarray
    cdf_theta: np.ndarray
    cdf_phi: np.ndarray
    row_fallback: np.ndarray
    eps: float
    albedo: np.ndarray  # (n_v,) luminance directional albedo estimated from the table

    @property
    def n_v(self) -> int:
        return self.theta_v.size

    @property
    def n_t(self) -> int:
        return self.cdf_theta.shape[1] - 1

    @property
    def n_p(self) -> int:
        return self.cdf_phi.shape[2] - 1

    def row(self, theta_v) -> np.ndarray:
        """Row index for view angle(s) ``theta_v`` (bins of width (pi/2)/n_v)."""
        t = np.asarray(theta_v, float)
        return np.clip(np.floor(t / (0.5 * np.pi) * self.n_v), 0, self.n_v - 1).astype(np.intp)

    # --- sampling --------------------------------------------------------------------------
    def sample(self, theta_v, mu, tau):
        """Inverse-CDF sampling. Returns ``(theta_l, phi_l, pdf)`` with pdf in 1/sr.

        ``mu`` picks theta_l (inverse of the marginal CDF, linear inside a cell); ``tau`` picks
        phi_l in [-pi, pi] through the symmetric conditional CDF (tau < 1/2: negative phi_l).
        """
        v = self.row(theta_v)
        mu, tau = np.broadcast_arrays(np.asarray(mu, float), np.asarray(tau, float))
        v = np.broadcast_to(v, mu.shape)
        cdf_t = self.cdf_theta[v]  # (..., n_t + 1)
        j = np.clip((cdf_t <= mu[..., None]).sum(-1) - 1, 0, self.n_t - 1)
        c0 = np.take_along_axis(cdf_t, j[..., None], -1)[..., 0]
        c1 = np.take_along_axis(cdf_t, (j + 1)[..., None], -1)[..., 0]
        m_t = c1 - c0
        dt = 0.5 * np.pi / self.n_t
        frac = np.where(m_t > 0, (mu - c0) / np.where(m_t > 0, m_t, 1), 0.5)
        theta_l = (j + np.clip(frac, 0, 1)) * dt
        # symmetric conditional in phi
        s = np.where(tau < 0.5, -1.0, 1.0)
        phi_abs, m_p = self.phi_cell(v, j, np.abs(2.0 * tau - 1.0))
        pdf = (m_t / dt) * (0.5 * m_p / (np.pi / self.n_p)) / np.maximum(np.sin(theta_l), 1e-300)
        return theta_l, s * phi_abs, pdf

    def phi_cell(self, v, j, u):
        """``(|phi_l|, m_p)``: the inverse of the half-range conditional CDF of row ``v``,
        theta_l cell ``j`` at ``u`` in [0, 1] (linear inside a phi cell), and the mass ``m_p``
        of the phi cell it falls in (d|phi_l|/du = (pi / n_p) / m_p where m_p > 0)."""
        cdf_p = self.cdf_phi[v, j]  # (..., n_p + 1)
        k = np.clip((cdf_p <= u[..., None]).sum(-1) - 1, 0, self.n_p - 1)
        q0 = np.take_along_axis(cdf_p, k[..., None], -1)[..., 0]
        q1 = np.take_along_axis(cdf_p, (k + 1)[..., None], -1)[..., 0]
        m_p = q1 - q0
        fp = np.where(m_p > 0, (u - q0) / np.where(m_p > 0, m_p, 1), 0.5)
        return (k + np.clip(fp, 0, 1)) * (np.pi / self.n_p), m_p

    def pdf(self, theta_v, theta_l, phi_l) -> np.ndarray:
        """Density in 1/sr of :meth:`sample` at light direction ``(theta_l, phi_l)``; 0 below
        the horizon."""
        v = self.row(theta_v)
        tl = np.asarray(theta_l, float)
        pl = np.abs(np.angle(np.exp(1j * np.asarray(phi_l, float))))  # fold to [0, pi]
        v, tl, pl = np.broadcast_arrays(v, tl, pl)
        dt = 0.5 * np.pi / self.n_t
        dp = np.pi / self.n_p
        j = np.clip(np.floor(tl / dt), 0, self.n_t - 1).astype(np.intp)
        k = np.clip(np.floor(pl / dp), 0, self.n_p - 1).astype(np.intp)
        m_t = self.cdf_theta[v, j + 1] - self.cdf_theta[v, j]
        m_p = self.cdf_phi[v, j, k + 1] - self.cdf_phi[v, j, k]
        p = (m_t / dt) * (0.5 * m_p / dp) / np.maximum(np.sin(tl), 1e-300)
        return np.where((tl >= 0) & (tl < 0.5 * np.pi), p, 0.0)


def inverse_pdf(pdf) -> np.ndarray:
    """1 / pdf where pdf > 0, else 0 (the estimator weight of a sample that cannot occur)."""
    pdf = np.asarray(pdf, float)
    return np.where(pdf > 0, 1.0 / np.where(pdf > 0, pdf, 1.0), 0.0)


def table_where(table: CDFTable, tab, tv, mu, tau, tl, pl, alpha):
    """``(theta_l, phi_l, alpha)`` with the table's samples (alpha = 1 / its pdf) where the
    boolean ``tab`` is set: the rows a rational sampler hands to the table (all arrays of one
    shape; the inputs are not modified)."""
    if not np.any(tab):
        return tl, pl, alpha
    t2, p2, pdf = table.sample(tv[tab], mu[tab], tau[tab])
    tl, pl, alpha = tl.copy(), pl.copy(), alpha.copy()
    tl[tab], pl[tab], alpha[tab] = t2, p2, inverse_pdf(pdf)
    return tl, pl, alpha


def _cosine_cell_masses(n_t: int, n_p: int):
    """Exact masses of the cosine-weighted hemisphere density on the (theta, phi in [0, pi]) cells."""
    edges = np.linspace(0, 0.5 * np.pi, n_t + 1)
    m_t = 0.5 * (np.sin(edges[1:]) ** 2 - np.sin(edges[:-1]) ** 2)  # sums to 1/2 ... normalized below
    m_t = m_t / m_t.sum()
    m_p = np.full(n_p, 1.0 / n_p)
    return m_t, m_p


def check_table_size(n_v: int, n_t: int, n_p: int, sub: int = 3, chunk_rows: int = 4) -> None:
    """``ValueError`` when a table of ``n_v`` rows x ``n_t`` x ``n_p`` cells (``sub`` x ``sub``
    points per cell) is beyond the limits of :mod:`fit.limits` (rows, cells, and the estimated
    memory of :func:`fit.sampling.table.tabulate`)."""
    for name, v, lo, hi in (("n_v", n_v, 2, MAX_CDF_ROWS), ("n_t", n_t, 2, MAX_CDF_THETA_CELLS),
                            ("n_p", n_p, 2, MAX_CDF_PHI_CELLS), ("sub", sub, 1, 16)):
        if not lo <= v <= hi:
            raise ValueError(f"{name} = {v} is outside [{lo}, {hi}] (fit.limits)")
    cells = n_v * n_t * n_p
    if cells > MAX_CDF_CELLS:
        raise ValueError(f"n_v x n_t x n_p = {cells} cells, above the limit {MAX_CDF_CELLS} "
                         "(fit.limits.MAX_CDF_CELLS)")
    pts = (n_t * sub) * (n_p * sub)
    # measured: 8 x 448 x 448 (sub 3) peaks at 1.58 GB, about 8 (8 cells + 100 points) bytes
    check_memory(8.0 * (8 * cells + 9 * chunk_rows * 3 * pts), f"a {n_v} x {n_t} x {n_p} table")


def tabulate(evaluate, n_v: int = 32, n_t: int = 64, n_p: int = 64, sub: int = 3,
             eps: float = 0.02, noise: float = 1e-6, chunk_rows: int = 4, progress=None) -> CDFTable:
    """Tabulate the inverse-CDF sampler of ``evaluate(wi, wo) -> (..., 3)`` (1/sr, RGB).

    ``wi`` is the light, ``wo`` the view. Cell masses use the Rec.709 luminance of
    ``rho * cos(theta_l) * sin(theta_l)`` (negative values clamped to 0). ``progress(stage,
    done, total)`` (:mod:`fit.progress`) is told the rows done, stage ``"tabulating the CDFs"``.
    """
    if not 0.0 < eps <= 1.0:
        raise ValueError("eps must be in (0, 1]: it keeps every direction sampleable")
    check_table_size(n_v, n_t, n_p, sub, chunk_rows)
    theta_v = (np.arange(n_v) + 0.5) / n_v * 0.5 * np.pi
    dt = 0.5 * np.pi / n_t
    dp = np.pi / n_p
    # sub-sample points inside each cell (midpoint rule)
    ft = (np.arange(n_t * sub) + 0.5) / (n_t * sub) * 0.5 * np.pi
    fp = (np.arange(n_p * sub) + 0.5) / (n_p * sub) * np.pi
    tt, pp = np.meshgrid(ft, fp, indexing="ij")
    wi = spherical_to_direction(tt, pp)
    weight = np.cos(tt) * np.sin(tt) * (dt / sub) * (dp / sub)
    mass = np.empty((n_v, n_t, n_p))
    report(progress, TABULATE_STAGE, 0, n_v)
    for r0 in range(0, n_v, chunk_rows):
        rows = theta_v[r0:r0 + chunk_rows]
        wo = spherical_to_direction(rows, np.zeros_like(rows))[:, None, None, :]
        f = np.asarray(evaluate(wi[None], wo), float) @ LUMINANCE
        f = np.maximum(np.nan_to_num(f, nan=0.0, posinf=0.0), 0.0) * weight
        mass[r0:r0 + chunk_rows] = f.reshape(len(rows), n_t, sub, n_p, sub).sum(axis=(2, 4))
        report(progress, TABULATE_STAGE, r0 + len(rows), n_v)
    total = mass.sum(axis=(1, 2))  # half-hemisphere luminance albedo / 2
    albedo = 2.0 * total
    fallback = (total <= 0) | (total < noise * max(total.max(), 0.0))
    cm_t, cm_p = _cosine_cell_masses(n_t, n_p)
    cos_mass = cm_t[:, None] * cm_p[None, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        brdf_mass = np.where(fallback[:, None, None], 0.0, mass / np.where(total > 0, total, 1)[:, None, None])
    w_brdf = np.where(fallback, 0.0, 1.0 - eps)
    mix = w_brdf[:, None, None] * brdf_mass + (1.0 - w_brdf)[:, None, None] * cos_mass
    # marginal in theta, conditional in phi
    m_t = mix.sum(axis=2)
    cdf_theta = np.concatenate([np.zeros((n_v, 1)), np.cumsum(m_t, axis=1)], axis=1)
    cdf_theta /= cdf_theta[:, -1:]
    cond = mix / m_t[..., None]
    cdf_phi = np.concatenate([np.zeros((n_v, n_t, 1)), np.cumsum(cond, axis=2)], axis=2)
    cdf_phi /= cdf_phi[..., -1:]
    return CDFTable(theta_v=theta_v, cdf_theta=cdf_theta, cdf_phi=cdf_phi, row_fallback=fallback,
                    eps=eps, albedo=albedo)


# --- tabulated inverse CDFs (targets of the rational fits, plots) ------------------------------
def _inverse_theta_rows(table: CDFTable, mu) -> np.ndarray:
    """CDF^-1_v(mu) -> theta_l for every row: shape (n_v, len(mu)). Piecewise linear (the
    inverse of the piecewise-linear CDF of the piecewise-constant density)."""
    edges = np.linspace(0.0, 0.5 * np.pi, table.n_t + 1)
    mu = np.asarray(mu, float)
    return np.stack([np.interp(mu, table.cdf_theta[v], edges) for v in range(table.n_v)])


def _inverse_phi_rows(table: CDFTable, theta_l, u) -> np.ndarray:
    """|phi_l| = CDF^-1_v(u | theta_l) on [0, pi] for u in [0, 1] (the half-range conditional;
    phi_l = sign(tau - 1/2) |phi_l| with u = |2 tau - 1|): shape (n_v, len(theta_l), len(u))."""
    edges = np.linspace(0.0, np.pi, table.n_p + 1)
    dt = 0.5 * np.pi / table.n_t
    j = np.clip(np.floor(np.asarray(theta_l, float) / dt), 0, table.n_t - 1).astype(np.intp)
    u = np.asarray(u, float)
    out = np.empty((table.n_v, len(j), len(u)))
    for v in range(table.n_v):
        for a, jj in enumerate(j):
            out[v, a] = np.interp(u, table.cdf_phi[v, jj], edges)
    return out


def _interp_rows(table: CDFTable, values: np.ndarray, theta_v) -> np.ndarray:
    """Linear interpolation of per-row ``values`` (n_v, ...) between row centres (constant
    beyond the first/last centre) at view angles ``theta_v`` (1-D)."""
    tv = np.asarray(theta_v, float)
    x = np.clip(tv, table.theta_v[0], table.theta_v[-1])
    i = np.clip(np.searchsorted(table.theta_v, x) - 1, 0, table.n_v - 2)
    w = (x - table.theta_v[i]) / (table.theta_v[i + 1] - table.theta_v[i])
    w = w.reshape((-1,) + (1,) * (values.ndim - 1))
    return (1 - w) * values[i] + w * values[i + 1]


def inverse_cdf_theta(table: CDFTable, theta_v, mu) -> np.ndarray:
    """Tabulated CDF^-1_v(mu) on a (theta_v, mu) grid, shape (len(theta_v), len(mu)), linearly
    interpolated between row centres in theta_v (the table itself uses the nearest row)."""
    return _interp_rows(table, _inverse_theta_rows(table, mu), np.atleast_1d(theta_v))


def inverse_cdf_phi(table: CDFTable, theta_v, theta_l, u) -> np.ndarray:
    """Tabulated half-range CDF^-1_v(u | theta_l) -> |phi_l| in [0, pi] on a (theta_v, theta_l,
    u) grid, shape (len(theta_v), len(theta_l), len(u)); rows interpolated as above."""
    return _interp_rows(table, _inverse_phi_rows(table, np.atleast_1d(theta_l), u), np.atleast_1d(theta_v))


def pdf_theta(table: CDFTable, theta_v) -> tuple:
    """(cell edges, PDF_v(theta_l) per radian on each cell) of the row of ``theta_v``."""
    v = int(table.row(theta_v))
    dt = 0.5 * np.pi / table.n_t
    return np.linspace(0, 0.5 * np.pi, table.n_t + 1), np.diff(table.cdf_theta[v]) / dt


def pdf_phi(table: CDFTable, theta_v, theta_l) -> tuple:
    """(cell edges on [-pi, pi], PDF_v(phi_l | theta_l) per radian) of the row/cell."""
    v = int(table.row(theta_v))
    j = int(np.clip(np.floor(theta_l / (0.5 * np.pi / table.n_t)), 0, table.n_t - 1))
    dp = np.pi / table.n_p
    half = 0.5 * np.diff(table.cdf_phi[v, j]) / dp
    edges = np.linspace(-np.pi, np.pi, 2 * table.n_p + 1)
    return edges, np.concatenate([half[::-1], half])
