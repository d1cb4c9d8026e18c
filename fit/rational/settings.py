"""Fit settings, scikit-learn style: every choice of a fit in one object's constructor, with
its unit and default, checked in one place; what a fit finds lives in its result's attributes.

* :class:`BRDFFitSettings`: the 2-D fit of a projected BRDF over ``(theta_h, theta_d)``
  (:func:`fit.rational.brdf_fit.fit_brdf`); its defaults are those of ``rbrdf-fit brdf``
  (:mod:`fit.cli.brdf` reads them from here), of the batch (:mod:`fit.batch.keys`) and of the
  studies (``studies/fits.py``);
* :class:`Fit3DSettings`: the 3-D fit of ``(theta_h, theta_d, |phi_d|)``
  (:func:`fit.rational.fit3d.fit_samples`, :func:`~fit.rational.fit3d.fit_rgl`,
  :func:`~fit.rational.fit3d.fit_rgl_select`).

Both are dataclasses with the same contract (``tests/test_fit_settings.py``):
``get_params()`` is a plain dict of every setting, ``type(s)(**s.get_params()) == s``;
``set_params(**kw)`` changes settings in place after checking the whole new combination (and
returns the object); ``clone(**kw)`` is a checked copy with changes. An unknown name raises
``TypeError`` and an invalid value ``ValueError``, both with one line naming the setting. The
fit entry points check their settings again (:meth:`validate`), so a value assigned directly
to an attribute cannot slip through. A setting never holds data or fitted state; the same
settings and data give the same fit, bit for bit.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields

from ..limits import (
    MAX_FIT_DEGREE,
    MAX_FIT_DEN_DEGREE,
    MAX_FLOOR_FRAC,
    MAX_TOLERANCE,
    MIN_CORE_THETA_D_DEG,
    MIN_TOLERANCE,
)
from .ceiling import DEFAULT_TIME_LIMIT
from .domain import THETA_D_MAX_DEG
from .model import VALUE_FACTORS
from .samples3d import DEFAULT_GRID, DEFAULT_NOISE_FRAC, DEFAULT_RANDOM, DEFAULT_THETA_FIT_DEG, OBJECTIVES

INTERVALS = ("tol", "tol+spread")               # interval policies of the 2-D fit
THETA_H_TRANSFORMS = ("sqrt", "identity")
VALUE_TRANSFORMS = ("log", "linear")

DEFAULT_DEGREES = (7, 3)             # numerator, denominator total degree per piece
DEFAULT_GRAZING_COS = 0.25          # cos(theta_i) cos(theta_o) below which the bound is on rho cos cos
DEFAULT_CHANNEL_FLOOR = 0.05        # a channel's error unit is at least this fraction of the largest channel
DEFAULT_VERIFY = 40000              # fresh points a fit is checked at (fit_rgl)
DEFAULT_RELAX = 2.0                 # second stage: intervals at this multiple of the smallest tolerance met
DEFAULT_OBJECTIVE = 4000            # objective points of the second stage per theta_h piece
#: What the 3-D layout selection compares (``Fit3DSettings.select_by``): ``"validation"``, the
#: held-out :func:`fit.rational.select3d.validation_score` of the setting ``objective``;
#: ``"image"``, :func:`fit.rational.select3d.image_score` of the fitter's image check
#: (:mod:`fit.rational.image_check`) of each layout's fit.
SELECT_BY = ("validation", "image")
DEFAULT_OBJECTIVE_KIND = "rho_cos_cos"   # what the second stage minimises and the selection compares
DEFAULT_RELATIVE_FLOOR = 0.1        # "relative": values below this fraction of a channel's median count by it
DEFAULT_VALUE_FACTOR = "1/cos_theta_i"  # 3-D functions give rho cos theta_i (step 8 divides), finite at the horizon
DEFAULT_ALBEDO_TOL = 0.05           # directional-albedo tolerance of the policy (fit.rational.albedo3d)
DEFAULT_ALBEDO_TIME = None          # the albedo step's own CPU-time safety net (s); None: the fit's (time_limit)
DEFAULT_ALBEDO_REFITS = 27          # channel corrections the albedo policy may try (9 weights x 3 channels)
DEFAULT_PROOF_ROUNDS = 4            # refits of the proof-guided refit (fit.rational.verify3d.refit_between_nodes)
DEFAULT_PROOF_ABOVE = 2.0           # ... of the cells and points more than this many times outside the stated bound
DEFAULT_LADDER_STEPS = 12           # infeasible tolerances at step 1.6 before the ladder squares its step
DEFAULT_ALBEDO_RMSE_GROWTH = 0.50   # the albedo correction may raise a channel's relative RMSE by this fraction
DEFAULT_ALBEDO_TOTAL_GROWTH = 0.15  # ... and the fit's (mean over R, G, B) by this one


def _number(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x)


def _integer(x) -> bool:
    return isinstance(x, numbers.Integral) and not isinstance(x, bool)


class _Settings:
    """The contract shared by the settings classes (module docstring)."""

    def __post_init__(self):
        self.validate()

    def get_params(self) -> dict:
        """Every setting by name, as given (a plain dict, in declaration order)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def clone(self, **params):
        """A new, checked settings object: these settings with ``params`` changed."""
        known = {f.name for f in fields(self)}
        for k in params:
            if k not in known:
                raise TypeError(f"{type(self).__name__}: unknown setting {k!r}")
        return type(self)(**dict(self.get_params(), **params))

    def set_params(self, **params):
        """Change ``params`` in place once the whole new combination is checked; returns self."""
        new = self.clone(**params)
        for k in params:
            setattr(self, k, getattr(new, k))
        return self

    def changed_params(self) -> dict:
        """The settings that differ from the class defaults."""
        default = type(self)().get_params()
        return {k: v for k, v in self.get_params().items() if v != default[k]}

    def validate(self) -> None:
        """``ValueError`` (one line naming the setting) for a value out of its range."""
        for name, ok, want in self._checks():
            if not ok:
                raise ValueError(f"{name} must be {want}, got {getattr(self, name)!r}")

    @classmethod
    def resolve(cls, settings=None, **overrides):
        """``settings`` (default: the class defaults) with ``overrides`` applied, checked: how the
        fit entry points read ``settings=`` and their keyword arguments."""
        if settings is None:
            return cls().clone(**overrides)
        if not isinstance(settings, cls):
            raise TypeError(f"settings must be a {cls.__name__}, got {type(settings).__name__}")
        settings.validate()
        return settings.clone(**overrides) if overrides else settings


@dataclass
class BRDFFitSettings(_Settings):
    """Settings of the 2-D fit (:func:`fit.rational.brdf_fit.fit_brdf`; its docstring and
    module docstring say what each does).

    * ``tol``: relative tolerance of the intervals (fraction, default 0.05);
    * ``intervals``, ``band_intervals``: interval policy of the guaranteed core and of the
      grazing band, one of :data:`INTERVALS` (default ``"tol"`` both);
    * ``core_theta_d_deg``: ``"auto"`` or the core's largest theta_d (degrees, in
      [``MIN_CORE_THETA_D_DEG``, 78.5]);
    * ``band_partial``: ``(fraction, factor)`` of the band's second try (None: none);
    * ``peak_split_deg``: theta_h (degrees) of the specular-peak split tried when no core is met
      (None: never);
    * ``max_theta_h_pieces``: when no core is met with the peak split either, the theta_h pieces
      that miss are split at their midpoints, round after round, up to this many pieces (an
      integer; 2: no split beyond the peak's);
    * ``theta_h_transform`` (``"sqrt"`` | ``"identity"``), ``value_transform`` (``"log"`` |
      ``"linear"``);
    * ``max_degree``, ``max_den_degree``: the largest numerator and denominator total degrees;
    * ``floor_frac``: absolute floor = ``floor_frac * tol * A_Y / pi`` (dimensionless);
    * ``spread_k``: multiple of a cluster's phi_d standard deviation (``"tol+spread"`` only).
    """

    tol: float = 0.05
    intervals: str = "tol"
    core_theta_d_deg: object = "auto"
    band_intervals: str = "tol"
    band_partial: tuple | None = (0.5, 2.0)
    peak_split_deg: float | None = 5.0
    max_theta_h_pieces: int = 6
    theta_h_transform: str = "sqrt"
    value_transform: str = "log"
    max_degree: int = 12
    max_den_degree: int = 6
    floor_frac: float = 1.0
    spread_k: float = 1.0

    def _checks(self):
        core = self.core_theta_d_deg
        bp = self.band_partial
        return [
            ("tol", _number(self.tol) and MIN_TOLERANCE <= self.tol <= MAX_TOLERANCE,
             f"in [{MIN_TOLERANCE:g}, {MAX_TOLERANCE:g}]"),
            ("max_degree", _integer(self.max_degree) and 0 <= self.max_degree <= MAX_FIT_DEGREE,
             f"an integer in [0, {MAX_FIT_DEGREE}]"),
            ("max_den_degree", _integer(self.max_den_degree) and 0 <= self.max_den_degree <= MAX_FIT_DEN_DEGREE,
             f"an integer in [0, {MAX_FIT_DEN_DEGREE}]"),
            ("floor_frac", _number(self.floor_frac) and 0.0 <= self.floor_frac <= MAX_FLOOR_FRAC,
             f"in [0, {MAX_FLOOR_FRAC:g}]"),
            ("core_theta_d_deg", core == "auto" or (_number(core) and MIN_CORE_THETA_D_DEG <= core <= THETA_D_MAX_DEG),
             f"'auto' or in [{MIN_CORE_THETA_D_DEG:g}, {THETA_D_MAX_DEG:g}] deg"),
            ("intervals", self.intervals in INTERVALS, f"one of {INTERVALS}"),
            ("band_intervals", self.band_intervals in INTERVALS, f"one of {INTERVALS}"),
            ("band_partial", bp is None or (isinstance(bp, (tuple, list)) and len(bp) == 2 and _number(bp[0])
                                            and 0.0 < bp[0] <= 1.0 and _number(bp[1]) and bp[1] >= 1.0),
             "None or (fraction in (0, 1], factor >= 1)"),
            ("peak_split_deg", self.peak_split_deg is None or (_number(self.peak_split_deg)
                                                               and 0.0 <= self.peak_split_deg < 90.0),
             "None or in [0, 90) deg"),
            ("max_theta_h_pieces", _integer(self.max_theta_h_pieces) and 2 <= self.max_theta_h_pieces <= 16,
             "an integer in [2, 16]"),
            ("theta_h_transform", self.theta_h_transform in THETA_H_TRANSFORMS, f"one of {THETA_H_TRANSFORMS}"),
            ("value_transform", self.value_transform in VALUE_TRANSFORMS, f"one of {VALUE_TRANSFORMS}"),
            ("spread_k", _number(self.spread_k) and self.spread_k >= 0.0, "a finite number >= 0"),
        ]


def _degree_pair(d) -> bool:
    return isinstance(d, (tuple, list)) and len(d) == 2 and all(_integer(x) and 0 <= x <= MAX_FIT_DEGREE for x in d)


def _optional_positive(x) -> bool:
    return x is None or (_number(x) and x > 0)


@dataclass
class Fit3DSettings(_Settings):
    """Settings of the 3-D fits (:mod:`fit.rational.fit3d`; docs/fitting.md, "The 3-D method",
    says what each does). Angles in radians unless the name ends in ``_deg``; times in seconds.

    The fit (:func:`~fit.rational.fit3d.fit_samples`):

    * ``tol``: the tolerance the ladder starts at (error units, default 0.03; the stated bound
      is what is met); ``degrees``: ``(numerator, denominator)`` total degrees per piece;
      ``theta_h_edges``: inner theta_h edges of the pieces (radians; None: one piece);
      ``piece_degrees``: degrees per piece (None: ``degrees`` everywhere);
    * ``value_factor``: what the functions give, one of :data:`fit.rational.model.VALUE_FACTORS`:
      ``"1/cos_theta_i"`` (default: rho cos theta_i, which the evaluation divides by cos theta_i,
      step 8 of the recipe; it stays finite where the measured data grow as 1 / cos theta_i towards
      the light's horizon) or ``"none"`` (rho itself);
    * ``noise_frac``: noise level as a fraction of a channel's median; ``grazing_cos``: the
      product of the cosines below which the bound is on ``rho cos cos``; ``channel_floor``: a
      channel's error unit is at least this fraction of the brightest channel;
    * ``relax``: the second stage's intervals at this multiple of the tolerance met (<= 1: one
      stage); ``ladder_steps``: infeasible tolerances before the ladder squares its step;
      ``time_limit``: the safety net in CPU seconds of the process (default
      :data:`fit.rational.ceiling.DEFAULT_TIME_LIMIT`, about 10x the largest fit; None: none),
      which a normal fit never reaches on any load; ``wall_limit``: a wall-clock limit (s; None,
      the default: none), only when a user asks for one (``rbrdf-fit brdf --time-limit``): a fit
      it stops depends on the machine's load.

    Sampling a file, verification and albedo policy (:func:`~fit.rational.fit3d.fit_rgl`):

    * ``grid``: ``(theta_h, theta_d, phi_d)`` grid sizes; ``n_random``: random points of each
      kind; ``theta_fit_deg``: data up to this incidence (degrees; at least the last measured);
    * ``verify``: fresh points of the verification (0: none); ``verify_rounds``: its refits;
      ``verify_above``: fresh points more than this many times outside the bound are refitted;
    * ``proof_rounds``: refits of the proof-guided refit after the verification
      (:func:`fit.rational.verify3d.refit_between_nodes`: the proof of the error between the grid
      nodes finds the cells where the fit leaves its bound, the worst points in them join the
      data; 0: none); ``proof_above``: cells and points more than this many times outside the
      stated bound count;
    * ``n_objective``: second-stage objective points per piece (0: one stage);
    * ``objective``: what the second stage minimises and the layout selection compares, one of
      :data:`fit.rational.samples3d.OBJECTIVES`: ``"relative"`` (squared relative error of rho,
      rho floored, over cosine-distributed pairs; the selection: median
      + 95th percentile of the relative error at held-out pairs), ``"rho_cos_cos"`` (squared
      error of ``rho cos theta_i cos theta_o`` in 1/sr; the selection: relative RMSE of it) or
      ``"blend"`` (the two objectives, each of unit sum; the selection as ``"relative"``);
      docs/fitting.md, "The second stage's objective", has what each achieves;
      ``relative_floor``: ``"relative"`` counts a value below this fraction of its channel's
      median of the data (or below the noise level) by that floor (fraction, default 0.1);
    * ``albedo``: apply the albedo policy; ``albedo_tol`` (fraction), ``albedo_time`` (s;
      None: none; CPU seconds, as ``time_limit``), ``albedo_rmse_growth``, ``albedo_total_growth`` (fractions),
      ``albedo_refits`` (channel corrections);
    * ``prove_bound``: prove the error between the grid nodes of the measurement, per piece and
      channel, in the unit of the stated tolerance (:func:`fit.rational.proved_bound.record_fit3d`,
      recorded in ``fit_info["bound"]`` and ``fit_info["domain"]``); on by default (2-6 s of a
      fit, docs/fitting.md, "The proved bound");
    * ``image_check``: record what the chosen fit looks like against the measurement, the ΔE2000
      of a virtual sphere's images under generic lights (:mod:`fit.rational.image_check`,
      ``fit_info["image_check"]``; about 3 s of a selection);

    Layout selection (:func:`~fit.rational.fit3d.fit_rgl_select`): ``select_by``, what it
    compares (:data:`SELECT_BY`: the held-out validation score of ``objective``, or the image
    check of each layout's fit, ``mean + p99 / 3``; a layout may set its own ``objective``);
    ``select_share`` of
    ``time_limit`` (and of ``wall_limit``) after which no further layout starts; ``max_variants`` layouts at most
    (None: all); ``target_rmse``: the coefficient count as the dial (None, the default: the lowest
    validation error of the layouts wins): the layouts are tried cheapest first and the first whose
    validation RMSE is within it is kept (:data:`fit.rational.select3d.TARGET_LADDER` by default).
    """

    tol: float = 0.03
    degrees: tuple = DEFAULT_DEGREES
    theta_h_edges: list | None = None
    piece_degrees: list | None = None
    value_factor: str = DEFAULT_VALUE_FACTOR
    noise_frac: float = DEFAULT_NOISE_FRAC
    grazing_cos: float = DEFAULT_GRAZING_COS
    channel_floor: float = DEFAULT_CHANNEL_FLOOR
    relax: float = DEFAULT_RELAX
    ladder_steps: int = DEFAULT_LADDER_STEPS
    time_limit: float | None = DEFAULT_TIME_LIMIT
    wall_limit: float | None = None
    grid: tuple = DEFAULT_GRID
    n_random: int = DEFAULT_RANDOM
    theta_fit_deg: float = DEFAULT_THETA_FIT_DEG
    verify: int = DEFAULT_VERIFY
    verify_rounds: int = 2
    verify_above: float = 1.0
    proof_rounds: int = DEFAULT_PROOF_ROUNDS
    proof_above: float = DEFAULT_PROOF_ABOVE
    n_objective: int = DEFAULT_OBJECTIVE
    objective: str = DEFAULT_OBJECTIVE_KIND
    relative_floor: float = DEFAULT_RELATIVE_FLOOR
    albedo: bool = True
    albedo_tol: float = DEFAULT_ALBEDO_TOL
    albedo_time: float | None = DEFAULT_ALBEDO_TIME
    albedo_rmse_growth: float = DEFAULT_ALBEDO_RMSE_GROWTH
    albedo_total_growth: float = DEFAULT_ALBEDO_TOTAL_GROWTH
    albedo_refits: int = DEFAULT_ALBEDO_REFITS
    prove_bound: bool = True
    image_check: bool = True
    select_by: str = "image"
    select_share: float = 0.6
    max_variants: int | None = None
    target_rmse: float | None = None

    def _checks(self):
        edges, pdeg = self.theta_h_edges, self.piece_degrees
        edges_ok = edges is None or (isinstance(edges, (tuple, list)) and all(_number(e) and e > 0 for e in edges))
        n_pieces = len(edges or []) + 1 if edges_ok else 0
        nonneg_int = lambda x: _integer(x) and x >= 0      # noqa: E731
        return [
            ("tol", _number(self.tol) and self.tol > 0, "a finite number > 0"),
            ("degrees", _degree_pair(self.degrees), f"a pair of integers in [0, {MAX_FIT_DEGREE}]"),
            ("theta_h_edges", edges_ok, "None or a list of angles > 0 (radians)"),
            ("piece_degrees", pdeg is None or (isinstance(pdeg, (tuple, list)) and len(pdeg) == n_pieces
                                               and all(_degree_pair(d) for d in pdeg)),
             f"None or one degree pair per piece ({n_pieces})"),
            ("value_factor", self.value_factor in VALUE_FACTORS, f"one of {VALUE_FACTORS}"),
            ("noise_frac", _number(self.noise_frac) and self.noise_frac > 0, "a finite number > 0"),
            ("grazing_cos", _number(self.grazing_cos) and 0.0 <= self.grazing_cos <= 1.0, "in [0, 1]"),
            ("channel_floor", _number(self.channel_floor) and 0.0 <= self.channel_floor <= 1.0, "in [0, 1]"),
            ("relax", _number(self.relax) and self.relax > 0, "a finite number > 0"),
            ("ladder_steps", _integer(self.ladder_steps) and self.ladder_steps >= 1, "an integer >= 1"),
            ("time_limit", _optional_positive(self.time_limit), "None or a finite number > 0 (s)"),
            ("target_rmse", _optional_positive(self.target_rmse), "None or a finite number > 0"),
            ("wall_limit", _optional_positive(self.wall_limit), "None or a finite number > 0 (s)"),
            ("grid", isinstance(self.grid, (tuple, list)) and len(self.grid) == 3
             and all(_integer(g) and g >= 1 for g in self.grid), "three integers >= 1"),
            ("n_random", nonneg_int(self.n_random), "an integer >= 0"),
            ("theta_fit_deg", _number(self.theta_fit_deg) and 0.0 < self.theta_fit_deg < 90.0, "in (0, 90) deg"),
            ("verify", nonneg_int(self.verify), "an integer >= 0"),
            ("verify_rounds", nonneg_int(self.verify_rounds), "an integer >= 0"),
            ("verify_above", _number(self.verify_above) and self.verify_above > 0, "a finite number > 0"),
            ("proof_rounds", nonneg_int(self.proof_rounds), "an integer >= 0"),
            ("proof_above", _number(self.proof_above) and self.proof_above > 0, "a finite number > 0"),
            ("n_objective", nonneg_int(self.n_objective), "an integer >= 0"),
            ("objective", self.objective in OBJECTIVES, f"one of {OBJECTIVES}"),
            ("relative_floor", _number(self.relative_floor) and self.relative_floor >= 0, "a finite number >= 0"),
            ("albedo", isinstance(self.albedo, bool), "True or False"),
            ("albedo_tol", _number(self.albedo_tol) and self.albedo_tol > 0, "a finite number > 0"),
            ("albedo_time", _optional_positive(self.albedo_time), "None or a finite number > 0 (s)"),
            ("albedo_rmse_growth", _number(self.albedo_rmse_growth) and self.albedo_rmse_growth >= 0,
             "a finite number >= 0"),
            ("albedo_total_growth", _number(self.albedo_total_growth) and self.albedo_total_growth >= 0,
             "a finite number >= 0"),
            ("albedo_refits", nonneg_int(self.albedo_refits), "an integer >= 0"),
            ("prove_bound", isinstance(self.prove_bound, bool), "True or False"),
            ("image_check", isinstance(self.image_check, bool), "True or False"),
            ("select_by", self.select_by in SELECT_BY, f"one of {SELECT_BY}"),
            ("select_share", _number(self.select_share) and 0.0 < self.select_share <= 1.0, "in (0, 1]"),
            ("max_variants", self.max_variants is None or nonneg_int(self.max_variants), "None or an integer >= 0"),
        ]
