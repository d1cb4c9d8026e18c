"""The (theta_h, theta_d) projection of a measured BRDF as data: :class:`ProjectedBRDF` and its
``.npz`` file (format ``rbrdf-projected`` version 1, written atomically, read validated without
pickles), with the vocabulary of a projection, :data:`STATISTICS` and :data:`GRAZING_ANGLES`.
:func:`fit.projection.project.project` computes one from a
:class:`fit.formats.measured.MeasuredBRDF`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import BRDFFileError
from ..formats.angles import above_horizon, directions_to_half_diff
from ..formats.grid import N_PHI_D, PHI_D_BINS, theta_d_centres, theta_d_index, theta_h_centres, theta_h_index
from ..limits import MAX_BRDF_VALUE

#: The per-cluster statistics a projection can hold in ``ProjectedBRDF.value``.
STATISTICS = ("median", "mean", "geometric", "harmonic", "rms")
#: How a grazing cut-off is measured (:func:`fit.projection.project.grazing_mask`).
GRAZING_ANGLES = ("theta_io", "theta_d")


@dataclass
class ProjectedBRDF:
    """A BRDF projected onto the (theta_h, theta_d) plane: one statistic per cluster.

    Each (theta_h, theta_d) cluster gathers the valid samples of its ``n_phi_d`` phi_d bins:
    180 for a table folded by reciprocity, 360 for a full-circle table (both orders of every
    (light, view) pair, so the projection does not depend on the roles of the directions).

    Attributes
    ----------
    value : float64 (90, 90, 3)
        The representative value of each cluster (the ``statistic``; median by default),
        NaN where the cluster has no valid sample.
    median, mean, variance : float64 (90, 90, 3)
        Per-cluster median, arithmetic mean and population variance (NaN when empty).
    count : int (90, 90, 3)
        Number of valid samples in each cluster, per channel.
    n_below_horizon : int (90, 90)
        Number of phi_d triplets of each cluster (out of ``n_phi_d``) whose light or view
        direction is at or below the tangent plane (computed from geometry at bin centres).
    statistic : str
        Which statistic ``value`` holds.
    grazing_cutoff_deg : float or None
        If set, samples with max(theta_i, theta_o) (or theta_d, see ``grazing_angle``)
        above this angle were dropped before the statistics.
    n_phi_d : int
        phi_d bins per cluster of the projected table: 180 (folded) or 360 (full circle).
    """

    value: np.ndarray
    median: np.ndarray
    mean: np.ndarray
    variance: np.ndarray
    count: np.ndarray
    n_below_horizon: np.ndarray
    statistic: str = "median"
    grazing_cutoff_deg: float | None = None
    grazing_angle: str = "theta_io"
    name: str = "brdf"
    source: str = ""
    source_sha256: str = ""
    n_phi_d: int = N_PHI_D

    @property
    def theta_h(self) -> np.ndarray:
        """theta_h cluster centres (radians), shape (90,)."""
        return theta_h_centres()

    @property
    def theta_d(self) -> np.ndarray:
        """theta_d cluster centres (radians), shape (90,)."""
        return theta_d_centres()

    @property
    def normalized_variance(self) -> np.ndarray:
        """variance / mean**2 per cluster (NaN where the mean is 0 or the cluster empty)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            nv = self.variance / self.mean**2
        return np.where(np.isfinite(nv), nv, np.nan)

    def lookup(self, theta_h, theta_d) -> np.ndarray:
        """Nearest-cluster ``value`` for (theta_h, theta_d) in radians; empty clusters give 0."""
        i = theta_h_index(theta_h)
        j = theta_d_index(theta_d)
        v = self.value[np.broadcast_arrays(i, j)]
        return np.nan_to_num(v, nan=0.0)

    def evaluate(self, wi, wo) -> np.ndarray:
        """rho(wi, wo) in 1/sr from the projected table (nearest cluster); ``(..., 3)``."""
        wi = np.asarray(wi, float)
        wo = np.asarray(wo, float)
        th, _, td, _ = directions_to_half_diff(wi, wo)
        out = self.lookup(th, td)
        return np.where(above_horizon(*np.broadcast_arrays(wi, wo))[..., None], out, 0.0)

    # Persistence ------------------------------------------------------------------------
    def save(self, path) -> None:
        """Write an ``.npz`` with every array and the metadata (format ``rbrdf-projected/1``;
        ``n_phi_d`` is stored too; files without it are read as 180). Written to a temporary
        file renamed onto ``path`` when complete (:func:`fit.outputs.atomic_write`); the name is
        used as given (no ``.npz`` appended)."""
        from ..outputs import atomic_write

        with atomic_write(path, "wb") as f:
            np.savez_compressed(
                f, format="rbrdf-projected", version=1,
                value=self.value, median=self.median, mean=self.mean, variance=self.variance,
                count=self.count, n_below_horizon=self.n_below_horizon,
                theta_h=self.theta_h, theta_d=self.theta_d,
                statistic=self.statistic,
                grazing_cutoff_deg=np.nan if self.grazing_cutoff_deg is None else self.grazing_cutoff_deg,
                grazing_angle=self.grazing_angle, name=self.name, source=self.source,
                source_sha256=self.source_sha256, n_phi_d=int(self.n_phi_d),
            )

    @classmethod
    def load(cls, path) -> "ProjectedBRDF":
        """Read a file written by :meth:`save`, validated (:func:`read_projection`): a one-line
        :class:`BRDFFileError` if it is not one, is of the wrong shape or holds values that a
        projection cannot hold."""
        return cls(**read_projection(path))


_STAT_KEYS = ("value", "median", "mean", "variance")


def _npz_arrays(path, keys: dict) -> dict:
    """The arrays ``keys`` (name -> (shape, dtype kind(s))) of the ``.npz`` ``path``; every
    member's size and header are checked before its data are read (no allocation a corrupt or
    compressed-bomb file could inflate, no pickles)."""
    import struct
    import zipfile
    import zlib

    from ..inputs import check_regular_file
    from ..limits import MAX_NPZ_BYTES, MAX_NPZ_MEMBER_BYTES

    check_regular_file(path, MAX_NPZ_BYTES, "projected-BRDF file")
    out = {}
    try:
        with zipfile.ZipFile(path) as z:
            names = set(z.namelist())
            for key, (shape, kinds, optional) in keys.items():
                member = key + ".npy"
                if member not in names:
                    if optional:
                        continue
                    raise BRDFFileError(path, f"not an rbrdf projected-BRDF file (no array {key!r})")
                info = z.getinfo(member)
                if info.file_size > MAX_NPZ_MEMBER_BYTES:
                    raise BRDFFileError(path, f"array {key!r} is {info.file_size} bytes uncompressed, above "
                                              f"{MAX_NPZ_MEMBER_BYTES} (fit.limits.MAX_NPZ_MEMBER_BYTES)")
                with z.open(member) as f:
                    version = np.lib.format.read_magic(f)
                    if version == (1, 0):
                        shp, fortran, dtype = np.lib.format.read_array_header_1_0(f)
                    elif version == (2, 0):
                        shp, fortran, dtype = np.lib.format.read_array_header_2_0(f)
                    else:
                        raise BRDFFileError(path, f"array {key!r}: unsupported .npy version {version}")
                    if dtype.hasobject or dtype.kind not in kinds:
                        raise BRDFFileError(path, f"array {key!r} has dtype {dtype}, expected "
                                                  f"{'a number' if 'f' in kinds else 'an integer' if 'i' in kinds else 'text'}")
                    if tuple(shp) != tuple(shape):
                        raise BRDFFileError(path, f"array {key!r} has shape {list(shp)}, expected {list(shape)}")
                    count = int(np.prod(shp, dtype=object))
                    if count * dtype.itemsize > MAX_NPZ_MEMBER_BYTES:
                        raise BRDFFileError(path, f"array {key!r} is too large")
                    data = f.read(count * dtype.itemsize)
                    if len(data) != count * dtype.itemsize:
                        raise BRDFFileError(path, f"array {key!r} is truncated")
                    a = np.frombuffer(data, dtype=dtype).reshape(shp, order="F" if fortran else "C")
                out[key] = a
    except BRDFFileError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, struct.error, OSError, EOFError, ValueError,
            KeyError, NotImplementedError, RuntimeError) as e:
        raise BRDFFileError(path, f"cannot read projected BRDF ({e.__class__.__name__}: "
                                  f"{str(e).splitlines()[0] if str(e) else ''})") from None
    return out


def read_projection(path) -> dict:
    """The validated fields of a projected-BRDF ``.npz`` (format ``rbrdf-projected`` version 1)
    as keyword arguments of :class:`ProjectedBRDF`: statistics of shape (90, 90, 3), finite
    and >= 0 on every cluster with samples and NaN on every empty one, counts in
    [0, n_phi_d], ``n_phi_d`` 180 or 360, a known statistic and grazing angle, a cut-off in
    (0, 90] deg or none. :class:`BRDFFileError` naming the file and the array otherwise."""
    shp = (90, 90, 3)
    text = (), "U", False
    spec = {"format": text, "version": ((), "iu", False), "statistic": text, "grazing_angle": text,
            "name": text, "source": text, "source_sha256": text,
            "grazing_cutoff_deg": ((), "f", False), "n_phi_d": ((), "iu", True),
            "count": (shp, "iu", False), "n_below_horizon": ((90, 90), "iu", False)}
    spec.update({k: (shp, "f", False) for k in _STAT_KEYS})
    z = _npz_arrays(path, spec)

    def fail(problem):
        raise BRDFFileError(path, problem)

    if str(z["format"]) != "rbrdf-projected":
        fail("not an rbrdf projected-BRDF file")
    if int(z["version"]) != 1:
        fail(f"unsupported projected-BRDF version {int(z['version'])}")
    n_phi_d = int(z["n_phi_d"]) if "n_phi_d" in z else N_PHI_D
    if n_phi_d not in PHI_D_BINS:
        fail(f"array 'n_phi_d' is {n_phi_d}, expected one of {PHI_D_BINS}")
    statistic = str(z["statistic"])
    if statistic not in STATISTICS:
        fail(f"array 'statistic' is {statistic[:40]!r}, expected one of {', '.join(STATISTICS)}")
    angle = str(z["grazing_angle"])
    if angle not in GRAZING_ANGLES:
        fail(f"array 'grazing_angle' is {angle[:40]!r}, expected one of {', '.join(GRAZING_ANGLES)}")
    cut = float(z["grazing_cutoff_deg"])
    if not (np.isnan(cut) or 0.0 < cut <= 90.0):
        fail(f"array 'grazing_cutoff_deg' is {cut:g}, expected a cut-off in (0, 90] deg or NaN (none)")
    count = np.asarray(z["count"]).astype(np.int64)
    below = np.asarray(z["n_below_horizon"]).astype(np.int64)
    if count.min() < 0 or count.max() > n_phi_d:
        fail(f"array 'count' holds values outside [0, {n_phi_d}]")
    if below.min() < 0 or below.max() > n_phi_d:
        fail(f"array 'n_below_horizon' holds values outside [0, {n_phi_d}]")
    empty = count == 0
    if empty.all():
        fail("every cluster is empty: no projected value")
    stats = {}
    for k in _STAT_KEYS:
        a = np.asarray(z[k], np.float64)
        full = a[~empty]
        if not np.all(np.isfinite(full)):
            fail(f"array {k!r} holds NaN/inf on clusters with samples")
        if full.min() < 0 or full.max() > (MAX_BRDF_VALUE if k != "variance" else MAX_BRDF_VALUE ** 2):
            fail(f"array {k!r} holds values outside [0, {MAX_BRDF_VALUE:g}] on clusters with samples")
        if not np.all(np.isnan(a[empty])):
            fail(f"array {k!r} holds values on empty clusters (count 0), where NaN is expected")
        stats[k] = a.copy()
    return dict(stats, count=count.astype(np.int32), n_below_horizon=below.astype(np.int32),
                statistic=statistic, grazing_cutoff_deg=None if np.isnan(cut) else cut,
                grazing_angle=angle, name=str(z["name"]), source=str(z["source"]),
                source_sha256=str(z["source_sha256"]), n_phi_d=n_phi_d)
