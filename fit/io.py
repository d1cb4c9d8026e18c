"""Open any supported measured-BRDF file by its extension.

* ``.binary``: MERL-MIT layout (:mod:`fit.merl`).
* ``.bsdf``: RGL-EPFL tensor files (:mod:`fit.rgl`), resampled onto the MERL grid.
"""
from __future__ import annotations

from pathlib import Path

from .errors import BRDFFileError
from .measured import MeasuredBRDF

SUFFIXES = (".binary", ".bsdf")


def load_measured(path) -> MeasuredBRDF:
    """Read a measured BRDF as a :class:`MeasuredBRDF` on the MERL grid."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".binary":
        from .merl import read_merl

        return read_merl(path)
    if suffix == ".bsdf":
        from .rgl import read_rgl

        return read_rgl(path).to_measured()
    raise BRDFFileError(path, f"unknown BRDF file type {suffix or '(no extension)'!r}; "
                              f"expected one of {', '.join(SUFFIXES)}")
