"""Re-proving what a coefficient file claims, on load: Q > 0 of every function on its box
(:func:`recertify`, exact Bernstein coefficients, whatever the file's ``q_certificate`` says)
and, for a model without a ``max`` clamp, its values bounded by
:data:`fit.limits.MAX_BRDF_VALUE` (:func:`fit.rational.value_bound.bound_ratio`), within the
work :class:`FileBudget` allows a whole file. The format: docs/formats.md ("Rational
coefficients", "Reading").
"""
from __future__ import annotations

import math

import numpy as np

from .. import jsonfields as F
from ..errors import BRDFFileError
from ..limits import MAX_BRDF_VALUE, MAX_CERTIFY_BOXES, MAX_CERTIFY_WORK
from .bernstein import certify_positive
from .model import PiecewiseRationalModel
from .value_bound import bound_ratio


class FileBudget:
    """What a whole file may ask for: coefficients (compiled into the renderer's kernels) and
    the work of re-proving Q > 0 (Bernstein coefficients examined)."""

    def __init__(self):
        self.coefficients = 0
        self.certify_work = 0


def _leaf_models(model, key: str = "") -> list:
    """``[(key path, single-box model)]`` of ``model``, pieces first to last."""
    if isinstance(model, PiecewiseRationalModel):
        return [leaf for i, p in enumerate(model.pieces) for leaf in _leaf_models(p, F.sub(F.sub(key, "pieces"), i))]
    return [(key, model)]


def recertify(model, path=None, budget: FileBudget | None = None) -> None:
    """Prove Q > 0 again on the box of every function of ``model`` (whatever its record says);
    :class:`BRDFFileError` naming the function when a denominator has a zero (a pole) or
    cannot be proven positive within :data:`fit.limits.MAX_CERTIFY_BOXES` sub-boxes and the
    file's work budget :data:`fit.limits.MAX_CERTIFY_WORK`. A model without an upper clamp
    (``max``) must also be proven bounded (:func:`_check_bounded`)."""
    budget = budget or FileBudget()
    for key, leaf in _leaf_models(model):
        for c, f in enumerate(leaf.functions):
            where = f"key {F.sub(F.sub(key, 'functions'), c)} ({leaf.outputs[c]})"
            size = int(np.prod(np.asarray(f.den_degrees) + 1))
            boxes = min(MAX_CERTIFY_BOXES, max((MAX_CERTIFY_WORK - budget.certify_work) // max(size, 1), 1))
            cert = certify_positive(f.den_exponents, f.den_coef, max_depth=12, max_boxes=boxes)
            budget.certify_work += cert.n_boxes * size
            if not cert.certified:
                said = leaf.function_info[c].get("q_certificate", {}) if leaf.function_info else {}
                claim = " although the file says it is certified" if isinstance(said, dict) and said.get(
                    "certified") is True else ""
                raise BRDFFileError(path, f"{where}: {cert.reason or 'Q > 0 could not be proven'} "
                                          f"(re-checked on load){claim}")
            if leaf.value_max is None and (leaf.kind == "brdf" or leaf.value_transform == "log"):
                _check_bounded(leaf, f, cert.lower_bound, where, path, budget)


def _check_bounded(leaf, f, q_lower: float, where: str, path, budget: FileBudget) -> None:
    """A function of a model without a ``max`` clamp: prove that its values stay within
    :data:`fit.limits.MAX_BRDF_VALUE` (a BRDF: P/Q, or exp(P/Q) - offset, on the whole box;
    another log-valued function: exp(P/Q) finite), :func:`fit.rational.value_bound.bound_ratio`
    within the file's certification budget; :class:`BRDFFileError` naming the function and
    ``value.max`` when they do not or cannot be proven to. The step-7 ranges do not count: they
    are optional records that older readers ignore."""
    log = leaf.value_transform == "log"
    top = MAX_BRDF_VALUE if leaf.kind == "brdf" else math.inf
    limit = math.log(top + leaf.value_offset) if log and math.isfinite(top) else (700.0 if log else top)
    size = int(np.prod(np.asarray(f.num_degrees) + 1)) + int(np.prod(np.asarray(f.den_degrees) + 1))
    boxes = min(MAX_CERTIFY_BOXES, max((MAX_CERTIFY_WORK - budget.certify_work) // max(size, 1), 1))
    res = bound_ratio(f.num_exponents, f.num_coef, f.den_exponents, f.den_coef, limit, q_lower, max_boxes=boxes)
    budget.certify_work += res.work
    if res.bounded:
        return
    what = "exp(P/Q) - offset" if log else "P/Q"
    if res.witness is None:
        raise BRDFFileError(path, f"{where}: no 'value.max' clamp, and {what} <= {top:g} 1/sr could not be "
                                  f"proven on the box ({res.reason}; fit.limits.MAX_BRDF_VALUE)")
    at = ", ".join(f"{v.name} = {_from_unit(t, v):.4g}" for t, v in zip(res.witness, leaf.variables))
    if log:
        shown = ("overflows float64: exp would overflow" if res.value > 709.0
                 else f"= {math.exp(res.value) - leaf.value_offset:.3g}")
        said = f"P/Q = {res.value:.3g}, exp(P/Q) - offset {shown}"
    else:
        said = f"P/Q = {res.value:.3g}"
    raise BRDFFileError(path, f"{where}: no 'value.max' clamp, and at {at} {said}, above "
                              f"{top:g} 1/sr (fit.limits.MAX_BRDF_VALUE)")


def _from_unit(t: float, var) -> float:
    """The variable's own value (its unit) at the box coordinate ``t`` in [-1, 1]."""
    ulo, uhi = var.rf_domain
    u = ulo + 0.5 * (t + 1.0) * (uhi - ulo)
    return u * u if var.transform == "sqrt" else u
