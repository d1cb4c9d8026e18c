"""The inputs of a conversion: any BRDF the project reads, as one evaluable :class:`Source`.

* ``.binary``: a MERL-MIT file (:func:`fit.formats.merl.read_merl`), evaluated trilinearly
  between its bin centres (``MeasuredBRDF.evaluate``'s default), reciprocal (its 180 phi_d bins
  fold (wi, wo) and (wo, wi) together);
* ``.bsdf``: an RGL-EPFL file (:func:`fit.formats.rgl.read_rgl`), evaluated exactly with the
  reference semantics (tensor incident direction = the view, ``incident="view"``); not
  reciprocal;
* ``.json``: an ``rbrdf-rational`` fit (:mod:`fit.convert.dense`), evaluated as the renderer
  shows it (measured domain, projected table where flagged): a 2-D fit is a function of
  (theta_h, theta_d) only, hence reciprocal; a 3-D fit keeps the roles (not reciprocal).

Every source evaluates ``rho(wi_light, wo_view)`` in 1/sr, RGB, *without* the cosine, for
local unit directions of shape ``(..., 3)`` (z = normal), 0 where either direction is at or
below the tangent plane (conventions.md).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import BRDFFileError

#: Input extensions and what they hold.
SOURCE_SUFFIXES = {".binary": "MERL-MIT", ".bsdf": "RGL-EPFL", ".json": "rbrdf-rational fit"}


@dataclass
class Source:
    """A BRDF to convert.

    Attributes
    ----------
    kind : str  ``"merl"``, ``"rgl"`` or ``"rational"``
    name, path, description : str
    evaluate : callable ``(wi, wo) -> (..., 3)``  rho in 1/sr (light ``wi``, view ``wo``)
    reciprocal : bool  ``evaluate(wi, wo) == evaluate(wo, wi)`` by construction
    obj : the object read (``MeasuredBRDF``, ``RGLBRDF`` or a rational model)
    notes : list of str  what the reader did to the data (clamps, domain), for the summary
    evaluate_angles : callable ``(theta_h, theta_d) -> (..., 3)`` or None  for a source that
        is a function of the Rusinkiewicz angles (radians) alone (a rational fit): the same
        rho above the horizon, so that a table is tabulated on 90 x 90 angles, not 1.5 M pairs
    """

    kind: str
    name: str
    path: str
    evaluate: Callable
    reciprocal: bool
    obj: object = None
    description: str = ""
    notes: list = field(default_factory=list)
    evaluate_angles: Callable | None = None


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
