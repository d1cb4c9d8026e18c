"""The RGL-EPFL *tensor file* container (``.bsdf``): a small binary container of named
n-dimensional arrays. Read defensively (every problem is a one-line :class:`BRDFFileError`) and
written (by the tests, to build valid and hostile variants of real files).

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

The BRDF stored in such a file is :mod:`fit.formats.rgl`.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import BRDFFileError
from ..inputs import read_bytes
from ..limits import MAX_RGL_FILE_BYTES

MAGIC = b"tensor_file\x00"
#: dtype codes of the tensor_file format
DTYPES = {1: "u1", 2: "i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<u8", 8: "<i8",
          9: "<f2", 10: "<f4", 11: "<f8"}
_CODES = {np.dtype(v).str: k for k, v in DTYPES.items()}
_CODES[np.dtype("u1").str] = 1
_CODES[np.dtype("i1").str] = 2

#: Files larger than this are refused (RGB RGL files are about 0.6-5 MB; fit.limits).
MAX_FILE_BYTES = MAX_RGL_FILE_BYTES
MAX_FIELDS = 4096
MAX_NDIM = 16


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
        extent = 1           # product of the non-zero sides: what NumPy must be able to index
        for s in shape:
            count *= int(s)  # Python ints: no overflow
            extent *= max(int(s), 1)
        if count == 0 and extent * dtype.itemsize > size:   # empty, but NumPy cannot index it
            fail(f"field {name!r} has the absurd shape {list(shape)}: a zero side, and the others "
                 f"span {extent * dtype.itemsize} bytes, more than the file's {size} (corrupt field table)")
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
    """The file's bytes: a regular file (never a pipe or device) of at most
    :data:`MAX_FILE_BYTES`."""
    return read_bytes(Path(path), MAX_FILE_BYTES, "RGL tensor file")


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
    from ..outputs import atomic_write

    with atomic_write(Path(path), "wb") as f:
        f.write(out)

