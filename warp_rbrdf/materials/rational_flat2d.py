"""The evaluation of a 2-D rational fit held by a flat record (:mod:`.rational_records`: at most
:data:`~.rational_records.FLAT_MAX_PIECES` boxes of (theta_h, theta_d) in one split or in one
split of splits, each of a degree class)
as one native function per set of classes (:func:`make_flat2d`): the recipe of
:mod:`.rational_kernel` without a walk, without ``atan2`` and without ``phi_d``.

* **Angles** (:func:`angles_2d`, :data:`ANGLES_SOURCE`): with ``s = wi + wo``, ``tan(theta_h / 2)
  = |s_xy| / (|s| + s_z)`` and ``tan(theta_d / 2) = |s x wi| / (|s| |wi| + s . wi)`` (theta_d:
  the angle between ``wi`` and the half vector, as :func:`.frame.half_diff` defines it for
  directions of any length; ``s x wi`` has no cancellation where ``wo`` is near ``-wi``), both in
  [0, 1] above the horizon, so each angle is ``2 atan(a)`` of :func:`warp_rbrdf.fastmath.atan2`'s
  polynomial on [0, 1] (by Estrin's scheme, :func:`atan_poly_source`), without its octant
  steps, a normalized half vector, a rotation into its frame or a branch; float32, within :data:`ANGLE_ATOL` of :func:`.frame.half_diff`'s values
  (``tests/test_rational_classes.py``). The measured-domain test's product ``cos theta_h cos
  theta_d`` is ``s_z (s . wi) / (|s|^2 |wi|)``.
* **The piece**: the outer piece ``k1 = #{edges < x}`` by compare-and-add over the padded edges,
  then the box ``k = first box of k1 + #{its inner edges < x2}`` in the inner split variable
  (a nested fit, e.g. the fitter's theta_h split of the first theta_d piece; +inf edges where a
  piece is one box), no branch; the box's header, ints and dense rows are read from the flat
  record's one run.
* **Steps 1-7** as :mod:`.rational_kernel` (clamp, sqrt, map, the class's sums of
  :func:`warp_rbrdf.chebyshev_dense.dense_block`, the vector steps of
  :data:`.rational_channels.VECTOR_STEPS`), the measured-domain move only near its edge
  (:data:`.rational_kernel.DOMAIN_MARGIN`), the fallback table's cluster only in a leaf that
  reads it.

Its values are the NumPy reference's (``fit.rational.vouched``) at the angles of
:func:`angles_2d` within float32 rounding. The function returns ``(R, G, B, 1)``; a CUDA build
returns ``(0, 0, 0, 0)`` (the vector types are Clang's) and the caller walks the records.
"""
from __future__ import annotations

import functools
import hashlib

import numpy as np
import warp as wp

from fit.rational.model import COS_FLOOR

from .. import fastmath
from ..chebyshev_dense import Native, class_of_key, dense_block, dense_block_scalar
from .rational_channels import MINMAX_SOURCE, SCALAR_STEPS, VECTOR_PRELUDE, VECTOR_STEPS
from .rational_records import (
    FF_BASES,
    FF_COS_CUT,
    FF_CUT,
    FF_EDGES,
    FF_INNER,
    FF_VAR2,
    FH_BOX,
    FH_VARS,
    FLAT_KINDS,
    FLAT_NI,
    LEAF_CLAMP,
    LEAF_INV_COS,
    LEAF_TABLE,
    N_FH,
)

#: |angles_2d - frame.half_diff| on the tests' pairs is within this (radians)
ANGLE_ATOL = 6e-7

#: fastmath.ATAN_COEFFS as C++ float32 literals
ATAN_LITERALS = [repr(float(np.float32(c))) + "f" for c in fastmath.ATAN_COEFFS]
#: step 8's floor of cos theta_i as a float32 (:data:`.rational_kernel.COS_FLOOR_F32`)
COS_FLOOR_F32 = float(np.float32(COS_FLOOR))

def atan_poly_source(s: str, p: str) -> str:
    """C++ statements declaring the float ``p``: the polynomial of
    :data:`warp_rbrdf.fastmath.ATAN_COEFFS` at ``s`` (``atan(a) = a p`` for ``s = a^2``, ``a`` in
    [0, 1]) by Estrin's scheme: four dependent multiply-adds where Horner's takes eight, the
    angles being on the path of every evaluation (:func:`atan_poly_numpy`: the same operations)."""
    c = ATAN_LITERALS
    return (f"const float {p}_2 = {s} * {s}, {p}_4 = {p}_2 * {p}_2;\n"
            f"const float {p}_03 = ({c[0]} + {c[1]} * {s}) + ({c[2]} + {c[3]} * {s}) * {p}_2;\n"
            f"const float {p}_47 = ({c[4]} + {c[5]} * {s}) + ({c[6]} + {c[7]} * {s}) * {p}_2;\n"
            f"const float {p} = ({p}_03 + {p}_47 * {p}_4) + {c[8]} * ({p}_4 * {p}_4);\n")


def atan_poly_numpy(z: np.ndarray) -> np.ndarray:
    """:func:`atan_poly_source`'s polynomial in NumPy float32 (the same operations up to fused
    multiply-adds)."""
    f = np.float32
    c = [f(k[:-1]) for k in ATAN_LITERALS]
    z = np.asarray(z, f)
    z2 = z * z
    z4 = z2 * z2
    p03 = (c[0] + c[1] * z) + (c[2] + c[3] * z) * z2
    p47 = (c[4] + c[5] * z) + (c[6] + c[7] * z) * z2
    return ((p03 + p47 * z4) + c[8] * (z4 * z4)).astype(f)


#: C++ statements: ``ang`` (``wp::vec3``: theta_h, theta_d, cos theta_h cos theta_d) of ``wi``, ``wo``
ANGLES_SOURCE = f"""const float sx = wi.c[0] + wo.c[0], sy = wi.c[1] + wo.c[1], sz = wi.c[2] + wo.c[2];
const float rs2 = sx * sx + sy * sy;
const float ls2 = rs2 + sz * sz;
const float ls = sqrtf(ls2);
const float li = sqrtf(wi.c[0] * wi.c[0] + wi.c[1] * wi.c[1] + wi.c[2] * wi.c[2]);
const float cx = sy * wi.c[2] - sz * wi.c[1];
const float cy = sz * wi.c[0] - sx * wi.c[2];
const float cz = sx * wi.c[1] - sy * wi.c[0];
const float sw = sx * wi.c[0] + sy * wi.c[1] + sz * wi.c[2];
const float a0 = sqrtf(rs2) / (ls + sz);
const float a1 = sqrtf(cx * cx + cy * cy + cz * cz) / (ls * li + sw);
const float s0 = a0 * a0, s1 = a1 * a1;
""" + atan_poly_source("s0", "p0") + atan_poly_source("s1", "p1") + """wp::vec3 ang;
ang.c[0] = 2.0f * (a0 * p0);
ang.c[1] = 2.0f * (a1 * p1);
ang.c[2] = sz * sw / (ls2 * li);
"""


@Native.func_native(ANGLES_SOURCE + "return ang;\n", "rational_angles_2d")
def angles_2d(wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    """``(theta_h, theta_d, cos theta_h cos theta_d)`` of a local direction pair above the
    horizon (module docstring; radians)."""
    ...


def angles_2d_numpy(wi, wo) -> np.ndarray:
    """:func:`angles_2d` in NumPy float32 (the same operations up to fused multiply-adds)."""
    f = np.float32
    wi, wo = np.asarray(wi, f), np.asarray(wo, f)
    s = wi + wo
    rs2 = s[:, 0] * s[:, 0] + s[:, 1] * s[:, 1]
    ls2 = rs2 + s[:, 2] * s[:, 2]
    ls = np.sqrt(ls2)
    li = np.sqrt((wi * wi).sum(-1, dtype=f))
    c = np.cross(s, wi)
    sw = (s * wi).sum(-1, dtype=f)
    out = []
    for a in (np.sqrt(rs2) / (ls + s[:, 2]), np.sqrt((c * c).sum(-1, dtype=f)) / (ls * li + sw)):
        out.append(f(2) * (a * atan_poly_numpy(a * a)))
    return np.stack(out + [s[:, 2] * sw / (ls2 * li)], -1).astype(f)


def flat_source(keys: tuple, margin: float, scalar: bool = False, n_vars: int = 2) -> str:
    """The C++ body of :func:`make_flat2d`'s function for the ``n_vars``-variable classes
    ``keys`` (3: :func:`.rational_flat3d.make_flat3d`'s): the vector form on the CPU and the
    scalar one in a CUDA build (``scalar``: the scalar form everywhere, for tests)."""
    if scalar:
        return _flat_body(keys, margin, False, n_vars)
    return ("#if defined(__CUDA_ARCH__)\n" + _flat_body(keys, margin, False, n_vars) + "#else\n"
            + _flat_body(keys, margin, True, n_vars) + "#endif\n")


def _flat_body(keys: tuple, margin: float, vector: bool, n_vars: int) -> str:
    """The function's statements. ``ang``: (theta_h, theta_d, cos theta_h cos theta_d) for 2
    variables, (theta_h, theta_d, |phi_d|, cos theta_h cos theta_d) for 3, whose records may
    carry step 8 (the value factor: ``cos_i``, wi.z)."""
    block = dense_block if vector else dense_block_scalar
    cases = [f"case {key}: {{\n{block(key)}\nbreak;\n}}" for key in keys]
    switch = "switch (P[2]) {\n" + "\n".join(cases) + "\ndefault: break;\n}\n"
    if vector:
        prelude = (VECTOR_PRELUDE
                   + "typedef double rbrdf_v4du __attribute__((ext_vector_type(4), aligned(8)));\n")
        sums = f"""const rbrdf_v4du* rows = (const rbrdf_v4du*)((const double*)dptr + P[3]);
rbrdf_v4d p = {{0.0, 0.0, 0.0, 0.0}};
rbrdf_v4d q = {{0.0, 0.0, 0.0, 1.0}};
"""
        steps = VECTOR_STEPS
    else:
        prelude = ""
        sums = """const double* rows = (const double*)dptr + P[3];
double p0 = 0.0, p1 = 0.0, p2 = 0.0, q0 = 0.0, q1 = 0.0, q2 = 0.0;
"""
        steps = ("wp::vec_t<6, double> pq;\npq.c[0] = p0; pq.c[1] = p1; pq.c[2] = p2; "
                 "pq.c[3] = q0; pq.c[4] = q1; pq.c[5] = q2;\n" + SCALAR_STEPS)
    _, max_pieces, max_outer, heads = FLAT_KINDS[n_vars]
    cos_prod = n_vars                      # the index of cos theta_h cos theta_d in ang
    pick = " + ".join(f"(x > F[{FF_EDGES + j}])" for j in range(max_outer - 1))
    if n_vars == 2:     # the outer piece, then, in a nested fit, the box in it (FF_INNER, FF_BASES)
        inner = " + ".join(f"(x2 > E2[{j}])" for j in range(max_pieces - 1))
        pick = (f"{pick};\nint k = k1;\nconst double nest = F[{FF_VAR2}];\n"
                f"if (nest != 0.0) {{   /* a predictable branch: one fit, one way */\n"
                f"    const double x2 = nest > 1.5 ? td : th;\n"
                f"    const double* E2 = F + {FF_INNER} + {max_pieces - 1} * k1;\n"
                f"    k = (int)F[{FF_BASES} + k1] + {inner};\n}}")
    if n_vars == 2:
        inputs = f"""double xh = th, xd = td;
if (flags & {LEAF_CLAMP}) {{
    xh = rb_clamp(xh, hd[{FH_VARS}], hd[{FH_VARS + 1}]);
    xd = rb_clamp(xd, hd[{FH_VARS + 4}], hd[{FH_VARS + 5}]);
}}
if (P[1] & 1) xh = wp::sqrt(rb_max(xh, 0.0));
if (P[1] & 2) xd = wp::sqrt(rb_max(xd, 0.0));
const double tb = (2.0 * xh - hd[{FH_VARS + 2}]) * hd[{FH_VARS + 3}];
const double tc = (2.0 * xd - hd[{FH_VARS + 6}]) * hd[{FH_VARS + 7}];
"""
        factor = ""
    else:
        inputs = f"""double xh = th, xd = td, xp = (double)ang.c[2];
if (flags & {LEAF_CLAMP}) {{
    xh = rb_clamp(xh, hd[{FH_VARS}], hd[{FH_VARS + 1}]);
    xd = rb_clamp(xd, hd[{FH_VARS + 4}], hd[{FH_VARS + 5}]);
    xp = rb_clamp(xp, hd[{FH_VARS + 8}], hd[{FH_VARS + 9}]);
}}
if (P[1] & 1) xh = wp::sqrt(rb_max(xh, 0.0));
if (P[1] & 2) xd = wp::sqrt(rb_max(xd, 0.0));
if (P[1] & 4) xp = wp::sqrt(rb_max(xp, 0.0));
const double ta = (2.0 * xh - hd[{FH_VARS + 2}]) * hd[{FH_VARS + 3}];
const double tb = (2.0 * xd - hd[{FH_VARS + 6}]) * hd[{FH_VARS + 7}];
const double tc = (2.0 * xp - hd[{FH_VARS + 10}]) * hd[{FH_VARS + 11}];
"""
        factor = f"""if (flags & {LEAF_INV_COS}) {{
    const float c = rb_max(cos_i, {COS_FLOOR_F32!r}f);
    out.c[0] = out.c[0] / c; out.c[1] = out.c[1] / c; out.c[2] = out.c[2] / c;
}}
"""
    return (prelude + MINMAX_SOURCE + f"""const double* F = (const double*)fptr;
const int* I = (const int*)iptr;
double th = (double)ang.c[0], td = (double)ang.c[1];
if ((double)ang.c[{cos_prod}] < F[{FF_COS_CUT}] + {margin!r}) {{
    const double t = rb_min(th, F[{FF_CUT}]);
    const double lim = wp::acos(rb_min(F[{FF_COS_CUT}] / wp::cos(t), 1.0));
    th = (double)(float)t;
    td = (double)(float)rb_min(td, lim);
}}
const double x = var ? td : th;
const int {"k1" if n_vars == 2 else "k"} = {pick};
const double* hd = F + {heads} + {N_FH} * k;
const int* P = I + {FLAT_NI} * k;
const int flags = P[0];
""" + inputs + sums + switch + f"""wp::vec3 tab(0.0f);
if (flags & {LEAF_TABLE}) {{
    const float bh = (float)rb_clamp(th, hd[{FH_BOX}], hd[{FH_BOX + 1}]);
    const float bd = (float)rb_clamp(td, hd[{FH_BOX + 2}], hd[{FH_BOX + 3}]);
    const int ih = wp::clamp((int)wp::floor(wp::sqrt(rb_max(bh, 0.0f) / 1.5707963267948966f) * 90.0f), 0, 89);
    const int jd = wp::clamp((int)wp::floor(bd / 1.5707963267948966f * 90.0f), 0, 89);
    const float* T = (const float*)tptr + 3 * (ih * 90 + jd);
    tab = wp::vec3(T[0], T[1], T[2]);
}}
const int m0 = P[4], m1 = P[5], m2 = P[6];
""" + steps + factor + "return wp::vec4(out.c[0], out.c[1], out.c[2], 1.0f);\n")


@functools.lru_cache(maxsize=None)
def make_flat2d(keys: tuple, margin: float, scalar: bool = False):
    """``flat2d(fptr, iptr, dptr, tptr, var, ang) -> vec4``: rho (before ``Materials.scale``) and 1
    of the flat record whose floats start at ``fptr`` and whose pieces' ints start at ``iptr``
    (``dptr``: the material's first float, where the dense rows' offsets start; ``tptr``: its
    fallback table; ``var``: the split variable) at the angles ``ang`` of :func:`angles_2d`;
    ``keys``: the scene's 2-variable classes (a leaf of another class gives P = 0, Q = 1, never
    packed as such); ``scalar``: the CUDA build's scalar form on every device (for tests).
    Cached: one function per tuple."""
    keys = tuple(k for k in keys if class_of_key(k)[0] == 2)
    source = flat_source(keys, margin, scalar, 2)
    name = "rational_flat2d_" + "_".join(f"{k:06x}" for k in keys) + "_" + hashlib.sha256(source.encode()).hexdigest()[:8]

    @Native.func_native(source, name)
    def flat2d(fptr: wp.uint64, iptr: wp.uint64, dptr: wp.uint64, tptr: wp.uint64, var: int,
               ang: wp.vec3) -> wp.vec4:
        ...

    return flat2d
