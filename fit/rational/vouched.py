"""What a 2-D rational fit shows wherever it is evaluated: the one NumPy definition that the
renderer (:mod:`warp_rbrdf.materials.rational`, whose Warp kernel is tested against it) and the
table conversions (:mod:`fit.convert.dense`: ``rbrdf-fit convert fit.json out.binary|.bsdf``)
share.

Two rules on top of the coefficient file's recipe (:mod:`fit.rational.coefficient_file`):

1. **The measured domain** (:mod:`fit.rational.domain`): a fit that records its grazing cut-off
   is evaluated with its angles moved onto the domain its projection has data in; beyond it the
   fitted function extrapolates freely (up to thousands of 1/sr where the measurement is below
   1).
2. **Flagged pieces** (:func:`fit.rational.flagged.flagged_regions`): every channel a piece
   does not vouch for is the fallback table's nearest (theta_h, theta_d) cluster
   (:mod:`fit.rational.fallback`: the median projection of the source measurement, ``(90, 90,
   3)`` in 1/sr) at the inputs clamped onto the piece's box, clamped to the piece's measured
   range.

Angles are Rusinkiewicz (theta_h, theta_d) in radians; values are rho in 1/sr, RGB, without
the cosine; directions are unit vectors in the local shading frame (z = normal). NumPy only.
"""
from __future__ import annotations

import numpy as np

from ..formats.angles import directions_to_half_diff
from ..formats.grid import N_THETA_D, theta_d_index, theta_h_index
from .domain import onto_measured_domain
from .flagged import flagged_regions
from .model import measured_range


def values_with_table(model, table, x) -> np.ndarray:
    """rho (1/sr) ``(..., 3)`` at Rusinkiewicz angles ``x`` ``(..., 2)`` (theta_h, theta_d,
    radians) of a model with a fallback table ``(90 * 90, 3)`` or ``(90, 90, 3)``: the model,
    except that every flagged channel of a flagged piece is the table's nearest cluster at the
    inputs clamped onto that piece's box, clamped to the piece's measured range."""
    flags = {r["leaf"]: r["channels"] for r in flagged_regions(model)}
    tab = np.asarray(table, np.float64).reshape(-1, N_THETA_D, 3)
    x = np.asarray(x, np.float64)
    out = np.array(model(x), dtype=np.float64)
    for k, (leaf, sel, xl) in enumerate(model.leaves(x)):
        if k not in flags or not np.any(sel):
            continue
        tv = tab[theta_h_index(xl[..., 0]), theta_d_index(xl[..., 1])]
        for c in flags[k]:
            v = tv[..., c]
            rng = measured_range(leaf.function_info[c])
            if rng is not None:
                v = np.clip(v, rng[0], rng[1])
            out[..., c] = np.where(sel, v, out[..., c])
    return out


def values_at_angles(model, table=None, cutoff_deg=None):
    """``evaluate(theta_h, theta_d) -> (..., 3)``: rho (1/sr) of a 2-D fit at broadcastable
    angle arrays (radians), moved onto the measured domain of ``cutoff_deg`` (degrees; None: not
    moved), with the fallback table ``table`` in flagged pieces (None: the fitted functions
    everywhere)."""
    tab = None if table is None else np.asarray(table, np.float32).astype(np.float64)

    def evaluate(theta_h, theta_d):
        x = np.stack(np.broadcast_arrays(np.asarray(theta_h, float), np.asarray(theta_d, float)), axis=-1)
        if cutoff_deg is not None:
            x = onto_measured_domain(x, cutoff_deg)
        return np.asarray(model(x), np.float64) if tab is None else values_with_table(model, tab, x)

    return evaluate


def evaluate_at_angles(model, table=None, cutoff_deg=None):
    """NumPy reference of the renderer's ``rational_eval`` for a 2-D fit: ``evaluate(wi, wo) ->
    (..., 3)``, rho (1/sr) at the directions' Rusinkiewicz angles through
    :func:`values_at_angles` (``cutoff_deg``, ``table`` as there); 0 below the horizon."""
    at = values_at_angles(model, table, cutoff_deg)

    def evaluate(wi, wo):
        wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
        th, _, td, _ = directions_to_half_diff(wi, wo)
        out = at(th, td)
        above = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
        return np.where(above[..., None], out, 0.0)

    return evaluate
