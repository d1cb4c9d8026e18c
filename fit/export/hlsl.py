"""HLSL export of a rational BRDF fit (Shader Model 5 style; no resources): the GLSL export's
functions with HLSL's types (:mod:`fit.export.glsl`). The statements come from the same
:class:`~fit.export.emitter.Emitter` with the same names and literals (``min``, ``max``,
``clamp``, ``sqrt``, ``exp`` exist in both languages), so the body is the GLSL body verbatim::

    float3 rbrdf_N_angles(float theta_h, float theta_d);   // rho (1/sr), radians
    float3 rbrdf_N(float3 wi, float3 wo);                  // local frame, z = normal; 0 below
    float3 rbrdf_N_frame(float3 L, float3 V, float3 N, float3 X, float3 Y);

A 3-D fit's ``rbrdf_N_angles`` takes ``phi_d`` too (``float theta_h, float theta_d, float
phi_d``; ``wi`` is the light, ``wo`` the viewer: such a fit is not reciprocal). Computation in
``float`` (the float C build measures it, docs/exports.md).
"""
from __future__ import annotations

from .emitter import Emitter, is_3d, policy_text
from .glsl import GLSL, directions_3d, function_name


def to_hlsl(model, name: str | None = None) -> str:
    """HLSL source of ``model``'s three functions (module docstring)."""
    fn = function_name(model, name)
    three = is_3d(model)
    body = Emitter(GLSL).rho(model, "theta_h", "theta_d")
    args = "float theta_h, float theta_d, float phi_d" if three else "float theta_h, float theta_d"
    out = ["/*"] + policy_text(model) + [
        f" * Functions: float3 {fn}(float3 wi, float3 wo); float3 {fn}_frame(float3 L, float3 V,",
        f" *   float3 N, float3 X, float3 Y); float3 {fn}_angles({args}).",
        " */",
        f"float3 {fn}_angles({args})", "{",
        "    float rho0 = 0.0;", "    float rho1 = 0.0;", "    float rho2 = 0.0;"]
    out += body
    out += ["    return float3(rho0, rho1, rho2);", "}", "", f"float3 {fn}(float3 wi, float3 wo)", "{"]
    out += directions_3d(fn, "float2", "float3", "atan2") if three else [
        "    if (wi.z <= 0.0 || wo.z <= 0.0) return float3(0.0, 0.0, 0.0);",
        "    float3 h = normalize(wi + wo);",
        "    float theta_h = atan2(length(h.xy), h.z);",
        "    float theta_d = atan2(length(cross(wi, h)), dot(wi, h));",
        f"    return {fn}_angles(theta_h, theta_d);"]
    out += ["}", "",
            f"float3 {fn}_frame(float3 L, float3 V, float3 N, float3 X, float3 Y)", "{",
            "    float3 wi = normalize(float3(dot(L, X), dot(L, Y), dot(L, N)));",
            "    float3 wo = normalize(float3(dot(V, X), dot(V, Y), dot(V, N)));",
            f"    return {fn}(wi, wo);", "}", ""]
    return "\n".join(out)
