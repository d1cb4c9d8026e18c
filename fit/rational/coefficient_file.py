"""Versioned JSON coefficient files of fitted rational functions: format ``rbrdf-rational``,
version 1 (one function per output), version 2 (pieces along one variable) and version 3
(3-D BRDF fits of theta_h, theta_d, |phi_d|).

Specification (version 1)
=========================
A UTF-8 JSON object. Keys (all required unless marked optional)::

    {
      "format":  "rbrdf-rational",           # exact string
      "version": 1,                          # integer; readers reject other versions
      "name":    "satin_rosaline_rgb",       # material / function name
      "kind":    "brdf",                     # "brdf" (outputs R, G, B in 1/sr) or "function"
      "variables": [                         # one entry per input variable, in order
        {"name": "theta_h", "unit": "rad",
         "transform": "sqrt",                # "identity": u = x ; "sqrt": u = sqrt(x)
         "domain": [lo, hi]},                # fitted box in the variable's own unit (x)
        {"name": "theta_d", "unit": "rad", "transform": "identity", "domain": [lo, hi]}
      ],
      "value": {"name": "rho", "unit": "1/sr",
                "transform": "linear",       # "linear": y = R(u) ; "log": y = exp(R(u)) - offset
                "offset": 0.0,               # only used by "log"
                "min": 0.0,                  # output is max(y, min); null = no clamp
                "max": 2300.0},              # optional: output is min(y, max); null = no clamp
      "basis": "chebyshev",
      "outputs": ["R", "G", "B"],
      "functions": [                         # one rational function per output, same order
        {"output": "R",
         "domain": [[u_lo, u_hi], ...],      # per variable, = transform(variable domain)
         "numerator":   {"exponents": [[e1, e2], ...], "coefficients": [c, ...]},
         "denominator": {"exponents": [[e1, e2], ...], "coefficients": [c, ...]},
         "num_degrees": [...], "den_degrees": [...],      # informative (max exponent per var)
         "n_coefficients": n,
         "feasible": true,                   # every data point inside its interval
         "valid": true,                      # feasible and Q > 0 certified (optional: the
                                             # fitter's verdict; false = the function is FLAGGED)
         "max_rel_error": 0.049, "rms_rel_error": 0.02, "max_abs_excess": 0.0,
         "measured_range": [0.01, 5.2],      # optional: min, max of the data it was fitted to
         "q_certificate": {"certified": true, "lower_bound": 0.3, "method": "..."}}
      ],
      "domain_policy": {"outside": "clamp", "below_horizon": "zero",
                        "grazing": "text", "theta_d_max_deg": 80.0},
      "fit": {"tolerance": 0.05, "tolerance_kind": "relative", "abs_floor": 1e-3,
              "time_s": 3.1, "fitter": "...", ...},          # informative
      "source": {"file": "satin_rosaline_rgb.bsdf", "sha256": "hex" },  # "" when built in memory
      "fallback": {...}                      # optional: the projected table of a flagged 2-D fit
    }

Evaluating one output (e.g. a BRDF channel at Rusinkiewicz angles theta_h, theta_d in radians)::

    1. clamp:      x_v = min(max(x_v, lo_v), hi_v)       for each variable v  (policy "clamp")
    2. transform:  u_v = x_v          ("identity")   or   u_v = sqrt(x_v)   ("sqrt")
    3. map:        t_v = (2 u_v - (u_lo_v + u_hi_v)) / (u_hi_v - u_lo_v)   in [-1, 1]
    4. basis:      T_0 = 1, T_1 = t, T_{k+1} = 2 t T_k - T_{k-1}
                   P = sum_j p_j prod_v T_{EP[j][v]}(t_v);  Q = sum_j q_j prod_v T_{EQ[j][v]}(t_v)
    5. value:      y = P / Q ("linear")   or   y = exp(P / Q) - offset ("log")
    6. clamp:      rho = min(max(y, min), max)   (min = 0 for BRDFs: never negative; max, when
                   given, bounds the function where no data constrain it; with "log" the
                   exponent is clipped at log(max + offset) first)
    7. range:      if the function is flagged and records "measured_range" [lo, hi], or is
                   valid and records "vouched_range" [lo, hi]: rho = min(max(rho, lo), hi)

A function is **flagged** (not within its stated bound) when its ``valid`` is false, or, in
records without ``valid``, when ``feasible`` or ``q_certificate.certified`` is false
(:func:`fit.rational.model.flagged`): some data point lies outside its interval, Q > 0 is not
certified, or the degree search stopped at its limit without meeting the intervals. Its
``measured_range`` is the min and max of the data points (projected clusters, values below 0
counted as 0) of its own box -- the piece it belongs to -- so a flagged function never leaves
the range of what was measured there. Files written before ``measured_range`` was recorded
read as before and have no step 7 (the renderer computes the range from the source file,
:mod:`warp_rbrdf.materials.rational`). A valid function's ``vouched_range`` is the envelope
of its data's intervals (lowest lower bound, at least 0; highest upper bound): clamping to it
changes no value at a data point, and bounds the fit in its piece's data-free clusters, which
the intervals do not constrain (a valid 5 % fit of cc_iris_purple_gem reached 919 /sr there
against <= 0.25 measured around them). All three keys are optional and ignored by older readers:
the version numbers are unchanged.

**Fallback table** (optional top-level key ``fallback``, any version with the 2-D BRDF
variables; :mod:`fit.rational.fallback`): written by the fitter only when a function is flagged,
it holds the part of the fit's projected median table (90 x 90 MERL grid, 3 channels, float32)
the renderer shows in place of the flagged functions, so the file renders without its source
measurement::

      "fallback": {"kind": "projected median table", "grid": "merl 90x90: ...",
                   "grazing_cutoff_deg": 79.0,          # = fit.grazing_cutoff_deg
                   "shape": [90, 90, 3], "dtype": "<f4", "encoding": "base64", "fill": 0.0,
                   "blocks": [{"theta_h_index": [i0, i1], "theta_d_index": [j0, j1],  # inclusive
                               "channels": [2], "data": "<base64 of the float32 block, C order>"}],
                   "source": {"file": "...", "sha256": "hex"}}

One block per flagged piece: its box's clusters (one more on each side) in its flagged
channels; other clusters are ``fill`` and never read. The reader checks it whole (kind, shape,
dtype, cut-off equal to the fit's, index ranges, base64 and byte length, finite values >= 0,
every flagged piece and channel covered and recording its ``measured_range``). Files without the
key are read as before; a fit with no flagged function is written without it (unchanged bytes).
Readers ignore top-level keys they do not know (this one and the earlier ones), so the version
numbers are unchanged: an older reader reads such a file and needs the source measurement.

For a BRDF the variables are exactly ``theta_h`` then ``theta_d`` (radians, Rusinkiewicz 1998,
as in conventions.md) and rho is in 1/sr without the cosine; rho = 0 when the light or view
direction is at or below the tangent plane ("below_horizon": "zero").

Version 2 (piecewise)
=====================
Same keys, except that ``functions`` is replaced by::

      "split":  {"variable": "theta_d", "edges": [e0, e1, ..., eK]},   # increasing, in the
                                                   # variable's unit; e0, eK = its domain
      "pieces": [{"variables": [...],              # as above, split variable's domain [e_k, e_k+1]
                  "functions": [...],              # as in version 1, on the piece's box
                  "info": {"theta_d_range_deg": [..], "intervals": "tol", "guaranteed": true, ...}},
                 ...]

Evaluation: clamp every input onto the top-level ``variables`` domains, pick the piece ``k``
with ``e_k <= x <= e_k+1`` (the lower piece at a shared edge), then apply steps 1-7 with that
piece's variables and functions. A piece may itself hold ``"split"`` and ``"pieces"`` instead
of ``"functions"`` (e.g. a theta_d core split at a theta_h edge into a specular-peak piece and
the rest), evaluated the same way, recursively. Readers of version 1 reject version 2 files (they would
evaluate only part of the model).

Version 3 (3-D BRDF fits)
=========================
A version-1 or version-2 body (``functions``, or ``split`` and ``pieces``) whose BRDF variables
are exactly ``theta_h``, ``theta_d``, ``phi_d`` (radians; theta_h and theta_d inside [0, pi/2],
phi_d inside [0, pi]), written by :mod:`fit.rational.fit3d`. ``phi_d`` is the Rusinkiewicz
difference azimuth **folded by mirror symmetry**, ``|phi_d|`` of phi_d in (-pi, pi] with the
light as ``wi`` (:mod:`fit.rational.variables3d`): the measurement's (light, view) roles are
kept, no reciprocity fold. Evaluation is steps 1-7 with the three variables. Each function's
record adds ``tolerance`` and ``noise``: every data point of its piece lies within
``rho +- tolerance * max(rho, noise)`` (``valid``: that, and Q > 0 certified); the top-level
``fit`` says which domain the data covered (``theta_max_deg``: the last measured incidence).
Readers of versions 1 and 2 reject version 3; this reader still reads versions 1 and 2.

Outside the fitted domain the inputs are clamped onto it (step 1), so the function is continuous
and bounded everywhere: e.g. for theta_d above ``theta_d_max_deg`` (grazing, where measurements
are unreliable and grow like 1/cos theta_o) it returns the value at the cut-off. Q > 0 holds on
the whole box (``q_certificate``: proved by exact Bernstein coefficients), so P/Q never divides
by zero after clamping. The error guarantee (every fitted data point within ``tolerance``
relative, or within ``abs_floor`` absolute where that is larger) holds for the data points
inside the domain.

Reading (:func:`load`, :func:`from_dict`) trusts nothing in the file: every value is checked for
type, shape and range, the sizes are bounded (:mod:`fit.limits`: variables, exponents, terms,
pieces, nesting, coefficients), a BRDF file must have the variables and outputs above, a
``min`` >= 0 and ``"outside": "clamp"``, and Q > 0 of every function is proved again
(:func:`recertify`) whatever its ``q_certificate`` says. A BRDF's values stay within
:data:`fit.limits.MAX_BRDF_VALUE`: ``max``, ``min``, ``offset``, the step-7 ranges and the
fallback table within it, and without ``max`` every function proven bounded on its box
(:func:`fit.rational.value_bound.bound_ratio`). Integer fields are JSON integers (``3.0`` is
refused), ``num_degrees`` / ``den_degrees`` / ``n_coefficients`` agree with the polynomials,
and names hold no control characters (:func:`fit.jsonfields.name`). Every problem is one
:class:`fit.errors.BRDFFileError` line naming the file and the key (docs/robustness.md).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .. import jsonfields as F
from ..errors import BRDFFileError
from ..formats.angles import HALF_PI
from ..inputs import read_json
from ..limits import (
    MAX_BERNSTEIN_COEFFICIENTS,
    MAX_BRDF_VALUE,
    MAX_CERTIFY_BOXES,
    MAX_CERTIFY_WORK,
    MAX_FILE_COEFFICIENTS,
    MAX_PIECES,
    MAX_RATIONAL_EXPONENT,
    MAX_RATIONAL_TERMS,
    MAX_RATIONAL_VARIABLES,
    MAX_SPLIT_DEPTH,
)
from .bernstein import certify_positive
from .fallback import table_from_record
from .function import RationalFunction
from .model import (
    INPUT_TRANSFORMS,
    VALUE_TRANSFORMS,
    PiecewiseRationalModel,
    RationalModel,
    Variable,
)
from .value_bound import bound_ratio

FORMAT = "rbrdf-rational"
VERSION = 1            # single rational function per output
VERSION_PIECEWISE = 2  # pieces along one variable (see PiecewiseRationalModel)
VERSION_3D = 3         # a BRDF of (theta_h, theta_d, |phi_d|), single or piecewise (fit.rational.fit3d)
VERSIONS = (VERSION, VERSION_PIECEWISE, VERSION_3D)
#: The variables of a version-3 BRDF (fit.rational.variables3d: phi_d folded to |phi_d|).
BRDF_VARIABLES_3D = ["theta_h", "theta_d", "phi_d"]


def _is_3d(model) -> bool:
    return model.kind == "brdf" and [v.name for v in model.variables] == BRDF_VARIABLES_3D


def to_dict(model) -> dict:
    """The file's JSON object of ``model``: version 1 for a :class:`RationalModel`, version 2 for
    a :class:`PiecewiseRationalModel` (pieces may be piecewise again)."""
    d = _piecewise_to_dict(model) if isinstance(model, PiecewiseRationalModel) else _model_to_dict(model)
    if _is_3d(model):
        d["version"] = VERSION_3D
    if getattr(model, "fallback", None) is not None:    # only flagged 2-D fits: others as before
        d["fallback"] = jsonable(model.fallback)
    return d


def _model_to_dict(model) -> dict:
    funcs = []
    for out, f, info in zip(model.outputs, model.functions, model.function_info):
        d = {"output": out}
        fd = f.to_dict()
        fd.pop("basis")
        d.update(fd)
        d["n_coefficients"] = f.n_coefficients
        d.update(jsonable(info))
        funcs.append(d)
    return {
        "format": FORMAT,
        "version": VERSION,
        "name": model.name,
        "kind": model.kind,
        "variables": [{"name": v.name, "unit": v.unit, "transform": v.transform,
                       "domain": list(v.domain)} for v in model.variables],
        "value": {"name": model.value_name, "unit": model.value_unit,
                  "transform": model.value_transform, "offset": model.value_offset,
                  "min": model.value_min, "max": model.value_max},
        "basis": "chebyshev",
        "outputs": list(model.outputs),
        "functions": funcs,
        "domain_policy": jsonable(model.domain_policy),
        "fit": jsonable(model.fit_info),
        "source": jsonable(model.source),
    }


def _piecewise_to_dict(model) -> dict:
    base = to_dict(model.pieces[0])
    pieces = []
    for piece, info in zip(model.pieces, model.piece_info):
        d = to_dict(piece)
        body = ({"functions": d["functions"]} if "functions" in d
                else {"split": d["split"], "pieces": d["pieces"]})   # nested piecewise piece
        pieces.append({"variables": d["variables"], **body, "info": jsonable(info)})
    return {
        "format": FORMAT, "version": VERSION_PIECEWISE, "name": model.name, "kind": model.kind,
        "variables": [{"name": v.name, "unit": v.unit, "transform": v.transform,
                       "domain": list(v.domain)} for v in model.variables],
        "value": base["value"], "basis": base["basis"], "outputs": base["outputs"],
        "split": {"variable": model.split_variable, "edges": list(model.edges)},
        "pieces": pieces,
        "domain_policy": jsonable(model.domain_policy),
        "fit": jsonable(model.fit_info),
        "source": jsonable(model.source),
    }


def jsonable(obj):
    """``obj`` with NumPy scalars and arrays as Python numbers and lists, non-finite floats as
    None (JSON has no NaN), dict keys as strings."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if math.isfinite(f) else None
    return obj


def save(model, path) -> None:
    """Write ``model`` as an ``rbrdf-rational`` JSON file (version 1, or 2 if piecewise),
    through a temporary file renamed onto ``path`` when complete (an existing file is never
    left half-written)."""
    from ..outputs import atomic_write

    text = json.dumps(to_dict(model), indent=1, allow_nan=False)
    with atomic_write(Path(path)) as f:
        f.write(text + "\n")


# --------------------------------------------------------------------------------------------
# Reading: every value checked for type, shape, range and size (fit.limits), Q > 0 re-proved
# --------------------------------------------------------------------------------------------
class _Budget:
    """What a whole file may ask for: coefficients (compiled into the renderer's kernels) and
    the work of re-proving Q > 0 (Bernstein coefficients examined)."""

    def __init__(self):
        self.coefficients = 0
        self.certify_work = 0


def _variables(v, key: str, kind: str, three_d: bool = False) -> list:
    vs = v
    if not isinstance(vs, list) or not 1 <= len(vs) <= MAX_RATIONAL_VARIABLES:
        raise F.Invalid(key, f"expected a list of 1 to {MAX_RATIONAL_VARIABLES} variables")
    out = []
    for i, vd in enumerate(vs):
        k = F.sub(key, i)
        F.obj(vd, k)
        name = F.name(F.get(vd, "name", k), F.sub(k, "name"), max_len=64)
        unit = F.name(vd.get("unit", ""), F.sub(k, "unit"), max_len=64)
        transform = F.string(vd.get("transform", "identity"), F.sub(k, "transform"), choices=INPUT_TRANSFORMS)
        lo, hi = F.array(F.get(vd, "domain", k), F.sub(k, "domain"), (2,))
        if not hi > lo:
            raise F.Invalid(F.sub(k, "domain"), f"empty domain [{lo:g}, {hi:g}]")
        if transform == "sqrt" and lo < 0:
            raise F.Invalid(F.sub(k, "domain"), f"starts at {lo:g} < 0 under the sqrt transform")
        out.append(Variable(name=name, unit=unit, transform=transform, domain=(float(lo), float(hi))))
    names = [v.name for v in out]
    if len(set(names)) != len(names):
        raise F.Invalid(key, f"variable names repeat: {names}")
    if kind == "brdf":
        want = BRDF_VARIABLES_3D if three_d else ["theta_h", "theta_d"]
        if names != want:
            raise F.Invalid(key, f"a {'version-3 ' if three_d else ''}BRDF's variables are {', '.join(want)}, "
                                 f"not {', '.join(names)}")
        for i, var in enumerate(out):
            top = math.pi if var.name == "phi_d" else HALF_PI
            if var.domain[0] < 0 or var.domain[1] > top + 1e-9:
                raise F.Invalid(F.sub(F.sub(key, i), "domain"), f"[{var.domain[0]:g}, {var.domain[1]:g}] rad "
                                                                f"is not inside [0, {'pi' if top > 2 else 'pi/2'}]")
    return out


def _polynomial(pd, key: str, n_vars: int, denominator: bool):
    F.obj(pd, key)
    kc = F.sub(key, "coefficients")
    ke = F.sub(key, "exponents")
    raw_c = F.get(pd, "coefficients", key)
    if not isinstance(raw_c, list):
        raise F.Invalid(kc, "expected a list of numbers")
    if len(raw_c) > MAX_RATIONAL_TERMS:
        raise F.Invalid(kc, f"{len(raw_c)} terms, above the limit {MAX_RATIONAL_TERMS} "
                            "(fit.limits.MAX_RATIONAL_TERMS)")
    if denominator and not raw_c:
        raise F.Invalid(kc, "the denominator needs at least one term")
    coef = F.array(raw_c, kc, (None,))
    exps = F.array(F.get(pd, "exponents", key), ke, (len(coef), n_vars), kind="int")
    if exps.size == 0:
        exps = np.zeros((0, n_vars), np.int64)
    if exps.size and (exps.min() < 0 or exps.max() > MAX_RATIONAL_EXPONENT):
        bad = int(exps.max()) if exps.max() > MAX_RATIONAL_EXPONENT else int(exps.min())
        raise F.Invalid(ke, f"exponent {bad} outside [0, {MAX_RATIONAL_EXPONENT}] "
                            "(fit.limits.MAX_RATIONAL_EXPONENT)")
    return exps, coef


def _degrees_record(fd, key: str, f: RationalFunction) -> None:
    """The informative ``num_degrees``, ``den_degrees`` and ``n_coefficients`` of a function
    record, when present: JSON integers that agree with its polynomials."""
    for k, want in (("num_degrees", list(f.num_degrees)), ("den_degrees", list(f.den_degrees))):
        if fd.get(k) is not None:
            got = F.array(fd[k], F.sub(key, k), (f.n_vars,), kind="int").tolist()
            if got != want:
                raise F.Invalid(F.sub(key, k), f"{got} does not match the exponents (their maxima are {want})")
    if fd.get("n_coefficients") is not None:
        got = F.integer(fd["n_coefficients"], F.sub(key, "n_coefficients"))
        if got != f.n_coefficients:
            raise F.Invalid(F.sub(key, "n_coefficients"), f"{got}, but the numerator and denominator hold "
                                                          f"{f.n_coefficients} coefficients")


def _function(fd, key: str, variables: list, budget: _Budget, kind: str = "function"):
    F.obj(fd, key)
    n = len(variables)
    F.name(fd.get("output", ""), F.sub(key, "output"), max_len=64)
    basis = F.string(fd.get("basis", "chebyshev"), F.sub(key, "basis"))
    if basis != "chebyshev":
        raise F.Invalid(F.sub(key, "basis"), f"unsupported basis {basis[:40]!r}")
    dom = F.array(F.get(fd, "domain", key), F.sub(key, "domain"), (n, 2))
    expected = np.array([v.rf_domain for v in variables])
    if not np.allclose(dom, expected, rtol=1e-12, atol=1e-12):
        raise F.Invalid(F.sub(key, "domain"), f"{dom.tolist()} does not match the transformed "
                                              f"variable domains {expected.tolist()}")
    ne, nc = _polynomial(F.get(fd, "numerator", key), F.sub(key, "numerator"), n, False)
    de, dc = _polynomial(F.get(fd, "denominator", key), F.sub(key, "denominator"), n, True)
    size = int(np.prod(de.max(axis=0) + 1))
    if size > MAX_BERNSTEIN_COEFFICIENTS:
        raise F.Invalid(F.sub(key, "denominator"), f"degrees {de.max(axis=0).tolist()} give {size} Bernstein "
                                                   f"coefficients, above {MAX_BERNSTEIN_COEFFICIENTS} "
                                                   "(fit.limits.MAX_BERNSTEIN_COEFFICIENTS)")
    budget.coefficients += len(nc) + len(dc)
    if budget.coefficients > MAX_FILE_COEFFICIENTS:
        raise F.Invalid(key, f"the file holds more than {MAX_FILE_COEFFICIENTS} coefficients "
                             "(fit.limits.MAX_FILE_COEFFICIENTS)")
    # the record of the fit (what flagged() and the output clamps read), strictly typed
    info = {k: v for k, v in fd.items() if k not in (
        "output", "domain", "numerator", "denominator", "num_degrees", "den_degrees", "n_coefficients",
        "basis")}
    for k in ("valid", "feasible"):
        if k in info:
            F.flag(info[k], F.sub(key, k))
    if "q_certificate" in info:
        F.obj(info["q_certificate"], F.sub(key, "q_certificate"))
        if "certified" in info["q_certificate"]:
            F.flag(info["q_certificate"]["certified"], F.sub(F.sub(key, "q_certificate"), "certified"))
    for k in ("measured_range", "vouched_range"):
        if info.get(k) is not None:
            lo, hi = F.array(info[k], F.sub(key, k), (2,))
            if not lo <= hi:
                raise F.Invalid(F.sub(key, k), f"[{lo:g}, {hi:g}] is empty")
            if kind == "brdf" and (lo < 0 or hi > MAX_BRDF_VALUE):
                raise F.Invalid(F.sub(key, k), f"[{lo:g}, {hi:g}] 1/sr is not inside [0, {MAX_BRDF_VALUE:g}] "
                                               "(fit.limits.MAX_BRDF_VALUE)")
    f = RationalFunction(domain=dom, num_exponents=ne, num_coef=nc, den_exponents=de, den_coef=dc,
                         var_names=tuple(v.name for v in variables))
    _degrees_record(fd, key, f)
    return f, info


def _value(d, key: str, kind: str) -> dict:
    v = d.get("value", {})
    F.obj(v, key)
    out = {
        "value_transform": F.string(v.get("transform", "linear"), F.sub(key, "transform"), choices=VALUE_TRANSFORMS),
        "value_offset": F.number(v.get("offset", 0.0) if v.get("offset") is not None else 0.0,
                                 F.sub(key, "offset"), lo=0.0),
        "value_min": F.number(v.get("min"), F.sub(key, "min"), optional=True),
        "value_max": F.number(v.get("max"), F.sub(key, "max"), optional=True),
        "value_name": F.name(v.get("name", "y"), F.sub(key, "name"), max_len=64),
        "value_unit": F.name(v.get("unit", ""), F.sub(key, "unit"), max_len=64),
    }
    lo, hi = out["value_min"], out["value_max"]
    if lo is not None and hi is not None and not hi > lo:
        raise F.Invalid(key, f"max {hi:g} is not above min {lo:g}")
    if kind == "brdf":
        if lo is None or lo < 0:
            raise F.Invalid(F.sub(key, "min"), "a BRDF needs a clamp min >= 0 (it is never negative)")
        if hi is not None and hi > MAX_BRDF_VALUE:
            raise F.Invalid(F.sub(key, "max"), f"{hi:g} 1/sr is above {MAX_BRDF_VALUE:g} (fit.limits.MAX_BRDF_VALUE)")
        if lo > MAX_BRDF_VALUE:
            raise F.Invalid(F.sub(key, "min"), f"{lo:g} 1/sr is above {MAX_BRDF_VALUE:g} (fit.limits.MAX_BRDF_VALUE)")
        if out["value_offset"] > MAX_BRDF_VALUE:
            raise F.Invalid(F.sub(key, "offset"), f"{out['value_offset']:g} 1/sr is above {MAX_BRDF_VALUE:g} "
                                                  "(fit.limits.MAX_BRDF_VALUE)")
    return out


def _source(d, key: str) -> dict:
    """The ``source`` record (informative), its ``file`` a name and its ``sha256`` hex when given."""
    return F.source_record(d.get("source", {"file": "", "sha256": ""}), key)


def _domain_policy(d, key: str) -> dict:
    pol = d.get("domain_policy", {"outside": "clamp"})
    F.obj(pol, key)
    # Q > 0 is proved on the box only: evaluating outside it (no clamp) could meet a pole
    F.string(pol.get("outside", "clamp"), F.sub(key, "outside"), choices=("clamp",))
    return dict(pol)


def _model(d: dict, path, key: str, depth: int, budget: _Budget, three_d: bool = False):
    """A RationalModel (version 1 body) or PiecewiseRationalModel (version 2 body) from ``d``."""
    F.obj(d, key or "(top level)")
    kind = F.string(d.get("kind", "function"), F.sub(key, "kind"), choices=("brdf", "function"))
    variables = _variables(F.get(d, "variables", key), F.sub(key, "variables"), kind, three_d)
    if "split" in d or "pieces" in d:
        return _piecewise(d, path, key, depth, budget, kind, variables, three_d)
    value = _value(d, F.sub(key, "value"), kind)
    raw = F.get(d, "functions", key)
    if not isinstance(raw, list) or not 1 <= len(raw) <= 16:
        raise F.Invalid(F.sub(key, "functions"), "expected a list of 1 to 16 functions")
    functions, infos = [], []
    for i, fd in enumerate(raw):
        f, info = _function(fd, F.sub(F.sub(key, "functions"), i), variables, budget, kind)
        functions.append(f)
        infos.append(info)
    outputs = d.get("outputs")
    if outputs is None:
        outputs = [fd.get("output", "") for fd in raw]
    if not isinstance(outputs, list) or len(outputs) != len(functions):
        raise F.Invalid(F.sub(key, "outputs"), f"expected a list of {len(functions)} output names")
    outputs = [F.name(o, F.sub(F.sub(key, "outputs"), i), max_len=64) for i, o in enumerate(outputs)]
    if kind == "brdf" and outputs != ["R", "G", "B"]:
        raise F.Invalid(F.sub(key, "outputs"), f"a BRDF's outputs are R, G, B, not {', '.join(outputs)}")
    basis = F.string(d.get("basis", "chebyshev"), F.sub(key, "basis"))
    if basis != "chebyshev":
        raise F.Invalid(F.sub(key, "basis"), f"unsupported basis {basis[:40]!r}")
    return RationalModel(
        name=F.name(d.get("name", ""), F.sub(key, "name")), variables=variables,
        functions=functions, outputs=tuple(outputs), kind=kind, **value,
        domain_policy=_domain_policy(d, F.sub(key, "domain_policy")),
        fit_info=_fit_info(d, key), function_info=infos,
        source=_source(d, F.sub(key, "source")))


def _fit_info(d: dict, key: str) -> dict:
    """The file's ``fit`` record (how the fit was made), with the fields that readers act on
    checked: ``grazing_cutoff_deg`` (the projection's grazing cut-off, degrees, in [0, 90] or
    null: :mod:`fit.rational.domain`, :mod:`fit.rational.fallback`). Other fields are kept as
    they are (what reaches generated code is escaped by :mod:`fit.export.escape`)."""
    info = dict(F.obj(d.get("fit", {}), F.sub(key, "fit")))
    fkey = F.sub(key, "fit")
    if info.get("grazing_cutoff_deg") is not None:
        info["grazing_cutoff_deg"] = F.number(info["grazing_cutoff_deg"], F.sub(fkey, "grazing_cutoff_deg"),
                                              lo=0.0, hi=90.0)
    return info


def _piecewise(d, path, key, depth, budget, kind, variables, three_d=False):
    if depth >= MAX_SPLIT_DEPTH:
        raise F.Invalid(key, f"pieces nested more than {MAX_SPLIT_DEPTH} deep (fit.limits.MAX_SPLIT_DEPTH)")
    name = F.name(d.get("name", ""), F.sub(key, "name"))    # before the pieces, which inherit it
    ks = F.sub(key, "split")
    split = F.obj(F.get(d, "split", key), ks)
    var = F.string(F.get(split, "variable", ks), F.sub(ks, "variable"), choices=[v.name for v in variables])
    raw = F.get(d, "pieces", key)
    kp = F.sub(key, "pieces")
    if not isinstance(raw, list) or not 1 <= len(raw) <= MAX_PIECES:
        raise F.Invalid(kp, f"expected a list of 1 to {MAX_PIECES} pieces (fit.limits.MAX_PIECES)")
    edges = F.array(F.get(split, "edges", ks), F.sub(ks, "edges"), (len(raw) + 1,))
    pieces, infos = [], []
    for i, pd in enumerate(raw):
        ki = F.sub(kp, i)
        F.obj(pd, ki)
        sub = {k: d[k] for k in ("name", "kind", "value", "basis", "outputs") if k in d}
        sub.update(variables=F.get(pd, "variables", ki), domain_policy=d.get("domain_policy", {"outside": "clamp"}))
        if "split" in pd:
            sub.update(split=pd["split"], pieces=F.get(pd, "pieces", ki))
        else:
            sub.update(functions=F.get(pd, "functions", ki))
        pieces.append(_model(sub, path, ki, depth + 1, budget, three_d))
        infos.append(dict(F.obj(pd.get("info", {}), F.sub(ki, "info"))))
    try:
        return PiecewiseRationalModel(
            name=name, variables=variables,
            split_variable=var, edges=[float(e) for e in edges], pieces=pieces, kind=kind,
            domain_policy=_domain_policy(d, F.sub(key, "domain_policy")),
            fit_info=_fit_info(d, key), piece_info=infos,
            source=_source(d, F.sub(key, "source")))
    except ValueError as e:
        raise F.Invalid(key or "pieces", str(e)) from None


def _leaf_models(model, key: str = "") -> list:
    """``[(key path, single-box model)]`` of ``model``, pieces first to last."""
    if isinstance(model, PiecewiseRationalModel):
        return [leaf for i, p in enumerate(model.pieces) for leaf in _leaf_models(p, F.sub(F.sub(key, "pieces"), i))]
    return [(key, model)]


def recertify(model, path=None, budget: _Budget | None = None) -> None:
    """Prove Q > 0 again on the box of every function of ``model`` (whatever its record says);
    :class:`BRDFFileError` naming the function when a denominator has a zero (a pole) or
    cannot be proven positive within :data:`fit.limits.MAX_CERTIFY_BOXES` sub-boxes and the
    file's work budget :data:`fit.limits.MAX_CERTIFY_WORK`. A model without an upper clamp
    (``max``) must also be proven bounded (:func:`_check_bounded`)."""
    budget = budget or _Budget()
    for key, leaf in _leaf_models(model):
        for c, f in enumerate(leaf.functions):
            where = f"key {F.sub(F.sub(key, 'functions'), c)} ({leaf.outputs[c]})"
            size = int(np.prod(np.asarray(f.den_degrees) + 1))
            boxes = min(MAX_CERTIFY_BOXES, max((MAX_CERTIFY_WORK - budget.certify_work) // max(size, 1), 1))
            cert = certify_positive(f.den_exponents, f.den_coef, max_depth=12, max_boxes=boxes)
            budget.certify_work += cert.n_boxes * size
            if not cert.certified:
                said = leaf.function_info[c].get("q_certificate", {}) if leaf.function_info else {}
                claim = " although the file says it is certified" if isinstance(said, dict) and said.get(
                    "certified") is True else ""
                raise BRDFFileError(path, f"{where}: {cert.reason or 'Q > 0 could not be proven'} "
                                          f"(re-checked on load){claim}")
            if leaf.value_max is None and (leaf.kind == "brdf" or leaf.value_transform == "log"):
                _check_bounded(leaf, f, cert.lower_bound, where, path, budget)


def _check_bounded(leaf, f, q_lower: float, where: str, path, budget: _Budget) -> None:
    """A function of a model without a ``max`` clamp: prove that its values stay within
    :data:`fit.limits.MAX_BRDF_VALUE` (a BRDF: P/Q, or exp(P/Q) - offset, on the whole box;
    another log-valued function: exp(P/Q) finite), :func:`fit.rational.value_bound.bound_ratio`
    within the file's certification budget; :class:`BRDFFileError` naming the function and
    ``value.max`` when they do not or cannot be proven to. The step-7 ranges do not count: they
    are optional records that older readers ignore."""
    log = leaf.value_transform == "log"
    top = MAX_BRDF_VALUE if leaf.kind == "brdf" else math.inf
    limit = math.log(top + leaf.value_offset) if log and math.isfinite(top) else (700.0 if log else top)
    size = int(np.prod(np.asarray(f.num_degrees) + 1)) + int(np.prod(np.asarray(f.den_degrees) + 1))
    boxes = min(MAX_CERTIFY_BOXES, max((MAX_CERTIFY_WORK - budget.certify_work) // max(size, 1), 1))
    res = bound_ratio(f.num_exponents, f.num_coef, f.den_exponents, f.den_coef, limit, q_lower, max_boxes=boxes)
    budget.certify_work += res.work
    if res.bounded:
        return
    what = "exp(P/Q) - offset" if log else "P/Q"
    if res.witness is None:
        raise BRDFFileError(path, f"{where}: no 'value.max' clamp, and {what} <= {top:g} 1/sr could not be "
                                  f"proven on the box ({res.reason}; fit.limits.MAX_BRDF_VALUE)")
    at = ", ".join(f"{v.name} = {_from_unit(t, v):.4g}" for t, v in zip(res.witness, leaf.variables))
    if log:
        shown = ("overflows float64: exp would overflow" if res.value > 709.0
                 else f"= {math.exp(res.value) - leaf.value_offset:.3g}")
        said = f"P/Q = {res.value:.3g}, exp(P/Q) - offset {shown}"
    else:
        said = f"P/Q = {res.value:.3g}"
    raise BRDFFileError(path, f"{where}: no 'value.max' clamp, and at {at} {said}, above "
                              f"{top:g} 1/sr (fit.limits.MAX_BRDF_VALUE)")


def _from_unit(t: float, var) -> float:
    """The variable's own value (its unit) at the box coordinate ``t`` in [-1, 1]."""
    ulo, uhi = var.rf_domain
    u = ulo + 0.5 * (t + 1.0) * (uhi - ulo)
    return u * u if var.transform == "sqrt" else u


def from_dict(d: dict, path=None, certify: bool = True):
    """Build a model from a parsed file (:class:`RationalModel` for version 1,
    :class:`PiecewiseRationalModel` for version 2) after checking every value's type, shape and
    range and the limits of :mod:`fit.limits`, and (``certify``) re-proving Q > 0 of every
    function (:func:`recertify`): a file's ``certified: true`` is never trusted.
    :class:`BRDFFileError` naming the file and the key on any problem."""
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        got = d.get("format") if isinstance(d, dict) else None
        raise BRDFFileError(path, f"not an {FORMAT} coefficient file (format key is "
                                  f"{str(got)[:40] if got is not None else None!r})")
    ver = d.get("version")
    if type(ver) is not int or ver not in VERSIONS:   # 3.0 or true is not the integer 3 or 1
        raise BRDFFileError(path, f"key version: unsupported {FORMAT} version "
                                  f"{ver if type(ver) is int else repr(ver)[:20]} (this reader knows the "
                                  f"integers {', '.join(map(str, VERSIONS))})")
    budget = _Budget()
    label = {VERSION_PIECEWISE: "version-2 ", VERSION_3D: "version-3 "}.get(ver, "")
    try:
        if ver == VERSION and ("split" in d or "pieces" in d):
            raise F.Invalid("version", "a version-1 file has no 'split' or 'pieces' (version 2)")
        if ver == VERSION_PIECEWISE and "split" not in d:
            raise F.Invalid("split", "missing (a version-2 file is piecewise)")
        model = _model(d, path, "", 0, budget, three_d=ver == VERSION_3D)
        if "fallback" in d:       # optional (flagged 2-D fits): checked whole, kept as written
            table = table_from_record(d["fallback"], model, "fallback")
            if table.max(initial=0.0) > MAX_BRDF_VALUE:
                raise F.Invalid("fallback.blocks", f"holds {float(table.max()):.3g} 1/sr, above {MAX_BRDF_VALUE:g} "
                                                   "(fit.limits.MAX_BRDF_VALUE)")
            model.fallback = d["fallback"]
    except F.Invalid as e:
        raise BRDFFileError(path, f"invalid {FORMAT} {label}coefficient file: {e}") from None
    except (KeyError, TypeError, ValueError, IndexError, ArithmeticError) as e:
        raise BRDFFileError(path, f"invalid {FORMAT} {label}coefficient file ({e.__class__.__name__}: {e})") from None
    if certify:
        recertify(model, path, budget)
    return model


def load(path):
    """Read an ``rbrdf-rational`` JSON file (:func:`fit.inputs.read_json`: a regular file of at
    most :data:`fit.limits.MAX_JSON_BYTES`, strict JSON) and build its model
    (:func:`from_dict`, Q > 0 re-proved); :class:`BRDFFileError` if missing, corrupt, of an
    unknown version, beyond a limit or with a denominator that is not positive."""
    return from_dict(read_json(path, "coefficient file"), path)
