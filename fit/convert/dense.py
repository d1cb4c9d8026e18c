"""A rational fit (an ``rbrdf-rational`` JSON file) as a conversion :class:`Source`: the fit is
evaluated densely, at every bin centre of a MERL table (:mod:`fit.convert.merl_writer`) or at
every node of an RGL file's warped grids (:mod:`fit.convert.rgl_writer`), so that tools that
only read tables can use it.

What the dense table holds is the fit's own evaluation (:mod:`fit.rational.coefficient_file`,
steps 1-7): a function of (theta_h, theta_d) only (phi_d-independent, hence reciprocal), inputs
clamped onto the fitted domain (beyond ``theta_d_max_deg`` the value at the cut-off), outputs
clamped to ``[min, max]`` and to a flagged piece's measured range, 0 below the horizon. The
summary of a conversion states the domain (:func:`rational_source` puts it in the notes).
"""
from __future__ import annotations

from pathlib import Path

from ..errors import BRDFFileError
from ..rational.coefficient_file import load
from .sources import Source


def rational_source(path) -> Source:
    """Load the fit ``path`` (re-certified, one-line :class:`fit.errors.BRDFFileError` on any
    problem) as a reciprocal :class:`Source` evaluating ``rho(wi, wo)`` in 1/sr."""
    path = Path(path)
    model = load(path)
    if getattr(model, "kind", "") != "brdf":
        raise BRDFFileError(path, f"a rational file of kind {getattr(model, 'kind', '?')!r}, not a BRDF fit "
                                  "(kind 'brdf'): nothing to tabulate as a BRDF")
    policy = getattr(model, "domain_policy", {}) or {}
    notes = [(f"rational fit of {model.n_coefficients} coefficients: a function of (theta_h, theta_d) "
             "only (no phi_d dependence, reciprocal)")]
    td = policy.get("theta_d_max_deg")
    if td is not None:
        notes.append(f"theta_d above {float(td):g} deg is the fit's value at its cut-off (clamp policy)")
    flagged = [o for o, f in zip(getattr(model, "outputs", ()), _flags(model)) if f]
    if flagged:
        notes.append(f"channel(s) {', '.join(flagged)} flagged by the fitter (not within their stated "
                     "bound): the table holds the clamped fit")
    src = getattr(model, "source", {}) or {}
    desc = f"rational fit of {src.get('file') or model.name}"
    return Source("rational", model.name, str(path), model.evaluate, True, model, description=desc,
                  notes=notes, evaluate_angles=model.evaluate_brdf)


def _flags(model):
    """Per output: True when any piece's function of that output is flagged."""
    fl = getattr(model, "flagged", None)
    if isinstance(fl, tuple):
        return fl
    out = [False] * len(getattr(model, "outputs", ()))
    for piece in getattr(model, "pieces", ()):
        for c, f in enumerate(_flags(piece)):
            out[c] = out[c] or f
    return out
