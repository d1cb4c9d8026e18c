"""Projection of a 3-D measured BRDF onto the (theta_h, theta_d) plane.

Each (theta_h, theta_d) cluster gathers the valid samples of its phi_d bins and is
summarised by one statistic: 180 bins over [0, pi) for a table folded by reciprocity (MERL),
360 over [0, 2 pi) for a full-circle table (data from a non-reciprocal source, e.g. an RGL-EPFL
file). Bins ``k`` and ``k + 180`` of a full-circle table hold the two orders, (light, view) and
(view, light), of the same pairs, so its clusters gather both and the projection (and what is
fitted to it) does not depend on the roles of the two directions; the counts
(``count``, ``n_below_horizon``) are out of 360 there. The Rational BRDF method uses the
**median** (robust to outliers and acquisition artefacts); the arithmetic, geometric and
harmonic means and the root mean square are available for comparison. Invalid samples (no
measurement / below the horizon) are never used. Optionally, noisy grazing samples are dropped
first.
"""
from __future__ import annotations

import numpy as np

from ..formats.angles import cos_theta_i_o
from ..formats.grid import N_PHI_D, grid_shape, phi_d_centres, theta_d_centres, theta_h_centres
from ..formats.measured import MeasuredBRDF
from .projected import GRAZING_ANGLES, STATISTICS, ProjectedBRDF


def below_horizon_counts(n_phi_d: int = N_PHI_D) -> np.ndarray:
    """Per (theta_h, theta_d) cluster, the number of its ``n_phi_d`` (180 or 360) phi_d bin
    centres whose light or view direction is at or below the tangent plane (closed form, see
    :func:`fit.formats.angles.cos_theta_i_o`). Shape (90, 90), int. The full circle counts
    twice the folded grid: phi_d + pi swaps the two directions."""
    ci, co = _cos_io_grid(n_phi_d)
    return np.sum((ci <= 0.0) | (co <= 0.0), axis=-1)


def _cos_io_grid(n_phi_d: int = N_PHI_D):
    th = theta_h_centres()[:, None, None]
    td = theta_d_centres()[None, :, None]
    pd = phi_d_centres(n_phi_d)[None, None, :]
    return cos_theta_i_o(th, td, pd)


def grazing_mask(cutoff_deg: float, angle: str = "theta_io", n_phi_d: int = N_PHI_D) -> np.ndarray:
    """Boolean (90, 90, n_phi_d), n_phi_d = 180 or 360: True for the triplets to *keep* under
    a grazing cut-off.

    ``angle="theta_io"`` drops triplets where the light or the view is more than
    ``cutoff_deg`` from the normal (the usual MERL practice); ``angle="theta_d"`` drops whole
    clusters with theta_d above the cut-off.
    """
    if angle not in GRAZING_ANGLES:
        raise ValueError(f"grazing angle must be one of {GRAZING_ANGLES}, got {angle!r}")
    c = np.cos(np.radians(cutoff_deg))
    if angle == "theta_io":
        ci, co = _cos_io_grid(n_phi_d)
        return (ci >= c) & (co >= c)
    td = theta_d_centres()[None, :, None]
    return np.broadcast_to(td <= np.radians(cutoff_deg), grid_shape(n_phi_d)).copy()


def project(brdf: MeasuredBRDF, statistic: str = "median",
            grazing_cutoff_deg: float | None = None, grazing_angle: str = "theta_io") -> ProjectedBRDF:
    """Project ``brdf`` onto (theta_h, theta_d), over its 180 (folded) or 360 (full-circle)
    phi_d bins (``ProjectedBRDF.n_phi_d``).

    Parameters
    ----------
    statistic : one of ``"median"`` (default), ``"mean"``, ``"geometric"``, ``"harmonic"``,
        ``"rms"``; stored in ``ProjectedBRDF.value``. Median, mean and variance are always
        computed too.
    grazing_cutoff_deg : drop samples beyond this angle (degrees) before the statistics;
        None keeps all valid samples.
    grazing_angle : ``"theta_io"`` or ``"theta_d"``, see :func:`grazing_mask`.

    Empty clusters get NaN statistics and ``count == 0``.
    """
    if statistic not in STATISTICS:
        raise ValueError(f"statistic must be one of {STATISTICS}, got {statistic!r}")
    n_phi_d = brdf.n_phi_d
    valid = brdf.valid
    if grazing_cutoff_deg is not None:
        valid = valid & grazing_mask(grazing_cutoff_deg, grazing_angle, n_phi_d)[..., None]
    # (theta_h, theta_d, channel, phi_d): the reduction axis last and contiguous.
    x = np.moveaxis(np.where(valid, brdf.values, np.nan), 2, 3)
    v = np.moveaxis(valid, 2, 3)
    count = v.sum(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        n = np.where(count > 0, count, 1)
        xs = np.sort(x, axis=-1)  # NaNs sort last
        lo = np.take_along_axis(xs, ((n - 1) // 2)[..., None], axis=-1)[..., 0]
        hi = np.take_along_axis(xs, (n // 2)[..., None], axis=-1)[..., 0]
        median = 0.5 * (lo + hi)
        x0 = np.where(v, x, 0.0)
        total = x0.sum(axis=-1)
        mean = total / n
        dev = np.where(v, x - mean[..., None], 0.0)  # two-pass: no cancellation
        variance = (dev * dev).sum(axis=-1) / n
        stats = {"median": median, "mean": mean}
        if statistic == "geometric":
            logs = np.where(v, np.log(np.where(v, x, 1.0)), 0.0)
            stats["geometric"] = np.exp(logs.sum(axis=-1) / n)
        elif statistic == "harmonic":
            inv = np.where(v, 1.0 / np.where(v, x, 1.0), 0.0)
            stats["harmonic"] = np.where(np.isinf(inv).any(axis=-1), 0.0, n / inv.sum(axis=-1))
        elif statistic == "rms":
            stats["rms"] = np.sqrt((x0 * x0).sum(axis=-1) / n)
    empty = count == 0
    median, mean, variance = (np.where(empty, np.nan, a) for a in (median, mean, variance))
    value = np.where(empty, np.nan, stats[statistic])
    return ProjectedBRDF(
        value=value, median=median, mean=mean, variance=variance, count=count.astype(np.int32),
        n_below_horizon=below_horizon_counts(n_phi_d).astype(np.int32), statistic=statistic,
        grazing_cutoff_deg=grazing_cutoff_deg, grazing_angle=grazing_angle,
        name=brdf.name, source=brdf.source, source_sha256=brdf.source_sha256, n_phi_d=n_phi_d,
    )
