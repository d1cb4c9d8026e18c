"""``uniform`` technique: uniform hemisphere around the normal (local frame, z = normal), exact
density 1 / (2 pi) in 1/sr."""
from __future__ import annotations

import numpy as np
import warp as wp

from .. import fastmath as fmath
from ..materials.data import Materials


@wp.func
def sample_uniform_hemisphere(u: wp.vec2) -> wp.vec3:
    z = u[0]
    r = wp.sqrt(fmath.fmax(0.0, 1.0 - z * z))
    phi = 2.0 * wp.pi * u[1]
    return wp.vec3(r * wp.cos(phi), r * wp.sin(phi), z)


@wp.func
def pdf_uniform_hemisphere(w: wp.vec3) -> float:
    if w[2] > 0.0:
        return 1.0 / (2.0 * wp.pi)
    return 0.0


@wp.func
def sample(mats: Materials, m: int, wo: wp.vec3, xi: wp.vec2) -> wp.vec4:
    w = sample_uniform_hemisphere(xi)
    return wp.vec4(w[0], w[1], w[2], 1.0 / pdf_uniform_hemisphere(w))


@wp.func
def pdf(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> float:
    return pdf_uniform_hemisphere(wi)


def kernel_functions(cdfs=()):
    return sample, pdf


def numpy_sample(cdf, wo, xi):
    """NumPy reference of :func:`sample`: ``(wi (N, 3), weight (N,))``."""
    xi = np.asarray(xi, float)
    z, phi = xi[:, 0], 2.0 * np.pi * xi[:, 1]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1), np.full(len(z), 2.0 * np.pi)


def numpy_pdf(cdf, wi, wo):
    return np.where(np.asarray(wi, float)[:, 2] > 0, 1.0 / (2.0 * np.pi), 0.0)
