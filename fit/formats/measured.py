"""The in-memory measured BRDF on the MERL (theta_h, theta_d, phi_d) grid.

:class:`MeasuredBRDF` holds a BRDF tabulated on the MERL-MIT grid (:mod:`fit.formats.grid`:
90 x 90 bins in theta_h, theta_d times 180 phi_d bins over [0, pi), folded by reciprocity, for
MERL files, or 360 over [0, 2 pi), not folded, for data from a non-reciprocal source such as an
RGL-EPFL file); :func:`check_values` refuses values no BRDF can hold; :func:`file_sha256`
fingerprints source files. Its projection onto the (theta_h, theta_d) clusters is
:class:`fit.projection.projected.ProjectedBRDF`.

Values are RGB reflectance in 1/sr, *without* the cosine factor (conventions.md).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import BRDFFileError
from ..limits import MAX_BRDF_VALUE
from .angles import above_horizon, directions_to_half_diff, half_diff_to_directions
from .grid import (
    INTERPOLATIONS,
    N_PHI_D,
    PHI_D_BINS,
    grid_shape,
    n_phi_d_for,
    phi_d_centres,
    phi_d_index,
    theta_d_centres,
    theta_d_index,
    theta_h_centres,
    theta_h_index,
    trilinear_corners,
)

#: Value of a bin without a sample in :attr:`MeasuredBRDF.kernel_table` (valid values are >= 0).
NO_SAMPLE = -1.0


def _read(table, valid, theta_h, theta_d, phi_d, n_phi_d, interpolation):
    """``table`` (90, 90, n_phi_d, 3) read at Rusinkiewicz angles: nearest bin, or trilinear
    over the bins where ``valid`` (None: every bin), weights renormalised per channel."""
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}")
    if interpolation == "nearest":
        i, j, k = np.broadcast_arrays(theta_h_index(theta_h), theta_d_index(theta_d),
                                      phi_d_index(phi_d, n_phi_d))
        return table[i, j, k]
    i, j, k, w = trilinear_corners(theta_h, theta_d, phi_d, n_phi_d)
    corners = table[i, j, k]                               # (..., 8, 3)
    if valid is None:
        return np.einsum("...c,...cr->...r", w, corners)
    wv = w[..., None] * valid[i, j, k]                     # (..., 8, 3)
    s = wv.sum(-2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(s > 0.0, (wv * corners).sum(-2) / np.where(s > 0.0, s, 1.0), 0.0)


@dataclass
class MeasuredBRDF:
    """An isotropic RGB BRDF tabulated on the MERL (theta_h, theta_d, phi_d) grid.

    The number of phi_d bins, ``n_phi_d = values.shape[2]``, says whether the table is
    folded by reciprocity (:mod:`fit.formats.grid`):

    * 180 (:attr:`reciprocal` True; MERL files, whose format defines the fold): phi_d in
      [0, pi); (wi, wo) and (wo, wi) share a bin.
    * 360 (:attr:`reciprocal` False; data resampled from a non-reciprocal source, e.g.
      :meth:`fit.formats.rgl.RGLBRDF.to_measured`): phi_d in [0, 2 pi), no fold; (wi, wo) in
      bin ``k``, (wo, wi) in bin ``(k + 180) % 360``.

    Attributes
    ----------
    values : float64 array (90, 90, n_phi_d, 3), n_phi_d = 180 or 360
        Reflectance in 1/sr, channel scales already applied. Entries where ``valid`` is
        False hold 0 and are never used by statistics.
    valid : bool array, same shape as ``values``
        True where the bin holds a measured sample (False: no sample / below horizon).
    name : str
        Material name (file stem by default).
    source : str
        Path of the file it was read from ("" if built in memory).
    source_sha256 : str
        sha256 of the source file's bytes ("" if built in memory).
    weighted, weighted_by : float64 array like ``values`` and ``"light"`` / ``"view"``, or None
        A source that stores f * cos(theta_x) (an RGL file: x is the direction that is *not*
        the tensors' incident one) can also give that smooth quantity at every bin centre
        (``weighted``; bins whose centre dips below the horizon get its grazing value).
        :meth:`evaluate` then returns ``weighted`` (read as ``interpolation`` says) divided by
        the pair's *own* cosine, so rho * cos(theta_x) is the table's f cos exactly: no 1 / cos of a bin
        centre near the horizon is multiplied by another direction's cosine (a line of
        pixels 10-20 % too dark along each bright light's terminator otherwise), and no bin
        straddling the horizon reads 0. ``values`` (rho at the centres) stays what the
        projection and the fits use.
    """

    values: np.ndarray
    valid: np.ndarray
    name: str = "brdf"
    source: str = ""
    source_sha256: str = ""
    metadata: dict = field(default_factory=dict)
    weighted: np.ndarray | None = None
    weighted_by: str | None = None

    def __post_init__(self):
        self.values = np.asarray(self.values, dtype=np.float64)
        self.valid = np.asarray(self.valid, dtype=bool)
        shapes = [grid_shape(n) + (3,) for n in PHI_D_BINS]
        if self.values.shape not in shapes:
            raise BRDFFileError(self.source or None, f"values must have shape {' or '.join(map(str, shapes))}, "
                                                     f"got {self.values.shape}")
        if self.valid.shape != self.values.shape:
            raise BRDFFileError(self.source or None, "valid mask shape differs from values shape")
        self.values = np.where(self.valid, self.values, 0.0)
        if self.weighted is not None:
            self.weighted = np.asarray(self.weighted, dtype=np.float64)
            if self.weighted.shape != self.values.shape or self.weighted_by not in ("light", "view"):
                raise BRDFFileError(self.source or None, "weighted table: shape of values and "
                                                         "weighted_by 'light' or 'view' expected")

    # Bin-centre coordinates -------------------------------------------------------------
    @property
    def theta_h(self) -> np.ndarray:
        """theta_h bin centres (radians), shape (90,)."""
        return theta_h_centres()

    @property
    def theta_d(self) -> np.ndarray:
        """theta_d bin centres (radians), shape (90,)."""
        return theta_d_centres()

    @property
    def n_phi_d(self) -> int:
        """Number of phi_d bins: 180 (folded by reciprocity) or 360 (full circle)."""
        return int(self.values.shape[2])

    @property
    def reciprocal(self) -> bool:
        """True when phi_d is folded into [0, pi) by reciprocity (180 bins, MERL files);
        False for a full-circle table (360 bins, data from a non-reciprocal source)."""
        return self.n_phi_d == N_PHI_D

    @property
    def phi_d(self) -> np.ndarray:
        """phi_d bin centres (radians): shape (180,) in [0, pi) or (360,) in [0, 2 pi)."""
        return phi_d_centres(self.n_phi_d)

    @property
    def valid_fraction(self) -> float:
        return float(self.valid.mean())

    # Evaluation -------------------------------------------------------------------------
    def lookup(self, theta_h, theta_d, phi_d, interpolation: str = "linear") -> np.ndarray:
        """``values`` at Rusinkiewicz angles (radians); shape ``broadcast(...) + (3,)``.

        ``phi_d`` is folded into [0, pi) when the table is :attr:`reciprocal`, else wrapped into
        [0, 2 pi). ``interpolation``: ``"linear"`` (default), trilinear between the 8 bin
        centres around the point (:func:`fit.formats.grid.trilinear_corners`), bins without a
        sample left out and the weights of the others renormalised (0 where none has one);
        ``"nearest"``, the bin the point falls in (the MERL reference code's lookup; bins
        without a sample return 0).
        """
        return _read(self.values, self.valid, theta_h, theta_d, phi_d, self.n_phi_d, interpolation)

    def evaluate(self, wi, wo, interpolation: str = "linear") -> np.ndarray:
        """rho(wi, wo) in 1/sr with the MERL conventions, read between the bin centres as
        ``interpolation`` says (:meth:`lookup`: ``"linear"`` or ``"nearest"``).

        ``wi`` (towards the light), ``wo`` (towards the viewer): unit vectors ``(..., 3)`` in the
        local frame; phi_d is that of ``wi`` in the half-vector frame
        (:func:`fit.formats.angles.directions_to_half_diff`), so on a full-circle table
        ``evaluate(wi, wo)`` and ``evaluate(wo, wi)`` read different bins. Returns ``(..., 3)``;
        0 where either direction is at or below the tangent plane. With a ``weighted`` table,
        ``weighted`` is read the same way and divided by the pair's own cos(theta_x).
        """
        wi = np.asarray(wi, float)
        wo = np.asarray(wo, float)
        th, _, td, pd = directions_to_half_diff(wi, wo)
        above = above_horizon(*np.broadcast_arrays(wi, wo))[..., None]
        if self.weighted is None:
            return np.where(above, self.lookup(th, td, pd, interpolation), 0.0)
        v = _read(self.weighted, None, th, td, pd, self.n_phi_d, interpolation)
        cos_x = np.broadcast_arrays(wi, wo)[0 if self.weighted_by == "light" else 1][..., 2:3]
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(above, v / np.where(above, cos_x, 1.0), 0.0)

    @property
    def kernel_table(self) -> tuple:
        """``(table, divide_by)`` for the renderer: ``values`` with its bins without a sample
        set to -1 (:data:`NO_SAMPLE`, so that an interpolating lookup can leave them out) and 0,
        or ``weighted`` (every bin filled) and the direction whose cosine divides it (1: the
        light, 2: the view)."""
        if self.weighted is None:
            return np.where(self.valid, self.values, NO_SAMPLE), 0
        return np.maximum(self.weighted, 0.0), 1 if self.weighted_by == "light" else 2

    @classmethod
    def from_function(cls, func, name: str = "analytic", reciprocal: bool = True) -> "MeasuredBRDF":
        """Tabulate ``func(wi_light, wo_view) -> (..., 3)`` at the bin centres (phi_h = 0).

        ``reciprocal=True`` (default): the MERL grid, 90 x 90 x 180 over phi_d in [0, pi)
        (right only if ``func`` is reciprocal); ``False``: 90 x 90 x 360 over [0, 2 pi), no
        fold. Triplets whose light or view direction is at or below the horizon are marked
        invalid, as in measured MERL files.
        """
        n = n_phi_d_for(reciprocal)
        th = theta_h_centres()[:, None, None]
        td = theta_d_centres()[None, :, None]
        pd = phi_d_centres(n)[None, None, :]
        wi, wo = half_diff_to_directions(th, 0.0, td, pd)
        vals = np.asarray(func(wi, wo), dtype=np.float64)
        vals = np.broadcast_to(vals, grid_shape(n) + (3,)).copy()
        valid = np.broadcast_to(above_horizon(wi, wo)[..., None], vals.shape).copy()
        return cls(values=vals, valid=valid, name=name)


def check_values(values: np.ndarray, valid: np.ndarray, path=None, max_value: float | None = MAX_BRDF_VALUE) -> None:
    """Refuse measured values that cannot be a BRDF: :class:`BRDFFileError` naming ``path``
    when a valid value is NaN, infinite, negative or above ``max_value``
    (:data:`fit.limits.MAX_BRDF_VALUE` 1/sr by default; None: no bound), or when a channel has
    no valid sample at all (a projection and a fit of it would be all NaN). ``values``,
    ``valid``: (..., 3)."""
    for c, ch in enumerate("RGB"):
        ok = valid[..., c]
        if not ok.any():
            raise BRDFFileError(path, f"no valid sample in channel {ch} (every value is marked "
                                      "'no sample'); nothing to fit or render")
        v = values[..., c][ok]
        if not np.all(np.isfinite(v)):
            raise BRDFFileError(path, f"{int((~np.isfinite(v)).sum())} NaN/inf values in channel {ch}")
        hi = float(v.max())
        if max_value is not None and hi > max_value:
            raise BRDFFileError(path, f"absurd BRDF value {hi:.4g} 1/sr in channel {ch} (above "
                                      f"{max_value:g}, fit.limits.MAX_BRDF_VALUE): corrupt data")
        if float(v.min()) < 0:
            raise BRDFFileError(path, f"negative BRDF value {float(v.min()):.4g} 1/sr in channel {ch}")


def file_sha256(path) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(Path(path), "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()
