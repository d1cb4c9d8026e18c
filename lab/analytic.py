"""Analytic reference BRDFs, in 1/sr, RGB: used to build exact-layout MERL files
(``fit.formats.measured.MeasuredBRDF.from_function`` + ``fit.formats.merl.write_merl``) and in the
tests and benchmarks.

Each factory returns ``f(wi, wo) -> (..., 3)`` for unit direction arrays ``(..., 3)`` in the local
frame (z = normal). Pure NumPy.
"""
from __future__ import annotations

import numpy as np

from fit.formats.angles import directions_to_half_diff
from fit.rational.variables3d import half_diff_3d


def lambert(albedo=(0.8, 0.5, 0.2)):
    """Lambertian BRDF ``albedo / pi`` (constant, RGB)."""
    a = np.asarray(albedo, float) / np.pi

    def f(wi, wo):
        shape = np.broadcast_shapes(np.shape(wi), np.shape(wo))[:-1]
        return np.broadcast_to(a, shape + (3,))

    return f


def glossy_lobe(exponent=80.0, kd=(0.05, 0.04, 0.03), ks=(0.6, 0.7, 0.8), phi_mod=0.0):
    """Blinn-Phong-like lobe in theta_h, with an optional cos(2 phi_d) term that makes the
    value depend on phi_d (reciprocal: invariant under phi_d -> phi_d + pi)."""
    kd = np.asarray(kd, float) / np.pi
    ks = np.asarray(ks, float) * (exponent + 2) / (2 * np.pi)

    def f(wi, wo):
        th, _, td, pd = directions_to_half_diff(wi, wo)
        lobe = np.cos(np.clip(th, 0, np.pi / 2)) ** exponent
        mod = 1.0 + phi_mod * np.cos(2 * pd) * np.sin(td)
        return (kd + ks * lobe[..., None]) * mod[..., None]

    return f


def phi_d_lobe(peak: float, width: float, td_power: int, base=(0.1, 0.15, 0.2)):
    """A diffuse ``base`` and a lobe in theta_h of height ``peak`` and width ``width`` (radians)
    that depends on phi_d (``1 + 0.3 cos phi_d``) and grows towards grazing theta_d
    (``1 + sin(theta_d)^td_power``), tinted (1, 0.9, 0.8); zero below the horizon; not
    reciprocal (the 3-D fitter's test material)."""
    base = np.array(base)

    def f(wi, wo):
        X = half_diff_3d(wi, wo)
        th, td, pd = X[..., 0], X[..., 1], X[..., 2]
        spec = peak * np.exp(-(th / width) ** 2) * (1.0 + 0.3 * np.cos(pd)) * (1.0 + np.sin(td) ** td_power)
        out = base + spec[..., None] * [1.0, 0.9, 0.8]
        above = (np.asarray(wi)[..., 2] > 0) & (np.asarray(wo)[..., 2] > 0)
        return np.where(above[..., None], out, 0.0)

    return f


class RGLLike:
    """An analytic BRDF dressed as a read RGL file for the 3-D fitter (``fit_rgl``,
    ``fit_rgl_select``, ``albedo_policy``): ``evaluate(wi, wo)`` (1/sr, RGB, (..., 3); the file's
    roles: ``wi`` the light), ``name``, the last measured incidence ``theta_i_max`` (radians,
    from ``theta_i_max_deg``) and no source file (``source``, ``source_sha256`` empty)."""

    source = ""
    source_sha256 = ""

    def __init__(self, evaluate, name: str, theta_i_max_deg: float = 80.0):
        self.evaluate = evaluate
        self.name = name
        self.theta_i_max = np.radians(theta_i_max_deg)
