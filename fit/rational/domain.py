"""The measured domain of a 2-D rational fit: where the projection it was made from has data.

A 2-D fit of (theta_h, theta_d) made from a median projection with a grazing cut-off c (the
file's ``fit.grazing_cutoff_deg``, :data:`GRAZING_CUTOFF_DEG` = 79 deg by default)
has data only where ``cos theta_h cos theta_d >= cos c``; beyond it the fit extrapolates
freely. Every evaluator of such a fit moves its angles onto that domain before the recipe of
:mod:`fit.rational.coefficient_file`: the renderer (:mod:`warp_rbrdf.materials.rational`: its
Warp kernel and NumPy reference) and the exports (:mod:`fit.export`: the same rule emitted in
GLSL, HLSL, C and the Mitsuba plugin's Dr.Jit) and the table conversions (:mod:`fit.convert.dense`,
through :mod:`fit.rational.vouched`). This module is the one definition of the rule and of
the fitted box; it needs only NumPy.

Constants of the fitted domain (see :mod:`fit.rational.brdf_fit` for the policy): samples with
max(theta_i, theta_o) above :data:`GRAZING_CUTOFF_DEG` are dropped before the median
projection; the box is theta_h in [0, :data:`THETA_H_MAX`] (radians) x theta_d in
[0, :data:`THETA_D_MAX_DEG`] (degrees); outputs :data:`CHANNELS`.
"""
from __future__ import annotations

import numpy as np

from ..formats.angles import HALF_PI

#: Default grazing cut-off (degrees) of a 2-D fit's median projection.
GRAZING_CUTOFF_DEG = 79.0
#: Largest theta_d (degrees) of a 2-D fit's box; beyond it the value at the cut-off.
THETA_D_MAX_DEG = 78.5
#: Largest theta_h (radians) of a 2-D fit's box.
THETA_H_MAX = HALF_PI
#: Output channels of a BRDF fit.
CHANNELS = ("R", "G", "B")


def measured_domain(model):
    """The grazing cut-off (degrees) of the projection a 2-D (theta_h, theta_d) fit was made
    from (``fit_info["grazing_cutoff_deg"]``: samples with max(theta_i, theta_o) above it were
    dropped), or None: a fit that records none (a model built by hand, a file written before the
    record), or a fit in other variables (version-3 fits of (theta_h, theta_d, |phi_d|) carry
    their own domain, :mod:`fit.rational.variables3d`). :func:`onto_measured_domain` says what
    the cut-off means for the fit's inputs."""
    if [v.name for v in model.variables] != ["theta_h", "theta_d"]:
        return None
    cut = (getattr(model, "fit_info", None) or {}).get("grazing_cutoff_deg")
    if cut is None:
        return None
    cut = float(cut)
    if not 0.0 < cut < 90.0:
        return None          # no cut-off (90 keeps every sample): the whole quadrant is measured
    return cut


def onto_measured_domain(x, cutoff_deg: float) -> np.ndarray:
    """Rusinkiewicz angles ``x`` ``(..., 2)`` (theta_h, theta_d, radians) moved onto the measured
    domain of a projection with grazing cut-off ``cutoff_deg`` (degrees); float64, same shape.

    A (theta_h, theta_d) cluster holds data iff one of its phi_d samples has both directions
    within the cut-off c. Since cos theta_i + cos theta_o = 2 cos theta_h cos theta_d and the two
    cosines are equal at phi_d = +-90 deg, the largest min(cos theta_i, cos theta_o) over phi_d is
    cos theta_h cos theta_d: the measured domain is ``cos theta_h cos theta_d >= cos c``, and
    every pair with both directions within c lies in it. Outside it (both directions grazing on
    average; the cut-off leaves these clusters empty) the fit has no data and extrapolates
    freely, up to the whole piece's vouched range (a specular peak's value off the peak). There
    the value is the fit's at the domain's edge at the same theta_h: theta_h is clamped to c,
    then theta_d to ``arccos(min(cos c / cos theta_h, 1))`` -- the rule the fits already apply
    beyond their last theta_d (the value at the cut-off). Inside the domain nothing changes."""
    x = np.array(x, dtype=np.float64)
    cut = np.radians(float(cutoff_deg))
    th = np.minimum(x[..., 0], cut)
    tdmax = np.arccos(np.minimum(np.cos(cut) / np.cos(th), 1.0))
    x[..., 0] = th
    x[..., 1] = np.minimum(x[..., 1], tdmax)
    return x
