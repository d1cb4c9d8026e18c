"""MERL-MIT ``.binary`` BRDF files: reader and writer.

Layout (Matusik et al. 2003, ``BRDFRead.cpp``): three little-endian int32 dimensions
``(90, 90, 180)``, then three blocks of float64 (R, G, B), each of 90*90*180 values with
phi_d varying fastest, then theta_d, then theta_h. Stored values are scaled: the BRDF in 1/sr
is ``R * 1/1500``, ``G * 1.15/1500``, ``B * 1.66/1500``. Negative stored values mean "no
sample" (below the horizon) and are never used.

The format folds phi_d into [0, pi) by reciprocity (:mod:`fit.formats.grid`): the reader
returns a reciprocal :class:`MeasuredBRDF` (180 phi_d bins), and the writer only accepts one;
a full-circle table (360 bins, from a non-reciprocal source) has no MERL representation.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import BRDFFileError
from ..inputs import check_regular_file, open_regular
from .grid import MERL_SHAPE
from .measured import MeasuredBRDF, check_values, file_sha256

#: Multiplier from stored values to reflectance in 1/sr, per channel (R, G, B).
MERL_SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
_HEADER_BYTES = 12
_N = int(np.prod(MERL_SHAPE))
MERL_FILE_BYTES = _HEADER_BYTES + 3 * _N * 8


def read_merl(path) -> MeasuredBRDF:
    """Read a MERL ``.binary`` file into a :class:`MeasuredBRDF`.

    Raises :class:`BRDFFileError` naming the file for: unreadable path or not a regular file
    (checked before opening: a named pipe never blocks), wrong header dimensions, truncated or
    oversized file, NaN or infinite values, values above :data:`fit.limits.MAX_BRDF_VALUE`, a
    channel without any valid (non-negative) sample.
    """
    path = Path(path)
    size = check_regular_file(path, what="MERL file")
    try:
        with open_regular(path, what="MERL file") as f:
            header = f.read(_HEADER_BYTES)
            if len(header) < _HEADER_BYTES:
                raise BRDFFileError(path, f"truncated MERL file: {size} bytes, header needs {_HEADER_BYTES}")
            dims = tuple(int(d) for d in np.frombuffer(header, dtype="<i4"))
            if dims != MERL_SHAPE:
                raise BRDFFileError(path, f"wrong MERL header: dimensions {dims}, expected {MERL_SHAPE}")
            if size < MERL_FILE_BYTES:
                raise BRDFFileError(path, f"truncated MERL file: {size} bytes, expected {MERL_FILE_BYTES}")
            if size > MERL_FILE_BYTES:
                raise BRDFFileError(path, f"oversized MERL file: {size} bytes, expected {MERL_FILE_BYTES} "
                                          "(trailing data)")
            raw = np.fromfile(f, dtype="<f8", count=3 * _N)
    except BRDFFileError:
        raise
    except FileNotFoundError:
        raise BRDFFileError(path, "file not found") from None
    except OSError as e:
        raise BRDFFileError(path, f"cannot read file ({e.strerror or e})") from None
    if raw.size != 3 * _N:  # file changed under us
        raise BRDFFileError(path, f"truncated MERL file: read {raw.size} of {3 * _N} values")
    bad = ~np.isfinite(raw)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        ch = "RGB"[first // _N]
        i, j, k = np.unravel_index(first % _N, MERL_SHAPE)
        raise BRDFFileError(path, f"{int(bad.sum())} NaN/inf values (first in channel {ch} at "
                                  f"theta_h bin {i}, theta_d bin {j}, phi_d bin {k})")
    stored = raw.reshape(3, *MERL_SHAPE)
    stored = np.moveaxis(stored, 0, -1)  # (90, 90, 180, 3)
    valid = stored >= 0.0
    values = np.where(valid, stored * MERL_SCALE, 0.0)
    check_values(values, valid, path)
    return MeasuredBRDF(values=values, valid=valid, name=path.stem, source=str(path),
                        source_sha256=file_sha256(path))


def write_merl(brdf: MeasuredBRDF, path) -> None:
    """Write ``brdf`` in the exact MERL layout; invalid bins are stored as -1. Only tables
    folded by reciprocity (180 phi_d bins) can be written."""
    values = np.asarray(brdf.values, float)
    if values.shape != MERL_SHAPE + (3,):
        extra = (" (a full-circle table of non-reciprocal data: MERL files fold phi_d by "
                 "reciprocity)" if values.shape[2:3] == (360,) else "")
        raise ValueError(f"values must have shape {MERL_SHAPE + (3,)}, got {values.shape}{extra}")
    if not np.all(np.isfinite(values[brdf.valid])):
        raise ValueError("cannot write non-finite BRDF values")
    if np.any(values[brdf.valid] < 0):
        raise ValueError("valid BRDF values must be >= 0 (negative means 'no sample' in MERL files)")
    stored = np.where(brdf.valid, values / MERL_SCALE, -1.0)
    from ..outputs import atomic_write

    with atomic_write(path, "wb") as f:
        f.write(np.asarray(MERL_SHAPE, dtype="<i4").tobytes())
        f.write(np.ascontiguousarray(np.moveaxis(stored, -1, 0), dtype="<f8").tobytes())
