"""``rational``: the fitter's ``rbrdf-rational`` coefficient files (:mod:`fit.rational.coefficient_file`,
versions 1 and 2) compiled to generated, fully unrolled Warp code; ``scale`` multiplies them.

For each rational material the generator writes one ``@wp.func`` ``(wi, wo) -> vec3`` that
follows the file's evaluation recipe exactly (see :mod:`fit.rational.coefficient_file`): Rusinkiewicz angles
-> clamp onto the fitted domain -> input transform (identity / sqrt) -> map onto [-1, 1] ->
Chebyshev recurrences up to the largest exponent used -> P/Q per channel as sums grouped by the
first variable's exponent -> value transform (linear / log) -> ``max(y, min)``; 0 below the
horizon. The polynomial part runs in float64 (Chebyshev sums can cancel); the angles come from
the float32 shading frame. Coefficients are literals (:mod:`warp_rbrdf.codegen`), so each fit
gets its own code, cached by Warp under the hash of the generated source;
:func:`kernel_eval` dispatches on ``Materials.offset`` (the material's index among the scene's
rational materials).
"""
from __future__ import annotations

import numpy as np
import warp as wp

from fit.rational.coefficient_file import load as load_coefficients

from ..codegen import lit as _lit
from ..codegen import load_generated
from ..errors import SceneError
from .data import LoadedMaterial, Materials
from .measured import scaled

SUPPORTED_VARIABLES = {"theta_h": 0, "theta_d": 1, "phi_d": 2}


def load(spec, scene_file="<scene>", key="materials") -> LoadedMaterial:
    """The :class:`fit.rational.model.RationalModel` of a material spec (``spec.data`` or file)."""
    if spec.data is not None:
        model = spec.data
    else:
        try:
            model = load_coefficients(spec.file)
        except Exception as e:  # noqa: BLE001 - BRDFFileError etc., one line
            raise SceneError(scene_file, f"{key}.file", f"cannot read coefficient file ({e})") from None
    check_model(model, scene_file, key)
    return LoadedMaterial(spec, model, scaled(model.evaluate, spec.scale), scale=spec.scale)


def check_model(model, file="<scene>", key="materials"):
    names = [v.name for v in model.variables]
    if model.kind != "brdf":
        raise SceneError(file, f"{key}.file", f"expected a coefficient file of kind 'brdf', got {model.kind!r}")
    bad = [n for n in names if n not in SUPPORTED_VARIABLES]
    if bad:
        raise SceneError(file, f"{key}.file", f"unsupported rational-BRDF variable {bad[0]!r}; expected "
                                              f"variables among {', '.join(SUPPORTED_VARIABLES)}")
    if len(model.outputs) != 3:
        raise SceneError(file, f"{key}.file", f"expected 3 outputs (R, G, B), got {len(model.outputs)}")


def _poly(lines, name, exps, coefs):
    """Emit ``name = sum_j c_j prod_v T_{e_jv}(t_v)`` grouped by the first variable's exponent."""
    groups: dict = {}
    for e, c in zip(exps, coefs):
        if c == 0.0:
            continue
        groups.setdefault(int(e[0]), []).append((tuple(int(k) for k in e[1:]), float(c)))
    lines.append(f"    {name} = wp.float64(0.0)")
    for a in sorted(groups):
        terms = []
        for rest, c in groups[a]:
            factors = [f"T{v + 1}_{k}" for v, k in enumerate(rest) if k > 0]
            terms.append(" * ".join([_lit(c)] + factors))
        inner = " + ".join(terms)
        lines.append(f"    {name} = {name} + " + (f"T0_{a} * ({inner})" if a > 0 else f"({inner})"))


def generate_function(model, name: str) -> str:
    """Source of ``@wp.func name(wi, wo) -> wp.vec3`` for a rational BRDF model; a piecewise
    model (file version 2) gets one function per piece (``name_p0``, ...) and a dispatcher
    that picks the piece from the split variable, clamped as in :mod:`fit.rational.coefficient_file`."""
    pieces = getattr(model, "pieces", None)
    if pieces is None:
        return _generate_single(model, name)
    parts = [generate_function(p, f"{name}_p{k}") for k, p in enumerate(pieces)]   # nested: recursive
    src = SUPPORTED_VARIABLES[model.split_variable]
    L = ["@wp.func", f"def {name}(wi: wp.vec3, wo: wp.vec3) -> wp.vec3:",
         f"    # piecewise rational BRDF {model.name!r}: {len(pieces)} pieces along {model.split_variable}",
         "    if wi[2] <= 0.0 or wo[2] <= 0.0:", "        return wp.vec3(0.0)",
         "    a = F.half_diff(wi, wo)", f"    x = wp.float64(a[{src}])"]
    for k in range(len(pieces) - 1):
        L.append(f"    if x <= {_lit(model.edges[k + 1])}:")
        L.append(f"        return {name}_p{k}(wi, wo)")
    L.append(f"    return {name}_p{len(pieces) - 1}(wi, wo)")
    return "\n\n".join(parts) + "\n\n" + "\n".join(L) + "\n"


def _generate_single(model, name: str) -> str:
    nv = len(model.variables)
    kmax = [0] * nv
    for f in model.functions:
        for ex in (f.num_exponents, f.den_exponents):
            if len(ex):
                kmax = [max(k, int(m)) for k, m in zip(kmax, ex.max(axis=0))]
    L = ["@wp.func", f"def {name}(wi: wp.vec3, wo: wp.vec3) -> wp.vec3:",
         f"    # generated from rational BRDF {model.name!r}: {model.n_coefficients} coefficients",
         "    if wi[2] <= 0.0 or wo[2] <= 0.0:", "        return wp.vec3(0.0)",
         "    a = F.half_diff(wi, wo)"]
    clamp = model.domain_policy.get("outside", "clamp") == "clamp"
    for v, var in enumerate(model.variables):
        src = SUPPORTED_VARIABLES[var.name]
        x = f"wp.float64(a[{src}])"
        if var.name == "phi_d":  # fold phi_d into [0, pi) as the MERL grid does
            L.append(f"    p{v} = a[{src}]")
            L.append(f"    if p{v} < 0.0:\n        p{v} = p{v} + wp.pi")
            x = f"wp.float64(p{v})"
        lo, hi = var.domain
        if clamp:
            x = f"wp.clamp({x}, {_lit(lo)}, {_lit(hi)})"
        if var.transform == "sqrt":
            x = f"wp.sqrt(wp.max({x}, wp.float64(0.0)))"
        ulo, uhi = var.rf_domain
        L.append(f"    u{v} = {x}")
        L.append(f"    t{v} = (wp.float64(2.0) * u{v} - {_lit(ulo + uhi)}) * {_lit(1.0 / (uhi - ulo))}")
        L.append(f"    T{v}_0 = wp.float64(1.0)")
        if kmax[v] >= 1:
            L.append(f"    T{v}_1 = t{v}")
        for k in range(2, kmax[v] + 1):
            L.append(f"    T{v}_{k} = wp.float64(2.0) * t{v} * T{v}_{k - 1} - T{v}_{k - 2}")
    outs = []
    for c, f in enumerate(model.functions):
        _poly(L, f"P{c}", f.num_exponents, f.num_coef)
        _poly(L, f"Q{c}", f.den_exponents, f.den_coef)
        L.append(f"    y{c} = P{c} / Q{c}")
        vmax = getattr(model, "value_max", None)
        if model.value_transform == "log":
            if vmax is not None:
                L.append(f"    y{c} = wp.min(y{c}, {_lit(np.log(vmax + model.value_offset))})")
            L.append(f"    y{c} = wp.exp(y{c}) - {_lit(model.value_offset)}")
        if model.value_min is not None:
            L.append(f"    y{c} = wp.max(y{c}, {_lit(model.value_min)})")
        if vmax is not None:
            L.append(f"    y{c} = wp.min(y{c}, {_lit(vmax)})")
        outs.append(f"float(y{c})")
    L.append(f"    return wp.vec3({', '.join(outs)})")
    return "\n".join(L) + "\n"


GENERATED_HEADER = """# Generated by warp_rbrdf.materials.rational -- do not edit.
import warp as wp

from warp_rbrdf.materials import frame as F
"""


def generated_functions(models) -> list:
    """The generated ``@wp.func (wi, wo) -> vec3`` of each model, in order (one module)."""
    if not models:
        return []
    src = GENERATED_HEADER + "\n\n" + "\n\n".join(generate_function(m, f"rational_{i}")
                                                   for i, m in enumerate(models))
    mod = load_generated(src, "rbrdf_rational")
    return [getattr(mod, f"rational_{i}") for i in range(len(models))]


@wp.func
def _no_rational(mats: Materials, m: int, r: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    return wp.vec3(0.0)


def _chain(funcs, first: int = 0):
    """``link(mats, m, r, wi, wo)``: generated function ``r`` (one closure per function, see
    :mod:`warp_rbrdf.integrator` for why not a static loop) times ``Materials.scale[m]``."""
    if first >= len(funcs):
        return _no_rational
    func, rest = funcs[first], _chain(funcs, first + 1)

    @wp.func
    def link(mats: Materials, m: int, r: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
        if r == wp.static(first):
            return wp.cw_mul(wp.static(func)(wi, wo), mats.scale[m])
        return wp.static(rest)(mats, m, r, wi, wo)

    return link


def kernel_eval(loaded_list):
    """``rational_eval(mats, m, wi, wo)``: the generated function of material ``m`` (index
    ``Materials.offset[m]`` among the scene's rational materials) times ``Materials.scale[m]``."""
    chain = _chain(generated_functions([lm.data for lm in loaded_list]))

    @wp.func
    def rational_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
        return wp.static(chain)(mats, m, mats.offset[m], wi, wo)

    return rational_eval
