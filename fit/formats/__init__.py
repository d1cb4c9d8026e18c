"""Measured-BRDF file formats and the types they are read into; open any supported file by its
extension with :func:`load_measured`.

* ``.binary``: MERL-MIT layout (:mod:`fit.formats.merl`).
* ``.bsdf``: RGL-EPFL tensor files (:mod:`fit.formats.rgl`, container
  :mod:`fit.formats.tensor_file`), resampled onto the MERL grid.

The MERL grid itself is :mod:`fit.formats.grid`, the in-memory types :mod:`fit.formats.measured`,
the angle conventions :mod:`fit.formats.angles`, the luminance weights :mod:`fit.formats.colour`.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import BRDFFileError
from .measured import MeasuredBRDF
from .merl import read_merl
from .rgl import read_rgl

SUFFIXES = (".binary", ".bsdf")


def max_file_bytes(path) -> int:
    """Largest file of the format of ``path`` (by its suffix) a reader accepts, in bytes: a
    MERL file has exactly :data:`fit.formats.merl.MERL_FILE_BYTES`, an RGL file at most
    :data:`fit.limits.MAX_RGL_FILE_BYTES`."""
    from ..limits import MAX_RGL_FILE_BYTES
    from .merl import MERL_FILE_BYTES

    return MERL_FILE_BYTES if Path(path).suffix.lower() == ".binary" else MAX_RGL_FILE_BYTES


def check_measured_file(path) -> int:
    """Size in bytes of the measured file ``path``, checked with ``stat`` before any byte is
    read (:func:`fit.inputs.check_regular_file`): a regular file (not a folder, named pipe,
    device or socket) within its format's size (:func:`max_file_bytes`); else a one-line
    :class:`BRDFFileError` naming it."""
    from ..inputs import check_regular_file

    what = "MERL file" if Path(path).suffix.lower() == ".binary" else "RGL tensor file"
    return check_regular_file(path, max_file_bytes(path), what)


def load_measured(path, incident: str = "view") -> MeasuredBRDF:
    """Read a measured BRDF as a :class:`MeasuredBRDF` on the MERL grid. ``incident``: the
    roles of an RGL file's directions (:attr:`fit.formats.rgl.RGLBRDF.incident`; MERL files
    are reciprocal and ignore it)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".binary":
        return read_merl(path)
    if suffix == ".bsdf":
        return read_rgl(path, incident=incident).to_measured()
    raise BRDFFileError(path, f"unknown BRDF file type {suffix or '(no extension)'!r}; "
                              f"expected one of {', '.join(SUFFIXES)}")
