"""``cosine`` technique: cosine-weighted hemisphere around the normal (local frame, z = normal),
exact density cos(theta) / pi in 1/sr."""
from __future__ import annotations

import numpy as np
import warp as wp

from .. import fastmath as fmath
from ..materials.data import Materials


@wp.func
def sample_cosine_hemisphere(u: wp.vec2) -> wp.vec3:
    r = wp.sqrt(u[0])
    phi = 2.0 * wp.pi * u[1]
    return wp.vec3(r * wp.cos(phi), r * wp.sin(phi), wp.sqrt(fmath.fmax(0.0, 1.0 - u[0])))


@wp.func
def pdf_cosine_hemisphere(w: wp.vec3) -> float:
    return fmath.fmax(w[2], 0.0) / wp.pi


@wp.func
def sample(mats: Materials, m: int, wo: wp.vec3, xi: wp.vec2) -> wp.vec4:
    w = sample_cosine_hemisphere(xi)
    return wp.vec4(w[0], w[1], w[2], 1.0 / pdf_cosine_hemisphere(w))


@wp.func
def pdf(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> float:
    return pdf_cosine_hemisphere(wi)


def kernel_functions(cdfs=()):
    return sample, pdf


def numpy_sample(cdf, wo, xi):
    """NumPy reference of :func:`sample`: ``(wi (N, 3), weight (N,))``."""
    xi = np.asarray(xi, float)
    r, phi = np.sqrt(xi[:, 0]), 2.0 * np.pi * xi[:, 1]
    w = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1.0 - xi[:, 0]))], -1)
    return w, np.pi / np.maximum(w[:, 2], 1e-300)


def numpy_pdf(cdf, wi, wo):
    return np.maximum(np.asarray(wi, float)[:, 2], 0.0) / np.pi
