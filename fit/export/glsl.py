"""GLSL export of a rational BRDF fit: a self-contained GLSL function (no uniforms, no
textures; compiled by the tests as ``#version 330 core``, ``410 core`` and ``300 es``; the
double variant needs 4.00).

Emitted functions (``N`` = :func:`fit.export.escape.identifier` of the name):

* ``vec3 rbrdf_N_angles(float theta_h, float theta_d)``: rho (1/sr) at Rusinkiewicz angles
  (radians), the fit's recipe with its clamps (:mod:`fit.export.emitter`), on the fit's
  measured domain when it records its grazing cut-off (emitter step 0);
* ``vec3 rbrdf_N(vec3 wi, vec3 wo)``: rho at unit directions of the local shading frame (z =
  normal, both pointing away from the surface); ``vec3(0)`` below the horizon;
* ``vec3 rbrdf_N_frame(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)``: the same with world-space
  light and view directions and an orthonormal frame (normal ``N``, tangent ``X``, bitangent
  ``Y``), BRDF Explorer's signature.

The angles come from ``atan(length(cross), dot)`` forms (full float precision near the
specular peak, where ``acos`` loses half the digits). Computation is in ``float``: the C export
built with ``RBRDF_REAL=float`` runs the same statements and measures what float32 costs
(docs/exports.md).
"""
from __future__ import annotations

from ..rational.domain import measured_domain
from .emitter import (
    Emitter,
    ExportError,
    Language,
    check_exportable,
    _digits,
    glsl_literal,
    policy_text,
)
from .escape import identifier

GLSL = Language(real="float", literal=glsl_literal,
                funcs={"min": "min", "max": "max", "clamp": "clamp", "sqrt": "sqrt", "exp": "exp",
                       "cos": "cos", "acos": "acos"})


def function_name(model, name: str | None = None) -> str:
    return "rbrdf_" + identifier(name or model.name)


def glsl_double_literal(v: float) -> str:
    """A GLSL double literal (``lf`` suffix), 17 significant digits; negative ones in
    parentheses."""
    s = _digits(abs(float(v)), 17) + "lf"
    return f"(-{s})" if v < 0 else s


def to_glsl(model, name: str | None = None, header: bool = True, precision: str = "float") -> str:
    """GLSL source (no ``#version`` line: it is meant to be pasted or included) of ``model``'s
    three functions (module docstring); ``name`` overrides the fit's name in the identifiers.
    ``precision="double"``: the recipe in ``double`` (GLSL 4.00 / ``GL_ARB_gpu_shader_fp64``;
    ``exp`` in float, GLSL has no double ``exp``; likewise ``cos`` and ``acos`` of the measured
    domain): the statements of the C double build."""
    check_exportable(model)
    fn = function_name(model, name)
    if precision == "float":
        lang, pre, conv = GLSL, [], ""
    elif precision == "double":
        lang = Language(real="double", literal=glsl_double_literal,
                        funcs=dict(GLSL.funcs, exp=f"{fn}_exp_"))
        pre = [f"double {fn}_exp_(double x)", "{", "    return double(exp(float(x)));", "}", ""]
        if measured_domain(model) is not None:
            lang.funcs.update(cos=f"{fn}_cos_", acos=f"{fn}_acos_")
            for f in ("cos", "acos"):
                pre += [f"double {fn}_{f}_(double x)", "{", f"    return double({f}(float(x)));", "}", ""]
        conv = "double"
    else:
        raise ExportError(f"precision {precision!r}: expected 'float' or 'double'")
    em = Emitter(lang)
    body = em.rho(model, "th_", "td_") if conv else em.rho(model, "theta_h", "theta_d")
    out = []
    if header:
        out += ["/*"] + policy_text(model) + [
            f" * Functions: vec3 {fn}(vec3 wi, vec3 wo); vec3 {fn}_frame(vec3 L, vec3 V, vec3 N,",
            f" *   vec3 X, vec3 Y); vec3 {fn}_angles(float theta_h, float theta_d).",
            " */"]
    r = lang.real
    out += pre + [f"vec3 {fn}_angles(float theta_h, float theta_d)", "{",
                  f"    {r} rho0 = {lang.literal(0.0)};", f"    {r} rho1 = {lang.literal(0.0)};",
                  f"    {r} rho2 = {lang.literal(0.0)};"]
    if conv:
        out += ["    double th_ = double(theta_h);", "    double td_ = double(theta_d);"]
    out += body
    out += ["    return vec3(rho0, rho1, rho2);", "}", "",
            f"vec3 {fn}(vec3 wi, vec3 wo)", "{",
            "    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);",
            "    vec3 h = normalize(wi + wo);",
            "    float theta_h = atan(length(h.xy), h.z);",
            "    float theta_d = atan(length(cross(wi, h)), dot(wi, h));",
            f"    return {fn}_angles(theta_h, theta_d);", "}", "",
            f"vec3 {fn}_frame(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)", "{",
            "    vec3 wi = normalize(vec3(dot(L, X), dot(L, Y), dot(L, N)));",
            "    vec3 wo = normalize(vec3(dot(V, X), dot(V, Y), dot(V, N)));",
            f"    return {fn}(wi, wo);", "}", ""]
    return "\n".join(out)
