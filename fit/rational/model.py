"""Rational models: rational functions (:mod:`fit.rational.function`) with their input and
value transforms and domain policy, evaluated at physical inputs.

* :class:`Variable`: an input's name, unit, transform (``"identity"``: u = x, ``"sqrt"``:
  u = sqrt(x)) and domain in its own unit;
* value transforms: ``"linear"`` (y = R(u)) or ``"log"`` (y = exp(R(u)) - offset), with the
  clamps ``value_min`` / ``value_max``;
* value factors (3-D BRDFs only, step 8 of the recipe): ``"none"`` (rho = y) or
  ``"1/cos_theta_i"`` (rho = y / max(cos theta_i, :data:`COS_FLOOR`): the functions give rho cos
  theta_i, which stays finite where measured data grow as 1 / cos theta_i towards the light's
  horizon; cos theta_i of the Rusinkiewicz angles before any clamp, :func:`cos_theta_i_of`);
* :class:`RationalModel`: one rational function per output on one box;
* :class:`PiecewiseRationalModel`: rational models on consecutive intervals of one variable;
* :func:`flagged`: whether a function's record (``function_info``) says that its fit is not
  within its intervals; such a function's output is clamped to the ``measured_range`` its
  record holds (the measured data of its piece, step 7 of the recipe in
  :mod:`fit.rational.coefficient_file`).

For BRDFs the variables are ``theta_h`` then ``theta_d`` (radians) and the outputs R, G, B in
1/sr; :meth:`~RationalModel.evaluate_brdf` and :meth:`~RationalModel.evaluate` (directions,
0 below the horizon) are the BRDF. The file format that stores these models, and the exact
evaluation recipe, are :mod:`fit.rational.coefficient_file`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..formats.angles import cos_theta_i_o, directions_to_half_diff
from ..limits import MAX_BRDF_VALUE

INPUT_TRANSFORMS = ("identity", "sqrt")
VALUE_TRANSFORMS = ("linear", "log")
#: Step 8 of the evaluation recipe (:mod:`fit.rational.coefficient_file`): ``"none"``, or
#: ``"1/cos_theta_i"`` (the functions give rho cos theta_i; 3-D BRDF fits only).
VALUE_FACTORS = ("none", "1/cos_theta_i")
#: The smallest cos theta_i the factor ``"1/cos_theta_i"`` divides by (theta_i = 89.94 deg):
#: below it rho cos theta_i falls linearly to 0 at the horizon instead of staying finite.
COS_FLOOR = 1.0e-3


def cos_theta_i_of(x) -> np.ndarray:
    """``cos theta_i`` (wi . n) of Rusinkiewicz rows ``x`` ``(..., 3)`` = ``(theta_h, theta_d,
    |phi_d|)`` (radians): ``cos th cos td - sin th sin td cos pd``
    (:func:`fit.formats.angles.cos_theta_i_o` of the rows' columns)."""
    x = np.asarray(x, dtype=np.float64)
    return cos_theta_i_o(x[..., 0], x[..., 1], x[..., 2])[0]


def _factor_divisor(x, factor: str) -> np.ndarray:
    """``(...)`` what step 8 divides the values at rows ``x`` by: ``max(cos theta_i, COS_FLOOR)``
    for ``"1/cos_theta_i"``; ValueError for a factor other than that and ``"none"``."""
    if factor != "1/cos_theta_i":
        raise ValueError(f"unknown value factor {factor!r}")
    return np.maximum(cos_theta_i_of(x), COS_FLOOR)


def apply_value_factor(y, x, factor: str):
    """Step 8: the values ``y`` ``(..., n_out)`` at the (unclamped) physical inputs ``x``
    ``(..., 3)`` times the model's value factor (:data:`VALUE_FACTORS`)."""
    if factor == "none":
        return y
    return y / _factor_divisor(x, factor)[..., None]


def value_factor_weights(x, factor: str) -> np.ndarray:
    """``(...)`` what the factor multiplies the functions' values by at rows ``x`` (1 for
    ``"none"``): the fitter fits ``rho / weight`` (e.g. rho cos theta_i)."""
    x = np.asarray(x, dtype=np.float64)
    if factor == "none":
        return np.ones(x.shape[:-1])
    return 1.0 / _factor_divisor(x, factor)


def apply_input_transform(x, transform: str):
    x = np.asarray(x, dtype=np.float64)
    if transform == "identity":
        return x
    if transform == "sqrt":
        return np.sqrt(np.maximum(x, 0.0))
    raise ValueError(f"unknown input transform {transform!r}")


def invert_input_transform(u, transform: str):
    """The variable's own value at ``u`` in its transformed coordinate: the inverse of
    :func:`apply_input_transform`."""
    u = np.asarray(u, dtype=np.float64)
    if transform == "identity":
        return u
    if transform == "sqrt":
        return u * u
    raise ValueError(f"unknown input transform {transform!r}")


def apply_value_transform(y, transform: str, offset: float = 0.0):
    """Data value -> fitted quantity (the inverse of step 5 of the evaluation recipe in
    :mod:`fit.rational.coefficient_file`)."""
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


def flagged(info: dict) -> bool:
    """True when a function's record says its fit is NOT within its intervals: ``valid`` is
    False (some data point outside its interval, Q > 0 not certified, or a search stopped at
    its degree or time limit), or, in records without ``valid``, ``feasible`` is False or the
    Q certificate failed. A function with no record (a model built by hand) is not flagged:
    nothing is claimed for it, and nothing is known against it."""
    if not info:
        return False
    if "valid" in info:
        return not bool(info["valid"])
    cert = info.get("q_certificate")
    if isinstance(cert, dict) and cert.get("certified") is False:
        return True
    return info.get("feasible") is False


def _recorded_range(info: dict, key: str):
    """``(lo, hi)`` of a function record's ``key``, or None when the record has none."""
    r = (info or {}).get(key)
    if r is None:
        return None
    lo, hi = (float(v) for v in r)
    return lo, hi


def measured_range(info: dict):
    """``(lo, hi)``: the recorded range of the measured data a function was fitted to (its
    piece's clusters), or None when the record has none (files written before it was
    recorded)."""
    return _recorded_range(info, "measured_range")


def vouched_range(info: dict):
    """``(lo, hi)``: the envelope of the intervals of the data a function was fitted to (its
    piece's clusters: the lowest lower bound, at least 0, and the highest upper bound), or None
    when the record has none (fits written before it was recorded). A valid function is clamped
    to it (step 7): no value at a data point changes (each lies inside its interval), and in the
    piece's data-free clusters the fit cannot leave what its data vouch for."""
    return _recorded_range(info, "vouched_range")


def vouched_envelope(lower, upper) -> list:
    """The ``vouched_range`` record of a function fitted to data with interval bounds
    ``lower``, ``upper`` (arrays, 1/sr): ``[max(min lower, 0), min(max upper,
    fit.limits.MAX_BRDF_VALUE)]``. The upper end is capped at the reader's limit on a BRDF
    value: a function whose stated tolerance is huge (a 3-D fit missing its data by orders of
    magnitude) would otherwise vouch for values no measurement holds and write a file its own
    reader refuses; the cap changes no value at a data point (every measured value is below it)."""
    return [float(max(np.min(lower), 0.0)), float(min(np.max(upper), MAX_BRDF_VALUE))]


def output_clamp(info: dict):
    """Step 7 of one function: its ``measured_range`` when flagged, its ``vouched_range`` when
    not (None when the record has neither)."""
    return measured_range(info) if flagged(info) else vouched_range(info)


def _check_factor(model) -> None:
    if model.value_factor not in VALUE_FACTORS:
        raise ValueError(f"unknown value factor {model.value_factor!r}")
    if model.value_factor != "none" and (model.kind != "brdf" or [v.name for v in model.variables]
                                         != ["theta_h", "theta_d", "phi_d"]):
        raise ValueError(f"value factor {model.value_factor!r} needs a 3-D BRDF (theta_h, theta_d, phi_d)")


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
    #: step 8 (:data:`VALUE_FACTORS`); only on a model evaluated as a whole, never on a piece of a
    #: PiecewiseRationalModel (whose own ``value_factor`` applies once, at the unclamped inputs)
    value_factor: str = "none"
    source: dict = field(default_factory=lambda: {"file": "", "sha256": ""})
    #: the file's optional "fallback" record (fit.rational.fallback: the projected table of a
    #: flagged 2-D fit, so that it renders without its source measurement); None: none
    fallback: dict | None = None
    #: the file's optional "sampler" record (fit.sampling.embedded: the fit's own inverse CDFs,
    #: bound to the rest of the file by its sha256); None: none
    sampler: dict | None = None

    def __post_init__(self):
        self.variables = [v if isinstance(v, Variable) else Variable(**v) for v in self.variables]
        self.outputs = tuple(self.outputs)
        if len(self.functions) != len(self.outputs):
            raise ValueError("one function per output is required")
        if self.value_transform not in VALUE_TRANSFORMS:
            raise ValueError(f"unknown value transform {self.value_transform!r}")
        _check_factor(self)
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

    @property
    def flagged(self) -> tuple:
        """Per output: the function's record says it is not within its intervals (:func:`flagged`)."""
        return tuple(flagged(i) for i in self.function_info)

    def output_clamps(self) -> list:
        """Per output: ``(lo, hi)`` of step 7 (:func:`output_clamp`: a flagged function's
        measured range, a valid function's vouched range), else None."""
        return [output_clamp(i) for i in self.function_info]

    def leaves(self, x) -> list:
        """``[(model, selection, x_clamped)]``: the single-box model that evaluates each input of
        ``x`` ``(..., n_vars)`` (here: this one, everywhere), and the inputs clamped onto its box."""
        x = np.asarray(x, dtype=np.float64)
        lo = np.array([v.domain[0] for v in self.variables])
        hi = np.array([v.domain[1] for v in self.variables])
        return [(self, np.ones(x.shape[:-1], bool), np.clip(x, lo, hi))]

    def __call__(self, x) -> np.ndarray:
        """Steps 1-8 at physical inputs ``x`` ``(..., n_vars)``: ``(..., n_outputs)``."""
        return apply_value_factor(self.values(x), x, self.value_factor)

    def values(self, x) -> np.ndarray:
        """Steps 1-7 (the functions' values, before the value factor of step 8)."""
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
        for c, rng in enumerate(self.output_clamps()):   # step 7: measured / vouched range
            if rng is not None:
                out[..., c] = np.clip(out[..., c], rng[0], rng[1])
        return out

    # Persistence ---------------------------------------------------------------------------


@dataclass
class PiecewiseRationalModel(_BRDFEvaluation):
    """Rational models on consecutive intervals of one variable (file version 2,
    :mod:`fit.rational.coefficient_file`).

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
    fallback: dict | None = None         # as RationalModel.fallback
    sampler: dict | None = None          # as RationalModel.sampler
    value_factor: str = "none"           # step 8, once for the whole model (its pieces have "none")

    def __post_init__(self):
        self.variables = [v if isinstance(v, Variable) else Variable(**v) for v in self.variables]
        _check_factor(self)
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
            if piece.value_factor != "none":
                raise ValueError(f"piece {k}: a piece has no value factor of its own (the model's applies)")
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

    def leaves(self, x) -> list:
        """``[(model, selection, x_clamped)]``: for every single-box piece (recursively), the
        inputs of ``x`` ``(..., n_vars)`` it evaluates (the selection :meth:`__call__` makes)
        and the inputs clamped onto its box."""
        x = np.asarray(x, dtype=np.float64)
        lo = np.array([v.domain[0] for v in self.variables])
        hi = np.array([v.domain[1] for v in self.variables])
        xc = np.clip(x, lo, hi)
        k = self.piece_index(xc[..., self._axis])
        out = []
        for i, piece in enumerate(self.pieces):
            for leaf, sel, xl in piece.leaves(xc):
                out.append((leaf, sel & (k == i), xl))
        return out

    def __call__(self, x) -> np.ndarray:
        """Steps 1-8 at physical inputs ``x`` ``(..., n_vars)``: ``(..., n_outputs)``."""
        return apply_value_factor(self.values(x), x, self.value_factor)

    def values(self, x) -> np.ndarray:
        """Steps 1-7 (the pieces' values, before the value factor of step 8)."""
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
