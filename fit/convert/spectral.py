"""RGB -> reflectance spectrum upsampling for spectral RGL-EPFL ``.bsdf`` files (the ``spectra``
and ``wavelengths`` fields that pbrt-v4's ``MeasuredBxDF`` and Mitsuba 3's spectral
``measured`` plugin read).

**Colour model.** A spectrum is stored at ``N`` wavelengths ``lambda_j`` (nm, increasing); both
readers interpolate it linearly between them and hold the end values outside (their
``PiecewiseLinear2D`` / ``Warp2D3`` parameter look-ups clamp). Its linear sRGB (Rec.709
primaries, D65 white) is that piecewise-linear spectrum ``s(lambda)`` seen under the CIE D65
illuminant by the CIE 1931 2-degree observer::

    XYZ = sum_l s(l) D65(l) cmf(l) / sum_l D65(l) ybar(l),   l = 360, 361, ..., 830 nm
    rgb = XYZ_TO_SRGB @ XYZ, rows rescaled so that s = 1 gives exactly (1, 1, 1)

(:func:`projection`, a ``(3, N)`` matrix; the tables below are interpolated linearly from 5 nm
to 1 nm). D65 is the white of sRGB and what both renderers' spectral modes multiply an RGB
light by (Mitsuba's ``srgb_d65`` emitter spectra, pbrt-v4's ``RGBIlluminantSpectrum``), so a
material upsampled here keeps its RGB colour under an RGB white light.

**Upsampling** (:func:`upsample`): the sigmoid-polynomial model of Jakob & Hanika 2019 ("A
low-dimensional function space for efficient spectral upsampling", the one pbrt-v4 itself uses
for unbounded RGB values, ``RGBUnboundedSpectrum``). For a node of linear sRGB ``c >= 0``,
``m = max(c)``::

    s(lambda) = 2 m S(a x^2 + b x + d),  x = (lambda - 360) / 470,  S(z) = 1/2 + z / (2 sqrt(1 + z^2))

with ``(a, b, d)`` found per node by damped Gauss-Newton so that the **tabulated** spectrum
(the values at the ``N`` wavelengths, as the readers interpolate them) projects back onto
``c``: ``projection(lambda) @ s = c``. The spectrum is smooth (three parameters),
non-negative and at most ``2 m`` by construction; it depends only on the chromaticity of
``c`` (it scales with ``m``), and since the readers interpolate linearly, any interpolated
spectrum projects onto the interpolated RGB. Colours at the edge of the sRGB gamut (a channel
near 0) cannot be reached exactly by a positive smooth spectrum: :func:`round_trip` measures
the residual (docs/interop.md states it for the RGL-EPFL materials).

Shapes: ``rgb`` ``(..., 3)``, spectra ``(..., N)``, wavelengths ``(N,)`` in nm.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Wavelength range of the tables and of the default sampling (nm): both renderers sample
#: wavelengths in [360, 830] nm.
LAMBDA_MIN = 360.0
LAMBDA_MAX = 830.0
#: Default number of wavelengths: 10 nm steps over [360, 830] nm.
DEFAULT_N_WAVELENGTHS = 48

#: CIE 1931 2-degree colour matching functions xbar, ybar, zbar (CIE 018:2019 / ISO 11664-1,
#: 5 nm) and the CIE D65 relative spectral power (CIE S 014-2 / ISO 11664-2, 5 nm; 785-830 nm
#: from the CIE daylight basis at the D65 CCT, scaled to the table at 780 nm):
#: (lambda nm, xbar, ybar, zbar, D65). Values from the published tables as tabulated by the
#: colour-science package 0.4.7.
CIE_5NM = np.array([
    (360, 0.0001299, 3.917e-06, 0.0006061, 46.6383),
    (365, 0.0002321, 6.965e-06, 0.001086, 49.3637),
    (370, 0.0004149, 1.239e-05, 0.001946, 52.0891),
    (375, 0.0007416, 2.202e-05, 0.003486, 51.0323),
    (380, 0.001368, 3.9e-05, 0.00645, 49.9755),
    (385, 0.002236, 6.4e-05, 0.01055, 52.3118),
    (390, 0.004243, 0.00012, 0.02005, 54.6482),
    (395, 0.00765, 0.000217, 0.03621, 68.7015),
    (400, 0.01431, 0.000396, 0.06785, 82.7549),
    (405, 0.02319, 0.00064, 0.1102, 87.1204),
    (410, 0.04351, 0.00121, 0.2074, 91.4860),
    (415, 0.07763, 0.00218, 0.3713, 92.4589),
    (420, 0.13438, 0.004, 0.6456, 93.4318),
    (425, 0.21477, 0.0073, 1.03905, 90.0570),
    (430, 0.2839, 0.0116, 1.3856, 86.6823),
    (435, 0.3285, 0.01684, 1.62296, 95.7736),
    (440, 0.34828, 0.023, 1.74706, 104.8650),
    (445, 0.34806, 0.0298, 1.7826, 110.9360),
    (450, 0.3362, 0.038, 1.77211, 117.0080),
    (455, 0.3187, 0.048, 1.7441, 117.4100),
    (460, 0.2908, 0.06, 1.6692, 117.8120),
    (465, 0.2511, 0.0739, 1.5281, 116.3360),
    (470, 0.19536, 0.09098, 1.28764, 114.8610),
    (475, 0.1421, 0.1126, 1.0419, 115.3920),
    (480, 0.09564, 0.13902, 0.81295, 115.9230),
    (485, 0.05795, 0.1693, 0.6162, 112.3670),
    (490, 0.03201, 0.20802, 0.46518, 108.8110),
    (495, 0.0147, 0.2586, 0.3533, 109.0820),
    (500, 0.0049, 0.323, 0.272, 109.3540),
    (505, 0.0024, 0.4073, 0.2123, 108.5780),
    (510, 0.0093, 0.503, 0.1582, 107.8020),
    (515, 0.0291, 0.6082, 0.1117, 106.2960),
    (520, 0.06327, 0.71, 0.07825, 104.7900),
    (525, 0.1096, 0.7932, 0.05725, 106.2390),
    (530, 0.1655, 0.862, 0.04216, 107.6890),
    (535, 0.22575, 0.91485, 0.02984, 106.0470),
    (540, 0.2904, 0.954, 0.0203, 104.4050),
    (545, 0.3597, 0.9803, 0.0134, 104.2250),
    (550, 0.43345, 0.99495, 0.00875, 104.0460),
    (555, 0.51205, 1, 0.00575, 102.0230),
    (560, 0.5945, 0.995, 0.0039, 100.0000),
    (565, 0.6784, 0.9786, 0.00275, 98.1671),
    (570, 0.7621, 0.952, 0.0021, 96.3342),
    (575, 0.8425, 0.9154, 0.0018, 96.0611),
    (580, 0.9163, 0.87, 0.00165, 95.7880),
    (585, 0.9786, 0.8163, 0.0014, 92.2368),
    (590, 1.0263, 0.757, 0.0011, 88.6856),
    (595, 1.0567, 0.6949, 0.001, 89.3459),
    (600, 1.0622, 0.631, 0.0008, 90.0062),
    (605, 1.0456, 0.5668, 0.0006, 89.8026),
    (610, 1.0026, 0.503, 0.00034, 89.5991),
    (615, 0.9384, 0.4412, 0.00024, 88.6489),
    (620, 0.85445, 0.381, 0.00019, 87.6987),
    (625, 0.7514, 0.321, 0.0001, 85.4936),
    (630, 0.6424, 0.265, 5e-05, 83.2886),
    (635, 0.5419, 0.217, 3e-05, 83.4939),
    (640, 0.4479, 0.175, 2e-05, 83.6992),
    (645, 0.3608, 0.1382, 1e-05, 81.8630),
    (650, 0.2835, 0.107, 2.11758e-22, 80.0268),
    (655, 0.2187, 0.0816, 0, 80.1207),
    (660, 0.1649, 0.061, 0, 80.2146),
    (665, 0.1212, 0.04458, 0, 81.2462),
    (670, 0.0874, 0.032, 0, 82.2778),
    (675, 0.0636, 0.0232, 0, 80.2810),
    (680, 0.04677, 0.017, 0, 78.2842),
    (685, 0.0329, 0.01192, 0, 74.0027),
    (690, 0.0227, 0.00821, 0, 69.7213),
    (695, 0.01584, 0.005723, 0, 70.6652),
    (700, 0.0113592, 0.004102, 0, 71.6091),
    (705, 0.00811092, 0.002929, 0, 72.9790),
    (710, 0.00579035, 0.002091, 0, 74.3490),
    (715, 0.00410946, 0.001484, 0, 67.9765),
    (720, 0.00289933, 0.001047, 0, 61.6040),
    (725, 0.00204919, 0.00074, 0, 65.7448),
    (730, 0.00143997, 0.00052, 0, 69.8856),
    (735, 0.000999949, 0.0003611, 0, 72.4863),
    (740, 0.000690079, 0.0002492, 0, 75.0870),
    (745, 0.000476021, 0.0001719, 0, 69.3398),
    (750, 0.000332301, 0.00012, 0, 63.5927),
    (755, 0.000234826, 8.48e-05, 0, 55.0054),
    (760, 0.000166151, 6e-05, 0, 46.4182),
    (765, 0.000117413, 4.24e-05, 0, 56.6118),
    (770, 8.30753e-05, 3e-05, 0, 66.8054),
    (775, 5.87065e-05, 2.12e-05, 0, 65.0941),
    (780, 4.15099e-05, 1.499e-05, 0, 63.3828),
    (785, 2.93533e-05, 1.06e-05, 0, 63.8433),
    (790, 2.06738e-05, 7.4657e-06, 0, 64.3038),
    (795, 1.45598e-05, 5.2578e-06, 0, 61.8779),
    (800, 1.0254e-05, 3.7029e-06, 0, 59.4520),
    (805, 7.22146e-06, 2.6078e-06, 0, 55.7058),
    (810, 5.08587e-06, 1.8366e-06, 0, 51.9595),
    (815, 3.58165e-06, 1.2934e-06, 0, 54.7002),
    (820, 2.52252e-06, 9.1093e-07, 0, 57.4409),
    (825, 1.77651e-06, 6.4153e-07, 0, 58.8768),
    (830, 1.25114e-06, 4.5181e-07, 0, 60.3127),
])

#: CIE XYZ -> linear sRGB (IEC 61966-2-1:1999).
XYZ_TO_SRGB = np.array([[3.2406, -1.5372, -0.4986],
                        [-0.9689, 1.8758, 0.0415],
                        [0.0557, -0.2040, 1.0570]])

_FINE = np.arange(LAMBDA_MIN, LAMBDA_MAX + 0.5, 1.0)


def default_wavelengths(n: int = DEFAULT_N_WAVELENGTHS) -> np.ndarray:
    """``n`` wavelengths (nm, float32) uniform over [360, 830] nm, ends included."""
    return np.linspace(LAMBDA_MIN, LAMBDA_MAX, int(n)).astype(np.float32)


def _weights() -> np.ndarray:
    """(F, 3): linear-sRGB weights of the 1 nm grid (D65 x CMFs, XYZ -> sRGB, white = 1)."""
    lam = CIE_5NM[:, 0]
    cmf = np.stack([np.interp(_FINE, lam, CIE_5NM[:, k]) for k in (1, 2, 3)], axis=-1)
    d65 = np.interp(_FINE, lam, CIE_5NM[:, 4])
    xyz = cmf * d65[:, None] / np.sum(d65 * cmf[:, 1])
    w = xyz @ XYZ_TO_SRGB.T
    return w / w.sum(axis=0)                 # a constant spectrum 1 -> rgb (1, 1, 1)


def projection(wavelengths) -> np.ndarray:
    """``(3, N)`` matrix: linear sRGB of the spectrum tabulated at ``wavelengths`` (nm,
    strictly increasing) and interpolated linearly between them, held constant outside."""
    lam = np.asarray(wavelengths, np.float64)
    if lam.ndim != 1 or lam.size < 2 or np.any(np.diff(lam) <= 0):
        raise ValueError("wavelengths must be a strictly increasing 1-D array of at least 2 values")
    eye = np.eye(lam.size)
    hat = np.stack([np.interp(_FINE, lam, eye[j]) for j in range(lam.size)], axis=-1)   # (F, N)
    return _weights().T @ hat


def to_rgb(spectra, wavelengths) -> np.ndarray:
    """Linear sRGB ``(..., 3)`` of ``spectra`` ``(..., N)`` tabulated at ``wavelengths``."""
    return np.asarray(spectra, np.float64) @ projection(wavelengths).T


def _sigmoid(z):
    r = 1.0 / np.sqrt(1.0 + z * z)
    return 0.5 + 0.5 * z * r, 0.5 * r * r * r        # S, dS/dz


def fit_coefficients(target, wavelengths, iterations: int = 60, tol: float = 1e-7):
    """Sigmoid-polynomial coefficients ``(..., 3)`` (a, b, d) whose tabulated spectrum
    ``S(a x^2 + b x + d)`` projects onto ``target`` ``(..., 3)`` (linear sRGB in [0, 1)).
    Damped Gauss-Newton (Levenberg-Marquardt, one damping per colour) from the grey 0.5."""
    lam = np.asarray(wavelengths, np.float64)
    a_mat = projection(lam)                                                  # (3, N)
    x = (lam - LAMBDA_MIN) / (LAMBDA_MAX - LAMBDA_MIN)
    basis = np.stack([x * x, x, np.ones_like(x)], axis=-1)                  # (N, 3)
    t = np.asarray(target, np.float64).reshape(-1, 3)
    coef = np.zeros_like(t)
    mu = np.full(len(t), 1e-3)

    def residual(c, tt):
        s, ds = _sigmoid(c @ basis.T)
        return s @ a_mat.T - tt, ds

    r, ds = residual(coef, t)
    err = np.abs(r).max(axis=1)
    for _ in range(int(iterations)):
        act = err > tol
        if not act.any():
            break
        jac = np.einsum("kj,nj,jl->nkl", a_mat, ds[act], basis)              # (n, 3, 3)
        jt = np.swapaxes(jac, 1, 2)
        jtj = jt @ jac
        lhs = jtj + mu[act, None, None] * (np.eye(3) * np.diagonal(jtj, axis1=1, axis2=2)[:, None, :]
                                           + 1e-12 * np.eye(3))
        step = np.linalg.solve(lhs, -(jt @ r[act][..., None]))[..., 0]
        trial = coef[act] + step
        r_new, ds_new = residual(trial, t[act])
        e_new = np.abs(r_new).max(axis=1)
        better = e_new < err[act]
        idx = np.flatnonzero(act)
        good = idx[better]
        coef[good], r[good], ds[good], err[good] = trial[better], r_new[better], ds_new[better], e_new[better]
        mu[good] = np.maximum(mu[good] / 3.0, 1e-9)
        mu[idx[~better]] *= 4.0
    return coef.reshape(np.shape(target)), basis


def upsample(rgb, wavelengths, iterations: int = 60) -> np.ndarray:
    """Smooth non-negative spectra ``(..., N)`` (same unit as ``rgb``) at ``wavelengths``
    (nm) of the linear sRGB values ``rgb`` ``(..., 3)`` (negative channels count as 0); the
    module docstring gives the model. Zero RGB gives a zero spectrum."""
    c = np.maximum(np.asarray(rgb, np.float64), 0.0)
    m = c.max(axis=-1, keepdims=True)
    scale = 2.0 * m
    safe = np.where(scale > 0, scale, 1.0)
    coef, basis = fit_coefficients(c / safe, wavelengths, iterations)
    s, _ = _sigmoid(coef @ basis.T)
    return np.where(scale > 0, scale * s, 0.0)


@dataclass
class RoundTrip:
    """The colour kept by an upsampling: spectra projected back (:func:`to_rgb`) against the
    RGB they were made from, relative to each colour's largest channel, over the colours whose
    largest channel is at least 1e-3 of the overall largest (``n`` of them): ``rel_max``,
    ``rel_p99``, ``rel_mean``."""

    n: int
    rel_max: float
    rel_p99: float
    rel_mean: float

    def describe(self) -> str:
        return (f"RGB -> spectrum -> sRGB round trip over {self.n} nodes: max {100 * self.rel_max:.3g} %, "
                f"p99 {100 * self.rel_p99:.3g} %, mean {100 * self.rel_mean:.3g} % of the node's largest channel")


def round_trip(rgb, spectra, wavelengths) -> RoundTrip:
    """:class:`RoundTrip` of ``spectra`` ``(..., N)`` against ``rgb`` ``(..., 3)``."""
    c = np.maximum(np.asarray(rgb, np.float64), 0.0).reshape(-1, 3)
    back = to_rgb(spectra, wavelengths).reshape(-1, 3)
    m = c.max(axis=1)
    keep = m >= 1e-3 * max(float(m.max(initial=0.0)), 1e-300)
    if not keep.any():
        return RoundTrip(0, 0.0, 0.0, 0.0)
    rel = np.abs(back[keep] - c[keep]).max(axis=1) / m[keep]
    return RoundTrip(int(keep.sum()), float(rel.max()), float(np.percentile(rel, 99)), float(rel.mean()))
