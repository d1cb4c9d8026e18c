"""GLSL export of a rational BRDF fit: a self-contained GLSL function (no uniforms, no
textures; compiled by the tests as ``#version 330 core``, ``410 core`` and ``300 es``; the
double variant needs 4.00).

Emitted functions (``N`` = :func:`fit.export.escape.identifier` of the name):

* ``vec3 rbrdf_N_angles(float theta_h, float theta_d)`` (a 3-D fit:
  ``rbrdf_N_angles(float theta_h, float theta_d, float phi_d)``, phi_d of the pair (light, view)
  in (-pi, pi], folded to ``|phi_d|``): rho (1/sr) at Rusinkiewicz angles (radians), the fit's
  recipe with its clamps (:mod:`fit.export.emitter`), on the fit's measured domain when it
  records its grazing cut-off (emitter step 0), divided by max(cos theta_i, 1e-3) (cos theta_i
  of these angles) when it has the value factor ``"1/cos_theta_i"`` (emitter step 8);
* ``vec3 rbrdf_N(vec3 wi, vec3 wo)``: rho at unit directions of the local shading frame (z =
  normal, both pointing away from the surface; ``wi`` towards the light, ``wo`` towards the
  viewer: a 3-D fit is not reciprocal); ``vec3(0)`` below the horizon;
* ``vec3 rbrdf_N_frame(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)``: the same with world-space
  light and view directions and an orthonormal frame (normal ``N``, tangent ``X``, bitangent
  ``Y``), BRDF Explorer's signature.

The angles come from ``atan(length(cross), dot)`` forms (full float precision near the
specular peak, where ``acos`` loses half the digits); a 3-D fit's from the rotations of
:func:`fit.formats.angles.directions_to_half_diff` (``wi`` rotated by ``-phi_h`` about z, then
by ``-theta_h`` about y, as the renderer computes them), in ``atan`` forms too. Computation is in ``float``: the C export
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
    has_cos_factor,
    is_3d,
    policy_text,
)
from .escape import identifier

GLSL = Language(real="float", literal=glsl_literal,
                funcs={"min": "min", "max": "max", "clamp": "clamp", "sqrt": "sqrt", "exp": "exp",
                       "cos": "cos", "acos": "acos", "abs": "abs", "sin": "sin"})


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
    domain and ``cos`` and ``sin`` of a value factor): the statements of the C double build with
    ``-DRBRDF_EXP_FLOAT``."""
    check_exportable(model)
    fn = function_name(model, name)
    if precision == "float":
        lang, pre, conv = GLSL, [], ""
    elif precision == "double":
        lang = Language(real="double", literal=glsl_double_literal,
                        funcs=dict(GLSL.funcs, exp=f"{fn}_exp_"))
        pre = [f"double {fn}_exp_(double x)", "{", "    return double(exp(float(x)));", "}", ""]
        trig = (["cos", "acos"] if measured_domain(model) is not None else []) + (
            ["cos", "sin"] if has_cos_factor(model) else [])
        for f in dict.fromkeys(trig):        # each once, in order
            lang.funcs[f] = f"{fn}_{f}_"
            pre += [f"double {fn}_{f}_(double x)", "{", f"    return double({f}(float(x)));", "}", ""]
        conv = "double"
    else:
        raise ExportError(f"precision {precision!r}: expected 'float' or 'double'")
    em = Emitter(lang)
    three = is_3d(model)
    body = em.rho(model, "th_", "td_", pd="pd_") if conv else em.rho(model, "theta_h", "theta_d")
    args = "float theta_h, float theta_d, float phi_d" if three else "float theta_h, float theta_d"
    out = []
    if header:
        out += ["/*"] + policy_text(model) + [
            f" * Functions: vec3 {fn}(vec3 wi, vec3 wo); vec3 {fn}_frame(vec3 L, vec3 V, vec3 N,",
            f" *   vec3 X, vec3 Y); vec3 {fn}_angles({args}).",
            " */"]
    r = lang.real
    out += pre + [f"vec3 {fn}_angles({args})", "{",
                  f"    {r} rho0 = {lang.literal(0.0)};", f"    {r} rho1 = {lang.literal(0.0)};",
                  f"    {r} rho2 = {lang.literal(0.0)};"]
    if conv:
        out += ["    double th_ = double(theta_h);", "    double td_ = double(theta_d);"]
        if three:
            out += ["    double pd_ = double(phi_d);"]
    out += body
    out += ["    return vec3(rho0, rho1, rho2);", "}", "", f"vec3 {fn}(vec3 wi, vec3 wo)", "{"]
    out += directions_3d(fn) if three else [
        "    if (wi.z <= 0.0 || wo.z <= 0.0) return vec3(0.0);",
        "    vec3 h = normalize(wi + wo);",
        "    float theta_h = atan(length(h.xy), h.z);",
        "    float theta_d = atan(length(cross(wi, h)), dot(wi, h));",
        f"    return {fn}_angles(theta_h, theta_d);"]
    out += ["}", "",
            f"vec3 {fn}_frame(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)", "{",
            "    vec3 wi = normalize(vec3(dot(L, X), dot(L, Y), dot(L, N)));",
            "    vec3 wo = normalize(vec3(dot(V, X), dot(V, Y), dot(V, N)));",
            f"    return {fn}(wi, wo);", "}", ""]
    return "\n".join(out)


def directions_3d(fn: str, vec2: str = "vec2", vec3: str = "vec3", atan2: str = "atan") -> list:
    """The body of ``rbrdf_N(wi, wo)`` of a 3-D fit (GLSL; HLSL with its type and ``atan2``
    names): (theta_h, theta_d, phi_d) of the pair by the renderer's rotations
    (:func:`fit.formats.angles.directions_to_half_diff`), phi_d = 0 where it is undefined."""
    return [
        f"    if (wi.z <= 0.0 || wo.z <= 0.0) return {vec3}(0.0, 0.0, 0.0);",
        f"    {vec3} h = normalize(wi + wo);",
        "    float r = length(h.xy);",
        f"    float theta_h = {atan2}(r, h.z);",
        "    float cp = 1.0;",
        "    float sp = 0.0;",
        "    if (r > 1.0e-12) {",
        "        cp = h.x / r;",
        "        sp = h.y / r;",
        "    }",
        "    float x1 = cp * wi.x + sp * wi.y;",
        "    float y1 = cp * wi.y - sp * wi.x;",
        "    float x2 = h.z * x1 - r * wi.z;",
        "    float z2 = r * x1 + h.z * wi.z;",
        f"    float theta_d = {atan2}(length({vec2}(x2, y1)), z2);",
        "    float phi_d = 0.0;",
        "    if (abs(x2) + abs(y1) > 1.0e-12) {",
        f"        phi_d = {atan2}(y1, x2);",
        "    }",
        f"    return {fn}_angles(theta_h, theta_d, phi_d);"]
