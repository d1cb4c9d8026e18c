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

**What the fit does not vouch for.** A piece whose record flags a channel as not within its
intervals (:func:`fit.rational.brdf_model.flagged_regions`: the core when no core was met, a
best-effort grazing band, a search stopped at its degree limit) is never rendered from its
fitted function. With the scene key ``unvouched = "projected"`` (default) that channel of that
piece is taken from the ``projected`` table of the measurement the fit was made from (the
file's ``source``, found next to the coefficient file, next to the scene or in
``$RBRDF_DATA`` and checked against its sha256; the fit's own median projection with its
grazing cut-off, empty clusters filled from the nearest measured cluster), clamped to the
measured range of that piece; the table goes into ``Materials.tables`` and ``Materials.param``
holds its start. With ``unvouched = "refuse"`` loading fails with one line naming the material,
the file and what is flagged. A fit without a flagged piece generates the same code as before.
"""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import warp as wp

from fit.formats.angles import directions_to_half_diff
from fit.formats.grid import (
    N_THETA_D,
    theta_d_centres,
    theta_d_index,
    theta_h_centres,
    theta_h_index,
)
from fit.formats.measured import file_sha256
from fit.rational.brdf_model import (
    GRAZING_CUTOFF_DEG,
    describe_regions,
    flagged_regions,
    region_measured_range,
)
from fit.rational.coefficient_file import load as load_coefficients
from fit.rational.model import flagged, measured_range, output_clamp

from ..codegen import lit as _lit
from ..codegen import load_generated
from ..errors import SceneError
from ..paths import data_root
from .data import LoadedMaterial, Materials
from .measured import scaled

SUPPORTED_VARIABLES = {"theta_h": 0, "theta_d": 1, "phi_d": 2}
UNVOUCHED = ("projected", "refuse")    # scene key ``unvouched``: what flagged pieces become


def load(spec, scene_file="<scene>", key="materials") -> LoadedMaterial:
    """The :class:`fit.rational.model.RationalModel` of a material spec (``spec.data`` or file);
    pieces the fit does not vouch for become the projected table or refuse the scene
    (``spec.unvouched``, module docstring)."""
    if spec.data is not None:
        model = spec.data
    else:
        try:
            model = load_coefficients(spec.file)
        except Exception as e:  # noqa: BLE001 - BRDFFileError etc., one line
            raise SceneError(scene_file, f"{key}.file", f"cannot read coefficient file ({e})") from None
    check_model(model, scene_file, key)
    regions = flagged_regions(model)
    if not regions:
        return LoadedMaterial(spec, model, scaled(model.evaluate, spec.scale), scale=spec.scale)
    what = describe_regions(model, regions)
    fit_name = spec.file.name if spec.file is not None else f"(in memory, {model.name!r})"
    head = f"material {spec.name!r}: rational fit {fit_name} is not within its bound for {what}"
    mode = getattr(spec, "unvouched", "projected")
    if mode == "refuse":
        raise SceneError(scene_file, f"{key}.unvouched", f"{head}; refused (unvouched = \"refuse\"; "
                                                         f"the default \"projected\" shows the measured "
                                                         f"projection there)")
    if mode != "projected":
        raise SceneError(scene_file, f"{key}.unvouched", f"expected one of {', '.join(UNVOUCHED)}, got {mode!r}")
    if [v.name for v in model.variables] != ["theta_h", "theta_d"]:
        raise SceneError(scene_file, f"{key}.file", f"{head}; a projected table can replace only a fit "
                                                    f"in (theta_h, theta_d)")
    src = find_source(model, spec, scene_file, key, head)
    # the measurement (and the fitter's projection policy) only for a flagged fit
    from fit.formats import load_measured
    from fit.rational.brdf_fit import project_for_fit

    try:
        cut = float(model.fit_info.get("grazing_cutoff_deg") or GRAZING_CUTOFF_DEG)
        p = project_for_fit(load_measured(src), grazing_cutoff_deg=cut)
    except Exception as e:  # noqa: BLE001 - BRDFFileError etc., one line
        raise SceneError(scene_file, f"{key}.file", f"{head}; cannot read its source measurement {src} "
                                                    f"({e})") from None
    model = copy.deepcopy(model)            # ranges of old files are added to a copy
    for r in flagged_regions(model):
        leaf = r["model"]
        for c in r["channels"]:
            if measured_range(leaf.function_info[c]) is None:
                rng = region_measured_range(p, leaf, c)
                if rng is not None:
                    leaf.function_info[c] = dict(leaf.function_info[c], measured_range=list(rng))
    table = fallback_table(p)
    note = (f"rational fit not within its bound for {what}: using the projected table there "
            f"(median projection of {src.name}, clamped to each region's measured range)")
    return LoadedMaterial(spec, model, scaled(evaluate_with_table(model, table), spec.scale),
                          scale=spec.scale, fallback_table=table, notes=(note,))


def source_dirs(spec, scene_file) -> list:
    """Where the source measurement of a fit is looked for, in order: the coefficient file's
    folder, the scene file's folder, the shared data folder and its subfolders (``rgl/``,
    ``merl/``, ...)."""
    dirs = []
    if spec.file is not None:
        dirs.append(Path(spec.file).parent)
    sf = Path(str(scene_file))
    if sf.is_file():
        dirs.append(sf.parent)
    root = data_root()
    if root is not None and Path(root).is_dir():
        dirs.append(Path(root))
        dirs += sorted(d for d in Path(root).iterdir() if d.is_dir())
    out = []
    for d in dirs:
        if d.resolve() not in [o.resolve() for o in out]:
            out.append(d)
    return out


def find_source(model, spec, scene_file, key, head) -> Path:
    """The source measurement a fit records (``source.file``, checked against
    ``source.sha256`` when recorded); a one-line :class:`SceneError` naming it when it cannot
    be found."""
    name = str((model.source or {}).get("file") or "")
    sha = str((model.source or {}).get("sha256") or "")
    if not name:
        raise SceneError(scene_file, f"{key}.file", f"{head}; the fit records no source measurement, so "
                                                    f"no projected table can replace it there")
    cands = [Path(name)] if Path(name).is_absolute() else []
    dirs = source_dirs(spec, scene_file)
    cands += [d / Path(name).name for d in dirs]
    mismatched = []
    for c in cands:
        if c.is_file():
            if not sha or file_sha256(c) == sha:
                return c
            mismatched.append(str(c))
    where = ", ".join(str(d) for d in dirs) or "nowhere (no coefficient file, scene file or RBRDF_DATA)"
    found = (f"; {', '.join(mismatched)} has another sha256 (not the measurement the fit was made from)"
             if mismatched else "")
    raise SceneError(scene_file, f"{key}.file",
                     f"{head}; the projected table that replaces it there needs its source measurement "
                     f"{name!r}" + (f" (sha256 {sha[:12]}...)" if sha else "") +
                     f", not found in {where}{found}")


def fallback_table(p) -> np.ndarray:
    """The (90, 90, 3) float32 table of a projection (values below 0 as 0) with every empty
    cluster given the value of the nearest (in theta_h, theta_d radians) non-empty cluster of
    the same channel: beyond the fit's grazing cut-off many clusters are empty, and 0 there
    would be a black rim, not a measurement."""
    from scipy.spatial import cKDTree

    v = np.maximum(np.array(p.value, dtype=np.float64), 0.0)
    th, td = np.meshgrid(theta_h_centres(), theta_d_centres(), indexing="ij")
    pts = np.stack([th, td], axis=-1)
    for c in range(v.shape[-1]):
        ch = v[..., c]
        bad = ~np.isfinite(ch)
        if bad.any() and (~bad).any():
            _, idx = cKDTree(pts[~bad]).query(pts[bad])
            ch[bad] = ch[~bad][idx]
    return np.nan_to_num(v, nan=0.0).astype(np.float32)


def evaluate_with_table(model, table):
    """NumPy reference of the generated code with a fallback table: the model, except that every
    flagged channel of a flagged piece is the table's nearest cluster at the inputs clamped onto
    that piece's box, clamped to the piece's measured range; 0 below the horizon."""
    flags = {r["leaf"]: r["channels"] for r in flagged_regions(model)}
    tab = np.asarray(table, np.float32).astype(np.float64)

    def evaluate(wi, wo):
        wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
        th, _, td, _ = directions_to_half_diff(wi, wo)
        x = np.stack(np.broadcast_arrays(th, td), axis=-1)
        out = np.array(model(x), dtype=np.float64)
        for k, (leaf, sel, xl) in enumerate(model.leaves(x)):
            if k not in flags or not np.any(sel):
                continue
            tv = tab[theta_h_index(xl[..., 0]), theta_d_index(xl[..., 1])]
            for c in flags[k]:
                v = tv[..., c]
                rng = measured_range(leaf.function_info[c])
                if rng is not None:
                    v = np.clip(v, rng[0], rng[1])
                out[..., c] = np.where(sel, v, out[..., c])
        above = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
        return np.where(above[..., None], out, 0.0)

    return evaluate


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


def _signature(name: str, table: bool) -> str:
    if table:   # the fallback table: mats.tables from index toff (Materials.param)
        return f"def {name}(mats: Materials, toff: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:"
    return f"def {name}(wi: wp.vec3, wo: wp.vec3) -> wp.vec3:"


def generate_function(model, name: str, table: bool = False) -> str:
    """Source of ``@wp.func name(wi, wo) -> wp.vec3`` for a rational BRDF model; a piecewise
    model (file version 2) gets one function per piece (``name_p0``, ...) and a dispatcher
    that picks the piece from the split variable, clamped as in :mod:`fit.rational.coefficient_file`.
    ``table``: the functions take ``(mats, toff, wi, wo)`` and every flagged channel reads the
    fallback table at ``mats.tables[toff + i * 90 + j]`` instead of its fitted function
    (module docstring); without it a flagged channel is its function clamped to its measured
    range (step 7 of the recipe), and an unflagged model's code is unchanged."""
    pieces = getattr(model, "pieces", None)
    if pieces is None:
        return _generate_single(model, name, table)
    parts = [generate_function(p, f"{name}_p{k}", table) for k, p in enumerate(pieces)]   # nested: recursive
    src = SUPPORTED_VARIABLES[model.split_variable]
    args = "mats, toff, wi, wo" if table else "wi, wo"
    L = ["@wp.func", _signature(name, table),
         f"    # piecewise rational BRDF {model.name!r}: {len(pieces)} pieces along {model.split_variable}",
         "    if wi[2] <= 0.0 or wo[2] <= 0.0:", "        return wp.vec3(0.0)",
         "    a = F.half_diff(wi, wo)", f"    x = wp.float64(a[{src}])"]
    for k in range(len(pieces) - 1):
        L.append(f"    if x <= {_lit(model.edges[k + 1])}:")
        L.append(f"        return {name}_p{k}({args})")
    L.append(f"    return {name}_p{len(pieces) - 1}({args})")
    return "\n\n".join(parts) + "\n\n" + "\n".join(L) + "\n"


def _generate_single(model, name: str, table: bool = False) -> str:
    nv = len(model.variables)
    flags = [flagged(i) for i in model.function_info]
    ranges = [output_clamp(i) for i in model.function_info]
    from_table = [table and fl for fl in flags]
    kmax = [0] * nv
    for f, tb in zip(model.functions, from_table):
        if tb:
            continue
        for ex in (f.num_exponents, f.den_exponents):
            if len(ex):
                kmax = [max(k, int(m)) for k, m in zip(kmax, ex.max(axis=0))]
    L = ["@wp.func", _signature(name, table),
         f"    # generated from rational BRDF {model.name!r}: {model.n_coefficients} coefficients"
         + (f"; channels {[c for c, tb in enumerate(from_table) if tb]} from the fallback table"
            if any(from_table) else ""),
         "    if wi[2] <= 0.0 or wo[2] <= 0.0:", "        return wp.vec3(0.0)",
         "    a = F.half_diff(wi, wo)"]
    if any(from_table):
        box = {v.name: v.domain for v in model.variables}
        (hl, hh), (dl, dh) = box["theta_h"], box["theta_d"]
        L.append(f"    ih = F.merl_theta_h_index(float(wp.clamp(wp.float64(a[0]), {_lit(hl)}, {_lit(hh)})))")
        L.append(f"    jd = F.merl_theta_d_index(float(wp.clamp(wp.float64(a[1]), {_lit(dl)}, {_lit(dh)})))")
        L.append(f"    tv = mats.tables[toff + ih * {N_THETA_D} + jd]")
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
        if from_table[c]:          # not vouched for: the measured projection, in its range
            L.append(f"    y{c} = wp.float64(tv[{c}])")
        else:
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
        if ranges[c] is not None:  # step 7: flagged: its measured range; valid: its vouched one
            L.append(f"    y{c} = wp.clamp(y{c}, {_lit(ranges[c][0])}, {_lit(ranges[c][1])})")
        outs.append(f"float(y{c})")
    L.append(f"    return wp.vec3({', '.join(outs)})")
    return "\n".join(L) + "\n"


GENERATED_HEADER = """# Generated by warp_rbrdf.materials.rational -- do not edit.
import warp as wp

from warp_rbrdf.materials import frame as F
"""


def generated_functions(models, tables=None) -> list:
    """The generated ``@wp.func`` of each model, in order (one module): ``(wi, wo) -> vec3``, or
    ``(mats, toff, wi, wo) -> vec3`` where ``tables[i]`` (the model has a fallback table)."""
    if not models:
        return []
    tables = [False] * len(models) if tables is None else [bool(t) for t in tables]
    header = GENERATED_HEADER + ("from warp_rbrdf.materials.data import Materials\n" if any(tables) else "")
    src = header + "\n\n" + "\n\n".join(generate_function(m, f"rational_{i}", t)
                                            for i, (m, t) in enumerate(zip(models, tables)))
    mod = load_generated(src, "rbrdf_rational")
    return [getattr(mod, f"rational_{i}") for i in range(len(models))]


@wp.func
def _no_rational(mats: Materials, m: int, r: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    return wp.vec3(0.0)


def _chain(funcs, first: int = 0, tables=None):
    """``link(mats, m, r, wi, wo)``: generated function ``r`` (one closure per function, see
    :mod:`warp_rbrdf.integrator` for why not a static loop) times ``Materials.scale[m]``;
    ``tables[r]``: that function reads a fallback table starting at ``Materials.param[m]``."""
    if first >= len(funcs):
        return _no_rational
    tables = [False] * len(funcs) if tables is None else tables
    func, rest = funcs[first], _chain(funcs, first + 1, tables)

    if tables[first]:
        @wp.func
        def link(mats: Materials, m: int, r: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
            if r == wp.static(first):
                return wp.cw_mul(wp.static(func)(mats, mats.param[m], wi, wo), mats.scale[m])
            return wp.static(rest)(mats, m, r, wi, wo)

        return link

    @wp.func
    def link(mats: Materials, m: int, r: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
        if r == wp.static(first):
            return wp.cw_mul(wp.static(func)(wi, wo), mats.scale[m])
        return wp.static(rest)(mats, m, r, wi, wo)

    return link


def kernel_eval(loaded_list):
    """``rational_eval(mats, m, wi, wo)``: the generated function of material ``m`` (index
    ``Materials.offset[m]`` among the scene's rational materials) times ``Materials.scale[m]``."""
    tables = [getattr(lm, "fallback_table", None) is not None for lm in loaded_list]
    chain = _chain(generated_functions([lm.data for lm in loaded_list], tables), tables=tables)

    @wp.func
    def rational_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
        return wp.static(chain)(mats, m, mats.offset[m], wi, wo)

    return rational_eval
