"""Disney BRDF Explorer export: an ``analytic`` ``.brdf`` file whose shader block embeds the
GLSL of :mod:`fit.export.glsl` and defines BRDF Explorer's entry point::

    vec3 BRDF(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)

(world-space light and view directions and the shading frame, as BRDF Explorer passes them),
returning rho in 1/sr (no cosine, as BRDF Explorer expects; a fit with the value factor
``"1/cos_theta_i"`` divided by max(cos theta_i, 1e-3) as the GLSL does, emitter step 8), times
the parameter ``scale`` (slider 0 to 4, default 1). The domain and clamp policy are in the
file's comments (``#`` lines before the blocks) and in the shader's header comment.

BRDF Explorer reads the parameters block (``float NAME MIN MAX DEFAULT``) as uniforms of the
shader; :func:`shader_block` is the text between ``::begin shader`` and ``::end shader``.
"""
from __future__ import annotations

from .emitter import policy_text
from .glsl import function_name, to_glsl

PARAMETER = "scale"


def shader_block(model, name: str | None = None) -> str:
    """The GLSL of the shader block (it expects ``uniform float scale`` from the parameters)."""
    fn = function_name(model, name)
    return (to_glsl(model, name) + "\n"
            "vec3 BRDF(vec3 L, vec3 V, vec3 N, vec3 X, vec3 Y)\n{\n"
            f"    return {PARAMETER} * {fn}_frame(L, V, N, X, Y);\n}}\n")


def to_brdf_explorer(model, name: str | None = None) -> str:
    """The ``.brdf`` file text (module docstring)."""
    lines = ["analytic", ""]
    lines += policy_text(model, prefix="# ")
    lines += ["#", f"# parameter {PARAMETER}: multiplies rho (1 = the fit).", "",
              "::begin parameters", f"float {PARAMETER} 0.0 4.0 1.0", "::end parameters", "",
              "::begin shader", shader_block(model, name).rstrip("\n"), "::end shader", ""]
    return "\n".join(lines)


def extract_shader(text: str) -> str:
    """The text between ``::begin shader`` and ``::end shader`` of a ``.brdf`` file (ValueError
    when the markers are missing)."""
    try:
        start = text.index("::begin shader") + len("::begin shader")
        end = text.index("::end shader", start)
    except ValueError:
        raise ValueError("no '::begin shader' ... '::end shader' block") from None
    return text[start:end]
