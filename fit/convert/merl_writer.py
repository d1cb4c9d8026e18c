"""Any :class:`fit.convert.source.Source` as a MERL-MIT table (written in the exact layout by
:func:`fit.formats.merl.write_merl`).

The table holds the source at the 90 x 90 x 180 bin centres of the MERL grid
(:mod:`fit.formats.grid`, phi_h = 0). Bins whose light or view direction lies at or below the
tangent plane -- or within ``horizon_margin_deg`` of it (default 1 deg), where a source that
stores f cos(theta) (an RGL file) divided by a cosine near 0 explodes -- are marked "no sample"
as the format does: stored as -1 (negative), never used by readers.

The phi_d fold. A MERL file has 180 phi_d bins over [0, pi): swapping light and view maps
phi_d to phi_d + pi, so one bin stands for both orientations of a pair (reciprocity). A
reciprocal source (a MERL file, a rational fit) loses nothing. A non-reciprocal one (an RGL
file: its tensors are indexed by the view direction) is tabulated at both orientations --
``f(wi, wo)`` at phi_d and ``f(wo, wi)`` at phi_d + pi, the 360-bin full-circle grid -- and
each bin stores their **mean**, the reciprocal part of the data; each orientation then differs
from the file by half the reciprocity difference ``|f(wi, wo) - f(wo, wi)| / mean``, which
:func:`tabulate_merl` measures over the valid bins and reports (:class:`FoldStats`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..formats.angles import half_diff_to_directions
from ..formats.colour import LUMINANCE
from ..formats.grid import (
    MERL_SHAPE,
    N_PHI_D,
    phi_d_centres,
    theta_d_centres,
    theta_h_centres,
)
from ..formats.measured import MeasuredBRDF, check_values
from .source import Source

#: Default margin above the horizon inside which bins are marked "no sample" (degrees).
HORIZON_MARGIN_DEG = 1.0
#: The fold's "core" statistics leave out bins with a direction beyond this angle (degrees).
CORE_THETA_DEG = 80.0
_CHUNK = 30  # theta_h rows per evaluation block (30 x 90 x 360 pairs)


@dataclass
class FoldStats:
    """What the phi_d fold did to a non-reciprocal source, over the bins it keeps.

    ``rel_max``, ``rel_rms``, ``rel_p99``: the reciprocity difference
    ``|f(wi, wo) - f(wo, wi)| / max(mean, floor)`` of the luminance (Rec.709), ``floor`` = 1 %
    of the 99th percentile of the mean (1/sr), over the ``n_bins`` valid bins; ``core_*``: the
    same over the bins whose two directions are within ``core_theta_deg`` (80 deg) of the
    normal (the grazing band, where the RGL-EPFL files extrapolate, left out). Each orientation
    of the source differs from the stored mean by half these numbers. All 0 for a reciprocal
    source (nothing is folded away).
    """

    reciprocal: bool
    n_bins: int = 0
    rel_max: float = 0.0
    rel_rms: float = 0.0
    rel_p99: float = 0.0
    core_theta_deg: float = CORE_THETA_DEG
    core_max: float = 0.0
    core_rms: float = 0.0
    core_p99: float = 0.0

    def describe(self) -> str:
        if self.reciprocal:
            return "phi_d fold: the source is reciprocal; nothing is lost by the fold"
        return (f"phi_d fold: the source is NOT reciprocal; each MERL bin stores the mean of the two "
                f"orientations (light, view) and (view, light). Their relative difference over the "
                f"{self.n_bins} valid bins: max {100 * self.rel_max:.1f} %, p99 {100 * self.rel_p99:.1f} %, "
                f"RMS {100 * self.rel_rms:.1f} %; with both directions within {self.core_theta_deg:g} deg of "
                f"the normal: max {100 * self.core_max:.1f} %, p99 {100 * self.core_p99:.1f} %, RMS "
                f"{100 * self.core_rms:.1f} % (each orientation is off by half of it)")


def _stats(rel):
    if rel.size == 0:
        return 0.0, 0.0, 0.0
    return float(rel.max()), float(np.sqrt(np.mean(rel ** 2))), float(np.percentile(rel, 99))


def bin_centre_directions(n_phi_d: int = N_PHI_D):
    """Light and view directions at the bin centres (phi_h = 0): two arrays
    ``(90, 90, n_phi_d, 3)``."""
    th = theta_h_centres()[:, None, None]
    td = theta_d_centres()[None, :, None]
    pd = phi_d_centres(n_phi_d)[None, None, :]
    return half_diff_to_directions(th, 0.0, td, pd)


def tabulate_merl(source: Source, horizon_margin_deg: float = HORIZON_MARGIN_DEG):
    """The MERL table of ``source``: ``(MeasuredBRDF with 180 phi_d bins, FoldStats)``.

    ``horizon_margin_deg`` in [0, 90): bins whose light or view direction is within this angle
    of the tangent plane are marked "no sample". Raises :class:`fit.errors.BRDFFileError`
    naming the source when a value is not finite or above :data:`fit.limits.MAX_BRDF_VALUE`.
    """
    wi, wo = bin_centre_directions(N_PHI_D)
    c_min = max(np.sin(np.radians(horizon_margin_deg)), 0.0)
    above = (wi[..., 2] > c_min) & (wo[..., 2] > c_min)
    a = np.zeros(MERL_SHAPE + (3,))
    if source.evaluate_angles is not None:
        # a function of (theta_h, theta_d) alone: one value per (theta_h, theta_d) bin
        rho = source.evaluate_angles(theta_h_centres()[:, None], theta_d_centres()[None, :])
        a[:] = np.asarray(rho, np.float64)[:, :, None, :]
    else:
        for i in range(0, MERL_SHAPE[0], _CHUNK):
            a[i:i + _CHUNK] = source.evaluate(wi[i:i + _CHUNK], wo[i:i + _CHUNK])
    stats = FoldStats(reciprocal=source.reciprocal)
    if not source.reciprocal:
        # the other orientation: phi_d + pi on the full-circle grid is exactly the swapped pair
        b = np.zeros_like(a)
        for i in range(0, MERL_SHAPE[0], _CHUNK):
            b[i:i + _CHUNK] = source.evaluate(wo[i:i + _CHUNK], wi[i:i + _CHUNK])
        ya, yb = a @ LUMINANCE, b @ LUMINANCE
        mean = 0.5 * (ya + yb)
        sel = above & np.isfinite(mean)
        if sel.any():
            floor = 0.01 * max(float(np.percentile(mean[sel], 99)), 1e-12)
            rel = np.abs(ya - yb) / np.maximum(mean, floor)
            c_core = np.cos(np.radians(CORE_THETA_DEG))
            core = sel & (wi[..., 2] >= c_core) & (wo[..., 2] >= c_core)
            stats = FoldStats(False, int(sel.sum()), *_stats(rel[sel]), CORE_THETA_DEG, *_stats(rel[core]))
        a = 0.5 * (a + b)
    valid = np.broadcast_to(above[..., None], a.shape).copy()
    values = np.where(valid, a, 0.0)
    check_values(values, valid, source.path)
    m = MeasuredBRDF(values=values, valid=valid, name=source.name, source=source.path)
    m.metadata.update({"converted_from": source.kind, "horizon_margin_deg": float(horizon_margin_deg)})
    return m, stats
