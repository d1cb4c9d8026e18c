"""``rational``: the fitter's ``rbrdf-rational`` coefficient files (:mod:`fit.rational.coefficient_file`,
versions 1 and 2, and version 3: 3-D fits of (theta_h, theta_d, |phi_d|), :mod:`fit.rational.fit3d`)
evaluated from data; ``scale`` multiplies them.

A fit is packed (:func:`pack_model`) into records of ``Materials.coef_i`` / ``coef_f`` /
``coef_q``: a split record per piecewise level (the split variable, its inner edges, the
pieces) and a leaf record per single-box piece (flags, per-variable box and map, per channel its
mode and step-7 range, and the six numerators and denominators of its channels packed as one
group of Chebyshev polynomials, :mod:`warp_rbrdf.chebyshev`). One Warp function,
:func:`rational_eval`, evaluates every fit: it follows the file's
recipe exactly (see :mod:`fit.rational.coefficient_file`): Rusinkiewicz angles -> (moved onto
the measured domain, below) -> the piece
(``x <= edge`` picks the lower piece) -> clamp onto the piece's box -> input transform
(identity / sqrt) -> map onto [-1, 1] -> Chebyshev sums -> P/Q per channel -> value transform
(linear / log) -> ``max(y, min)``, ``min(y, max)`` -> the step-7 range; 0 below the horizon.
The polynomial part runs in float64 (Chebyshev sums can cancel); the angles come from the
float32 shading frame. The kernels' source does not depend on the coefficients: a new fit
compiles nothing (the kernel cache serves the same code for every fit).

**Where the fit has no data.** A 2-D fit made from a median projection with a grazing cut-off c
(the file's ``fit.grazing_cutoff_deg``, 79 deg) has data only in the clusters with
``cos theta_h cos theta_d >= cos c`` (:func:`onto_measured_domain`); beyond, the cut-off left the
clusters empty and the fit extrapolates, bounded only by its whole piece's range (on the
fidelity study's fits up to 4400 /sr where the measurement is below 1: rim rings). The renderer
evaluates such a fit at the edge of its measured domain at the same theta_h (a domain record at
the root of the packed fit; :func:`measured_domain`), as the fits already do beyond their last
theta_d. Fits that record no cut-off, and version-3 fits, are evaluated by the recipe alone.

**What the fit does not vouch for.** A piece whose record flags a channel as not within its
intervals (:func:`fit.rational.flagged.flagged_regions`: the core when no core was met, a
best-effort grazing band, a search stopped at its degree limit) is never rendered from its
fitted function. With the scene key ``unvouched = "projected"`` (default) that channel of that
piece is taken from the ``projected`` table of the measurement the fit was made from (the
fit's own median projection with its grazing cut-off, empty clusters filled from the nearest
measured cluster, :func:`fit.rational.fallback.fallback_table`), clamped to the measured range
of that piece; the table goes into ``Materials.tables`` and ``Materials.param`` holds its start.
The fitter embeds the part of that table read here in the coefficient file (its ``fallback``
key, :mod:`fit.rational.fallback`), so such a fit renders without its source measurement, with
the same values bit for bit; the table is checked against the fit (shape, dtype, cut-off,
coverage of the flagged pieces and channels, finite values >= 0; a bad one is a one-line
:class:`SceneError` naming the file and the key). Files written before the table was embedded
take it from the source measurement (the file's ``source``, found next to the coefficient file,
next to the scene or in ``$RBRDF_DATA`` and checked against its sha256; a one-line error naming
it when it is not found). The load note says which. With ``unvouched = "refuse"`` loading fails with one line naming the material,
the file and what is flagged. A fit without a flagged piece packs exactly as before the table
existed (no channel reads a table; only the domain record above).
"""
from __future__ import annotations

import copy
from functools import partial
from pathlib import Path

import numpy as np
import warp as wp

from fit.formats.grid import N_THETA_D
from fit.errors import BRDFFileError
from fit.formats import check_measured_file
from fit.inputs import sha256_regular
from fit.rational.flagged import (
    describe_regions,
    flagged_regions,
    region_measured_range,
)
from fit.rational.coefficient_file import load as load_coefficients
from fit.rational.domain import measured_domain, onto_measured_domain  # noqa: F401 - re-exported
from fit.rational.fallback import fallback_table, fit_cutoff_deg, table_from_record
from fit.rational.model import flagged, measured_range, output_clamp
from fit.rational.variables3d import evaluate_directions, is_3d
from fit.rational.vouched import evaluate_at_angles, values_with_table  # noqa: F401 - re-exported

from ..chebyshev import FlatData, cheb_sum6
from ..errors import SceneError
from ..paths import data_root
from . import frame as F
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
    cut = measured_domain(model)
    if not regions:
        evaluate = (partial(evaluate_directions, model) if is_3d(model) else
                    model.evaluate if cut is None else evaluate_at_angles(model, None, cut))
        return LoadedMaterial(spec, model, scaled(evaluate, spec.scale), scale=spec.scale,
                              coefficients=_packed(model, False, scene_file, key, cut))
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
    if getattr(model, "fallback", None) is not None:
        # the table the fitter wrote into the file (fit.rational.fallback): no measurement needed
        try:
            table = table_from_record(model.fallback, model)
        except ValueError as e:       # fit.jsonfields.Invalid names the key; one line
            raise SceneError(scene_file, f"{key}.file", f"{head}; {fit_name}: embedded fallback table "
                                                        f"unusable ({e})") from None
        src_name = str((model.source or {}).get("file") or "") or "its source measurement"
        origin = f"{src_name}, " + (f"embedded in {fit_name}" if spec.file is not None else "carried by the fit")
    else:
        model, table, origin = _table_from_source(model, spec, scene_file, key, head)
    note = (f"rational fit not within its bound for {what}: using the projected table there "
            f"(median projection of {origin}, clamped to each region's measured range)")
    return LoadedMaterial(spec, model, scaled(evaluate_at_angles(model, table, cut), spec.scale),
                          scale=spec.scale, fallback_table=table, notes=(note,),
                          coefficients=_packed(model, True, scene_file, key, cut))


def _table_from_source(model, spec, scene_file, key, head) -> tuple:
    """``(model, table, source name)`` of a flagged fit whose file carries no table (written
    before the fitter embedded it): the fallback table of the fitter's projection of its source
    measurement (:func:`find_source`) with the fit's grazing cut-off, and a copy of the model
    with the measured ranges its flagged channels lack."""
    from fit.formats import load_measured
    from fit.rational.brdf_fit import project_for_fit

    src = find_source(model, spec, scene_file, key, head)
    try:
        p = project_for_fit(load_measured(src), grazing_cutoff_deg=fit_cutoff_deg(model))
    except Exception as e:  # noqa: BLE001 - BRDFFileError etc., one line
        raise SceneError(scene_file, f"{key}.file", f"{head}; cannot read its source measurement {src} "
                                                    f"({e})") from None
    model = copy.deepcopy(model)            # ranges missing from the file are added to a copy
    for r in flagged_regions(model):
        leaf = r["model"]
        for c in r["channels"]:
            if measured_range(leaf.function_info[c]) is None:
                rng = region_measured_range(p, leaf, c)
                if rng is not None:
                    leaf.function_info[c] = dict(leaf.function_info[c], measured_range=list(rng))
    return model, fallback_table(p), src.name


def _packed(model, table, scene_file, key, cutoff_deg=None) -> tuple:
    try:
        return pack_model(model, table, cutoff_deg)
    except ValueError as e:
        raise SceneError(scene_file, f"{key}.file", f"cannot render this rational fit ({e})") from None


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
            try:    # stat before the hash: a file over its format's size is never read
                usable = not sha or sha256_regular(c, check_measured_file(c), "measured file") == sha
            except BRDFFileError:
                usable = False
            if usable:
                return c
            mismatched.append(str(c))
    where = ", ".join(str(d) for d in dirs) or "nowhere (no coefficient file, scene file or RBRDF_DATA)"
    found = (f"; {', '.join(mismatched)} has another sha256 (not the measurement the fit was made from)"
             if mismatched else "")
    raise SceneError(scene_file, f"{key}.file",
                     f"{head}; the projected table that replaces it there needs its source measurement "
                     f"{name!r}" + (f" (sha256 {sha[:12]}...)" if sha else "") +
                     f", not found in {where}{found}")


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


# --------------------------------------------------------------------------------------------
# The fit as data (Materials.coef_i / coef_f / coef_q) and the one Warp function that evaluates it
# --------------------------------------------------------------------------------------------
NODE_LEAF, NODE_SPLIT, NODE_DOMAIN = 0, 1, 2
# domain record (ints), only at the root of a fit with a measured domain (:func:`measured_domain`):
# kind, float offset of (cos c, c) (c: the grazing cut-off, radians), the fit's int offset
DOMAIN_FLOATS, DOMAIN_CHILD = 1, 2
# split record (ints): kind, variable (SUPPORTED_VARIABLES), pieces K, float offset of its K - 1
# inner edges, then the K children's int offsets
SPLIT_VAR, SPLIT_N, SPLIT_EDGES, SPLIT_CHILDREN = 1, 2, 3, 4
# leaf record (ints): kind, variables, flags, float offset of its header, 3 variable codes
# (source angle | transform << 2), the int and row offsets of its polynomials (one packed
# group: P_R, P_G, P_B, Q_R, Q_G, Q_B, :func:`warp_rbrdf.chebyshev.cheb_sum6`), and per
# channel its mode
LEAF_NV, LEAF_FLAGS, LEAF_FH, LEAF_VARS, LEAF_POLY, LEAF_MODES = 1, 2, 3, 4, 7, 9
LEAF_CLAMP, LEAF_LOG, LEAF_MIN, LEAF_MAX, LEAF_TABLE = 1, 2, 4, 8, 16   # flags
CH_TABLE, CH_RANGE = 1, 2                                               # channel mode bits
TRANSFORM_CODES = {"identity": 0, "sqrt": 1}
# leaf header (floats): value offset, min, max, log(max + offset); per variable (lo, hi,
# u_lo + u_hi, 1 / (u_hi - u_lo)); per channel the step-7 range (lo, hi); the table box
# (theta_h lo, hi, theta_d lo, hi)
FH_OFFSET, FH_MIN, FH_MAX, FH_LOGMAX, FH_VARS, FH_RANGES, FH_BOX = 0, 1, 2, 3, 4, 16, 22
N_FH = 26


def channel_modes(model, table: bool = False) -> list:
    """Per output of a single-box model: ``(from_table, range)``: whether the channel reads the
    fallback table (``table`` and the function is flagged) and its step-7 clamp
    (:func:`fit.rational.model.output_clamp`; None: none)."""
    return [(bool(table and flagged(i)), output_clamp(i)) for i in model.function_info]


def pack_model(model, table: bool = False, cutoff_deg: float | None = None) -> tuple:
    """``(ints int32, floats float64, rows float64 (n, 6))``: a
    :class:`~fit.rational.model.RationalModel` or :class:`~fit.rational.model.PiecewiseRationalModel`
    (nested pieces included) as the records :func:`rational_eval` walks, the root at int 0;
    offsets are relative to the material's starts. ``table``: flagged channels read the
    fallback table (module docstring). ``cutoff_deg``: the angles are first moved onto the
    measured domain of that grazing cut-off (:func:`onto_measured_domain`; a domain record at
    the root); None (default): the file's recipe alone."""
    fd = FlatData(6)
    if cutoff_deg is None:
        _pack_node(fd, model, table)
    else:
        cut = np.radians(float(cutoff_deg))
        n = fd.add_ints([NODE_DOMAIN, 0, 0])
        fd.ints[n + DOMAIN_FLOATS] = fd.add_floats([np.cos(cut), cut])
        fd.ints[n + DOMAIN_CHILD] = _pack_node(fd, model, table)
    return fd.arrays()


def _pack_node(fd, model, table) -> int:
    pieces = getattr(model, "pieces", None)
    if pieces is None:
        return _pack_leaf(fd, model, table)
    n = fd.add_ints([NODE_SPLIT, SUPPORTED_VARIABLES[model.split_variable], len(pieces), 0] + [0] * len(pieces))
    fd.ints[n + SPLIT_EDGES] = fd.add_floats(model.edges[1:-1])
    for k, piece in enumerate(pieces):
        fd.ints[n + SPLIT_CHILDREN + k] = _pack_node(fd, piece, table)
    return n


def _pack_leaf(fd, model, table) -> int:
    nv = len(model.variables)
    modes = channel_modes(model, table)
    vmax, vmin, off = model.value_max, model.value_min, float(model.value_offset)
    flags = ((LEAF_CLAMP if model.domain_policy.get("outside", "clamp") == "clamp" else 0)
             | (LEAF_LOG if model.value_transform == "log" else 0)
             | (LEAF_MIN if vmin is not None else 0) | (LEAF_MAX if vmax is not None else 0)
             | (LEAF_TABLE if any(t for t, _ in modes) else 0))
    codes = [SUPPORTED_VARIABLES[v.name] | TRANSFORM_CODES[v.transform] << 2 for v in model.variables]
    n = fd.add_ints([NODE_LEAF, nv, flags, 0] + codes + [0] * (3 - nv) + [0, 0] + [0] * 3)
    head = np.zeros(N_FH)
    head[[FH_OFFSET, FH_MIN, FH_MAX]] = off, vmin or 0.0, vmax or 0.0
    if vmax is not None and model.value_transform == "log":
        head[FH_LOGMAX] = np.log(vmax + off)
    for v, var in enumerate(model.variables):
        ulo, uhi = var.rf_domain
        head[FH_VARS + 4 * v: FH_VARS + 4 * v + 4] = var.domain[0], var.domain[1], ulo + uhi, 1.0 / (uhi - ulo)
    for c, (_, rng) in enumerate(modes):
        if rng is not None:
            head[FH_RANGES + 2 * c: FH_RANGES + 2 * c + 2] = rng
    if flags & LEAF_TABLE:
        box = {v.name: v.domain for v in model.variables}
        head[FH_BOX:FH_BOX + 4] = (*box["theta_h"], *box["theta_d"])
    fd.ints[n + LEAF_FH] = fd.add_floats(head)
    fits = [(f, t) for f, (t, _) in zip(model.functions, modes)]
    fd.ints[n + LEAF_POLY:n + LEAF_POLY + 2] = fd.add_polynomials(
        [None if t else (f.num_exponents, f.num_coef) for f, t in fits] +
        [None if t else (f.den_exponents, f.den_coef) for f, t in fits], nv)
    for c, (from_table, rng) in enumerate(modes):
        fd.ints[n + LEAF_MODES + c] = (CH_TABLE if from_table else 0) | (CH_RANGE if rng is not None else 0)
    return n


@wp.func
def _mapped_input(ci: wp.array(dtype=int), cf: wp.array(dtype=wp.float64), code: int, b: int, flags: int,
                  a: wp.vec3) -> wp.float64:
    """Steps 1-3 of the recipe for a variable of code ``code`` (a leaf's variable code) whose
    header entries start at float ``b``: clamp onto the box, transform, map onto [-1, 1];
    phi_d folded into [0, pi] first by the mirror symmetry of isotropy, |phi_d| (file version 3,
    :mod:`fit.rational.variables3d`; the light's and the view's roles are kept)."""
    src = code & 3
    x = wp.float64(a[src])
    if src == 2:
        x = wp.float64(wp.abs(a[2]))
    if (flags & LEAF_CLAMP) != 0:
        x = wp.clamp(x, cf[b], cf[b + 1])
    if (code >> 2) == 1:
        x = wp.sqrt(wp.max(x, wp.float64(0.0)))
    return (wp.float64(2.0) * x - cf[b + 2]) * cf[b + 3]


@wp.func
def _channel(cf: wp.array(dtype=wp.float64), mode: int, h: int, flags: int, c: int, p: wp.float64,
             q: wp.float64, tab: float) -> float:
    """Steps 5-7 of channel ``c`` (``mode``) of a leaf with header at float ``h``: P/Q, value
    transform, clamps; ``tab``: the fallback table's value, used where the channel is flagged
    and a table is present."""
    y = wp.float64(0.0)
    if (mode & CH_TABLE) != 0:
        y = wp.float64(tab)
    else:
        y = p / q
        if (flags & LEAF_LOG) != 0:
            if (flags & LEAF_MAX) != 0:
                y = wp.min(y, cf[h + FH_LOGMAX])
            y = wp.exp(y) - cf[h + FH_OFFSET]
        if (flags & LEAF_MIN) != 0:
            y = wp.max(y, cf[h + FH_MIN])
        if (flags & LEAF_MAX) != 0:
            y = wp.min(y, cf[h + FH_MAX])
    if (mode & CH_RANGE) != 0:
        y = wp.clamp(y, cf[h + FH_RANGES + 2 * c], cf[h + FH_RANGES + 2 * c + 1])
    return float(y)


@wp.func
def _onto_domain(a: wp.vec3, cos_cut: wp.float64, cut: wp.float64) -> wp.vec3:
    """Rusinkiewicz angles ``a`` (theta_h, theta_d, phi_d) moved onto the measured domain
    ``cos theta_h cos theta_d >= cos_cut`` (:func:`onto_measured_domain`, in float64)."""
    th = wp.min(wp.float64(a[0]), cut)
    lim = wp.acos(wp.min(cos_cut / wp.cos(th), wp.float64(1.0)))
    return wp.vec3(float(th), float(wp.min(wp.float64(a[1]), lim)), a[2])


@wp.func
def rational_eval(mats: Materials, m: int, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    """rho (1/sr) of rational material ``m``: its packed fit (:func:`pack_model`, ints from
    ``coef_i[3 m]``, floats from ``coef_i[3 m + 1]``, coefficient rows from ``coef_i[3 m + 2]``)
    at (wi, wo), times ``Materials.scale[m]``; 0 below the horizon."""
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0)
    ci = mats.coef_i
    cf = mats.coef_f
    ib = ci[3 * m]
    fb = ci[3 * m + 1]
    a = F.half_diff(wi, wo)
    n = ib
    if ci[n] == NODE_DOMAIN:       # no extrapolation beyond the measured domain
        d = fb + ci[n + DOMAIN_FLOATS]
        a = _onto_domain(a, cf[d], cf[d + 1])
        n = ib + ci[n + DOMAIN_CHILD]
    while ci[n] == NODE_SPLIT:     # piece k: the first with x <= edge k + 1
        x = wp.float64(a[ci[n + SPLIT_VAR]])
        if ci[n + SPLIT_VAR] == 2:
            x = wp.abs(x)
        e = fb + ci[n + SPLIT_EDGES]
        k = int(0)      # noqa: UP018, RUF046 - Warp: a dynamic int (a literal is constant in the loop)
        for j in range(ci[n + SPLIT_N] - 1):
            if x > cf[e + j]:
                k = j + 1
        n = ib + ci[n + SPLIT_CHILDREN + k]
    nv = ci[n + LEAF_NV]
    flags = ci[n + LEAF_FLAGS]
    h = fb + ci[n + LEAF_FH]
    t0 = _mapped_input(ci, cf, ci[n + LEAF_VARS], h + FH_VARS, flags, a)
    t1 = wp.float64(0.0)
    t2 = wp.float64(0.0)
    if nv >= 2:
        t1 = _mapped_input(ci, cf, ci[n + LEAF_VARS + 1], h + FH_VARS + 4, flags, a)
    if nv >= 3:
        t2 = _mapped_input(ci, cf, ci[n + LEAF_VARS + 2], h + FH_VARS + 8, flags, a)
    ta = wp.float64(0.0)        # padded in front (chebyshev module docstring)
    tb = wp.float64(0.0)
    tc = t0
    if nv == 2:
        tb = t0
        tc = t1
    elif nv == 3:
        ta = t0
        tb = t1
        tc = t2
    tab = wp.vec3(0.0)
    if (flags & LEAF_TABLE) != 0:   # the projected table (theta_h, theta_d) clamped onto the box
        ih = F.merl_theta_h_index(float(wp.clamp(wp.float64(a[0]), cf[h + FH_BOX], cf[h + FH_BOX + 1])))
        jd = F.merl_theta_d_index(float(wp.clamp(wp.float64(a[1]), cf[h + FH_BOX + 2], cf[h + FH_BOX + 3])))
        tab = mats.tables[mats.param[m] + ih * N_THETA_D + jd]
    pq = cheb_sum6(mats.coef_q, ci, ci[3 * m + 2] + ci[n + LEAF_POLY + 1], ib + ci[n + LEAF_POLY],
                   ta, tb, tc)
    r = n + LEAF_MODES
    y = wp.vec3(_channel(cf, ci[r], h, flags, 0, pq[0], pq[3], tab[0]),
                _channel(cf, ci[r + 1], h, flags, 1, pq[1], pq[4], tab[1]),
                _channel(cf, ci[r + 2], h, flags, 2, pq[2], pq[5], tab[2]))
    return wp.cw_mul(y, mats.scale[m])


def kernel_eval(loaded_list):
    """:func:`rational_eval`, the same function for every scene: the fits are data
    (:attr:`LoadedMaterial.coefficients`), so a new fit compiles nothing."""
    return rational_eval
