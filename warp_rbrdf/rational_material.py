"""Rational BRDF material: the fitter's ``rbrdf-rational`` v1 coefficient files
(:mod:`fit.coefficients`) compiled to generated, fully unrolled Warp code.

For each rational material the generator writes one ``@wp.func`` ``(wi, wo) -> vec3`` that
follows the file's evaluation recipe exactly (see :mod:`fit.coefficients`): Rusinkiewicz angles
-> clamp onto the fitted domain -> input transform (identity / sqrt) -> map onto [-1, 1] ->
Chebyshev recurrences up to the largest exponent used -> P/Q per channel as sums grouped by the
first variable's exponent -> value transform (linear / log) -> ``max(y, min)``; 0 below the
horizon. The polynomial part runs in float64 (Chebyshev sums can cancel); the angles come from
the float32 shading frame. Coefficients are literals, so each (material, degree) pair gets its own
code and the kernel module is cached by Warp under the hash of the generated source.
"""
from __future__ import annotations

import numpy as np

from .errors import SceneError

SUPPORTED_VARIABLES = {"theta_h": 0, "theta_d": 1, "phi_d": 2}


def rational_available() -> bool:
    try:
        import fit.rational.coefficient_file  # noqa: F401
    except ImportError:
        return False
    return True


def load_rational(spec, file="<scene>", key="materials"):
    """The :class:`fit.coefficients.RationalModel` of a material spec (``spec.data`` or file)."""
    if spec.data is not None:
        model = spec.data
    else:
        try:
            from fit.rational.coefficient_file import load
        except ImportError as e:
            raise SceneError(file, f"{key}.file", f"rational materials need fit.rational.coefficient_file ({e})") from None
        try:
            model = load(spec.file)
        except Exception as e:  # noqa: BLE001 - BRDFFileError etc., one line
            raise SceneError(file, f"{key}.file", f"cannot read coefficient file ({e})") from None
    check_model(model, file, key)
    return model


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


def _lit(x: float) -> str:
    return f"wp.float64({float(x)!r})"


def _poly(lines, name, exps, coefs, tvars):
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
    that picks the piece from the split variable, clamped as in :mod:`fit.coefficients`."""
    pieces = getattr(model, "pieces", None)
    if pieces is None:
        return _generate_single(model, name)
    parts = [generate_function(p, f"{name}_p{k}") for k, p in enumerate(pieces)]   # nested: recursive
    src = SUPPORTED_VARIABLES[model.split_variable]
    L = ["@wp.func", f"def {name}(wi: wp.vec3, wo: wp.vec3) -> wp.vec3:",
         f"    # piecewise rational BRDF {model.name!r}: {len(pieces)} pieces along {model.split_variable}",
         "    if wi[2] <= 0.0 or wo[2] <= 0.0:", "        return wp.vec3(0.0)",
         "    a = M.half_diff(wi, wo)", f"    x = wp.float64(a[{src}])"]
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
         "    a = M.half_diff(wi, wo)"]
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
        _poly(L, f"P{c}", f.num_exponents, f.num_coef, None)
        _poly(L, f"Q{c}", f.den_exponents, f.den_coef, None)
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


def generate_functions(models):
    """``[(name, source)]`` for the scene's rational materials, in material-offset order."""
    return [(f"rational_{i}", generate_function(m, f"rational_{i}")) for i, m in enumerate(models)]
