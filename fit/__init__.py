"""warp-rbrdf fitter: measured isotropic BRDFs, their (theta_h, theta_d) projection and
rational-function fits with an error guaranteed at their data points. Pure NumPy/SciPy; never imports Warp.

Sub-packages: :mod:`fit.formats` (measured-BRDF files and types), :mod:`fit.projection`,
:mod:`fit.rational` (rational functions, the interval fitter, coefficient files, ``fit_brdf``),
:mod:`fit.sampling` (tabulated and rational inverse CDFs, ``fit_cdf``), :mod:`fit.cli`
(``rbrdf-fit``).

The public API below keeps ``import fit`` cheap: ``fit_brdf``, ``fit_cdf`` and ``load_cdf``
(SciPy's optimizer and interpolators) are imported on first use.
"""
from .errors import BRDFFileError, FlagError, OutputError, RbrdfError
from .formats import load_measured
from .formats.measured import MeasuredBRDF
from .lazy import lazy_attributes
from .projection.project import project
from .projection.projected import ProjectedBRDF
from .rational.coefficient_file import load as load_coefficients

__all__ = ["BRDFFileError", "FlagError", "OutputError", "RbrdfError", "MeasuredBRDF", "ProjectedBRDF", "load_measured", "project",
           "fit_brdf", "fit_cdf", "load_coefficients", "load_cdf"]
__version__ = "0.1.0"

_LAZY = {"fit_brdf": ("fit.rational.brdf_fit", "fit_brdf"),
         "fit_cdf": ("fit.sampling.cdf_file", "fit_cdf"),
         "load_cdf": ("fit.sampling.cdf_file", "load")}


__getattr__ = lazy_attributes(__name__, _LAZY, globals())
