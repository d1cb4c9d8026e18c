"""Versioned JSON coefficient files of fitted rational functions: format ``rbrdf-rational``,
version 1 (one function per output) and version 2 (pieces along one variable).

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
      "source": {"file": "satin_rosaline_rgb.bsdf", "sha256": "hex" }   # "" when built in memory
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

Outside the fitted domain the inputs are clamped onto it (step 1), so the function is continuous
and bounded everywhere: e.g. for theta_d above ``theta_d_max_deg`` (grazing, where measurements
are unreliable and grow like 1/cos theta_o) it returns the value at the cut-off. Q > 0 holds on
the whole box (``q_certificate``: proved by exact Bernstein coefficients), so P/Q never divides
by zero after clamping. The error guarantee (every fitted data point within ``tolerance``
relative, or within ``abs_floor`` absolute where that is larger) holds for the data points
inside the domain.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..errors import BRDFFileError
from .function import RationalFunction
from .model import PiecewiseRationalModel, RationalModel, Variable

FORMAT = "rbrdf-rational"
VERSION = 1            # single rational function per output
VERSION_PIECEWISE = 2  # pieces along one variable (see PiecewiseRationalModel)
VERSIONS = (VERSION, VERSION_PIECEWISE)


def to_dict(model) -> dict:
    """The file's JSON object of ``model``: version 1 for a :class:`RationalModel`, version 2 for
    a :class:`PiecewiseRationalModel` (pieces may be piecewise again)."""
    if isinstance(model, PiecewiseRationalModel):
        return _piecewise_to_dict(model)
    return _model_to_dict(model)


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
    """Write ``model`` as an ``rbrdf-rational`` JSON file (version 1, or 2 if piecewise)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(to_dict(model), indent=1, allow_nan=False)
    path.write_text(text + "\n", encoding="utf-8")


def from_dict(d: dict, path=None):
    """Build a model from a parsed file (:class:`RationalModel` for version 1,
    :class:`PiecewiseRationalModel` for version 2); :class:`BRDFFileError` on any problem."""
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise BRDFFileError(path, f"not an {FORMAT} coefficient file (format key is "
                                  f"{d.get('format') if isinstance(d, dict) else None!r})")
    ver = d.get("version")
    if ver not in VERSIONS:
        raise BRDFFileError(path, f"unsupported {FORMAT} version {ver!r} (this reader knows versions "
                                  f"{', '.join(map(str, VERSIONS))})")
    if ver == VERSION_PIECEWISE:
        return _piecewise_from_dict(d, path)
    try:
        if d.get("basis", "chebyshev") != "chebyshev":
            raise ValueError(f"unsupported basis {d.get('basis')!r}")
        variables = [Variable(name=str(v["name"]), unit=str(v.get("unit", "")),
                              transform=str(v.get("transform", "identity")), domain=v["domain"])
                     for v in d["variables"]]
        names = tuple(v.name for v in variables)
        functions, infos = [], []
        for fd in d["functions"]:
            f = RationalFunction.from_dict(fd, var_names=names)
            expected = np.array([v.rf_domain for v in variables])
            if not np.allclose(f.domain, expected, rtol=1e-12, atol=1e-12):
                raise ValueError(f"function {fd.get('output')}: domain {f.domain.tolist()} does not match "
                                 f"the transformed variable domains {expected.tolist()}")
            if not (np.all(np.isfinite(f.num_coef)) and np.all(np.isfinite(f.den_coef))):
                raise ValueError("non-finite coefficient")
            functions.append(f)
            infos.append({k: v for k, v in fd.items() if k not in (
                "output", "domain", "numerator", "denominator", "num_degrees", "den_degrees",
                "n_coefficients")})
        value = d.get("value", {})
        outputs = tuple(d.get("outputs") or [fd["output"] for fd in d["functions"]])
        return RationalModel(
            name=str(d.get("name", "")), variables=variables, functions=functions, outputs=outputs,
            kind=str(d.get("kind", "function")),
            value_transform=str(value.get("transform", "linear")),
            value_offset=float(value.get("offset", 0.0) or 0.0),
            value_min=value.get("min", None), value_max=value.get("max", None),
            value_name=str(value.get("name", "y")),
            value_unit=str(value.get("unit", "")),
            domain_policy=dict(d.get("domain_policy", {"outside": "clamp"})),
            fit_info=dict(d.get("fit", {})), function_info=infos,
            source=dict(d.get("source", {"file": "", "sha256": ""})),
        )
    except BRDFFileError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise BRDFFileError(path, f"invalid {FORMAT} coefficient file ({e.__class__.__name__}: {e})") from None


def _piecewise_from_dict(d: dict, path=None) -> PiecewiseRationalModel:
    try:
        split = d["split"]
        pieces, infos = [], []
        for k, pd in enumerate(d["pieces"]):
            sub = {key: d[key] for key in ("name", "kind", "value", "basis", "outputs") if key in d}
            sub.update(format=FORMAT, variables=pd["variables"],
                       domain_policy=d.get("domain_policy", {"outside": "clamp"}))
            if "split" in pd:        # a piece split again (e.g. theta_h peak piece + rest)
                sub.update(version=VERSION_PIECEWISE, split=pd["split"], pieces=pd["pieces"])
            else:
                sub.update(version=VERSION, functions=pd["functions"])
            pieces.append(from_dict(sub, path))
            infos.append(dict(pd.get("info", {})))
        variables = [Variable(name=str(v["name"]), unit=str(v.get("unit", "")),
                              transform=str(v.get("transform", "identity")), domain=v["domain"])
                     for v in d["variables"]]
        return PiecewiseRationalModel(
            name=str(d.get("name", "")), variables=variables, split_variable=str(split["variable"]),
            edges=list(split["edges"]), pieces=pieces, kind=str(d.get("kind", "function")),
            domain_policy=dict(d.get("domain_policy", {"outside": "clamp"})),
            fit_info=dict(d.get("fit", {})), piece_info=infos,
            source=dict(d.get("source", {"file": "", "sha256": ""})))
    except BRDFFileError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise BRDFFileError(path, f"invalid {FORMAT} version-2 coefficient file "
                                  f"({e.__class__.__name__}: {e})") from None


def load(path):
    """Read an ``rbrdf-rational`` JSON file; :class:`BRDFFileError` if missing, corrupt or of
    an unknown version."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise BRDFFileError(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise BRDFFileError(path, f"cannot read coefficient file ({e.__class__.__name__}: {e})") from None
    try:
        d = json.loads(text)
    except json.JSONDecodeError as e:
        raise BRDFFileError(path, f"corrupt coefficient file: not valid JSON ({e})") from None
    return from_dict(d, path)
