"""Colour constants shared by the fitter: the Rec.709 luminance weights of linear RGB.

``LUMINANCE @ rgb`` is the luminance Y of a linear Rec.709 RGB triple (reflectance in 1/sr
stays in 1/sr). Used where a scalar stands for an RGB BRDF: the absolute floor of the BRDF fit
(:mod:`fit.rational.brdf_fit`), the sampling tables and the variance gate (:mod:`fit.sampling`).
"""
from __future__ import annotations

import numpy as np

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec.709
