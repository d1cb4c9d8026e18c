"""Exports of a rational BRDF fit (``rbrdf-rational`` coefficient files,
:mod:`fit.rational.coefficient_file`) for tools that do not have this project installed:

* :func:`to_glsl` (:mod:`fit.export.glsl`): a self-contained GLSL function;
* :func:`to_c` (:mod:`fit.export.c_source`): the same in C99 / C++ (float or double);
* :func:`to_hlsl` (:mod:`fit.export.hlsl`): the same in HLSL;
* :func:`to_brdf_explorer` (:mod:`fit.export.brdf_explorer`): a Disney BRDF Explorer
  ``.brdf`` file (``analytic``) embedding the GLSL;
* :func:`to_mitsuba_plugin` / :func:`fit.export.mitsuba_plugin.register`
  (:mod:`fit.export.mitsuba_plugin`): a Mitsuba 3 BSDF plugin (Python, ``mi.register_bsdf``).

Both kinds of fit are exported: 2-D fits of (theta_h, theta_d) (file versions 1 and 2) and 3-D
fits of (theta_h, theta_d, |phi_d|) (version 3, :mod:`fit.rational.variables3d`; not reciprocal,
so every exported function takes the light's direction first and the viewer's second; version 4:
their functions give rho cos theta_i, and every export divides by max(cos theta_i, 1e-3), the
recipe's step 8, :mod:`fit.export.emitter`). The
GLSL, HLSL and C code come from one statement emitter (:mod:`fit.export.emitter`) that follows
the file's evaluation recipe, on the fit's measured domain when it records the grazing cut-off
of its projection (:mod:`fit.rational.domain`, the renderer's rule: no extrapolation where the
fit has no data; fits without a recorded cut-off export as before); the Mitsuba plugin's
runtime does the same in Dr.Jit. The domain and clamp policy of every export is in its header
and in docs/exports.md, with the measured agreement against the NumPy evaluation. Text of the
fit (its name, source, tolerance record, channel names) reaches generated code only through
:mod:`fit.export.escape` (quoted inert forms in comments and docstrings, ASCII literals,
identifiers of letters and digits).
"""
from __future__ import annotations

from .brdf_explorer import to_brdf_explorer
from .c_source import to_c
from .emitter import ExportError
from .glsl import to_glsl
from .hlsl import to_hlsl
from .mitsuba_plugin import to_mitsuba_plugin

__all__ = ["ExportError", "to_brdf_explorer", "to_c", "to_glsl", "to_hlsl", "to_mitsuba_plugin"]
