"""Versioned JSON coefficient files of fitted rational functions: format ``rbrdf-rational``, version 1.

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
                "min": 0.0},                 # output is max(y, min); null = no clamp
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
    6. clamp:      rho = max(y, min)       (min = 0 for BRDFs: never negative)

For a BRDF the variables are exactly ``theta_h`` then ``theta_d`` (radians, Rusinkiewicz 1998,
as in conventions.md) and rho is in 1/sr without the cosine; rho = 0 when the light or view
direction is at or below the tangent plane ("below_horizon": "zero").

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
VERSION = 1
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


@dataclass
class RationalModel:
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
        out = np.stack([invert_value_transform(f(u), self.value_transform, self.value_offset)
                        for f in self.functions], axis=-1)
        if self.value_min is not None:
            out = np.maximum(out, self.value_min)
        return out

    def evaluate_brdf(self, theta_h, theta_d) -> np.ndarray:
        """rho in 1/sr at Rusinkiewicz angles (radians); shape ``broadcast + (3,)``."""
        th, td = np.broadcast_arrays(np.asarray(theta_h, float), np.asarray(theta_d, float))
        return self(np.stack([th, td], axis=-1))

    def evaluate(self, wi, wo) -> np.ndarray:
        """rho(wi, wo) in 1/sr for local unit directions ``(..., 3)``; 0 below the horizon."""
        from .angles import directions_to_half_diff

        wi = np.asarray(wi, float)
        wo = np.asarray(wo, float)
        th, _, td, _ = directions_to_half_diff(wi, wo)
        out = self.evaluate_brdf(th, td)
        wi, wo = np.broadcast_arrays(wi, wo)
        above = (wi[..., 2] > 0.0) & (wo[..., 2] > 0.0)
        return np.where(above[..., None], out, 0.0)

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
                      "min": self.value_min},
            "basis": "chebyshev",
            "outputs": list(self.outputs),
            "functions": funcs,
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


def save(model: RationalModel, path) -> None:
    """Write ``model`` as an ``rbrdf-rational`` version-1 JSON file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(model.to_dict(), indent=1, allow_nan=False)
    path.write_text(text + "\n", encoding="utf-8")


def from_dict(d: dict, path=None) -> RationalModel:
    """Build a model from a parsed file; :class:`BRDFFileError` on any problem."""
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise BRDFFileError(path, f"not an {FORMAT} coefficient file (format key is "
                                  f"{d.get('format') if isinstance(d, dict) else None!r})")
    ver = d.get("version")
    if ver != VERSION:
        raise BRDFFileError(path, f"unsupported {FORMAT} version {ver!r} (this reader knows version {VERSION})")
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
            value_min=value.get("min", None), value_name=str(value.get("name", "y")),
            value_unit=str(value.get("unit", "")),
            domain_policy=dict(d.get("domain_policy", {"outside": "clamp"})),
            fit_info=dict(d.get("fit", {})), function_info=infos,
            source=dict(d.get("source", {"file": "", "sha256": ""})),
        )
    except BRDFFileError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise BRDFFileError(path, f"invalid {FORMAT} coefficient file ({e.__class__.__name__}: {e})") from None


def load(path) -> RationalModel:
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
