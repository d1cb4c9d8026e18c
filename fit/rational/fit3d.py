"""3-D rational BRDF fits of ``(theta_h, theta_d, |phi_d|)`` with a guaranteed bound at every
data point (coefficient file version 3, :mod:`fit.rational.coefficient_file`): the entry points
in one place. The method (what is fitted, the intervals and the bound, the two stages, the
verification, the directional-albedo policy, pieces, budgets, measurements) is specified in
docs/fitting.md, "The 3-D method".

The modules, one step each:

* :mod:`fit.rational.samples3d`: the data (sample grid, objective points, noise levels, grazing
  weight); :mod:`fit.rational.variables3d`: the variables;
* :mod:`fit.rational.ladder3d`: :func:`fit_samples`, the fit of given samples (tolerance ladder,
  second stage, pieces);
* :mod:`fit.rational.verify3d`: :func:`verification_ratio`, :func:`verify_and_refit`;
* :mod:`fit.rational.albedo3d`: the directional-albedo policy;
* :mod:`fit.rational.rgl3d`: :func:`fit_rgl`, an RGL file sampled, fitted, verified, albedo policy;
* :mod:`fit.rational.select3d`: :func:`fit_rgl_select`, :data:`VARIANTS`, :data:`TARGET_LADDER`, :func:`validation_rmse`;
* :mod:`fit.rational.result3d`: :class:`Fit3D`, :class:`FitData3D`, :func:`domain_record`;
* :mod:`fit.rational.settings`: :class:`Fit3DSettings` and the defaults; :mod:`fit.rational.ceiling`:
  the wall-clock safety net.
"""
from __future__ import annotations

from .ceiling import DEFAULT_TIME_LIMIT, Ceiling
from .ladder3d import fit_samples
from .result3d import INTERVALS, Fit3D, FitData3D, domain_record
from .rgl3d import fit_rgl
from .samples3d import (
    DEFAULT_GRID,
    DEFAULT_NOISE_FRAC,
    DEFAULT_RANDOM,
    DEFAULT_THETA_FIT_DEG,
    OBJECTIVES,
    grazing_weight,
    noise_levels,
    objective_points,
    sample_grid,
    sample_rgl,
)
from .select3d import SELECT_MARGIN, SELECTION_KEYS, TARGET_LADDER, VARIANTS, fit_rgl_select, validation_rmse
from .settings import (
    DEFAULT_ALBEDO_REFITS,
    DEFAULT_ALBEDO_RMSE_GROWTH,
    DEFAULT_ALBEDO_TIME,
    DEFAULT_ALBEDO_TOL,
    DEFAULT_ALBEDO_TOTAL_GROWTH,
    DEFAULT_CHANNEL_FLOOR,
    DEFAULT_DEGREES,
    DEFAULT_GRAZING_COS,
    DEFAULT_LADDER_STEPS,
    DEFAULT_OBJECTIVE,
    DEFAULT_RELAX,
    DEFAULT_VERIFY,
    Fit3DSettings,
)
from .verify3d import verification_ratio, verify_and_refit

__all__ = [
    "DEFAULT_ALBEDO_REFITS", "DEFAULT_ALBEDO_RMSE_GROWTH", "DEFAULT_ALBEDO_TIME", "DEFAULT_ALBEDO_TOL",
    "DEFAULT_ALBEDO_TOTAL_GROWTH", "DEFAULT_CHANNEL_FLOOR", "DEFAULT_DEGREES", "DEFAULT_GRAZING_COS",
    "DEFAULT_GRID", "DEFAULT_LADDER_STEPS", "DEFAULT_NOISE_FRAC", "DEFAULT_OBJECTIVE", "DEFAULT_RANDOM",
    "DEFAULT_RELAX", "DEFAULT_THETA_FIT_DEG", "DEFAULT_TIME_LIMIT", "DEFAULT_VERIFY", "INTERVALS", "OBJECTIVES",
    "SELECT_MARGIN", "SELECTION_KEYS",
    "TARGET_LADDER", "VARIANTS", "Ceiling", "Fit3D", "Fit3DSettings", "FitData3D", "domain_record", "fit_rgl", "fit_rgl_select",
    "fit_samples", "grazing_weight", "noise_levels", "objective_points", "sample_grid", "sample_rgl",
    "validation_rmse", "verification_ratio", "verify_and_refit",
]
