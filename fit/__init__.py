"""warp-rbrdf fitter: measured isotropic BRDFs, their (theta_h, theta_d) projection and
rational-function fits with guaranteed error. Pure NumPy/SciPy; never imports Warp."""
from .errors import BRDFFileError, RbrdfError
from .formats.grid import MERL_SHAPE
from .formats.measured import MeasuredBRDF, ProjectedBRDF

__all__ = ["BRDFFileError", "RbrdfError", "MeasuredBRDF", "ProjectedBRDF", "MERL_SHAPE"]
__version__ = "0.1.0"
