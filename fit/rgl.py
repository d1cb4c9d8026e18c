"""RGL-EPFL measured BRDFs (``.bsdf`` tensor files, Dupuy & Jakob 2018).

The RGL-EPFL material database stores each material in a *tensor file*: a small binary
container of named n-dimensional arrays. This module reads it defensively and evaluates the
BRDF with the semantics of the authors' reference loader ("powitacq", rgl-epfl/brdf-loader,
and Mitsuba's ``measured`` plugin), vectorized with NumPy.

Container layout (little endian)::

    12 bytes  magic  b"tensor_file\\0"
     2 bytes  version (major, minor) = (1, 0)
     u32      number of fields
    per field:
     u16      name length, then the name (UTF-8)
     u16      ndim
     u8       dtype code (1 u8, 2 i8, 3 u16, 4 i16, 5 u32, 6 i32, 7 u64, 8 i64, 9 f16, 10 f32, 11 f64)
     u64      byte offset of the data in the file
     ndim x u64  shape (C order, last axis contiguous)

Fields of an isotropic RGB material: ``description`` (u8 text), ``phi_i`` (1), ``theta_i``
(n_theta, radians), ``ndf`` and ``sigma`` (2-D tables over (phi, sqrt-theta)), ``vndf``
(1, n_theta, ny, nx), ``luminance`` (1, n_theta, n, n), ``rgb`` (1, n_theta, 3, n, n),
``jacobian`` (u8 flag) and ``valid`` (bit-packed u8 mask, not used by the evaluation).

Evaluation (what :meth:`RGLBRDF.evaluate` computes), for wi (light) and wo (view) above the
tangent plane:

1. ``wm = normalize(wi + wo)``; ``u_wi = (sqrt(2 theta_i / pi), (phi_i + pi) / 2pi)`` and
   ``u_wm = (sqrt(2 theta_m / pi), frac((phi_m - phi_i + pi) / 2pi))``.
2. The VNDF warp of the incidence ``theta_i`` (a marginal/conditional warp built from the
   ``vndf`` table, with its CDFs linearly interpolated between the two nearest ``theta_i``
   slices) is inverted at ``u_wm``: this gives the 2-D coordinate ``s`` in [0, 1]^2 of the
   ``rgb`` table. (The ``luminance`` warp is only used for importance sampling; the reference
   evaluation does not invert it, nor does this one.)
3. ``rgb`` is interpolated bilinearly at ``s`` and linearly in ``theta_i``.
4. If the ``jacobian`` flag is set, the value is multiplied by ``ndf(u_wm) / (4 sigma(u_wi))``
   (bilinear look-ups of the raw tables). The result is the reference's ``eval``:
   ``f_r(wi, wo) * cos(theta_o)``.
5. rho = that value divided by ``cos(theta_o)`` (our convention: the BRDF *without* cosine).

Negative ``rgb`` entries (measurement noise, down to about -0.04) are clamped to 0 when the
file is read (conventions.md); the reference instead clamps after interpolation. Both give
non-negative values; they differ only next to clamped entries.

Incidence beyond the last measured angle: these files store a last ``theta_i`` slice at
90 deg whose ``rgb`` is a copy of the previous (last measured) slice, e.g. 78.5 deg
(:attr:`RGLBRDF.theta_i_max`). Between ``theta_i_max`` and 90 deg the ``rgb`` values therefore
stay those of the last measured incidence at the same warped coordinate ``s`` (clamped
interpolation), while the VNDF warp, ``ndf`` and ``sigma`` continue to vary; the result is an
extrapolation, not a measurement.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import BRDFFileError

MAGIC = b"tensor_file\x00"
#: dtype codes of the tensor_file format
DTYPES = {1: "u1", 2: "i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<u8", 8: "<i8",
          9: "<f2", 10: "<f4", 11: "<f8"}
_CODES = {np.dtype(v).str: k for k, v in DTYPES.items()}
_CODES[np.dtype("u1").str] = 1
_CODES[np.dtype("i1").str] = 2

#: Files larger than this are refused (RGB RGL files are about 0.6-5 MB).
MAX_FILE_BYTES = 256 << 20
MAX_FIELDS = 4096
MAX_NDIM = 16
#: Evaluation tables are built from these fields; the others are optional.
REQUIRED_FIELDS = ("description", "phi_i", "theta_i", "ndf", "sigma", "vndf", "luminance",
                   "rgb", "jacobian")
_HALF_PI = 0.5 * np.pi
_CHUNK = 1 << 15


# ----------------------------------------------------------------------------------------
# Container
# ----------------------------------------------------------------------------------------
@dataclass
class TensorField:
    """One array of a tensor file (``data`` is a read-only view of the file's bytes)."""

    name: str
    dtype_code: int
    offset: int
    shape: tuple
    data: np.ndarray


def parse_tensor_file(buf: bytes, path=None) -> dict[str, TensorField]:
    """Parse the bytes of a tensor file; every problem is a one-line :class:`BRDFFileError`.

    All offsets and sizes are checked against ``len(buf)`` before any array is made, and the
    arrays are views into ``buf`` (no allocation that the file's header could inflate).
    """
    size = len(buf)

    def fail(problem):
        raise BRDFFileError(path, problem)

    if size < len(MAGIC) + 6:
        if size >= 1 and not MAGIC.startswith(bytes(buf[:len(MAGIC)])):
            fail("not an RGL tensor file (bad magic; expected 'tensor_file\\0')")
        fail(f"truncated RGL tensor file: {size} bytes, the header alone needs 18")
    if bytes(buf[:12]) != MAGIC:
        fail("not an RGL tensor file (bad magic; expected 'tensor_file\\0')")
    major, minor = buf[12], buf[13]
    if (major, minor) != (1, 0):
        fail(f"unsupported tensor file version {major}.{minor} (only 1.0 is known)")
    (n_fields,) = struct.unpack_from("<I", buf, 14)
    if n_fields > MAX_FIELDS:
        fail(f"corrupt field table: {n_fields} fields declared (at most {MAX_FIELDS} expected)")

    pos = 18
    entries = []

    def need(nbytes, what):
        if pos + nbytes > size:
            fail(f"truncated RGL tensor file: field table ends inside {what} "
                 f"(needs byte {pos + nbytes}, file has {size})")

    for i in range(n_fields):
        need(2, f"the name length of field #{i}")
        (name_len,) = struct.unpack_from("<H", buf, pos)
        pos += 2
        need(name_len, f"the name of field #{i}")
        raw = bytes(buf[pos:pos + name_len])
        pos += name_len
        try:
            name = raw.decode("utf-8")
        except UnicodeDecodeError:
            fail(f"corrupt field table: field #{i} has a name that is not UTF-8 ({raw[:20]!r})")
        need(11, f"the header of field {name!r}")
        ndim, code, offset = struct.unpack_from("<HBQ", buf, pos)
        pos += 11
        if code not in DTYPES:
            fail(f"unknown dtype code {code} in field {name!r} (known: 1-11)")
        if ndim > MAX_NDIM:
            fail(f"absurd shape in field {name!r}: {ndim} dimensions (truncated or corrupt field table)")
        need(8 * ndim, f"the shape of field {name!r}")
        shape = struct.unpack_from(f"<{ndim}Q", buf, pos)
        pos += 8 * ndim
        if name in (e[0] for e in entries):
            fail(f"corrupt field table: field {name!r} appears twice")
        entries.append((name, ndim, code, offset, shape))

    header_end = pos
    fields = {}
    for name, ndim, code, offset, shape in entries:
        dtype = np.dtype(DTYPES[code])
        count = 1
        for s in shape:
            count *= int(s)  # Python ints: no overflow
        nbytes = count * dtype.itemsize
        if nbytes > size:
            fail(f"field {name!r} of shape {list(shape)} needs {nbytes} bytes but the file has "
                 f"{size} (truncated file or absurd shape)")
        if offset < header_end or offset > size or offset + nbytes > size:
            fail(f"field {name!r}: data at bytes [{offset}, {offset + nbytes}) lies outside the "
                 f"data area [{header_end}, {size}) (wrong offset or truncated file)")
        arr = np.frombuffer(buf, dtype=dtype, count=count, offset=offset).reshape(shape)
        fields[name] = TensorField(name, code, offset, tuple(int(s) for s in shape), arr)
    return fields


def read_tensor_file(path) -> dict[str, TensorField]:
    """Read and parse a tensor file (see :func:`parse_tensor_file`)."""
    buf = _read_bytes(path)
    return parse_tensor_file(buf, path)


def _read_bytes(path) -> bytes:
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise BRDFFileError(path, f"file is {size} bytes; RGL RGB files this large "
                                      f"(> {MAX_FILE_BYTES} bytes) are not supported")
        with open(path, "rb") as f:
            return f.read(MAX_FILE_BYTES + 1)
    except BRDFFileError:
        raise
    except OSError as e:
        raise BRDFFileError(path, f"cannot read file ({e.strerror or e})") from None


def write_tensor_file(path, fields: dict) -> None:
    """Write ``{name: array}`` as a tensor file (version 1.0, data 8-byte aligned).

    Used by the tests to build valid and hostile variants of real files.
    """
    items = [(str(k), np.ascontiguousarray(v)) for k, v in fields.items()]
    header = bytearray(MAGIC + bytes([1, 0]) + struct.pack("<I", len(items)))
    for name, arr in items:
        nm = name.encode("utf-8")
        header += struct.pack("<H", len(nm)) + nm + struct.pack("<HBQ", arr.ndim, 0, 0)
        header += struct.pack(f"<{arr.ndim}Q", *arr.shape)
    pos = (len(header) + 7) // 8 * 8
    blobs, offsets = [], []
    for _, arr in items:
        offsets.append(pos)
        b = arr.astype(arr.dtype.newbyteorder("<"), copy=False).tobytes()
        blobs.append(b + bytes((-len(b)) % 8))
        pos += len(blobs[-1])
    # patch dtype codes and offsets into the header
    p = 18
    for (name, arr), off in zip(items, offsets):
        nm_len = len(name.encode("utf-8"))
        p += 2 + nm_len
        code = _CODES.get(arr.dtype.newbyteorder("<").str) or _CODES.get(arr.dtype.str)
        if code is None:
            raise ValueError(f"dtype {arr.dtype} of field {name!r} has no tensor_file code")
        struct.pack_into("<HBQ", header, p, arr.ndim, code, off)
        p += 11 + 8 * arr.ndim
    out = bytes(header) + bytes((-len(header)) % 8) + b"".join(blobs)
    Path(path).write_bytes(out)


# ----------------------------------------------------------------------------------------
# Interpolants (vectorized re-implementation of the reference's Marginal2D)
# ----------------------------------------------------------------------------------------
def _interval(values: np.ndarray, x: np.ndarray):
    """Reference ``find_interval`` over a sorted parameter axis, with the linear weight.

    Returns ``(i0, w1)``: the left index clamped to [0, n-2] and the weight of ``i0 + 1``
    clamped to [0, 1] (clamped interpolation outside the axis). For n == 1: (0, 0).
    """
    n = values.size
    if n == 1:
        return np.zeros(x.shape, np.intp), np.zeros(x.shape)
    i0 = np.searchsorted(values[1:-1], x, side="right")
    p0 = values[i0]
    p1 = values[i0 + 1]
    w1 = np.clip((x - p0) / (p1 - p0), 0.0, 1.0)
    return i0, w1


def _patch(u: np.ndarray, n: int):
    """Cell index in [0, n-2] and fractional position for a coordinate u in [0, 1]."""
    x = u * (n - 1)
    i = np.minimum(np.maximum(x, 0.0).astype(np.intp), n - 2)
    return i, x - i


class _Bilinear:
    """Plain bilinear interpolant of a 2-D table (reference ``Marginal2D<0>`` without CDF)."""

    def __init__(self, table: np.ndarray):
        t = np.asarray(table, np.float64)
        self.ny, self.nx = t.shape
        self.corners = np.ascontiguousarray(
            np.stack([t[:-1, :-1], t[:-1, 1:], t[1:, :-1], t[1:, 1:]], axis=-1)
        ).reshape(-1, 4)

    def eval(self, ux, uy):
        ix, fx = _patch(ux, self.nx)
        iy, fy = _patch(uy, self.ny)
        c = np.take(self.corners, iy * (self.nx - 1) + ix, axis=0)
        a = c[:, 0] + fx * (c[:, 1] - c[:, 0])
        b = c[:, 2] + fx * (c[:, 3] - c[:, 2])
        return a + fy * (b - a)


class _VNDFWarp:
    """Marginal/conditional warp of 2-D densities, conditioned on theta_i (reference
    ``Marginal2D<2>`` with one phi_i slice): per-slice CDFs, linear interpolation of every
    looked-up quantity between the two nearest theta_i slices."""

    def __init__(self, data: np.ndarray, theta: np.ndarray, path=None):
        d = np.asarray(data, np.float64)  # (S, ny, nx)
        self.S, self.ny, self.nx = d.shape
        self.theta = np.asarray(theta, np.float64)
        cond = np.zeros_like(d)
        cond[:, :, 1:] = np.cumsum(0.5 * (d[:, :, 1:] + d[:, :, :-1]), axis=2)
        rows = cond[:, :, -1]
        marg = np.zeros((self.S, self.ny))
        marg[:, 1:] = np.cumsum(0.5 * (rows[:, 1:] + rows[:, :-1]), axis=1)
        total = marg[:, -1]
        bad = ~(np.isfinite(total) & (total > 0))
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise BRDFFileError(path, f"vndf slice theta_i[{k}] has no positive finite mass; "
                                      "cannot build its warp")
        norm = (1.0 / total)[:, None, None]
        d = d * norm
        cond = cond * norm
        marg = marg * norm[:, :, 0]
        rows = cond[:, :, -1]
        self.data = d
        self.cond = cond
        self.marg = marg
        # Per patch: v00 v10 v01 v11, cond(y,x) cond(y+1,x), row totals r(y) r(y+1), marg(y)
        S, ny, nx = self.S, self.ny, self.nx
        tab = np.empty((S, ny - 1, nx - 1, 9))
        tab[..., 0] = d[:, :-1, :-1]
        tab[..., 1] = d[:, :-1, 1:]
        tab[..., 2] = d[:, 1:, :-1]
        tab[..., 3] = d[:, 1:, 1:]
        tab[..., 4] = cond[:, :-1, :-1]
        tab[..., 5] = cond[:, 1:, :-1]
        tab[..., 6] = rows[:, :-1, None]
        tab[..., 7] = rows[:, 1:, None]
        tab[..., 8] = marg[:, :-1, None]
        self.table = tab.reshape(-1, 9)
        self.slice_stride = (ny - 1) * (nx - 1) if S > 1 else 0

    def invert(self, ux, uy, t0, w1):
        """Inverse warp of points (ux, uy) of the unit square; returns (sx, sy, pdf)."""
        ix, fx = _patch(ux, self.nx)
        iy, fy = _patch(uy, self.ny)
        k = (t0 * (self.ny - 1) + iy) * (self.nx - 1) + ix
        g = np.take(self.table, k, axis=0)
        if self.slice_stride:
            g1 = np.take(self.table, k + self.slice_stride, axis=0)
            g += w1[:, None] * (g1 - g)
        v00, v10, v01, v11, cc0, cc1, r0, r1, m0 = g.T
        gy = 1.0 - fy
        c0 = gy * v00 + fy * v01
        c1 = gy * v10 + fy * v11
        pdf = c0 + fx * (c1 - c0)
        rr = gy * r0 + fy * r1
        sx = (fx * (c0 + 0.5 * fx * (c1 - c0)) + gy * cc0 + fy * cc1) / rr
        sy = fy * (r0 + 0.5 * fy * (r1 - r0)) + m0
        return sx, sy, pdf * ((self.nx - 1) * (self.ny - 1))

    # -- forward warp (used by the tests and for sampling) ------------------------------
    def _lerp(self, arr, t0, w1, *index):
        a = arr[(t0,) + index]
        if self.S > 1:
            a = a + w1 * (arr[(t0 + 1,) + index] - a)
        return a

    def sample(self, sx, sy, t0, w1):
        """Forward warp (reference ``Marginal2D::sample``): points of the unit square ->
        (ux, uy, pdf). Vectorized with O(N * (nx + ny)) work; meant for tests and sampling."""
        eps = 1.0 - np.float32(0.999999940395355225)
        sx = np.clip(np.asarray(sx, float), eps, 1.0 - eps)
        sy = np.clip(np.asarray(sy, float), eps, 1.0 - eps)
        t0 = np.asarray(t0)
        w1 = np.asarray(w1, float)
        ny, nx = self.ny, self.nx
        # row: marginal CDF (interpolated across slices) < sy, counted over 1..ny-2
        m = self.marg[t0]
        if self.S > 1:
            m = m + w1[:, None] * (self.marg[t0 + 1] - m)
        row = np.clip(np.sum(m[:, 1:ny - 1] < sy[:, None], axis=1), 0, ny - 2)
        sy = sy - np.take_along_axis(m, row[:, None], axis=1)[:, 0]
        r0 = self._lerp(self.cond, t0, w1, row, nx - 1)
        r1 = self._lerp(self.cond, t0, w1, row + 1, nx - 1)
        const = np.abs(r0 - r1) < 1e-4 * (r0 + r1)
        with np.errstate(divide="ignore", invalid="ignore"):
            fy = np.where(const, 2.0 * sy / (r0 + r1),
                          (r0 - np.sqrt(np.maximum(r0 * r0 - 2.0 * sy * (r0 - r1), 0.0))) / (r0 - r1))
        sx = sx * ((1.0 - fy) * r0 + fy * r1)
        ca = self.cond[t0, row]
        cb = self.cond[t0, row + 1]
        if self.S > 1:
            ca = ca + w1[:, None] * (self.cond[t0 + 1, row] - ca)
            cb = cb + w1[:, None] * (self.cond[t0 + 1, row + 1] - cb)
        cc = (1.0 - fy)[:, None] * ca + fy[:, None] * cb
        col = np.clip(np.sum(cc[:, 1:nx - 1] < sx[:, None], axis=1), 0, nx - 2)
        sx = sx - np.take_along_axis(cc, col[:, None], axis=1)[:, 0]
        v00 = self._lerp(self.data, t0, w1, row, col)
        v10 = self._lerp(self.data, t0, w1, row, col + 1)
        v01 = self._lerp(self.data, t0, w1, row + 1, col)
        v11 = self._lerp(self.data, t0, w1, row + 1, col + 1)
        c0 = (1.0 - fy) * v00 + fy * v01
        c1 = (1.0 - fy) * v10 + fy * v11
        const = np.abs(c0 - c1) < 1e-4 * (c0 + c1)
        with np.errstate(divide="ignore", invalid="ignore"):
            fx = np.where(const, 2.0 * sx / (c0 + c1),
                          (c0 - np.sqrt(np.maximum(c0 * c0 - 2.0 * sx * (c0 - c1), 0.0))) / (c0 - c1))
        pdf = ((1.0 - fx) * c0 + fx * c1) * ((nx - 1) * (ny - 1))
        return (col + fx) / (nx - 1), (row + fy) / (ny - 1), pdf


class _RGBTable:
    """Bilinear (s) x linear (theta_i) interpolant of the (n_theta, 3, ny, nx) rgb tensor."""

    def __init__(self, rgb: np.ndarray):
        r = np.asarray(rgb, np.float64)  # (S, 3, ny, nx)
        self.S, _, self.ny, self.nx = r.shape
        r = np.moveaxis(r, 1, -1)  # (S, ny, nx, 3)
        tab = np.concatenate([r[:, :-1, :-1], r[:, :-1, 1:], r[:, 1:, :-1], r[:, 1:, 1:]], axis=-1)
        self.table = np.ascontiguousarray(tab).reshape(-1, 12)
        self.slice_stride = (self.ny - 1) * (self.nx - 1) if self.S > 1 else 0

    def eval(self, sx, sy, t0, w1):
        ix, fx = _patch(sx, self.nx)
        iy, fy = _patch(sy, self.ny)
        k = (t0 * (self.ny - 1) + iy) * (self.nx - 1) + ix
        g = np.take(self.table, k, axis=0)
        if self.slice_stride:
            g1 = np.take(self.table, k + self.slice_stride, axis=0)
            g += w1[:, None] * (g1 - g)
        fx = fx[:, None]
        a = g[:, 0:3] + fx * (g[:, 3:6] - g[:, 0:3])
        b = g[:, 6:9] + fx * (g[:, 9:12] - g[:, 6:9])
        return a + fy[:, None] * (b - a)


# ----------------------------------------------------------------------------------------
# The BRDF
# ----------------------------------------------------------------------------------------
def _theta_to_u(theta):
    return np.sqrt(theta * (2.0 / np.pi))


def _u_to_theta(u):
    return u * u * _HALF_PI


def _elevation(v):
    return np.arctan2(np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1]), v[:, 2])


class RGLBRDF:
    """An isotropic RGB material of the RGL-EPFL database.

    Attributes
    ----------
    name, source, source_sha256, description : str
    theta_i : float64 (n_theta,)  incidence angles of the tables (radians)
    theta_i_max : float  last *measured* incidence (radians); trailing slices whose ``rgb``
        is an exact copy of the previous one (the 90 deg padding slice) are not counted.
    jacobian : bool  the file's flag; when set the ndf / (4 sigma) factor is applied.
    rgb : float64 (n_theta, 3, ny, nx)  the ``rgb`` tensor with negative values clamped to 0.
    n_negative_clamped : int  number of ``rgb`` entries that were negative in the file.
    valid_bits : uint8 array or None  the raw bit-packed ``valid`` field (not used here).
    fields : dict  every :class:`TensorField` of the file.
    """

    def __init__(self, fields: dict, path=None, name: str | None = None, sha256: str = ""):
        self.fields = fields
        self.source = str(path) if path is not None else ""
        self.name = name or (Path(path).stem if path is not None else "rgl")
        self.source_sha256 = sha256
        self._path = path
        self._validate_and_build()

    # -- validation -----------------------------------------------------------------------
    def _fail(self, problem):
        raise BRDFFileError(self._path, problem)

    def _float_field(self, name, ndim):
        f = self.fields[name]
        if f.dtype_code not in (9, 10, 11):
            self._fail(f"field {name!r} must be floating point, got dtype {f.data.dtype}")
        if len(f.shape) != ndim:
            self._fail(f"field {name!r} must have {ndim} dimension(s), got shape {list(f.shape)}")
        with np.errstate(invalid="ignore", over="ignore"):
            a = np.asarray(f.data, np.float64)
        if not np.all(np.isfinite(a)):
            self._fail(f"field {name!r} contains NaN or infinite values")
        return a

    def _validate_and_build(self):
        f = self.fields
        if "rgb" not in f and ("spectra" in f or "wavelengths" in f):
            self._fail("spectral-only RGL file (has 'spectra' but no 'rgb' field); only the RGB "
                       "versions (*_rgb.bsdf) are supported")
        missing = [k for k in REQUIRED_FIELDS if k not in f]
        if missing:
            self._fail(f"not a complete RGL BRDF file: missing field(s) {', '.join(missing)}")

        phi_i = self._float_field("phi_i", 1)
        if phi_i.size > 1:
            self._fail(f"anisotropic measurements are not supported yet (phi_i has "
                       f"{phi_i.size} entries; only isotropic files with one phi_i are)")
        if phi_i.size != 1:
            self._fail("field 'phi_i' is empty")
        theta = self._float_field("theta_i", 1)
        n = theta.size
        if n < 1:
            self._fail("field 'theta_i' is empty")
        if np.any(np.diff(theta) <= 0):
            self._fail("field 'theta_i' is not strictly increasing")
        if theta[0] < -1e-6 or theta[-1] > _HALF_PI + 1e-3:
            self._fail(f"field 'theta_i' outside [0, 90] deg: [{np.degrees(theta[0]):.3g}, "
                       f"{np.degrees(theta[-1]):.3g}]")
        d = f["description"]
        if len(d.shape) != 1 or d.dtype_code not in (1, 2):
            self._fail(f"field 'description' must be 1-D uint8 text, got shape {list(d.shape)}")
        self.description = bytes(np.asarray(d.data, np.uint8)).decode("utf-8", "replace").rstrip("\x00")
        jac = f["jacobian"]
        if jac.shape != (1,) or jac.dtype_code not in (1, 2):
            self._fail(f"field 'jacobian' must be a single uint8 flag, got shape {list(jac.shape)}")
        self.jacobian = bool(jac.data[0])

        ndf = self._float_field("ndf", 2)
        sigma = self._float_field("sigma", 2)
        for nm, a in (("ndf", ndf), ("sigma", sigma)):
            if min(a.shape) < 2:
                self._fail(f"field {nm!r} must be at least 2 x 2, got shape {list(a.shape)}")
        vndf = self._float_field("vndf", 4)
        lum = f["luminance"]
        rgb = self._float_field("rgb", 5)
        if vndf.shape[:2] != (1, n) or min(vndf.shape[2:]) < 2:
            self._fail(f"field 'vndf' has shape {list(vndf.shape)}; expected [1, {n}, ny >= 2, nx >= 2]")
        if rgb.shape[:3] != (1, n, 3) or min(rgb.shape[3:]) < 2:
            self._fail(f"field 'rgb' has shape {list(rgb.shape)}; expected [1, {n}, 3, ny >= 2, nx >= 2]")
        if len(lum.shape) != 4 or tuple(lum.shape[:2]) != (1, n) or tuple(lum.shape[2:]) != rgb.shape[3:]:
            self._fail(f"field 'luminance' has shape {list(lum.shape)}; expected "
                       f"[1, {n}, {rgb.shape[3]}, {rgb.shape[4]}]")
        if np.any(vndf < 0) or np.any(ndf < 0) or np.any(sigma <= 0):
            self._fail("fields 'vndf'/'ndf' must be >= 0 and 'sigma' > 0")

        self.theta_i = theta
        self.phi_i = phi_i
        neg = rgb < 0
        self.n_negative_clamped = int(neg.sum())
        self.rgb = np.where(neg, 0.0, rgb)[0]
        v = f.get("valid")
        self.valid_bits = None if v is None else np.asarray(v.data, np.uint8)

        # last measured incidence: drop trailing slices that copy the previous one
        last = n - 1
        while last > 0 and np.array_equal(self.rgb[last], self.rgb[last - 1]):
            last -= 1
        self.theta_i_max = float(theta[last])

        self._ndf = _Bilinear(ndf)
        self._sigma = _Bilinear(sigma)
        self._vndf = _VNDFWarp(vndf[0], theta, self._path)
        self._rgb = _RGBTable(self.rgb)
        self._sigma_iso = bool(np.all(sigma == sigma[:1]))

    # -- evaluation -----------------------------------------------------------------------
    def __repr__(self):
        return (f"RGLBRDF({self.name!r}, {self.description!r}, theta_i={self.theta_i.size}, "
                f"rgb={self.rgb.shape[2]}x{self.rgb.shape[3]}, vndf={self._vndf.ny}x{self._vndf.nx})")

    def _eval_flat(self, wi, wo, cosine: bool):
        n = wi.shape[0]
        out = np.zeros((n, 3))
        for a in range(0, n, _CHUNK):
            b = min(a + _CHUNK, n)
            out[a:b] = self._eval_chunk(wi[a:b], wo[a:b], cosine)
        return out

    def _eval_chunk(self, wi, wo, cosine):
        zi, zo = wi[:, 2], wo[:, 2]
        finite = np.isfinite(wi).all(axis=1) & np.isfinite(wo).all(axis=1)
        above = (zi > 0.0) & (zo > 0.0) & finite
        if not above.all():
            # below the horizon: 0; non-finite input: NaN
            res = np.where(finite, 0.0, np.nan)[:, None].repeat(3, axis=1)
            if above.any():
                res[above] = self._eval_chunk(wi[above], wo[above], cosine)
            return res
        m = wi + wo
        m /= np.sqrt(np.einsum("ij,ij->i", m, m))[:, None]
        theta_i = _elevation(wi)
        theta_m = _elevation(m)
        phi_i = np.arctan2(wi[:, 1], wi[:, 0])
        phi_m = np.arctan2(m[:, 1], m[:, 0])
        um_x = _theta_to_u(theta_m)
        um_y = (phi_m - phi_i + np.pi) * (0.5 / np.pi)
        um_y -= np.floor(um_y)
        t0, w1 = _interval(self.theta_i, theta_i)
        sx, sy, _ = self._vndf.invert(um_x, um_y, t0, w1)
        val = self._rgb.eval(sx, sy, t0, w1)
        if self.jacobian:
            ui_x = _theta_to_u(theta_i)
            if self._sigma_iso:
                ui_y = np.zeros_like(ui_x)
            else:
                ui_y = (phi_i + np.pi) * (0.5 / np.pi)
            scale = self._ndf.eval(um_x, um_y) / (4.0 * self._sigma.eval(ui_x, ui_y))
            if not cosine:
                scale /= zo
            val *= scale[:, None]
        elif not cosine:
            val /= zo[:, None]
        return val

    def _prepare(self, wi, wo):
        wi = np.asarray(wi, np.float64)
        wo = np.asarray(wo, np.float64)
        if wi.shape[-1] != 3 or wo.shape[-1] != 3:
            raise ValueError("wi and wo must have shape (..., 3)")
        shape = np.broadcast_shapes(wi.shape, wo.shape)
        wi = np.ascontiguousarray(np.broadcast_to(wi, shape)).reshape(-1, 3)
        wo = np.ascontiguousarray(np.broadcast_to(wo, shape)).reshape(-1, 3)
        return wi, wo, shape

    def evaluate(self, wi, wo) -> np.ndarray:
        """rho(wi, wo) in 1/sr (RGB, without the cosine): the reference value / cos(theta_o).

        ``wi`` (towards the light) and ``wo`` (towards the viewer) are unit vectors
        ``(..., 3)`` in the local frame (z = normal), broadcastable. Returns ``(..., 3)``;
        0 where either direction is at or below the tangent plane (NaN for non-finite
        input). Directions must be unit vectors. Beyond
        :attr:`theta_i_max` the ``rgb`` interpolation is clamped (see the module docstring).
        """
        wi, wo, shape = self._prepare(wi, wo)
        return self._eval_flat(wi, wo, cosine=False).reshape(shape[:-1] + (3,))

    def evaluate_cosine(self, wi, wo) -> np.ndarray:
        """The reference ``eval``: f_r(wi, wo) * cos(theta_o), RGB, shape ``(..., 3)``."""
        wi, wo, shape = self._prepare(wi, wo)
        return self._eval_flat(wi, wo, cosine=True).reshape(shape[:-1] + (3,))

    # -- warped coordinates ---------------------------------------------------------------
    def vndf_sample(self, sx, sy, theta_i):
        """Forward VNDF warp at incidence ``theta_i`` (radians): points ``(sx, sy)`` of the
        ``rgb`` table's unit square -> micro-normal coordinates ``(u_x, u_y)`` with
        ``theta_m = u_x**2 * pi/2`` and ``phi_m - phi_i = (2 u_y - 1) pi``. Returns
        ``(u_x, u_y, pdf)``."""
        sx, sy, th = np.broadcast_arrays(np.asarray(sx, float), np.asarray(sy, float),
                                         np.asarray(theta_i, float))
        shape = sx.shape
        t0, w1 = _interval(self.theta_i, th.ravel())
        ux, uy, pdf = self._vndf.sample(sx.ravel(), sy.ravel(), t0, w1)
        return ux.reshape(shape), uy.reshape(shape), pdf.reshape(shape)

    def vndf_invert(self, wi, wo):
        """Warped ``rgb``-table coordinates ``(sx, sy)`` of direction pairs (inverse VNDF warp)."""
        wi, wo, shape = self._prepare(wi, wo)
        m = wi + wo
        m /= np.linalg.norm(m, axis=1, keepdims=True)
        theta_i = _elevation(wi)
        um_x = _theta_to_u(_elevation(m))
        um_y = (np.arctan2(m[:, 1], m[:, 0]) - np.arctan2(wi[:, 1], wi[:, 0]) + np.pi) / (2 * np.pi)
        um_y -= np.floor(um_y)
        t0, w1 = _interval(self.theta_i, theta_i)
        sx, sy, _ = self._vndf.invert(um_x, um_y, t0, w1)
        return sx.reshape(shape[:-1]), sy.reshape(shape[:-1])

    def normalization(self, wi, wo) -> np.ndarray:
        """The reference's factor ``ndf(u_wm) / (4 sigma(u_wi))`` (1 if the jacobian flag is
        off); shape ``(...)``."""
        wi, wo, shape = self._prepare(wi, wo)
        if not self.jacobian:
            return np.ones(shape[:-1])
        m = wi + wo
        m /= np.linalg.norm(m, axis=1, keepdims=True)
        phi_i = np.arctan2(wi[:, 1], wi[:, 0])
        um_y = (np.arctan2(m[:, 1], m[:, 0]) - phi_i + np.pi) / (2 * np.pi)
        um_y -= np.floor(um_y)
        ui_y = (phi_i + np.pi) / (2 * np.pi)
        r = self._ndf.eval(_theta_to_u(_elevation(m)), um_y) / (
            4.0 * self._sigma.eval(_theta_to_u(_elevation(wi)), ui_y))
        return r.reshape(shape[:-1])

    # -- MERL grid ------------------------------------------------------------------------
    def to_measured(self, horizon_margin_deg: float = 1.0):
        """Resample at the MERL (theta_h, theta_d, phi_d) bin centres (phi_h = 0).

        Bins whose light or view direction is at or below the horizon are invalid (value 0),
        and so are bins within ``horizon_margin_deg`` of it: there the stored f*cos(theta_o)
        is divided by a cosine below sin(margin) and the values explode (up to ~1e7 1/sr on
        the glossy films at cos(theta_o) ~ 1e-5, against <= 31 in the file). Set 0 to keep
        every above-horizon bin.
        """
        from .angles import half_diff_to_directions
        from .measured import MERL_SHAPE, MeasuredBRDF, phi_d_centres, theta_d_centres, theta_h_centres

        th = theta_h_centres()[:, None, None]
        td = theta_d_centres()[None, :, None]
        pd = phi_d_centres()[None, None, :]
        wi, wo = half_diff_to_directions(th, 0.0, td, pd)
        vals = self.evaluate(wi, wo)
        c_min = max(np.sin(np.radians(horizon_margin_deg)), 0.0)
        above = (wi[..., 2] > c_min) & (wo[..., 2] > c_min)
        valid = np.broadcast_to(above[..., None],
                                MERL_SHAPE + (3,)).copy()
        m = MeasuredBRDF(values=vals, valid=valid, name=self.name, source=self.source,
                         source_sha256=self.source_sha256)
        m.metadata.update({
            "description": self.description,
            "format": "rgl-epfl tensor_file (RGB), resampled at MERL bin centres",
            "theta_i_max_deg": float(np.degrees(self.theta_i_max)),
            "rgb_resolution": [int(self.rgb.shape[2]), int(self.rgb.shape[3])],
            "n_theta_i": int(self.theta_i.size),
            "negative_values_clamped": self.n_negative_clamped,
            "horizon_margin_deg": float(horizon_margin_deg),
        })
        return m


def read_rgl(path) -> RGLBRDF:
    """Read an isotropic RGB RGL-EPFL ``.bsdf`` file; one-line :class:`BRDFFileError` on
    any problem (bad magic, truncation, unknown dtype, missing fields, spectral-only or
    anisotropic files, inconsistent shapes)."""
    from .measured import file_sha256

    path = Path(path)
    buf = _read_bytes(path)
    fields = parse_tensor_file(buf, path)
    return RGLBRDF(fields, path=path, sha256=file_sha256(path))
