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
         "max_rel_error": 0.049, "rms_rel_error": 0.02, "max_abs_excess": 0.0,
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
with ``e_k <= x <= e_k+1`` (the lower piece at a shared edge), then apply steps 1-6 with that
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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import BRDFFileError
from .rational import RationalFunction

FORMAT = "rbrdf-rational"
VERSION = 1            # single rational function per output
VERSION_PIECEWISE = 2  # pieces along one variable (see PiecewiseRationalModel)
VERSIONS = (VERSION, VERSION_PIECEWISE)
INPUT_TRANSFORMS = ("identity", "sqrt")
VALUE_TRANSFORMS = ("linear", "log")


def apply_input_transform(x, transform: str):
    x = np.asarray(x, dtype=np.float64)
    if transform == "identity":
        return x
    if transform == "sqrt":
        return np.sqrt(np.maximum(x, 0.0))
    raise ValueError(f"unknown input transform {transform!r}")


def apply_value_transform(y, transform: str, offset: float = 0.0):
    """Data value -> fitted quantity (the inverse of step 5)."""
    y = np.asarray(y, dtype=np.float64)
    if transform == "linear":
        return y
    if transform == "log":
        return np.log(y + offset)
    raise ValueError(f"unknown value transform {transform!r}")


def invert_value_transform(r, transform: str, offset: float = 0.0):
    r = np.asarray(r, dtype=np.float64)
    if transform == "linear":
        return r
    if transform == "log":
        return np.exp(r) - offset
    raise ValueError(f"unknown value transform {transform!r}")


@dataclass
class Variable:
    name: str
    unit: str
    transform: str
    domain: tuple

    def __post_init__(self):
        if self.transform not in INPUT_TRANSFORMS:
            raise ValueError(f"unknown input transform {self.transform!r}")
        lo, hi = (float(v) for v in self.domain)
        if not hi > lo:
            raise ValueError(f"variable {self.name}: empty domain [{lo}, {hi}]")
        self.domain = (lo, hi)

    @property
    def rf_domain(self) -> tuple:
        return tuple(float(apply_input_transform(v, self.transform)) for v in self.domain)


class _BRDFEvaluation:
    """``evaluate_brdf`` / ``evaluate`` for models whose ``__call__`` takes ``(theta_h, theta_d)``."""

    def evaluate_brdf(self, theta_h, theta_d) -> np.ndarray:
        """rho in 1/sr at Rusinkiewicz angles (radians); shape ``broadcast + (3,)``."""
        th, td = np.broadcast_arrays(np.asarray(theta_h, float), np.asarray(theta_d, float))
        return self(np.stack([th, td], axis=-1))

    def evaluate(self, wi, wo) -> np.ndarray:
        """rho(wi, wo) in 1/sr for local unit directions ``(..., 3)``; 0 below the horizon."""
        from .formats.angles import directions_to_half_diff

        wi = np.asarray(wi, float)
        wo = np.asarray(wo, float)
        th, _, td, _ = directions_to_half_diff(wi, wo)
        out = self.evaluate_brdf(th, td)
        wi, wo = np.broadcast_arrays(wi, wo)
        above = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
        return np.where(above[..., None], out, 0.0)


@dataclass
class RationalModel(_BRDFEvaluation):
    """Rational functions with their input/value transforms and domain policy (one file).

    ``model(x)`` evaluates all outputs at physical inputs ``x`` of shape ``(..., n_vars)``,
    returning ``(..., n_outputs)``. For BRDFs use :meth:`evaluate_brdf` (angles in radians)
    or :meth:`evaluate` (directions).
    """

    name: str
    variables: list
    functions: list                      # RationalFunction per output (on the transformed domain)
    outputs: tuple = ("R", "G", "B")
    kind: str = "brdf"
    value_transform: str = "linear"
    value_offset: float = 0.0
    value_min: float | None = 0.0
    value_max: float | None = None       # output clamp from above (bounded in data-free corners)
    value_name: str = "rho"
    value_unit: str = "1/sr"
    domain_policy: dict = field(default_factory=lambda: {"outside": "clamp", "below_horizon": "zero"})
    fit_info: dict = field(default_factory=dict)
    function_info: list = field(default_factory=list)   # per-output dicts (errors, certificate)
    source: dict = field(default_factory=lambda: {"file": "", "sha256": ""})

    def __post_init__(self):
        self.variables = [v if isinstance(v, Variable) else Variable(**v) for v in self.variables]
        self.outputs = tuple(self.outputs)
        if len(self.functions) != len(self.outputs):
            raise ValueError("one function per output is required")
        if self.value_transform not in VALUE_TRANSFORMS:
            raise ValueError(f"unknown value transform {self.value_transform!r}")
        for f in self.functions:
            if f.n_vars != len(self.variables):
                raise ValueError("function and variable counts differ")
        if not self.function_info:
            self.function_info = [{} for _ in self.functions]

    # Evaluation ----------------------------------------------------------------------------
    @property
    def n_vars(self) -> int:
        return len(self.variables)

    @property
    def n_coefficients(self) -> int:
        return sum(f.n_coefficients for f in self.functions)

    def rf_inputs(self, x) -> np.ndarray:
        """Physical inputs ``(..., n_vars)`` -> clamped, transformed RF inputs (steps 1-2)."""
        x = np.asarray(x, dtype=np.float64)
        cols = []
        for v, var in enumerate(self.variables):
            xv = x[..., v]
            if self.domain_policy.get("outside", "clamp") == "clamp":
                xv = np.clip(xv, var.domain[0], var.domain[1])
            cols.append(apply_input_transform(xv, var.transform))
        return np.stack(cols, axis=-1)

    def __call__(self, x) -> np.ndarray:
        u = self.rf_inputs(x)
        vals = []
        for f in self.functions:
            r = f(u)
            if self.value_max is not None and self.value_transform == "log":
                r = np.minimum(r, np.log(self.value_max + self.value_offset))   # no exp overflow
            vals.append(invert_value_transform(r, self.value_transform, self.value_offset))
        out = np.stack(vals, axis=-1)
        if self.value_min is not None:
            out = np.maximum(out, self.value_min)
        if self.value_max is not None:
            out = np.minimum(out, self.value_max)
        return out

    # Persistence ---------------------------------------------------------------------------
    def to_dict(self) -> dict:
        funcs = []
        for out, f, info in zip(self.outputs, self.functions, self.function_info):
            d = {"output": out}
            fd = f.to_dict()
            fd.pop("basis")
            d.update(fd)
            d["n_coefficients"] = f.n_coefficients
            d.update(_jsonable(info))
            funcs.append(d)
        return {
            "format": FORMAT,
            "version": VERSION,
            "name": self.name,
            "kind": self.kind,
            "variables": [{"name": v.name, "unit": v.unit, "transform": v.transform,
                           "domain": list(v.domain)} for v in self.variables],
            "value": {"name": self.value_name, "unit": self.value_unit,
                      "transform": self.value_transform, "offset": self.value_offset,
                      "min": self.value_min, "max": self.value_max},
            "basis": "chebyshev",
            "outputs": list(self.outputs),
            "functions": funcs,
            "domain_policy": _jsonable(self.domain_policy),
            "fit": _jsonable(self.fit_info),
            "source": _jsonable(self.source),
        }

    def save(self, path) -> None:
        save(self, path)


@dataclass
class PiecewiseRationalModel(_BRDFEvaluation):
    """Rational models on consecutive intervals of one variable (file version 2).

    ``pieces[k]`` is a :class:`RationalModel` whose domain in ``split_variable`` is
    ``[edges[k], edges[k + 1]]`` (same other variables, outputs and value transform).
    Evaluation: clamp the inputs onto the whole box (``variables``), then evaluate the piece
    ``k`` with ``edges[k] <= x <= edges[k + 1]`` (the lower piece at a shared edge). Each
    piece carries its own guarantee in ``piece_info`` (e.g. the interval policy it meets).
    """

    name: str
    variables: list
    split_variable: str
    edges: list
    pieces: list
    kind: str = "brdf"
    domain_policy: dict = field(default_factory=lambda: {"outside": "clamp", "below_horizon": "zero"})
    fit_info: dict = field(default_factory=dict)
    piece_info: list = field(default_factory=list)
    source: dict = field(default_factory=lambda: {"file": "", "sha256": ""})

    def __post_init__(self):
        self.variables = [v if isinstance(v, Variable) else Variable(**v) for v in self.variables]
        names = [v.name for v in self.variables]
        if self.split_variable not in names:
            raise ValueError(f"split variable {self.split_variable!r} is not among {names}")
        self.edges = [float(e) for e in self.edges]
        if len(self.edges) != len(self.pieces) + 1 or np.any(np.diff(self.edges) <= 0):
            raise ValueError("edges must be increasing, one more than the pieces")
        self._axis = names.index(self.split_variable)
        var = self.variables[self._axis]
        if not (np.isclose(self.edges[0], var.domain[0]) and np.isclose(self.edges[-1], var.domain[1])):
            raise ValueError(f"edges {self.edges} do not span the domain {var.domain} of {var.name}")
        for k, piece in enumerate(self.pieces):
            if [v.name for v in piece.variables] != names or piece.outputs != self.pieces[0].outputs:
                raise ValueError(f"piece {k}: variables or outputs differ from the model's")
            if not np.allclose(piece.variables[self._axis].domain, self.edges[k:k + 2]):
                raise ValueError(f"piece {k}: {var.name} domain {piece.variables[self._axis].domain} "
                                 f"!= [{self.edges[k]}, {self.edges[k + 1]}]")
            if (piece.value_transform, piece.value_offset) != (self.pieces[0].value_transform,
                                                               self.pieces[0].value_offset):
                raise ValueError(f"piece {k}: value transform differs from piece 0")
        if not self.piece_info:
            self.piece_info = [{} for _ in self.pieces]

    @property
    def outputs(self) -> tuple:
        return self.pieces[0].outputs

    @property
    def n_vars(self) -> int:
        return len(self.variables)

    @property
    def n_coefficients(self) -> int:
        return sum(p.n_coefficients for p in self.pieces)

    @property
    def functions(self) -> list:
        """Every piece's functions, piece by piece."""
        return [f for p in self.pieces for f in p.functions]

    @property
    def value_transform(self) -> str:
        return self.pieces[0].value_transform

    @property
    def value_offset(self) -> float:
        return self.pieces[0].value_offset

    @property
    def value_min(self):
        return self.pieces[0].value_min

    @property
    def value_max(self):
        return self.pieces[0].value_max

    def piece_index(self, x_split) -> np.ndarray:
        """Index of the piece that evaluates each value of the split variable (clamped)."""
        inner = np.asarray(self.edges[1:-1])
        return np.searchsorted(inner, np.asarray(x_split, float), side="left")

    def __call__(self, x) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if self.domain_policy.get("outside", "clamp") == "clamp":
            lo = np.array([v.domain[0] for v in self.variables])
            hi = np.array([v.domain[1] for v in self.variables])
            x = np.clip(x, lo, hi)
        k = self.piece_index(x[..., self._axis])
        out = np.zeros(x.shape[:-1] + (len(self.outputs),))
        for i, piece in enumerate(self.pieces):
            sel = k == i
            if np.any(sel):
                out[sel] = piece(x[sel])
        return out

    def to_dict(self) -> dict:
        base = self.pieces[0].to_dict()
        pieces = []
        for piece, info in zip(self.pieces, self.piece_info):
            d = piece.to_dict()
            body = ({"functions": d["functions"]} if "functions" in d
                    else {"split": d["split"], "pieces": d["pieces"]})   # nested piecewise piece
            pieces.append({"variables": d["variables"], **body, "info": _jsonable(info)})
        return {
            "format": FORMAT, "version": VERSION_PIECEWISE, "name": self.name, "kind": self.kind,
            "variables": [{"name": v.name, "unit": v.unit, "transform": v.transform,
                           "domain": list(v.domain)} for v in self.variables],
            "value": base["value"], "basis": base["basis"], "outputs": base["outputs"],
            "split": {"variable": self.split_variable, "edges": list(self.edges)},
            "pieces": pieces,
            "domain_policy": _jsonable(self.domain_policy),
            "fit": _jsonable(self.fit_info),
            "source": _jsonable(self.source),
        }

    def save(self, path) -> None:
        save(self, path)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
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
    text = json.dumps(model.to_dict(), indent=1, allow_nan=False)
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
