"""What a fit looks like, checked inside the fitter: the CIE ΔE2000 between the images of a
virtual sphere shaded with a fit and with its measurement, under fixed generic lights
(:func:`image_delta_e`).

The scene: a unit sphere seen orthographically along +z, ``n`` x ``n`` pixels over its disc
(the pixels' view directions are cosine-distributed over the hemisphere of normals, as on the
renderer's reference sphere); ``k`` directional lights on a Fibonacci sphere (world directions),
a sky brighter towards +y with a per-light texture and one sun that carries most of the light
(:data:`DEFAULT_SUN` times the sky's radiance in its one direction: 82 % of the light, as
a clear day's sun or a studio's key lamp), seeded: no environment map of the project, so the
check is held out from every render it predicts. Pixel
value (linear Rec.709 RGB): ``sum_k rho(wi_k, wo) cos(theta_i,k) L_k (4 pi / k)`` over the lights
above the pixel's horizon, in the pixel's local frame (isotropic BRDFs: any tangent frame).
Exposure: the truth image's 99th-percentile luminance is L* = 100 (as the studies measure).

The colour difference is CIEDE2000 (Sharma, Wu and Dalal 2005) of CIE Lab under D65 from linear
Rec.709 primaries, computed here in NumPy (the fitter does not import the studies or
colour-science; tests/test_image_check.py compares it with colour-science).

Measured (docs/fit_accuracy.md, "A check with a sun"): over 60 fits of the 20 RGL materials
(three layouts and objectives each), its score ``mean + p99 / 3`` ranks the fits as their
1,024-spp renders under the chart's two environment maps do with Spearman 0.88 (0.45 with a sun
of 40, a third of the light), and the fit it ranks first is the renders' best on 18 of the 20
materials (16 with the sun of 40). The worst pixels of the renders are the terminator under the
maps' suns (docs/fit_accuracy.md, "Where the p99 misses come from"); a sky-dominated check
does not see them.
"""
from __future__ import annotations

import numpy as np

from ..formats.colour import LUMINANCE

#: Rec.709 / sRGB primaries and the D65 white (CIE xy).
_PRIMARIES = np.array([[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]])
_WHITE = np.array([0.3127, 0.3290])
DEFAULT_PIXELS = 40
DEFAULT_LIGHTS = 192
DEFAULT_SEEDS = (1, 2, 3)
#: The sun's radiance over the sky's (the sky 0.13-1.2 per light direction; 192 directions): the sun
#: carries 82 % of the light (32 % at 40). Chosen from 40, 150, 400 and 1,000 by the rank correlation with
#: the chart's renders (module docstring: 0.45, 0.76, 0.88, 0.86).
DEFAULT_SUN = 400.0


def _xyz(xy):
    x, y = xy[..., 0], xy[..., 1]
    return np.stack([x / y, np.ones_like(x), (1 - x - y) / y], axis=-1)


def _rgb_to_xyz_matrix() -> np.ndarray:
    P = _xyz(_PRIMARIES).T                      # columns: the primaries' XYZ at Y = 1
    s = np.linalg.solve(P, _xyz(_WHITE))        # scales so that RGB = 1 is the white
    return P * s[None, :]


RGB_TO_XYZ = _rgb_to_xyz_matrix()
WHITE_XYZ = _xyz(_WHITE)


def rgb_to_lab(rgb, exposure: float = 1.0) -> np.ndarray:
    """CIE Lab (D65) of linear Rec.709 RGB ``(..., 3)`` scaled by ``exposure``."""
    xyz = (np.asarray(rgb, np.float64) * exposure) @ RGB_TO_XYZ.T / WHITE_XYZ
    d = 6.0 / 29.0
    f = np.where(xyz > d ** 3, np.cbrt(np.maximum(xyz, d ** 3)), xyz / (3 * d * d) + 4.0 / 29.0)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], axis=-1)


def delta_e2000(lab1, lab2) -> np.ndarray:
    """CIEDE2000 colour difference of two CIE Lab arrays ``(..., 3)`` (kL = kC = kH = 1)."""
    L1, a1, b1 = np.moveaxis(np.asarray(lab1, np.float64), -1, 0)
    L2, a2, b2 = np.moveaxis(np.asarray(lab2, np.float64), -1, 0)
    C1, C2 = np.hypot(a1, b1), np.hypot(a2, b2)
    Cm7 = ((C1 + C2) / 2) ** 7
    G = 0.5 * (1 - np.sqrt(Cm7 / (Cm7 + 25.0 ** 7)))
    a1p, a2p = (1 + G) * a1, (1 + G) * a2
    C1p, C2p = np.hypot(a1p, b1), np.hypot(a2p, b2)
    h1p = np.degrees(np.arctan2(b1, a1p)) % 360
    h2p = np.degrees(np.arctan2(b2, a2p)) % 360
    dLp = L2 - L1
    dCp = C2p - C1p
    zero = (C1p * C2p) == 0
    dh = h2p - h1p
    dh = np.where(dh > 180, dh - 360, np.where(dh < -180, dh + 360, dh))
    dh = np.where(zero, 0.0, dh)
    dHp = 2 * np.sqrt(C1p * C2p) * np.sin(np.radians(dh) / 2)
    Lpm = (L1 + L2) / 2
    Cpm = (C1p + C2p) / 2
    hsum = h1p + h2p
    hpm = np.where(zero, hsum, np.where(np.abs(h1p - h2p) <= 180, hsum / 2,
                                        np.where(hsum < 360, (hsum + 360) / 2, (hsum - 360) / 2)))
    T = (1 - 0.17 * np.cos(np.radians(hpm - 30)) + 0.24 * np.cos(np.radians(2 * hpm))
         + 0.32 * np.cos(np.radians(3 * hpm + 6)) - 0.20 * np.cos(np.radians(4 * hpm - 63)))
    dtheta = 30 * np.exp(-(((hpm - 275) / 25) ** 2))
    Cpm7 = Cpm ** 7
    RC = 2 * np.sqrt(Cpm7 / (Cpm7 + 25.0 ** 7))
    SL = 1 + 0.015 * (Lpm - 50) ** 2 / np.sqrt(20 + (Lpm - 50) ** 2)
    SC = 1 + 0.045 * Cpm
    SH = 1 + 0.015 * Cpm * T
    RT = -np.sin(np.radians(2 * dtheta)) * RC
    return np.sqrt((dLp / SL) ** 2 + (dCp / SC) ** 2 + (dHp / SH) ** 2 + RT * (dCp / SC) * (dHp / SH))


def tangent_frames(normals) -> np.ndarray:
    """``(3, P, 3)``: tangent, bitangent and normal (world unit vectors) of each unit normal
    ``(P, 3)``; any tangent serves an isotropic BRDF."""
    nrm = np.asarray(normals, np.float64)
    a = np.where(np.abs(nrm[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    t = np.cross(a, nrm)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return np.stack([t, np.cross(nrm, t), nrm])


def sphere_views(n: int = DEFAULT_PIXELS):
    """``(frames (3, P, 3), wo (P, 3))``: per pixel of the sphere's disc (``n`` x ``n``) its local
    frame (:func:`tangent_frames`) and the view direction in it."""
    c = (np.arange(n) + 0.5) / n * 2 - 1
    x, y = np.meshgrid(c, -c)
    inside = x * x + y * y < 1
    frames = tangent_frames(np.stack([x[inside], y[inside], np.sqrt(1 - x[inside] ** 2 - y[inside] ** 2)], axis=1))
    return frames, frames[:, :, 2].T.copy()            # the view (0, 0, 1) in each frame


def generic_lights(seed: int, k: int = DEFAULT_LIGHTS, sun: float = DEFAULT_SUN):
    """``(dirs (k, 3), radiance (k, 3))``: the module docstring's lights, each radiance times its
    solid angle ``4 pi / k``; one of them (seeded) holds the sun, ``sun`` more radiance."""
    rng = np.random.default_rng(seed)
    i = np.arange(k) + 0.5
    z = 1 - 2 * i / k
    r = np.sqrt(1 - z * z)
    ph = np.pi * (1 + 5 ** 0.5) * i
    d = np.stack([r * np.cos(ph), r * np.sin(ph), z], axis=1)
    L = (0.3 + 0.7 * np.clip(d[:, 1], 0, 1))[:, None] * np.array([[0.8, 0.9, 1.0]])
    L = L * (0.5 + rng.random((k, 1)))
    L[rng.integers(k)] += sun * np.array([1.0, 0.95, 0.85])
    return d, L * (4 * np.pi / k)


def sphere_image(evaluate, dirs, radiance, views) -> np.ndarray:
    """``(P, 3)`` linear RGB of the sphere's pixels: ``evaluate(wi (M, 3), wo (M, 3)) -> (M, 3)``
    (1/sr, local frames) under the lights ``dirs``, ``radiance`` (:func:`generic_lights`)."""
    frames, wo = views
    wi = np.einsum("kj,fpj->kpf", dirs, frames)          # (K, P, 3): each light in each pixel's frame
    kk, pp = np.nonzero(wi[..., 2] > 1e-4)
    w = wi[kk, pp]
    f = np.maximum(np.asarray(evaluate(w, wo[pp]), np.float64), 0.0)
    img = np.zeros((len(wo), 3))
    np.add.at(img, pp, f * w[:, 2:3] * radiance[kk])
    return img


def image_delta_e(truth, fit, n: int = DEFAULT_PIXELS, k: int = DEFAULT_LIGHTS, seeds=DEFAULT_SEEDS,
                  sun: float = DEFAULT_SUN) -> dict:
    """``{"mean", "p99", "pixels", "lights", "seeds", "sun"}``: ΔE2000 of the sphere images of ``fit``
    against ``truth`` (each ``evaluate(wi, wo) -> rho (M, 3)``), the mean and the 99th percentile
    over the pixels, each averaged over the light sets of ``seeds`` (module docstring)."""
    views = sphere_views(n)
    means, p99s = [], []
    for s in seeds:
        dirs, L = generic_lights(s, k, sun)
        ref = sphere_image(truth, dirs, L, views)
        img = sphere_image(fit, dirs, L, views)
        Y = np.percentile(ref @ LUMINANCE, 99.0)
        expo = 1.0 / Y if Y > 0 else 1.0
        de = delta_e2000(rgb_to_lab(img, expo), rgb_to_lab(ref, expo))
        means.append(float(de.mean()))
        p99s.append(float(np.percentile(de, 99)))
    return {"mean": float(np.mean(means)), "p99": float(np.mean(p99s)), "pixels": int(n), "lights": int(k),
            "seeds": [int(s) for s in seeds], "sun": float(sun)}


def image_check(brdf, model, **kw) -> dict:
    """:func:`image_delta_e` of a 3-D rational ``model`` against an RGL ``brdf`` (its reference
    evaluation, light = ``wi``)."""
    from .variables3d import evaluate_directions

    return image_delta_e(lambda wi, wo: brdf.evaluate(wi, wo), lambda wi, wo: evaluate_directions(model, wi, wo), **kw)
