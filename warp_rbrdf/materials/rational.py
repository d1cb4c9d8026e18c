"""``rational``: the fitter's ``rbrdf-rational`` coefficient files (:mod:`fit.rational.coefficient_file`,
versions 1 and 2, version 3: 3-D fits of (theta_h, theta_d, |phi_d|), :mod:`fit.rational.fit3d`, and
version 4: 3-D fits whose functions give rho cos theta_i, the value factor ``"1/cos_theta_i"`` a
flag of every leaf, :mod:`.rational_records`) evaluated from data; ``scale`` multiplies them.

A fit is packed (:func:`pack_model`, :mod:`.rational_records`) into records of
``Materials.coef_i`` / ``coef_f`` / ``coef_q``: a split record per piecewise level and a leaf
record per single-box piece, whose numerators and denominators are stored twice: packed
(:mod:`warp_rbrdf.chebyshev`, readable by one function for every fit) and densely for the
piece's degree class (:mod:`warp_rbrdf.chebyshev_dense`). The Warp evaluation
(:mod:`.rational_kernel`) follows the file's recipe exactly (see
:mod:`fit.rational.coefficient_file`); :func:`kernel_eval` gives the renderer the evaluator
specialised to the degree classes of the scene's fits: the coefficients stay data, and a new fit
compiles only when it brings a class no compiled kernel has (the fitter's total-degree fits:
one class per (variables, numerator degree, denominator degree) of a piece).

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

from fit.errors import BRDFFileError
from fit.formats import check_measured_file
from fit.inputs import sha256_regular
from fit.rational.coefficient_file import load as load_coefficients
from fit.rational.domain import measured_domain, onto_measured_domain  # noqa: F401 - re-exported
from fit.rational.fallback import fallback_table, fit_cutoff_deg, table_from_record
from fit.rational.flagged import (
    describe_regions,
    flagged_regions,
    region_measured_range,
)
from fit.rational.model import measured_range
from fit.rational.variables3d import evaluate_directions, is_3d
from fit.rational.vouched import evaluate_at_angles, values_with_table  # noqa: F401 - re-exported

from ..errors import SceneError
from ..paths import data_root
from .data import LoadedMaterial
from .measured import scaled
from .rational_kernel import make_rational_eval, rational_eval  # noqa: F401 - re-exported
from .rational_records import (  # noqa: F401 - re-exported
    NODE_DOMAIN,
    NODE_LEAF,
    NODE_SPLIT,
    SUPPORTED_VARIABLES,
    channel_modes,
    pack_model,
    packed_classes,
)

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


def kernel_eval(loaded_list):
    """The Warp evaluation of the scene's rational materials: :func:`.rational_kernel.rational_eval`
    specialised to the degree classes of their fits' pieces
    (:func:`.rational_kernel.make_rational_eval`; the coefficients stay data, so another fit
    of the same classes compiles nothing)."""
    classes = set()
    for lm in loaded_list:
        if lm.coefficients is not None:
            classes |= packed_classes(lm.coefficients[0])
    return make_rational_eval(tuple(sorted(classes)))
