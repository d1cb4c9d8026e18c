"""A rational fit (an ``rbrdf-rational`` JSON file) as a conversion :class:`Source`: the fit is
evaluated densely, at every bin centre of a MERL table (:mod:`fit.convert.merl_writer`) or at
every node of an RGL file's warped grids (:mod:`fit.convert.rgl_writer`), so that tools that
only read tables can use it.

What the dense table holds is what the renderer shows of the fit (:mod:`fit.rational.vouched`,
the NumPy reference of the renderer's kernel): the file's recipe (:mod:`fit.rational.coefficient_file`,
steps 1-7: a function of (theta_h, theta_d) only, phi_d-independent, hence reciprocal; inputs
clamped onto the fitted domain, beyond ``theta_d_max_deg`` the value at the cut-off; outputs
clamped to ``[min, max]``), evaluated with its angles moved onto the measured domain of its
grazing cut-off (:mod:`fit.rational.domain`: beyond it the fitted function extrapolates
freely), and, in every piece and channel the fitter flags as not within its bound, the
projected table the fitter embedded in the file (its ``fallback`` key), clamped to the piece's
measured range; 0 below the horizon. A flagged fit whose file carries no such table (written
before the fitter embedded it) is refused with one line: its fitted function there is not
vouched for, and the table needs the source measurement (convert that instead, or refit). The
summary of a conversion states all of this (:func:`rational_source` puts it in the notes).
"""
from __future__ import annotations

from functools import partial
from pathlib import Path

from ..errors import BRDFFileError
from ..rational.coefficient_file import load
from ..rational.domain import measured_domain
from ..rational.fallback import table_from_record
from ..rational.flagged import describe_regions, flagged_regions
from ..rational.variables3d import evaluate_directions, is_3d
from ..rational.vouched import evaluate_at_angles, values_at_angles
from .source import Source


def rational_source(path) -> Source:
    """Load the fit ``path`` (re-certified, one-line :class:`fit.errors.BRDFFileError` on any
    problem) as a :class:`Source` evaluating ``rho(wi, wo)`` in 1/sr as the renderer does: a 2-D
    fit (reciprocal) through :mod:`fit.rational.vouched`; a 3-D fit of (theta_h, theta_d,
    |phi_d|) (:mod:`fit.rational.variables3d`, the light's and the view's roles kept: not
    reciprocal) by its recipe. A flagged 3-D fit is refused (no projected table can stand in
    for it; the renderer refuses it too)."""
    path = Path(path)
    model = load(path)
    if getattr(model, "kind", "") != "brdf":
        raise BRDFFileError(path, f"a rational file of kind {getattr(model, 'kind', '?')!r}, not a BRDF fit "
                                  "(kind 'brdf'): nothing to tabulate as a BRDF")
    src = getattr(model, "source", {}) or {}
    desc = f"rational fit of {src.get('file') or model.name}"
    if is_3d(model):
        regions = flagged_regions(model)
        if regions:
            raise BRDFFileError(path, f"the 3-D fit is not within its bound for {describe_regions(model, regions)}: "
                                      "nothing vouched to tabulate there (convert its source measurement instead)")
        notes = [f"3-D rational fit of {model.n_coefficients} coefficients in (theta_h, theta_d, |phi_d|): the "
                 "light's and the view's roles kept (not reciprocal)"]
        return Source("rational", model.name, str(path), partial(evaluate_directions, model), False, model,
                      description=desc, notes=notes)
    policy = getattr(model, "domain_policy", {}) or {}
    notes = [(f"rational fit of {model.n_coefficients} coefficients: a function of (theta_h, theta_d) "
             "only (no phi_d dependence, reciprocal)")]
    td = policy.get("theta_d_max_deg")
    if td is not None:
        notes.append(f"theta_d above {float(td):g} deg is the fit's value at its cut-off (clamp policy)")
    cut = measured_domain(model)
    if cut is not None:
        notes.append(f"beyond the measured domain of its {cut:g} deg grazing cut-off (cos theta_h cos theta_d "
                     f"< cos {cut:g} deg) the fit's value at the domain's edge, as rendered")
    table = None
    flagged = flagged_regions(model)
    if flagged:
        regions = describe_regions(model, flagged)
        if getattr(model, "fallback", None) is None:
            raise BRDFFileError(path, f"the fit is not within its bound for {regions} and the file carries no "
                                      "projected table to use there (written before the fitter embedded it): "
                                      "convert its source measurement instead, or refit it")
        try:
            table = table_from_record(model.fallback, model)
        except ValueError as e:
            raise BRDFFileError(path, f"embedded fallback table unusable ({e})") from None
        notes.append(f"not within its bound for {regions}: the projected table embedded in the file there "
                     "(median projection of its source measurement, clamped to each region's measured "
                     "range), as rendered")
    return Source("rational", model.name, str(path), evaluate_at_angles(model, table, cut), True, model,
                  description=desc, notes=notes, evaluate_angles=values_at_angles(model, table, cut))
