"""The inputs of a conversion: any BRDF file the project reads, as one evaluable
:class:`fit.convert.source.Source`, chosen by its extension.

* ``.binary``: a MERL-MIT file (:func:`fit.formats.merl.read_merl`), evaluated trilinearly
  between its bin centres (``MeasuredBRDF.evaluate``'s default), reciprocal (its 180 phi_d bins
  fold (wi, wo) and (wo, wi) together);
* ``.bsdf``: an RGL-EPFL file (:func:`fit.formats.rgl.read_rgl`), evaluated exactly with the
  reference semantics (tensor incident direction = the view, ``incident="view"``); not
  reciprocal;
* ``.json``: an ``rbrdf-rational`` fit (:mod:`fit.convert.dense`), evaluated as the renderer
  shows it (measured domain, projected table where flagged): a 2-D fit is a function of
  (theta_h, theta_d) only, hence reciprocal; a 3-D fit keeps the roles (not reciprocal).
"""
from __future__ import annotations

from pathlib import Path

from ..errors import BRDFFileError
from .source import Source

#: Input extensions and what they hold.
SOURCE_SUFFIXES = {".binary": "MERL-MIT", ".bsdf": "RGL-EPFL", ".json": "rbrdf-rational fit"}


def load_source(path) -> Source:
    """Read ``path`` by its extension (:data:`SOURCE_SUFFIXES`); one-line
    :class:`BRDFFileError` for an unknown extension or a file that cannot be read."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".binary":
        from ..formats.merl import read_merl

        m = read_merl(path)
        return Source("merl", m.name, str(path), m.evaluate, True, m,
                      notes=[(f"MERL input: trilinear between bin centres, {100 * (1 - m.valid_fraction):.1f} % of "
                             "the bins marked 'no sample'")])
    if suffix == ".bsdf":
        from ..formats.rgl import read_rgl

        r = read_rgl(path, incident="view")
        notes = []
        if r.n_negative_clamped:
            notes.append(f"{r.n_negative_clamped} negative rgb entries of the input clamped to 0 (as the "
                         "reader does)")
        return Source("rgl", r.name, str(path), r.evaluate, False, r, description=r.description,
                      notes=notes)
    if suffix == ".json":
        from .dense import rational_source

        return rational_source(path)
    raise BRDFFileError(path, f"unknown input type {suffix or '(no extension)'!r}; expected one of "
                              f"{', '.join(SOURCE_SUFFIXES)}")
