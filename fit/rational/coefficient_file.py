"""Versioned JSON coefficient files of fitted rational functions, format ``rbrdf-rational``:
version 1 (one function per output), version 2 (pieces along one variable), version 3 (3-D
BRDF fits of theta_h, theta_d, |phi_d|) and version 4 (version 3 whose functions give rho cos
theta_i). The format, its evaluation recipe (steps 1-8: clamp, transform, map, Chebyshev basis,
value, output clamp, range, value factor) and what a reader checks are
specified in docs/formats.md ("Rational coefficients").

The public face of the format, one module per concern:

* :mod:`fit.rational.coefficient_format`: :data:`FORMAT`, the versions, :data:`BRDF_VARIABLES_3D`;
* :mod:`fit.rational.coefficient_writer`: :func:`to_dict`, :func:`jsonable`, :func:`save`;
* :mod:`fit.rational.coefficient_reader`: :func:`from_dict`, :func:`load` (every value checked);
* :mod:`fit.rational.coefficient_certify`: :func:`recertify` (Q > 0 and the value bound proved
  again on load).
"""
from __future__ import annotations

from .coefficient_certify import recertify
from .coefficient_format import (BRDF_VARIABLES_3D, FORMAT, VERSION, VERSION_3D, VERSION_3D_FACTOR, VERSION_PIECEWISE,
                                 VERSIONS)
from .coefficient_reader import from_dict, load
from .coefficient_writer import jsonable, save, to_dict

__all__ = ["BRDF_VARIABLES_3D", "FORMAT", "VERSION", "VERSIONS", "VERSION_3D", "VERSION_3D_FACTOR", "VERSION_PIECEWISE",
           "from_dict", "jsonable", "load", "recertify", "save", "to_dict"]
