"""3-D rational BRDF fits of ``(theta_h, theta_d, |phi_d|)`` with a guaranteed bound at every
data point (coefficient file version 3, :mod:`fit.rational.coefficient_file`).

What is fitted
==============
The measurement itself, not its phi_d-median projection: rho (1/sr, RGB) sampled from the
RGL reference evaluation (:meth:`fit.formats.rgl.RGLBRDF.evaluate`, the file's own (light,
view) roles, no reciprocity fold; negatives clamped to 0) at points of the variables of
:mod:`fit.rational.variables3d` (:func:`sample_grid`):

* a grid ``theta_h = theta_max s^2`` (``s`` uniform: dense at the specular peak), ``theta_d``
  uniform on ``[0, theta_max]``, ``phi_d`` uniform on ``[0, pi]``;
* ``n_random`` points uniform in ``(sqrt(theta_h), theta_d, phi_d)`` and ``n_random`` pairs of
  cosine-distributed directions (seeded): without them a fit met its bound on a 5,700-point
  grid and was 50x off between the grid points (satin_rosaline, relative RMSE 53);
* kept where both directions are above the horizon and within ``theta_max`` of the normal:
  :func:`fit_rgl` takes ``theta_max`` = 89 deg (``theta_fit_deg``), beyond the **last measured
  incidence** (:attr:`RGLBRDF.theta_i_max`, 78-85 deg on the six materials): the whole
  measured domain, and the file's own extrapolation beyond it (its rgb tables clamped, its
  other factors not), which is the truth the renderer's ``rgl`` material and the benchmark
  use. Fitted only up to the last incidence, 8 % of cosine-distributed pairs lie outside the
  data and made 39 % of the squared error of satin_rosaline (the fit extrapolated freely in
  its box). ``fit_info.theta_measured_deg`` records the last measured incidence.

Intervals and the bound
=======================
Per channel ``c`` a noise level ``n_c`` (:func:`noise_levels`: 1 % of the channel's median, or
more where the file clamped negative values to 0) and, per point, the error unit

    s = max(rho_c, n_c, channel_floor * max(rho_R, rho_G, rho_B)) * g,
    g = max(1, grazing_cos / (cos theta_i cos theta_o))

and the interval ``rho_c +- tol * s``: relative to the value down to the noise level (not an
albedo-wide floor), a channel that is below ``channel_floor`` (5 %) of the brightest channel of
the same pair bounded relative to that channel (vch_golden_yellow's blue rises from 0 to 0.8
/sr within 10 deg of theta_d in the specular peak where green is 4 /sr: relative to itself it
could not be followed, bound 100 %, relative RMSE 0.32; with the floor 0.17), and where
``cos theta_i cos theta_o >= grazing_cos`` (default 0.25, e.g. both
directions within 60 deg), and beyond it a bound on what a renderer sees, ``rho cos theta_i
cos theta_o``, within ``tol * max(rho, n_c) * grazing_cos`` (the grazing pairs of the RGL
files are where one function of these variables fails: paper_white, one piece of degrees
(5, 2), met 2.5 % with both directions within 60 deg and 15 % over the whole domain; with
``g`` its three pieces meet 1.6-6.5 % and the relative RMSE drops from 0.069 to 0.028).
``grazing_cos = 0`` makes the bound relative everywhere. Values are fitted as
``log(rho + offset)`` (``offset`` = the smallest ``n_c``), so the interval is
``[log(max(rho - tol s, 0) + offset), log(rho + tol s + offset)]``: linear constraints of the
interval LP of :class:`fit.rational.fitter.IntervalRationalFitter`, with constraint generation
and the ``Q >= q_min`` Bernstein rows on the whole box.

The degrees are fixed per piece (``degrees``; the coefficient budget is the design choice),
and the **tolerance is the outcome**. A fit has two stages:

1. **Minimax (feasibility).** ``tol, 1.6 tol, 1.6^2 tol, ...`` are tried until the intervals are
   met (:func:`_fit_channel`; a channel starts one step below the tolerance its piece's previous
   channel met). The LP is exact for feasibility only: its least-violation solution when
   infeasible is not a minimax fit (its margins are weighted by Q, and a small Q hid errors of
   100x on satin_rosaline), so it is never used. At the smallest tolerance met, ``t``, the error
   equi-oscillates: most points sit near the bound and the average error is close to it.
2. **Average (the default when objective points are given, ``relax`` = 2).** Within the
   intervals at ``relax * t`` (still a bound at every data point), the fit that minimises the
   benchmark's metric, the squared error of ``rho cos theta_i cos theta_o`` over pairs of
   independent cosine-distributed directions, estimated on :func:`objective_points` (4,000 per
   piece, importance-weighted: many near the peak, where the values are large and such pairs
   rare): :func:`fit.rational.refine.refine`, a Sanathanan-Koerner iteration of weighted
   least-squares problems with the interval rows and the Bernstein ``Q >= q_min`` rows as
   constraints (a least-distance problem, Lawson-Hanson NNLS; HiGHS QP as the fallback), the
   log-value residuals weighted by the secant slope of ``exp`` (:func:`fit.rational.secant.secant_weights`: the
   error of the value, not of its log). Measured (one layout, four pieces, 50,000 pairs; one
   stage -> two stages): satin_rosaline 0.127 -> 0.054, cc_iris_purple_gem 0.281 -> 0.072,
   vch_golden_yellow 0.157 -> 0.044, paper_white 0.035 -> 0.020 (0.0098 with one piece of
   degrees (7, 3)); the stated bound doubles at most (``relax``: 1.5 gave 0.058 / 0.060 / 0.050
   on satin / iris / vch, 3 gave 0.052 on satin but 0.099 against 0.074 on cc_ibiza_sunset).
   Where the second stage fails (a QP not optimal, a point outside by rounding, Q > 0 not
   certified) the channel keeps its minimax function (``stage`` in the record says which).

The stated bound is then measured on every data point in float64: ``tol_c = max |fit - rho| / s``
per channel and piece (at most ``relax * t``, ``t`` for a minimax channel). Every data point lies
within ``rho +- tol_c s`` and Q > 0 is certified on each piece's box (exact Bernstein
coefficients); the record says so (``valid``, ``tolerance``, ``intervals``, ``stage``). The bound
holds at the data points; between them the fit is bounded by its ``vouched_range`` (step 7 of the
file's recipe), checked at 40,000 fresh points by :func:`fit_rgl` (violators join the data and
the functions outside their bound there are fitted again: constraint generation over the sampled
domain; ``fit_info.verified``, ``verify_max_ratio`` say how far that got within the refit budget)
and measured by
``benchmarks/bench_fit_accuracy.py``. :func:`fit_rgl_select` fits a few layouts
(:data:`VARIANTS`) and keeps the one with the lowest relative RMSE on validation pairs.

Directional albedo
==================
A bound on rho at the data points says little about the directional albedo at grazing
incidence, where the grazing weight ``g`` relaxes the bound (before this policy the two-stage
fits were off by 12-14 % at 75 deg on vch_golden_yellow and cc_ibiza_sunset, 30 % at 0 deg on
cc_iris_purple_gem). :func:`fit_rgl` and :func:`fit_rgl_select` end (after the verification)
with the albedo policy of :mod:`fit.rational.albedo3d` (``albedo=True`` by default): the
directional albedo is measured on a fixed quadrature at 0, 15, 30, 45, 60, 75 deg and the last
measured incidence; a channel outside ``albedo_tol`` (default 5 %, :data:`DEFAULT_ALBEDO_TOL`;
not the fit's ``tol``) has every piece's function refitted by the second stage with the squared
relative albedo errors of every angle added to its objective (weights on a ladder, the data
intervals unchanged: the stated bound does not grow, Q > 0 certified again), kept only where
the channel's largest albedo error drops, no refitted function moves more than 4 T from its
pre-policy self at 200,000 fresh points (a spike guard) and the channel's relative RMSE on
100,000 check pairs grows by at most ``albedo_rmse_growth`` (50 %) and the fit's (the mean over
R, G, B) by at most ``albedo_total_growth`` (15 %), with at most
``albedo_refits`` (27) channel corrections (the ladder's 9 weights for three channels; 0.1-17
s on the 20 RGL materials, see "Budgets"). Measured (before the budgets; benchmark,
largest albedo error over angles and channels on the policy's quadrature, before -> after):
paper_white, colodur_napoli_4f, satin_rosaline within 5 % untouched (0.5 / 2.9 / 2.6 %);
cc_ibiza_sunset 14.5 -> 7.4 % (relative RMSE 0.0700 -> 0.0710), vch_golden_yellow 40.0 ->
8.3 % (0.0434 -> 0.0427), cc_iris_purple_gem 17.9 % unchanged (its red at 0 deg cannot be
corrected within the 10 %; 0.071 -> 0.077 from green and blue). What stays outside is recorded in ``fit_info["albedo"]``
(``within``, ``outside``: incidences, channels and errors, ``max_error``; errors before and
after) and saved with the coefficient file. The correction trades average error for albedo
(docs/fit_accuracy.md has the numbers). When it changed a function, ``verify_max_ratio`` is
measured again on the verification's last fresh points (``verify_after_albedo``).

Pieces
======
``theta_h_edges`` splits the box along ``theta_h`` (a specular-peak piece, its shoulder and the
rest, where one function cannot follow the lobe); each piece is fitted to its own points (points
on an edge go to both sides) and the file is a piecewise model whose variables are the 3-D ones.

Budgets
=======
No rule of a fit reads the clock: every loop stops on a count, so the same inputs give the same
coefficients, bit for bit, whatever the machine's load (``tests/test_fit3d_budget.py``: a clock
that jumps 10 s at every reading changes nothing). Before, the loops stopped on wall-clock
seconds: vch_golden_yellow's fresh-point ratio was 11.03 on a quiet machine and 9.17 under load,
and a material took 60.2 s under load. The budgets:

* the tolerance ladder (:func:`_fit_channel`): after ``ladder_steps`` (12,
  :data:`DEFAULT_LADDER_STEPS`) infeasible tolerances the step is squared at every further one
  (a channel would have to fail 0.01 ... 0.01 x 1.6^11 = 1.8 first); a one-stage fit always takes
  its bisection step; the interval LP's constraint generation makes at most 40 rounds;
* the second stage (:func:`fit.rational.refine.refine`): 3 Sanathanan-Koerner iterations of at
  most 12 constraint-generation rounds, NNLS at most ``20 n`` iterations, the HiGHS QP fallback at
  most ``qp_iterations`` (20,000);
* the layouts (:func:`fit_rgl_select`): every layout of :data:`VARIANTS` (``max_variants``: all),
  the one-piece one only below its validation RMSE (``if_rmse_below``);
* the verification (:func:`verify_and_refit`): ``verify_rounds`` refits (2), each adding the
  worst fresh points outside the bound and refitting only the functions (piece, channel) outside
  it there, with the first fit's noise levels. The one-piece (7, 3) layout's own entry: one
  refit, only for spikes (fresh points more than 4 times outside the bound, ``verify_above``):
  its refit of three channels costs 20-26 s (the four pieces' 1-5 s), and without any,
  acrylic_felt_purple was 10.7 times outside at a fresh point (1.53 after one refit of its red
  and blue, 14 s; the other nine one-piece fits stay below 4 and are not refitted);
* the albedo policy (:mod:`fit.rational.albedo3d`): the 9 weights of its ladder, at most
  ``albedo_refits`` (27, :data:`DEFAULT_ALBEDO_REFITS`) channel corrections.

``time_limit`` (default :data:`DEFAULT_TIME_LIMIT` = 120 s for a whole :func:`fit_rgl` or
:func:`fit_rgl_select`, :func:`fit_samples` and :func:`verify_and_refit` alike) is only a
last-resort safety net (:class:`Ceiling`), never reached in normal runs: once it is passed the
ladder squares its steps and no layout (past ``select_share`` of it), refit or albedo round is
started; ``fit_info["stopped"] = "time"`` and ``stopped_at`` (where) record it (``stopped`` is
None otherwise). ``albedo_time`` (default None) adds a ceiling of the albedo step's own.

Measured with these budgets (``benchmarks/bench_fit_accuracy.py`` defaults, i.e.
:func:`fit_rgl_select` with ``tol=0.01``; the 20 RGL materials one at a time, one thread, on
this 2-core machine with the other core busy, 2026-11-24): 12.7-42.2 s per material, layout
selection, verification and albedo policy included (acrylic_felt_purple 42.2 s with its spike
refit, ilm_solo_m_68 41.1 s, vch_golden_yellow 39.8 s; the other diffuse materials, both
layouts fitted, 24-33 s); two runs of all 20 gave the same coefficients, bit for bit, and times
up to 5 s apart. Before: 15-60 s under load, 51-60 s for the diffuse materials (their one-piece
fit refitted once in full when the clock allowed). Relative RMSE on the six materials of the
issue: paper_white 0.0098, colodur_napoli_4f 0.0196, satin_rosaline 0.0555, cc_ibiza_sunset
0.0710, cc_iris_purple_gem 0.0775, vch_golden_yellow 0.0427 (before: 0.0099, 0.0197, 0.0555,
0.0710, 0.0774, 0.0427; docs/fit_accuracy.md has all 20).
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..formats.angles import cosine_directions, half_diff_to_directions
from ..progress import report
from .albedo3d import albedo_policy
from .ceiling import DEFAULT_TIME_LIMIT, Ceiling
from .fitter import IntervalRationalFitter
from .model import PiecewiseRationalModel, RationalModel, Variable
from .refine import refine
from .samples3d import (
    DEFAULT_GRID,
    DEFAULT_NOISE_FRAC,
    DEFAULT_RANDOM,
    DEFAULT_THETA_FIT_DEG,
    grazing_weight,
    noise_levels,
    objective_points,
    sample_grid,
    sample_rgl,
)
from .secant import log_intervals, secant_weights
from .settings import (
    DEFAULT_ALBEDO_REFITS,
    DEFAULT_ALBEDO_RMSE_GROWTH,
    DEFAULT_ALBEDO_TIME,
    DEFAULT_ALBEDO_TOL,
    DEFAULT_ALBEDO_TOTAL_GROWTH,
    DEFAULT_CHANNEL_FLOOR,
    DEFAULT_DEGREES,
    DEFAULT_GRAZING_COS,
    DEFAULT_LADDER_STEPS,
    DEFAULT_OBJECTIVE,
    DEFAULT_RELAX,
    DEFAULT_VERIFY,
    Fit3DSettings,
)

__all__ = [
    "DEFAULT_ALBEDO_REFITS", "DEFAULT_ALBEDO_RMSE_GROWTH", "DEFAULT_ALBEDO_TIME", "DEFAULT_ALBEDO_TOL",
    "DEFAULT_ALBEDO_TOTAL_GROWTH", "DEFAULT_CHANNEL_FLOOR", "DEFAULT_DEGREES", "DEFAULT_GRAZING_COS",
    "DEFAULT_GRID", "DEFAULT_LADDER_STEPS", "DEFAULT_NOISE_FRAC", "DEFAULT_OBJECTIVE", "DEFAULT_RANDOM",
    "DEFAULT_RELAX", "DEFAULT_THETA_FIT_DEG", "DEFAULT_TIME_LIMIT", "DEFAULT_VERIFY", "INTERVALS", "SELECT_MARGIN",
    "VARIANTS", "Ceiling", "Fit3D", "Fit3DSettings", "FitData3D", "domain_record", "fit_rgl", "fit_rgl_select",
    "fit_samples", "grazing_weight", "noise_levels", "objective_points", "sample_grid", "sample_rgl",
    "validation_rmse", "verification_ratio", "verify_and_refit",
]

INTERVALS = ("rho_c +- tolerance * max(rho_c, noise_c, channel_floor * max(rho_R, rho_G, rho_B)) "
             "* max(1, grazing_cos / (cos theta_i cos theta_o))")


@dataclass
class FitData3D:
    """What a refit of a fit made by :func:`fit_rgl` needs (:func:`verify_and_refit`, the albedo
    policy of :mod:`fit.rational.albedo3d`): the data ``X`` ``(N, 3)`` (radians) and ``rho``
    ``(N, 3)`` (1/sr), ``theta_max`` (radians), the ``source`` record, the second stage's
    ``objective`` (``(Xo, rho_o, w)`` or None), the model's ``name`` and the ``progress``
    callback."""

    X: np.ndarray
    rho: np.ndarray
    theta_max: float
    source: dict
    objective: tuple | None = None
    name: str = "brdf3d"
    progress: object = None


@dataclass
class Fit3D:
    """A 3-D fit: ``model`` (evaluate with :func:`fit.rational.variables3d.evaluate_directions`),
    ``records`` (per piece and channel: degrees, stated tolerance, LP rounds, seconds),
    ``tolerance`` (the largest stated tolerance: every data point is within it), ``time_s``;
    ``settings`` (:class:`fit.rational.settings.Fit3DSettings`), ``data`` (:class:`FitData3D`)
    and ``verify_points`` hold what made it and what a refit needs."""

    model: object
    records: list
    tolerance: float
    valid: bool
    time_s: float
    n_points: int
    noise: tuple
    info: dict = field(default_factory=dict)
    settings: Fit3DSettings | None = None          # the settings that made it
    data: FitData3D | None = None                  # what a refit needs (fit_rgl); None after fit_rgl_select
    verify_points: tuple | None = None             # (X, rho) of the last verification's fresh points

    @property
    def n_coefficients(self) -> int:
        return int(self.model.n_coefficients)

    def summary(self) -> str:
        return (f"3-D fit {self.model.name}: {self.n_coefficients} coefficients, bound "
                f"{100 * self.tolerance:.3g} % of max(rho, noise) at {self.n_points} points, "
                f"{'valid' if self.valid else 'NOT valid'}, {self.time_s:.1f} s")


def _variables(box) -> list:
    (h0, h1), (d0, d1), (p0, p1) = box
    return [Variable("theta_h", "rad", "sqrt", (h0, h1)), Variable("theta_d", "rad", "identity", (d0, d1)),
            Variable("phi_d", "rad", "identity", (p0, p1))]


class _TolFitter(IntervalRationalFitter):
    """The interval fitter at fixed degrees, answering one question per tolerance: is there a
    fit within these intervals (constraint generation, fast rejection on a subset), and if so
    the certified function."""

    def try_fit(self, U, lower, upper, degrees):
        t0 = time.perf_counter()
        self._prepare(U, None, lower, upper)
        m, n = degrees
        att = self._fit_pair(m, n)
        if not att.feasible:
            return None
        att = self._make_certified(att)
        if not att.feasible:
            return None
        return self._finish(att, [(m, n, True, self._ncoef(m, n))], t0)


def _fit_channel(U, y, scale, offset, domain, tol, degrees, ladder_steps=DEFAULT_LADDER_STEPS, step=1.6,
                 max_tol=64.0, objective=None, relax=1.0, start=None, ceiling=None):
    """One channel of one piece: ``(RationalFunction, record)``; ``U`` transformed inputs, ``y``
    the values, ``scale`` the per-point error unit (``max(rho, noise) * g``, module docstring).

    Tolerances ``start, start * step, ...`` (``start`` >= ``tol``, default ``tol``; e.g. a step
    below another channel's result) are tried until one is met (the LP is exact only for
    feasibility: a least-violation LP solution can hide large errors where Q is small); when the
    first is met and above ``tol``, one step down is tried. After ``ladder_steps`` infeasible
    tolerances (a count: the same ladder on any machine) the step is squared at every further
    one (larger steps to any feasible level; also when the fit's safety :class:`Ceiling` is
    passed). One-stage fits (no ``objective``) then take one geometric bisection step (not when
    the ceiling is passed). Two-stage fits solve the second
    stage (:func:`fit.rational.refine.refine`) within ``relax`` times the tolerance met. The
    stated tolerance is the error measured at every point afterwards (at most the tolerance met,
    times ``relax`` for a two-stage fit)."""
    t0 = time.perf_counter()
    fitter = _TolFitter(domain=domain, max_iter=40, q_grid=7)
    tried, res, t_ok, t_bad = [], None, None, None
    two_stage = objective is not None and relax > 1.0
    t = max(float(tol), float(start or tol))
    n_bad = 0
    while t <= max_tol:
        r = fitter.try_fit(U, *log_intervals(y, scale, offset, t), degrees)
        tried.append([t, r is not None])
        if r is not None:
            res, t_ok = r, t
            break
        t_bad = t
        n_bad += 1
        t *= step
        if n_bad >= ladder_steps or (ceiling is not None and ceiling.out("tolerance ladder")):
            step = step * step      # out of budget: larger steps to any feasible level
    if res is None:
        raise RuntimeError(f"no fit within {max_tol:g} x the error unit at degrees {degrees}")
    if t_bad is None and t_ok > tol * (1 + 1e-9):      # started above tol and met at once: one step down
        t = max(t_ok / step, float(tol))
        r = fitter.try_fit(U, *log_intervals(y, scale, offset, t), degrees)
        tried.append([t, r is not None])
        if r is not None:
            res, t_ok = r, t
        else:
            t_bad = t
    if not two_stage and t_bad is not None and not (ceiling is not None and ceiling.out("bisection")):
        t = float(np.sqrt(t_ok * t_bad))
        r = fitter.try_fit(U, *log_intervals(y, scale, offset, t), degrees)
        tried.append([t, r is not None])
        if r is not None:
            res, t_ok = r, t
    f = res.function
    cert = res.certificate
    minimax = float(np.max(np.abs(np.maximum(np.exp(f(U)) - offset, 0.0) - y) / scale))
    stage = {"kind": "minimax"}
    if two_stage:
        # second stage: the smallest weighted squared error of the value within relax * t_ok
        Uo, yo, wo = objective
        to = np.log(yo + offset)
        f2, info = refine(f, U, *log_intervals(y, scale, offset, relax * t_ok), Uo, to, wo * (yo + offset) ** 2,
                          reweight=secant_weights(wo))
        stage = {"kind": "two-stage", "relax": float(relax), "minimax_tolerance": minimax, "minimax_met": t_ok,
                 "objective_points": len(yo), "qp_solves": int(info.get("qp", 0))}
        if f2 is not None:
            f, cert = f2, info["certificate"]
            t_ok = relax * t_ok
        else:
            stage["kind"] = "minimax"
            stage["second_stage_failed"] = str(info.get("reason"))
    fit = np.maximum(np.exp(f(U)) - offset, 0.0)
    err = np.abs(fit - y) / scale
    stated = float(np.max(err))
    rec = {"degrees": [int(res.num_degree), int(res.den_degree)], "n_coefficients": int(f.n_coefficients),
           "stage": stage,
           "tolerance": stated, "tolerance_met": t_ok, "tolerances_tried": tried,
           "max_rel_error": stated, "rms_rel_error": float(np.sqrt(np.mean(err ** 2))),
           "n_points": len(y), "n_constraints": int(res.n_constraints), "n_lp": int(res.n_lp),
           "time_s": time.perf_counter() - t0, "feasible": True,
           "valid": bool(cert.certified and stated <= t_ok * (1 + 1e-9)),
           "q_certificate": {"certified": bool(cert.certified), "lower_bound": float(cert.lower_bound),
                             "method": "Bernstein coefficients, exact subdivision"},
           "intervals": INTERVALS,
           "measured_range": [float(y.min()), float(y.max())],
           "vouched_range": [float(np.maximum(y - stated * scale, 0.0).min()), float((y + stated * scale).max())]}
    return f, rec


def _kept_channel(f, old, U, y, scale, offset):
    """A function kept by a refit (:func:`fit_samples`'s ``keep``) and its record measured again on
    the refit's data (stated tolerance, errors, ranges; valid where Q > 0 was certified and every
    point is within the tolerance it met)."""
    fit = np.maximum(np.exp(f(U)) - offset, 0.0)
    err = np.abs(fit - y) / scale
    stated = float(np.max(err))
    t_ok = float(old["tolerance_met"])
    rec = dict(old, tolerance=stated, max_rel_error=stated, rms_rel_error=float(np.sqrt(np.mean(err ** 2))),
               n_points=len(y), time_s=0.0, kept=True,
               valid=bool(old["q_certificate"]["certified"] and stated <= t_ok * (1 + 1e-9)),
               measured_range=[float(y.min()), float(y.max())],
               vouched_range=[float(np.maximum(y - stated * scale, 0.0).min()), float((y + stated * scale).max())])
    for key in ("piece", "channel", "noise"):
        rec.pop(key, None)
    return f, rec


def fit_samples(X, rho, *, settings: Fit3DSettings | None = None, name="brdf3d", theta_max=None, source=None,
                objective=None, ceiling=None, noise=None, keep=None, progress=None, **params) -> Fit3D:
    """3-D fit of data ``X`` ``(N, 3)`` (theta_h, theta_d, |phi_d|, radians) with values ``rho``
    ``(N, 3)`` (1/sr) with ``settings`` (:class:`fit.rational.settings.Fit3DSettings`, default
    its defaults; each of its names is also a keyword argument that overrides it): pieces along theta_h at ``theta_h_edges`` (inner edges), each channel a
    rational function of total degrees ``degrees`` (or ``piece_degrees[k]``) aiming at ``tol``
    (module docstring: the stated bound is what is met). ``ladder_steps``: the tolerance ladder's
    budget (:func:`_fit_channel`). ``time_limit`` (s): the wall-clock safety net only (a
    :class:`Ceiling`; ``ceiling`` shares one with a caller), recorded as ``stopped`` in
    ``fit_info`` when it is passed. ``objective`` = ``(Xo (M, 3), rho_o (M, 3), w (M,))`` (:func:`objective_points`
    and the values there) turns on the second stage within ``relax`` times the tolerance met
    (module docstring); without it (or ``relax <= 1``) the fit is the minimax one. ``noise``:
    the noise levels (default :func:`noise_levels` of ``rho``); ``keep`` (a refit of
    :func:`verify_and_refit`, with the earlier fit's ``noise``): ``{(piece, channel): (function,
    record)}`` of functions kept as they are (their records measured again on this data; one that
    is no longer within the tolerance it met, or not certified, is fitted again), the others
    fitted with their tolerance ladder started one step below the earlier record's
    ``minimax_met``. ``progress(stage, done, total)`` (:mod:`fit.progress`) is told the
    functions (piece x channel) done: stage ``"3-D fit"`` (``"3-D refit"`` with ``keep``)."""
    s = Fit3DSettings.resolve(settings, **params)
    tol, degrees, theta_h_edges, piece_degrees = s.tol, s.degrees, s.theta_h_edges, s.piece_degrees
    noise_frac, grazing_cos, channel_floor = s.noise_frac, s.grazing_cos, s.channel_floor
    relax, ladder_steps = s.relax, s.ladder_steps
    t0 = time.perf_counter()
    if ceiling is None:
        ceiling = Ceiling(s.time_limit)
    X = np.asarray(X, np.float64)
    rho = np.maximum(np.asarray(rho, np.float64), 0.0)
    tm = float(theta_max if theta_max is not None else max(X[:, 0].max(), X[:, 1].max()))
    noise = noise_levels(rho, noise_frac) if noise is None else np.asarray(noise, np.float64)
    keep = keep or {}
    g = grazing_weight(X, grazing_cos)
    offset = float(noise.min())
    edges = [0.0] + sorted(float(e) for e in (theta_h_edges or [])) + [tm]
    pieces, piece_info, records = [], [], []
    n_pieces = len(edges) - 1
    stage = "3-D refit" if keep else "3-D fit"
    report(progress, stage, 0, 3 * n_pieces)
    for k in range(n_pieces):
        a, b = edges[k], edges[k + 1]
        sel = (X[:, 0] >= a - 1e-12) & (X[:, 0] <= b + 1e-12)
        box = [(a, b), (0.0, tm), (0.0, np.pi)]
        variables = _variables(box)
        U = np.stack([np.sqrt(X[sel, 0]), X[sel, 1], X[sel, 2]], axis=1)
        domain = np.array([v.rf_domain for v in variables])
        deg = tuple(piece_degrees[k]) if piece_degrees else tuple(degrees)
        obj = None
        if objective is not None:
            Xo, ro, wo = objective
            so = (Xo[:, 0] >= a - 1e-12) & (Xo[:, 0] <= b + 1e-12) & (wo > 0)
            Uo = np.stack([np.sqrt(Xo[so, 0]), Xo[so, 1], Xo[so, 2]], axis=1)
        funcs, infos = [], []
        for c in range(3):
            scale = np.maximum(np.maximum(rho[sel, c], noise[c]), channel_floor * rho[sel].max(axis=1)) * g[sel]
            if objective is not None:
                obj = (Uo, np.maximum(ro[so, c], 0.0), wo[so])
            start = min(r["stage"].get("minimax_met", r["tolerance_met"]) for r in infos) / 1.6 if infos else None
            f = None
            if (k, c) in keep and keep[(k, c)][0] is not None:
                f, rec = _kept_channel(*keep[(k, c)], U, rho[sel, c], scale, offset)
                if not rec["valid"]:        # outside the tolerance it met at a new point: fitted again
                    f = None
            if f is None:
                if (k, c) in keep:      # refitted: its ladder starts one step below the tolerance it met before
                    old = keep[(k, c)][1]
                    start = old["stage"].get("minimax_met", old["tolerance_met"]) / 1.6
                f, rec = _fit_channel(U, rho[sel, c], scale, offset, domain, tol, deg, ladder_steps, objective=obj,
                                      relax=relax, start=start, ceiling=ceiling)
            rec["noise"] = float(noise[c])
            funcs.append(f)
            infos.append(rec)
            records.append(dict(rec, piece=k, channel="RGB"[c]))
            report(progress, stage, 3 * k + c + 1, 3 * n_pieces)
        vmax = float(2.0 * rho[sel].max() + 1.0)
        pieces.append(RationalModel(name=name, variables=variables, functions=funcs, value_transform="log",
                                    value_offset=offset, value_min=0.0, value_max=vmax, function_info=infos))
        piece_info.append({"theta_h_range_deg": [float(np.degrees(a)), float(np.degrees(b))],
                           "intervals": INTERVALS, "guaranteed": all(
                               i["valid"] for i in infos), "n_points": int(sel.sum())})
    tol_all = max(r["tolerance"] for r in records)
    valid = all(r["valid"] for r in records)
    elapsed = time.perf_counter() - t0
    fit_info = {"kind": "3d", "tolerance": tol_all, "tolerance_kind": INTERVALS, "grazing_cos": grazing_cos,
                "channel_floor": channel_floor,
                "start_tolerance": tol, "noise": noise.tolist(), "noise_frac": noise_frac,
                "theta_max_deg": float(np.degrees(tm)), "n_points": len(X), "time_s": elapsed,
                "fitter": "fit.rational.fit3d (interval LP, constraint generation, fixed degrees)",
                "theta_h_edges": edges[1:-1], "valid": valid, "ladder_steps": int(ladder_steps),
                "guarantee": "every data point (theta_i, theta_o <= theta_max: the whole measured domain and the "
                             "file's own extrapolation beyond its last incidence up to theta_max) "
                             f"within {INTERVALS}; Q > 0 certified on every piece"}
    ceiling.record(fit_info)
    src = source or {"file": "", "sha256": ""}
    if n_pieces == 1:
        model = pieces[0]
        model.fit_info, model.source = fit_info, src
    else:
        model = PiecewiseRationalModel(name=name, variables=_variables([(0.0, tm), (0.0, tm), (0.0, np.pi)]),
                                       split_variable="theta_h", edges=edges, pieces=pieces,
                                       fit_info=fit_info, piece_info=piece_info, source=src)
    return Fit3D(model, records, tol_all, valid, elapsed, len(X), tuple(noise.tolist()),
                 {"edges": edges}, settings=s)


def verification_ratio(res, X, rho, per_channel: bool = False) -> np.ndarray:
    """Per point of ``X`` ``(N, 3)`` with values ``rho`` ``(N, 3)``: the largest over R, G, B of
    ``|fit - rho| / (s * tol_piece_channel)`` (``s`` the error unit of :func:`fit_samples` with the
    fit's noise levels and policies, ``tol`` the stated tolerance of the piece and channel that
    evaluates the point); <= 1 where the fit is within its stated bound. ``per_channel``: the
    ``(N, 3)`` ratios of R, G, B instead of their largest."""
    fi = res.model.fit_info
    noise = np.asarray(res.noise)
    g = grazing_weight(X, float(fi.get("grazing_cos", DEFAULT_GRAZING_COS)))
    s = np.maximum(np.maximum(rho, noise[None, :]), float(fi.get("channel_floor", DEFAULT_CHANNEL_FLOOR))
                   * rho.max(axis=1, keepdims=True)) * g[:, None]
    edges = res.info["edges"]
    k = np.searchsorted(np.asarray(edges[1:-1]), np.clip(X[:, 0], edges[0], edges[-1]), side="left")
    tol = np.zeros((len(edges) - 1, 3))
    for r in res.records:
        tol[r["piece"], "RGB".index(r["channel"])] = r["tolerance"]
    err = np.abs(res.model(X) - rho) / s
    ratio = err / np.maximum(tol[k], 1e-12)
    return ratio if per_channel else np.max(ratio, axis=1)


def fit_rgl(brdf, *, settings: Fit3DSettings | None = None, name=None, ceiling=None, progress=None,
            **params) -> Fit3D:
    """:func:`fit_samples` of an :class:`fit.formats.rgl.RGLBRDF` sampled by :func:`sample_rgl`
    (the sampling time counts in ``time_s``) with ``settings``
    (:class:`fit.rational.settings.Fit3DSettings`, default its defaults; each of its names is
    also a keyword argument that overrides it; ``name`` default ``"<material>_3d"``), then **verified between the data points**: the fit
    is evaluated at ``verify`` fresh points (half uniform in the variables, half cosine-distributed
    pairs, new seed each round) and, where it leaves its stated bound there, the worst of them join
    the data and it is fitted again (at most ``verify_rounds`` refits: constraint generation over
    the sampled domain). Without it, a fit of satin_purple within 21 % at its 19,000 points reached
    94 /sr against 0.4 in a spike between them (relative RMSE 1.35 on the benchmark's pairs).
    ``fit_info`` records the last verification (``verify_points``, ``verify_max_ratio``: the
    largest error over the stated bound there, ``verified``: <= 1). ``n_objective`` objective
    points per piece (:func:`objective_points`, evaluated on the RGL reference) drive the second
    stage (``relax``, default 2; ``n_objective=0`` or ``relax=1``: one stage).
    ``albedo`` (default on): the directional-albedo policy last (:func:`_albedo_step`,
    :mod:`fit.rational.albedo3d`: measured at 0-75 deg and the last incidence, corrected where
    outside ``albedo_tol`` with at most ``albedo_refits`` channel corrections at a cost of at most
    ``albedo_rmse_growth`` of a channel's relative RMSE and ``albedo_total_growth`` of the fit's, what stays outside recorded in
    ``fit_info["albedo"]``). Every step stops on a count (module docstring, "Budgets");
    ``time_limit`` (default :data:`DEFAULT_TIME_LIMIT` = 120 s) is only the
    wall-clock safety net of the whole fit (``albedo_time``: an extra one of the albedo step),
    recorded as ``fit_info["stopped"] = "time"`` when it is passed. ``progress(stage, done,
    total)`` (:mod:`fit.progress`): stages ``"sampling the file"``, ``"3-D
    fit"`` (functions done), ``"verification"`` (rounds), ``"3-D refit"``, ``"albedo
    policy"``."""
    s = Fit3DSettings.resolve(settings, **params)
    t0 = time.perf_counter()
    if ceiling is None:
        ceiling = Ceiling(s.time_limit)
    report(progress, "sampling the file", 0, 1)
    X, rho, tm = sample_rgl(brdf, s.grid, s.n_random, s.theta_fit_deg)
    report(progress, "sampling the file", 1, 1)
    src = {"file": str(getattr(brdf, "source", "") or ""), "sha256": str(getattr(brdf, "source_sha256", "") or "")}
    name = name or f"{brdf.name}_3d"
    objective = None
    if s.n_objective and s.relax > 1.0:
        edges = [0.0] + sorted(float(e) for e in (s.theta_h_edges or [])) + [tm]
        Xo, wo = objective_points(tm, edges, s.n_objective)
        wi, wo_dir = half_diff_to_directions(Xo[:, 0], 0.0, Xo[:, 1], Xo[:, 2])
        ro = np.maximum(np.asarray(brdf.evaluate(wi, wo_dir), np.float64), 0.0)
        objective = (Xo, ro, wo)
    res = fit_samples(X, rho, settings=s, name=name, theta_max=tm, source=src, objective=objective,
                      ceiling=ceiling, progress=progress)
    res.data = FitData3D(X, rho, tm, src, objective, name, progress)
    res = verify_and_refit(brdf, res, s.verify, s.verify_rounds, ceiling=ceiling, refit_above=s.verify_above)
    if s.albedo:
        report(progress, "albedo policy", 0, 1)
        _albedo_step(brdf, res, s.albedo_tol, s.albedo_time, s.verify, s.albedo_rmse_growth, ceiling=ceiling,
                     refits=s.albedo_refits, total_growth=s.albedo_total_growth)
        report(progress, "albedo policy", 1, 1)
    ceiling.record(res.model.fit_info)
    domain_record(res.model.fit_info)
    res.time_s = time.perf_counter() - t0
    res.model.fit_info["time_s"] = res.time_s
    res.model.fit_info["grid"] = list(s.grid)
    res.model.fit_info["theta_measured_deg"] = float(np.degrees(brdf.theta_i_max))
    return res


def _albedo_step(brdf, res, albedo_tol: float, albedo_time, verify: int,
                 rmse_growth: float = DEFAULT_ALBEDO_RMSE_GROWTH, ceiling=None,
                 refits: int = DEFAULT_ALBEDO_REFITS, total_growth: float = DEFAULT_ALBEDO_TOTAL_GROWTH) -> None:
    """The albedo policy (:func:`fit.rational.albedo3d.albedo_policy`) on a fit of
    :func:`fit_rgl`; where it changed a function after the verification, the verification's
    largest ratio is measured again on the last round's fresh points (no refit; the points and
    their reference values as :func:`verify_and_refit` kept them), so that ``verify_max_ratio``
    describes the fit that is returned (``verify_after_albedo``)."""
    res.info["model_before_albedo"] = copy.deepcopy(res.model)
    rec = albedo_policy(brdf, res, tol=albedo_tol, time_limit=albedo_time, rmse_growth=rmse_growth,
                        total_growth=total_growth, max_refits=refits, ceiling=ceiling)
    if rec["refitted"] and verify and res.verify_points is not None:
        Xv, rv = res.verify_points
        ratio_max = float(verification_ratio(res, Xv, rv).max())
        res.model.fit_info.update(verify_max_ratio=ratio_max, verified=bool(ratio_max <= 1.0),
                                  verify_after_albedo=True)
        res.info.update(verify_max_ratio=ratio_max, verified=bool(ratio_max <= 1.0))


def verify_and_refit(brdf, res, verify: int = DEFAULT_VERIFY, verify_rounds: int = 2, time_limit=None,
                     ceiling=None, refit_all: bool = False, refit_above: float = 1.0, progress=None):
    """The verification of :func:`fit_rgl` on a fit made by it (its data in ``res.data``):
    returns the fit after at most ``verify_rounds`` refits (the budget: a count). A refit adds
    the worst (at most 2,000) fresh points more than ``refit_above`` times outside the stated
    bound (1: any; 4: spikes only) to the data and fits again only the functions (piece,
    channel) that are outside their bound at one of them (the others
    are kept, their records measured again on the enlarged data; ``refit_all``: every function),
    with the noise levels of the first fit; ``fit_info["verify_refitted"]`` lists them per round.
    ``time_limit`` (s; None: none) or a caller's ``ceiling`` (:class:`Ceiling`) is only the
    wall-clock safety net: once passed, no further refit is started (``fit_info["stopped"]``).
    ``progress(stage, done, total)`` (default: the fit's own, ``res.data.progress``;
    :mod:`fit.progress`): stage ``"verification"``, the rounds done."""
    t0 = time.perf_counter()
    if ceiling is None:
        ceiling = Ceiling(time_limit)
    data = res.data
    X, rho, tm = data.X, data.rho, data.theta_max
    progress = progress if progress is not None else data.progress
    ratio_max, n_added, refitted = None, 0, []
    n_rounds = verify_rounds + 1 if verify else 0
    for rnd in range(n_rounds):
        report(progress, "verification", rnd, n_rounds)
        Xv = sample_grid(tm, (1, 1, 1), verify // 2, seed=1000 + rnd)
        wi, wo = half_diff_to_directions(Xv[:, 0], 0.0, Xv[:, 1], Xv[:, 2])
        rv = np.maximum(np.asarray(brdf.evaluate(wi, wo), np.float64), 0.0)
        ratio_c = verification_ratio(res, Xv, rv, per_channel=True)
        ratio = np.max(ratio_c, axis=1)
        ratio_max = float(ratio.max())
        res.info["verify_round"] = rnd
        res.verify_points = (Xv, rv)    # the fresh points the returned fit was checked at
        bad = np.flatnonzero(ratio > refit_above)
        if len(bad) == 0 or rnd == verify_rounds or ceiling.out("verification"):
            break
        worst = bad[np.argsort(-ratio[bad])[:2000]]
        X, rho = np.concatenate([X, Xv[worst]]), np.concatenate([rho, rv[worst]])
        n_added += len(worst)
        edges = res.info["edges"]
        pieces = list(res.model.pieces) if hasattr(res.model, "pieces") else [res.model]
        redo = set()
        for k in range(len(edges) - 1):
            inside = (Xv[worst, 0] >= edges[k] - 1e-12) & (Xv[worst, 0] <= edges[k + 1] + 1e-12)
            for c in range(3):
                if refit_all or np.any(ratio_c[worst[inside], c] > 1.0):
                    redo.add((k, c))
        keep = {(r["piece"], "RGB".index(r["channel"])): (None, r) for r in res.records}
        for (k, c), (_, r) in keep.items():
            if (k, c) not in redo:
                keep[(k, c)] = (pieces[k].functions[c], r)
        refitted.append([f"{k}{'RGB'[c]}" for k, c in sorted(redo)])
        res = fit_samples(X, rho, settings=res.settings, name=data.name, theta_max=tm, source=data.source,
                          objective=data.objective, ceiling=ceiling, noise=res.noise, keep=keep,
                          progress=data.progress)
        data = replace(data, X=X, rho=rho)
        res.data = data
    if ratio_max is not None:
        res.model.fit_info.update(verify_points=int(verify // 2 * 2), verify_max_ratio=ratio_max,
                                  verified=bool(ratio_max <= 1.0), verify_points_added=n_added)
        res.info.update(verify_max_ratio=ratio_max, verified=bool(ratio_max <= 1.0), verify_points_added=n_added)
    res.model.fit_info.update(verify_rounds=int(verify_rounds), verify_refit_above=float(refit_above),
                              verify_refitted=refitted)
    ceiling.record(res.model.fit_info)
    res.info["verify_s"] = time.perf_counter() - t0
    return res



#: The layouts :func:`fit_rgl_select` tries by default (fit_rgl keyword arguments), in order:
#: four theta_h pieces (the peak, two for the lobe's shoulder, the rest; 666 coefficients), then
#: one piece of degrees (7, 3) (420: the diffuse materials, whose error is spread over the whole
#: domain; paper_white 0.0098 against 0.020 with the four pieces, both two-stage, 50,000 pairs).
#: ``"if_rmse_below"`` (not a fit_rgl argument): the layout is tried only when the best validation
#: RMSE so far is below it, which spares the glossiest materials a 20-26 s fit they would not
#: keep. ``"verify_rounds"``, ``"verify_above"``: the layout's own verification budget when it is
#: chosen (module docstring, "Budgets": one refit, for spikes only).
#: Measured (validation RMSE of the four pieces -> relative RMSE, four pieces / one piece): it won
#: on 6 of the 7 materials below 0.04 (paper_white 0.0196 -> 0.0097; vch_ultra_pink 0.0317 ->
#: 0.0327 kept the four pieces) and on ilm_l3_37_matte (0.062: 0.050 / 0.040) and
#: acrylic_felt_pink (0.042: 0.041 / 0.032); it lost on satin_purple (0.0545: 0.051 / 0.067) and
#: satin_rosaline (0.063: 0.063 / 0.085); the glossy films above 0.065 (cc_ibiza_sunset,
#: cc_iris_purple_gem, cm_toxic_green, chm_mint) do not try it.
VARIANTS = (
    {"theta_h_edges": [0.05, 0.1, 0.2], "piece_degrees": [(4, 2), (5, 2), (5, 2), (4, 2)]},
    {"theta_h_edges": [], "degrees": (7, 3), "if_rmse_below": 0.065, "verify_rounds": 1, "verify_above": 4.0},
)
#: A later layout replaces the one chosen so far only when its validation RMSE is lower by this
#: fraction: vch_golden_yellow's one piece (0.0439 against 0.0441) was chosen without it, and
#: it was 0.045 against 0.043 on the benchmark's pairs and 52.6 against 9.2 times its bound at
#: the fresh points (a spike between the data points); every other switch was by more than 20 %.
SELECT_MARGIN = 0.05
#: Settings of the selection itself (its budgets, verification and albedo policy), not of a
#: layout's fit: not listed in the layouts' ``"options"`` log.
_SELECT_SETTINGS = frozenset({"time_limit", "select_share", "verify", "verify_rounds", "verify_above", "albedo",
                              "albedo_tol", "albedo_time", "albedo_rmse_growth", "albedo_total_growth",
                              "albedo_refits", "max_variants"})


def validation_rmse(brdf, model, n: int = 20000, seed: int = 12345) -> float:
    """Relative RMSE of ``rho cos(theta_i) cos(theta_o)`` (mean over R, G, B) of a 3-D ``model``
    against the RGL reference on ``n`` pairs of cosine-distributed directions (``seed``: not the
    benchmark's): the selection criterion of :func:`fit_rgl_select`."""
    from .variables3d import evaluate_directions

    rng = np.random.default_rng(seed)
    wi, wo = cosine_directions(rng, n), cosine_directions(rng, n)
    c = (wi[:, 2] * wo[:, 2])[:, None]
    t = np.maximum(np.asarray(brdf.evaluate(wi, wo), np.float64), 0.0) * c
    f = evaluate_directions(model, wi, wo) * c
    return float(np.mean(np.sqrt(np.mean((f - t) ** 2, axis=0)) / np.maximum(np.sqrt(np.mean(t ** 2, axis=0)), 1e-300)))


def fit_rgl_select(brdf, variants=VARIANTS, *, settings: Fit3DSettings | None = None, progress=None,
                   **params) -> Fit3D:
    """Fit every layout of ``variants`` (each a dict of settings that replace those of
    ``settings``, :class:`fit.rational.settings.Fit3DSettings`, default its defaults, whose
    names are also keyword arguments that override it) with :func:`fit_rgl` and return the one with the lowest :func:`validation_rmse` (a later layout must
    be :data:`SELECT_MARGIN` lower to replace an earlier one; a layout with ``"if_rmse_below"`` is
    tried only below that RMSE); ``info["variants"]`` logs what each achieved (coefficients,
    stated bound, validation RMSE, seconds). The budgets are counts (module docstring,
    "Budgets"): at most ``max_variants`` layouts are fitted (None: all; later ones are logged as
    skipped, "budget"); the chosen fit is then verified with at most ``verify_rounds`` refits
    (:func:`verify_and_refit`; a layout's own ``"verify_rounds"`` entry overrides it) and the
    albedo policy applied last with at most ``albedo_refits`` channel corrections (``albedo``, as in :func:`fit_rgl`).
    ``time_limit`` (s; default 120; None: none) is only the wall-clock safety net of the whole
    selection: past ``select_share`` of it no further layout is started (logged as skipped,
    "time"), past it no refit and no albedo round; ``fit_info["stopped"] = "time"`` and
    ``stopped_at`` record it. ``time_s`` is the whole selection. ``progress(stage, done,
    total)`` (:mod:`fit.progress`): each layout's stages as in :func:`fit_rgl`, then the chosen
    one's ``"verification"`` and ``"albedo policy"``."""
    s = Fit3DSettings.resolve(settings, **params)
    t0 = time.perf_counter()
    ceiling = Ceiling(s.time_limit)
    common = {k: v for k, v in s.changed_params().items() if k not in _SELECT_SETTINGS}
    best, chosen, log = None, None, []
    for k, v in enumerate(variants):
        v = dict(v)
        below = v.pop("if_rmse_below", None)
        rounds = v.pop("verify_rounds", s.verify_rounds)
        above = v.pop("verify_above", s.verify_above)
        opts = dict(common, **v)
        if s.max_variants is not None and k >= int(s.max_variants):
            log.append({"variant": k, "options": _plain(opts), "skipped": "budget"})
            continue
        if k and (best is None or ceiling.out("selection", s.select_share)):
            log.append({"variant": k, "options": _plain(opts), "skipped": "time"})
            continue
        if below is not None and best is not None and best.info["validation_rmse"] >= below:
            log.append({"variant": k, "options": _plain(opts), "skipped": f"validation RMSE >= {below:g}"})
            continue
        layout = s.clone(**v, verify_rounds=rounds, verify_above=above)
        res = fit_rgl(brdf, settings=layout.clone(verify=0, albedo=False), ceiling=ceiling, progress=progress)
        v_rmse = validation_rmse(brdf, res.model)
        log.append({"variant": k, "options": _plain(v), "coefficients": res.n_coefficients,
                    "bound": res.tolerance, "valid": res.valid, "validation_rmse": v_rmse, "time_s": res.time_s})
        if res.valid and (best is None or v_rmse < (1.0 - SELECT_MARGIN) * best.info["validation_rmse"]):
            best = res
            best.info["validation_rmse"] = v_rmse
            best.info["variant"] = k
            chosen = layout
    if best is None:
        raise RuntimeError(f"no valid 3-D fit of {brdf.name}")
    info = best.info
    best = verify_and_refit(brdf, best, s.verify, chosen.verify_rounds, ceiling=ceiling,
                            refit_above=chosen.verify_above, progress=progress)
    for key in ("validation_rmse", "variant"):
        best.info[key] = info[key]
    best.info["validation_rmse"] = validation_rmse(brdf, best.model)
    if s.albedo:
        report(progress, "albedo policy", 0, 1)
        _albedo_step(brdf, best, s.albedo_tol, s.albedo_time, s.verify, s.albedo_rmse_growth, ceiling=ceiling,
                     refits=s.albedo_refits, total_growth=s.albedo_total_growth)
        report(progress, "albedo policy", 1, 1)
        v_after = validation_rmse(brdf, best.model) if best.info["albedo"]["refitted"] else best.info["validation_rmse"]
        best.info["albedo"]["validation_rmse_before"] = best.info["validation_rmse"]
        best.info["albedo"]["validation_rmse"] = v_after
        best.info["validation_rmse"] = v_after
    best.info["variants"] = log
    best.time_s = time.perf_counter() - t0
    best.model.fit_info.update(time_s=best.time_s, variant=best.info["variant"], variants=log,
                               validation_rmse=best.info["validation_rmse"],
                               budgets={"max_variants": s.max_variants, "verify_rounds": int(chosen.verify_rounds),
                                        "albedo_refits": int(s.albedo_refits),
                                        "ladder_steps": int(s.ladder_steps)})
    ceiling.record(best.model.fit_info)
    domain_record(best.model.fit_info)
    best.settings = chosen
    best.data = best.verify_points = None          # the data and fresh points are not kept
    return best


def domain_record(fit_info: dict) -> dict:
    """``fit_info["domain"]``: what the fit guarantees on the whole measured domain (theta_i,
    theta_o <= ``theta_max_deg``), and why not more, from its own record (issue 25 asks for the
    guarantee there "or the reason it cannot be, per material, in the file and the report").

    The bound is *proved* at every data point (an LP certificate of each point, exactly
    re-measured in float64) and Q > 0 on every piece's box (exact Bernstein coefficients); the
    fit is bounded by its ``vouched_range`` everywhere. Between the data points it is only
    *checked*: at ``verify_points`` fresh points, the largest error over the bound is
    ``verify_max_ratio``. A proof there would need bounds on the derivatives of the measurement's
    interpolant and of the fit on every cell; the RGL format's interpolant (bilinear in warped
    coordinates, warps built from the data) has none that is stated, and a Lipschitz bound of the
    fit alone, at a lobe's peak, is orders of magnitude wider than the bound itself. ``proved``
    is therefore False for every fit, and ``reason`` says so with the material's numbers."""
    n = fit_info.get("n_points")
    tm = fit_info.get("theta_max_deg")
    ratio = fit_info.get("verify_max_ratio")
    m = fit_info.get("verify_points")
    if ratio is None:
        checked = "not checked between the data points (no verification)"
    elif ratio <= 1.0:
        checked = (f"checked, not proved, between them: within the bound at all {m} fresh points "
                   f"(largest error {ratio:.3g} x the bound)")
    else:
        checked = (f"not within it between them: at {m} fresh points the largest error is "
                   f"{ratio:.3g} x the bound")
    rec = {"proved": False, "proved_at": "data points", "n_points": n, "theta_max_deg": tm,
           "fresh_points": m, "fresh_max_ratio": ratio,
           "reason": (f"bound proved at the {n} data points (theta_i, theta_o <= {tm:.4g} deg) and Q > 0 "
                      f"on every piece; {checked}. No proof between data points: the measurement's "
                      "interpolant states no derivative bound, and the fit's own, at the peak, is far "
                      "wider than the bound")}
    fit_info["domain"] = rec
    return rec


def _plain(d: dict) -> dict:
    return {k: ([list(x) if isinstance(x, tuple) else x for x in v] if isinstance(v, list)
                else list(v) if isinstance(v, tuple) else v) for k, v in d.items()}
