"""The identity of the ``rbrdf-rational`` coefficient format: its name, its versions and the
variables of a 3-D BRDF (version 3). The format is specified in docs/formats.md ("Rational
coefficients"); :mod:`fit.rational.coefficient_file` is its public face.
"""
from __future__ import annotations

import hashlib
import json

FORMAT = "rbrdf-rational"
VERSION = 1            # single rational function per output
VERSION_PIECEWISE = 2  # pieces along one variable (see PiecewiseRationalModel)
VERSION_3D = 3         # a BRDF of (theta_h, theta_d, |phi_d|), single or piecewise (fit.rational.fit3d)
VERSION_3D_FACTOR = 4  # version 3 whose functions give rho cos theta_i (value factor "1/cos_theta_i", step 8):
                       # a new version so that a reader without step 8 refuses the file instead of misreading it
VERSIONS = (VERSION, VERSION_PIECEWISE, VERSION_3D, VERSION_3D_FACTOR)
#: The variables of a version-3 BRDF (fit.rational.variables3d: phi_d folded to |phi_d|).
BRDF_VARIABLES_3D = ["theta_h", "theta_d", "phi_d"]


def is_3d(model) -> bool:
    """True for a BRDF model of the version-3 variables (theta_h, theta_d, |phi_d|)."""
    return model.kind == "brdf" and [v.name for v in model.variables] == BRDF_VARIABLES_3D


#: The optional top-level key of a fit's own inverse CDFs (:mod:`fit.sampling.embedded`).
SAMPLER_KEY = "sampler"


def content_sha256(d: dict) -> str:
    """SHA-256 (hex) of a coefficient file's parsed JSON object without its :data:`SAMPLER_KEY`
    record: canonical JSON (sorted keys, no spaces, ASCII), so the written and the read-back
    object give the same digest. A sampler record names the fit it was made from by it."""
    body = {k: v for k, v in d.items() if k != SAMPLER_KEY}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    return hashlib.sha256(text.encode("ascii")).hexdigest()
