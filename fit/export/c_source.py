"""C export of a rational BRDF fit: C99 (also valid C++), one file usable as a header
(``static inline`` functions, the default) or compiled on its own (``-DRBRDF_API=`` gives the
functions external linkage; :func:`to_c` with ``header=False`` writes that define in).

Emitted functions (``N`` = :func:`fit.export.escape.identifier` of the name), all computing in
``RBRDF_REAL`` (``float`` by default, ``-DRBRDF_REAL_DOUBLE`` for ``double``)::

    void rbrdf_N_angles(RBRDF_REAL theta_h, RBRDF_REAL theta_d, RBRDF_REAL rho[3]);
    void rbrdf_N(const RBRDF_REAL wi[3], const RBRDF_REAL wo[3], RBRDF_REAL rho[3]);
    void rbrdf_N_frame(const RBRDF_REAL L[3], const RBRDF_REAL V[3], const RBRDF_REAL N[3],
                       const RBRDF_REAL X[3], const RBRDF_REAL Y[3], RBRDF_REAL rho[3]);

A 3-D fit's ``rbrdf_N_angles`` takes ``phi_d`` too (``RBRDF_REAL theta_h, RBRDF_REAL theta_d,
RBRDF_REAL phi_d, RBRDF_REAL rho[3]``; phi_d of the pair (light, view), folded to ``|phi_d|``);
``wi`` is the light, ``wo`` the viewer (such a fit is not reciprocal).

Same meaning as the GLSL functions (:mod:`fit.export.glsl`; the statements come from the same
:class:`~fit.export.emitter.Emitter`): rho in 1/sr, radians, local frame with z = normal, 0
below the horizon, the fit's clamps, and for a fit that records its grazing cut-off the angles
moved onto its measured domain first (:mod:`fit.export.emitter`, step 0; ``cos`` and ``acos``
through ``RBRDF_COS`` / ``RBRDF_ACOS``, defined by a second guarded prelude only in such
files; with ``-DRBRDF_EXP_FLOAT`` they run in float as well, as GLSL's double variant does).
The ``fabs`` of a 3-D fit's fold is ``RBRDF_ABS``, defined by a third guarded prelude only in
3-D files. A fit with the value factor ``"1/cos_theta_i"`` (file version 4, emitter step 8)
computes cos theta_i from its angles with ``RBRDF_COS`` and ``RBRDF_SIN``, defined by a fourth
guarded prelude only in such files (float under ``-DRBRDF_EXP_FLOAT`` too; its ``RBRDF_COS``,
when the domain prelude has not defined it, is that prelude's definition token for token, so
that headers of both kinds of fit include together). Needs ``<math.h>`` (link with ``-lm``).
"""
from __future__ import annotations

from ..rational.domain import measured_domain
from .emitter import Emitter, Language, c_literal, has_cos_factor, is_3d, policy_text
from .escape import identifier

C = Language(real="RBRDF_REAL", literal=c_literal,
             funcs={"min": "RBRDF_MIN", "max": "RBRDF_MAX", "clamp": "rbrdf_clamp_",
                    "sqrt": "RBRDF_SQRT", "exp": "RBRDF_EXP", "cos": "RBRDF_COS", "acos": "RBRDF_ACOS",
                    "abs": "RBRDF_ABS", "sin": "RBRDF_SIN"})

PRELUDE = r"""#include <math.h>

#ifndef RBRDF_API
#define RBRDF_API static inline
#endif

#ifndef RBRDF_PRELUDE_
#define RBRDF_PRELUDE_
#ifdef RBRDF_REAL_DOUBLE
#define RBRDF_REAL double
#define RBRDF_K(x) x
#define RBRDF_SQRT sqrt
#ifdef RBRDF_EXP_FLOAT  /* what the GLSL double variant does: GLSL has no double exp */
#define RBRDF_EXP(x) ((double)expf((float)(x)))
#else
#define RBRDF_EXP exp
#endif
#define RBRDF_ATAN2 atan2
#define RBRDF_MIN fmin
#define RBRDF_MAX fmax
#else
#define RBRDF_REAL float
#define RBRDF_K(x) x##f
#define RBRDF_SQRT sqrtf
#define RBRDF_EXP expf
#define RBRDF_ATAN2 atan2f
#define RBRDF_MIN fminf
#define RBRDF_MAX fmaxf
#endif
static inline RBRDF_REAL rbrdf_clamp_(RBRDF_REAL x, RBRDF_REAL lo, RBRDF_REAL hi)
{
    return RBRDF_MIN(RBRDF_MAX(x, lo), hi);
}
#endif
"""

# only in files of fits with a measured domain (other fits' files hold none of it)
DOMAIN_PRELUDE = r"""#ifndef RBRDF_DOMAIN_PRELUDE_
#define RBRDF_DOMAIN_PRELUDE_
#ifdef RBRDF_REAL_DOUBLE
#ifdef RBRDF_EXP_FLOAT  /* GLSL has no double cos / acos either */
#define RBRDF_COS(x) ((double)cosf((float)(x)))
#define RBRDF_ACOS(x) ((double)acosf((float)(x)))
#else
#define RBRDF_COS cos
#define RBRDF_ACOS acos
#endif
#else
#define RBRDF_COS cosf
#define RBRDF_ACOS acosf
#endif
#endif
"""

# only in files of 3-D fits (the fold of phi_d; other fits' files hold none of it)
PHI_PRELUDE = r"""#ifndef RBRDF_PHI_PRELUDE_
#define RBRDF_PHI_PRELUDE_
#ifdef RBRDF_REAL_DOUBLE
#define RBRDF_ABS fabs
#else
#define RBRDF_ABS fabsf
#endif
#endif
"""


# only in files of fits with the value factor "1/cos_theta_i" (step 8: cos theta_i of the angles;
# RBRDF_COS exactly as DOMAIN_PRELUDE defines it, a permitted identical redefinition)
FACTOR_PRELUDE = r"""#ifndef RBRDF_FACTOR_PRELUDE_
#define RBRDF_FACTOR_PRELUDE_
#ifdef RBRDF_REAL_DOUBLE
#ifdef RBRDF_EXP_FLOAT  /* GLSL has no double sin / cos either */
#define RBRDF_SIN(x) ((double)sinf((float)(x)))
#ifndef RBRDF_COS
#define RBRDF_COS(x) ((double)cosf((float)(x)))
#endif
#else
#define RBRDF_SIN sin
#ifndef RBRDF_COS
#define RBRDF_COS cos
#endif
#endif
#else
#define RBRDF_SIN sinf
#ifndef RBRDF_COS
#define RBRDF_COS cosf
#endif
#endif
#endif
"""


def function_name(model, name: str | None = None) -> str:
    return "rbrdf_" + identifier(name or model.name)


def to_c(model, name: str | None = None, header: bool = True) -> str:
    """C99/C++ source of ``model``'s three functions (module docstring). ``header``: a header
    (include guard, ``static inline`` by default); else a translation unit whose functions
    have external linkage."""
    fn = function_name(model, name)
    guard = fn.upper() + "_H_"
    R = "RBRDF_REAL"
    three = is_3d(model)
    em = Emitter(C)
    body = em.rho(model, "theta_h", "theta_d")
    out = ["/*"] + policy_text(model) + [
        " * C99 / C++. Scalars are RBRDF_REAL: float by default, double with -DRBRDF_REAL_DOUBLE.",
        f" * Functions: {fn}_angles, {fn}, {fn}_frame (rho[3] in 1/sr). Link with -lm.",
        " */"]
    if header:
        out += [f"#ifndef {guard}", f"#define {guard}"]
    else:
        out += ["#ifndef RBRDF_API", "#define RBRDF_API", "#endif"]
    args = f"{R} theta_h, {R} theta_d, {R} phi_d" if three else f"{R} theta_h, {R} theta_d"
    out += [PRELUDE] + ([DOMAIN_PRELUDE] if measured_domain(model) is not None else []) + (
            [PHI_PRELUDE] if three else []) + ([FACTOR_PRELUDE] if has_cos_factor(model) else []) + [
            "#ifdef __cplusplus", 'extern "C" {', "#endif", "",
            f"RBRDF_API void {fn}_angles({args}, {R} rho[3])", "{",
            f"    {R} rho0 = RBRDF_K(0.0);", f"    {R} rho1 = RBRDF_K(0.0);", f"    {R} rho2 = RBRDF_K(0.0);"]
    out += body
    out += ["    rho[0] = rho0;", "    rho[1] = rho1;", "    rho[2] = rho2;", "}", "",
            f"RBRDF_API void {fn}(const {R} wi[3], const {R} wo[3], {R} rho[3])", "{"]
    out += _directions_3d(fn) if three else [
            f"    {R} h[3], n, c[3], theta_h, theta_d;",
            "    if (wi[2] <= RBRDF_K(0.0) || wo[2] <= RBRDF_K(0.0)) {",
            "        rho[0] = rho[1] = rho[2] = RBRDF_K(0.0);", "        return;", "    }",
            "    h[0] = wi[0] + wo[0]; h[1] = wi[1] + wo[1]; h[2] = wi[2] + wo[2];",
            "    n = RBRDF_SQRT(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);",
            "    h[0] /= n; h[1] /= n; h[2] /= n;",
            "    theta_h = RBRDF_ATAN2(RBRDF_SQRT(h[0] * h[0] + h[1] * h[1]), h[2]);",
            "    c[0] = wi[1] * h[2] - wi[2] * h[1];",
            "    c[1] = wi[2] * h[0] - wi[0] * h[2];",
            "    c[2] = wi[0] * h[1] - wi[1] * h[0];",
            "    theta_d = RBRDF_ATAN2(RBRDF_SQRT(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]),",
            "                          wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]);",
            f"    {fn}_angles(theta_h, theta_d, rho);"]
    out += ["}", "",
            f"static inline void {fn}_local_(const {R} D[3], const {R} N[3], const {R} X[3],",
            f"                               const {R} Y[3], {R} w[3])", "{",
            "    w[0] = D[0] * X[0] + D[1] * X[1] + D[2] * X[2];",
            "    w[1] = D[0] * Y[0] + D[1] * Y[1] + D[2] * Y[2];",
            "    w[2] = D[0] * N[0] + D[1] * N[1] + D[2] * N[2];", "}", "",
            f"RBRDF_API void {fn}_frame(const {R} L[3], const {R} V[3], const {R} N[3],",
            f"                    const {R} X[3], const {R} Y[3], {R} rho[3])", "{",
            f"    {R} wi[3], wo[3], a, b;",
            f"    {fn}_local_(L, N, X, Y, wi);",
            f"    {fn}_local_(V, N, X, Y, wo);",
            "    a = RBRDF_SQRT(wi[0] * wi[0] + wi[1] * wi[1] + wi[2] * wi[2]);",
            "    b = RBRDF_SQRT(wo[0] * wo[0] + wo[1] * wo[1] + wo[2] * wo[2]);",
            "    wi[0] /= a; wi[1] /= a; wi[2] /= a;",
            "    wo[0] /= b; wo[1] /= b; wo[2] /= b;",
            f"    {fn}(wi, wo, rho);", "}", "",
            "#ifdef __cplusplus", "}", "#endif"]
    if header:
        out += [f"#endif /* {guard} */"]
    return "\n".join(out) + "\n"


def _directions_3d(fn: str) -> list:
    """The body of a 3-D fit's ``rbrdf_N(wi, wo, rho)``: (theta_h, theta_d, phi_d) of the pair
    by the renderer's rotations (:func:`fit.export.glsl.directions_3d`, the same statements)."""
    R = "RBRDF_REAL"
    return [
        f"    {R} h[3], n, r, cp, sp, x1, y1, x2, z2, theta_h, theta_d, phi_d;",
        "    if (wi[2] <= RBRDF_K(0.0) || wo[2] <= RBRDF_K(0.0)) {",
        "        rho[0] = rho[1] = rho[2] = RBRDF_K(0.0);", "        return;", "    }",
        "    h[0] = wi[0] + wo[0]; h[1] = wi[1] + wo[1]; h[2] = wi[2] + wo[2];",
        "    n = RBRDF_SQRT(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);",
        "    h[0] /= n; h[1] /= n; h[2] /= n;",
        "    r = RBRDF_SQRT(h[0] * h[0] + h[1] * h[1]);",
        "    theta_h = RBRDF_ATAN2(r, h[2]);",
        "    cp = RBRDF_K(1.0);",
        "    sp = RBRDF_K(0.0);",
        "    if (r > RBRDF_K(1.0e-12)) {",
        "        cp = h[0] / r;",
        "        sp = h[1] / r;",
        "    }",
        "    x1 = cp * wi[0] + sp * wi[1];",
        "    y1 = cp * wi[1] - sp * wi[0];",
        "    x2 = h[2] * x1 - r * wi[2];",
        "    z2 = r * x1 + h[2] * wi[2];",
        "    theta_d = RBRDF_ATAN2(RBRDF_SQRT(x2 * x2 + y1 * y1), z2);",
        "    phi_d = RBRDF_K(0.0);",
        "    if (RBRDF_ABS(x2) + RBRDF_ABS(y1) > RBRDF_K(1.0e-12)) {",
        "        phi_d = RBRDF_ATAN2(y1, x2);",
        "    }",
        f"    {fn}_angles(theta_h, theta_d, phi_d, rho);"]
