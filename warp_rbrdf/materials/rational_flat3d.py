"""The evaluation of a 3-D rational fit held by a flat record (:mod:`.rational_records`: at most
:data:`~.rational_records.FLAT3_MAX_PIECES` boxes of (theta_h, theta_d, |phi_d|) in one split of
theta_h or theta_d, each of a degree class; the 3-D fitter's six theta_h pieces are one) as one
native function per set of classes (:func:`make_flat3d`): the recipe of :mod:`.rational_kernel`
without a walk and without ``atan2``, as :mod:`.rational_flat2d` does for 2-D fits.

* **Angles** (:func:`angles_3d`, :data:`ANGLES_3D_SOURCE`): theta_h and theta_d as
  :func:`.rational_flat2d.angles_2d` computes them (tangents of the half angles, one polynomial
  each); |phi_d| from the light's direction in the half vector's frame without building the
  frame: with ``s = wi + wo`` and ``d = wi - wo`` (``wi = (s + d) / 2``, and ``s`` is the half
  vector's direction), ``Y = |s| (s x d)_z`` and ``X = s_z (s . d) - |s|^2 d_z`` are that
  direction's (y, x) times ``2 |s_xy| |s|`` (> 0). Products of ``s`` and ``d`` keep their
  precision where ``wi`` and ``wo`` nearly coincide (``d`` small, exact) and where they nearly
  oppose (``s`` small, exact), and neither carries the direction's component along the half
  vector (``s . d = |wi|^2 - |wo|^2`` is the unit vectors' rounding). So ``|phi_d| =
  atan2(|Y|, X)``, taken as
  ``2 atan(|Y| / (rho + |X|))`` (rho = ``sqrt(X^2 + Y^2)``; the argument is in [0, 1]) for
  ``X >= 0`` and ``pi`` minus it for ``X < 0``, with the same polynomial. Where the half vector
  is the normal (``|s_xy|^2 <= 1e-24 |s|^2``) the frame is the shading frame's, as in
  :func:`.rational_kernel.half_diff_frame`; float32, within :data:`ANGLE_ATOL_3D` of the
  float64 angle (``tests/test_rational_classes.py``; the walk's |phi_d|, through a rotated
  frame, is up to 2e-5 off near the retro-reflection direction).
* **The piece, steps 1-7** as :mod:`.rational_flat2d` (the class sums of
  :func:`warp_rbrdf.chebyshev_dense.dense_block` in ``ta``, ``tb``, ``tc``: theta_h, theta_d,
  |phi_d|), then **step 8** (the value factor ``"1/cos_theta_i"``): the three channels divided
  by ``max(wi.z, COS_FLOOR)`` in float32, as the walk divides them.

Its values are the NumPy reference's (``fit.rational.variables3d``) at the angles of
:func:`angles_3d` within float32 rounding. The function returns ``(R, G, B, 1)``; a CUDA build
compiles the scalar form of the sums and steps (one sum per channel).
"""
from __future__ import annotations

import functools
import hashlib

import numpy as np
import warp as wp

from ..chebyshev_dense import Native, class_of_key
from .rational_flat2d import ANGLES_SOURCE, angles_2d_numpy, atan_poly_numpy, atan_poly_source, flat_source

#: |phi_d| of :func:`angles_3d` is within this of the float64 angle of the same float32
#: directions on the tests' pairs (radians; grazing, near-mirror and near-retro pairs included)
ANGLE_ATOL_3D = 1e-6

#: C++ statements: ``ang`` (``wp::vec4``: theta_h, theta_d, |phi_d|, cos theta_h cos theta_d) of
#: ``wi``, ``wo`` (the statements of :data:`.rational_flat2d.ANGLES_SOURCE`, then |phi_d|)
ANGLES_3D_SOURCE = ANGLES_SOURCE + f"""const float dx = wi.c[0] - wo.c[0], dy = wi.c[1] - wo.c[1], dz = wi.c[2] - wo.c[2];
const float sd = sx * dx + sy * dy + sz * dz;
float py = ls * (sx * dy - sy * dx), px = sz * sd - ls2 * dz;
if (rs2 <= 1.0e-24f * ls2) {{ py = wi.c[1]; px = wi.c[0]; }}
py = fabsf(py);
const float rho = sqrtf(px * px + py * py);
const float a2 = rho > 0.0f ? py / (rho + fabsf(px)) : 0.0f;
const float s2 = a2 * a2;
""" + atan_poly_source("s2", "p2") + """const float half = 2.0f * (a2 * p2);
wp::vec4 ang4(ang.c[0], ang.c[1], px >= 0.0f ? half : 3.14159265358979f - half, ang.c[2]);
return ang4;
"""


@Native.func_native(ANGLES_3D_SOURCE, "rational_angles_3d")
def angles_3d(wi: wp.vec3, wo: wp.vec3) -> wp.vec4:
    """``(theta_h, theta_d, |phi_d|, cos theta_h cos theta_d)`` of a local direction pair above
    the horizon (module docstring; radians)."""
    ...


def angles_3d_numpy(wi, wo) -> np.ndarray:
    """:func:`angles_3d` in NumPy float32 (the same operations up to fused multiply-adds)."""
    f = np.float32
    wi, wo = np.asarray(wi, f), np.asarray(wo, f)
    a2d = angles_2d_numpy(wi, wo)
    s = wi + wo
    rs2 = s[:, 0] * s[:, 0] + s[:, 1] * s[:, 1]
    ls2 = rs2 + s[:, 2] * s[:, 2]
    ls = np.sqrt(ls2)
    d = wi - wo
    sd = (s * d).sum(-1, dtype=f)
    py, px = ls * (s[:, 0] * d[:, 1] - s[:, 1] * d[:, 0]), s[:, 2] * sd - ls2 * d[:, 2]
    normal = rs2 <= f(1e-24) * ls2
    py, px = np.where(normal, wi[:, 1], py), np.where(normal, wi[:, 0], px)
    py = np.abs(py)
    rho = np.sqrt(px * px + py * py)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(rho > 0, py / (rho + np.abs(px)), f(0)).astype(f)
    half = f(2) * (a * atan_poly_numpy(a * a))
    phi = np.where(px >= 0, half, f(3.14159265358979) - half)
    return np.stack([a2d[:, 0], a2d[:, 1], phi, a2d[:, 2]], -1).astype(f)


@functools.lru_cache(maxsize=None)
def make_flat3d(keys: tuple, margin: float, scalar: bool = False):
    """``flat3d(fptr, iptr, dptr, tptr, var, ang, cos_i) -> vec4``: rho (before
    ``Materials.scale``) and 1 of the 3-D flat record whose floats start at ``fptr`` and whose
    pieces' ints start at ``iptr`` (``dptr``: the material's first float, where the dense rows'
    offsets start; ``tptr``: its fallback table; ``var``: the split variable) at the angles
    ``ang`` of :func:`angles_3d`, with step 8 at ``cos_i`` (wi.z); ``keys``: the scene's
    3-variable classes (a leaf of another class gives P = 0, Q = 1, never packed as such);
    ``margin``: the measured-domain move's (:data:`.rational_kernel.DOMAIN_MARGIN`);
    ``scalar``: the CUDA build's scalar form on every device (for tests). Cached: one function
    per tuple."""
    keys = tuple(k for k in keys if class_of_key(k)[0] == 3)
    source = flat_source(keys, margin, scalar, 3)
    name = "rational_flat3d_" + "_".join(f"{k:06x}" for k in keys) + "_" + hashlib.sha256(source.encode()).hexdigest()[:8]

    @Native.func_native(source, name)
    def flat3d(fptr: wp.uint64, iptr: wp.uint64, dptr: wp.uint64, tptr: wp.uint64, var: int,
               ang: wp.vec4, cos_i: float) -> wp.vec4:
        ...

    return flat3d
