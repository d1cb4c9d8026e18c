"""The data of a 2-D BRDF fit (:func:`fit.rational.brdf_fit.fit_brdf`): the median projection
with the grazing cut-off (:func:`project_for_fit`), the white-sky albedo that sets the absolute
floor (:func:`white_sky_albedo`), and per channel the clusters of a theta_d range with their
intervals (:func:`channel_data`, :class:`ChannelData`). The policy (cut-off, interval kinds,
floor) is stated in :mod:`fit.rational.brdf_fit`'s docstring.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..formats.colour import LUMINANCE
from ..projection.albedo import directional_albedo
from ..projection.project import project
from ..projection.projected import ProjectedBRDF
from .domain import GRAZING_CUTOFF_DEG, THETA_D_MAX_DEG
from .fitter import intervals_from_spread, intervals_from_tolerance
from .settings import INTERVALS


@dataclass
class ChannelData:
    """The clusters of one channel and theta_d range, as :func:`channel_data` gives them to the
    fitter."""

    X: np.ndarray          # physical inputs (theta_h, theta_d) in radians, (N, 2)
    y: np.ndarray          # values in 1/sr
    lower: np.ndarray
    upper: np.ndarray
    abs_floor: float


def project_for_fit(brdf, grazing_cutoff_deg: float = GRAZING_CUTOFF_DEG) -> ProjectedBRDF:
    """Median projection with the grazing cut-off on max(theta_i, theta_o)."""
    if isinstance(brdf, ProjectedBRDF):
        return brdf
    return project(brdf, statistic="median", grazing_cutoff_deg=grazing_cutoff_deg, grazing_angle="theta_io")


def white_sky_albedo(p: ProjectedBRDF, n_incidence: int = 9) -> np.ndarray:
    """Bihemispherical reflectance A per channel, shape (3,): the fraction of uniform white
    sky light reflected, ``A = 2 int_0^{pi/2} a(theta_i) cos(theta_i) sin(theta_i) d theta_i``
    with ``a`` the directional albedo of the projected table (:mod:`fit.projection.albedo`; midpoint
    rule, ``n_incidence`` nodes in theta_i; empty clusters count as 0)."""
    def ev(wi, wo):
        return np.nan_to_num(p.evaluate(wi, wo), nan=0.0)

    t = (np.arange(n_incidence) + 0.5) / n_incidence * (0.5 * np.pi)
    a = np.array([directional_albedo(ev, ti, n_theta=45, n_phi=180) for ti in t])
    w = 2.0 * np.cos(t) * np.sin(t) * (0.5 * np.pi / n_incidence)
    return (a * w[:, None]).sum(axis=0)


def channel_data(p: ProjectedBRDF, c: int, tol: float, intervals: str = "tol+spread",
                 floor_frac: float = 1.0, spread_k: float = 1.0,
                 theta_d_range_deg=(0.0, THETA_D_MAX_DEG), rho_ref: float | None = None,
                 partial_min_fraction: float | None = None, partial_factor: float = 2.0) -> ChannelData:
    """Clusters of channel ``c`` with ``theta_d`` in ``theta_d_range_deg`` and their intervals.

    The absolute floor is ``floor_frac * tol * rho_ref`` with ``rho_ref = A_Y / pi`` by default
    (A_Y: Rec.709 luminance of :func:`white_sky_albedo`), the value of the Lambertian that
    reflects as much uniform white sky light: below ``rho_ref`` the guarantee is an absolute
    error of at most ``tol * rho_ref`` (same in R, G, B), which changes the radiance reflected
    from a uniform white sky by at most ``tol * A_Y``.

    ``partial_min_fraction``: clusters that kept fewer than this fraction of their
    above-horizon phi_d samples (``p.n_phi_d``, 180 or 360, minus ``n_below_horizon``) after
    the grazing cut-off hold the median of a biased subset; their intervals are widened to at
    least ``[y / partial_factor, y * partial_factor]``.
    """
    th, td = np.meshgrid(p.theta_h, p.theta_d, indexing="ij")
    v = p.value[..., c]
    a, b = (np.deg2rad(float(x)) for x in theta_d_range_deg)
    ok = np.isfinite(v) & (td >= a - 1e-12) & (td <= b + 1e-12)
    y = np.maximum(v[ok], 0.0)
    if y.size == 0:
        raise ValueError("no finite cluster in the fitted domain")
    if rho_ref is None:
        rho_ref = float(LUMINANCE @ white_sky_albedo(p)) / np.pi
    if not rho_ref > 0:
        pos = y[y > 0]
        rho_ref = float(np.median(pos)) if pos.size else 1.0
    floor = floor_frac * tol * rho_ref
    if intervals == "tol":
        lo, hi = intervals_from_tolerance(y, tol, floor)
    elif intervals == "tol+spread":
        sd = np.sqrt(np.nan_to_num(p.variance[..., c][ok], nan=0.0))
        lo, hi = intervals_from_spread(y, sd, k=spread_k, abs_floor=floor, tol_min=tol)
    else:
        raise ValueError(f"intervals must be one of {INTERVALS}")
    if partial_min_fraction is not None:
        avail = (p.n_phi_d - p.n_below_horizon)[ok]
        partial = p.count[..., c][ok] < partial_min_fraction * avail
        lo = np.where(partial, np.minimum(lo, y / partial_factor), lo)
        hi = np.where(partial, np.maximum(hi, y * partial_factor), hi)
    # BRDF values are >= 0: a lower bound below -floor carries no information (and would make
    # the log transform undefined); clip it there.
    lo = np.maximum(lo, -floor)
    return ChannelData(np.stack([th[ok], td[ok]], axis=-1), y, lo, hi, floor)
