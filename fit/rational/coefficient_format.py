"""The identity of the ``rbrdf-rational`` coefficient format: its name, its versions and the
variables of a 3-D BRDF (version 3). The format is specified in docs/formats.md ("Rational
coefficients"); :mod:`fit.rational.coefficient_file` is its public face.
"""
from __future__ import annotations

FORMAT = "rbrdf-rational"
VERSION = 1            # single rational function per output
VERSION_PIECEWISE = 2  # pieces along one variable (see PiecewiseRationalModel)
VERSION_3D = 3         # a BRDF of (theta_h, theta_d, |phi_d|), single or piecewise (fit.rational.fit3d)
VERSIONS = (VERSION, VERSION_PIECEWISE, VERSION_3D)
#: The variables of a version-3 BRDF (fit.rational.variables3d: phi_d folded to |phi_d|).
BRDF_VARIABLES_3D = ["theta_h", "theta_d", "phi_d"]


def is_3d(model) -> bool:
    """True for a BRDF model of the version-3 variables (theta_h, theta_d, |phi_d|)."""
    return model.kind == "brdf" and [v.name for v in model.variables] == BRDF_VARIABLES_3D
