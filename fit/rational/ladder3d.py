"""The 3-D fit of given samples (:func:`fit_samples`): pieces along theta_h, and per piece and
channel a rational function of ``(sqrt(theta_h), theta_d, |phi_d|)`` at fixed degrees, found by
the tolerance ladder of the interval LP (:func:`_fit_channel`, stage 1, minimax) and then, when
objective points are given, the second stage within ``relax`` times the tolerance met
(:func:`fit.rational.refine.refine`, stage 2, average). The method, its intervals and its
budgets are specified in docs/fitting.md ("The 3-D method").
"""
from __future__ import annotations

import time

import numpy as np

from ..progress import report
from .ceiling import Ceiling
from .fitter import IntervalRationalFitter
from .model import PiecewiseRationalModel, RationalModel, Variable, value_factor_weights, vouched_envelope
from .refine import refine
from .result3d import INTERVALS, Fit3D
from .samples3d import grazing_weight, noise_levels, objective_weights
from .secant import log_intervals, secant_weights
from .settings import DEFAULT_LADDER_STEPS, Fit3DSettings


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
    the values, ``scale`` the per-point error unit (``max(rho, noise) * g``, docs/fitting.md).

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
           "vouched_range": vouched_envelope(y - stated * scale, y + stated * scale)}
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
               vouched_range=vouched_envelope(y - stated * scale, y + stated * scale))
    for key in ("piece", "channel", "noise"):
        rec.pop(key, None)
    return f, rec


def fit_samples(X, rho, *, settings: Fit3DSettings | None = None, name="brdf3d", theta_max=None, source=None,
                objective=None, ceiling=None, noise=None, keep=None, progress=None, **params) -> Fit3D:
    """3-D fit of data ``X`` ``(N, 3)`` (theta_h, theta_d, |phi_d|, radians) with values ``rho``
    ``(N, 3)`` (1/sr; the functions are fitted to ``rho / w``, ``w`` the weight of the setting
    ``value_factor``, :func:`fit.rational.model.value_factor_weights`: ``rho cos theta_i`` by
    default, and the noise levels, error units, ranges and objective are in that unit) with
    ``settings`` (:class:`fit.rational.settings.Fit3DSettings`, default its
    defaults; each of its names is also a keyword argument that overrides it): pieces along theta_h
    at ``theta_h_edges`` (inner edges), each channel a rational function of total degrees
    ``degrees`` (or ``piece_degrees[k]``) aiming at ``tol`` (docs/fitting.md: the stated bound is
    what is met). ``ladder_steps``: the tolerance ladder's budget (:func:`_fit_channel`).
    ``time_limit`` (CPU s) and ``wall_limit`` (s): the safety net only (a
    :class:`fit.rational.ceiling.Ceiling`; ``ceiling`` shares one with a caller), recorded as ``stopped`` in ``fit_info`` when it is
    passed. ``objective`` = ``(Xo (M, 3), rho_o (M, 3), w (M,))``
    (:func:`fit.rational.samples3d.objective_points` and the values there) turns on the second stage
    within ``relax`` times the tolerance met (docs/fitting.md); without it (or ``relax <= 1``) the
    fit is the minimax one. ``noise``: the noise levels (default
    :func:`fit.rational.samples3d.noise_levels` of ``rho``); ``keep`` (a refit of
    :func:`fit.rational.verify3d.verify_and_refit`, with the earlier fit's ``noise``, in the
    functions' unit): ``{(piece, channel): (function, record)}`` of functions kept as they are
    (their records measured again on this data; one that is no longer within the tolerance it
    met, or not certified, is fitted again), the others fitted with their tolerance ladder started
    one step below the earlier record's ``minimax_met``. ``progress(stage, done, total)`` (:mod:`fit.progress`) is told the
    functions (piece x channel) done: stage ``"3-D fit"`` (``"3-D refit"`` with ``keep``)."""
    s = Fit3DSettings.resolve(settings, **params)
    tol, degrees, theta_h_edges, piece_degrees = s.tol, s.degrees, s.theta_h_edges, s.piece_degrees
    noise_frac, grazing_cos, channel_floor = s.noise_frac, s.grazing_cos, s.channel_floor
    relax, ladder_steps = s.relax, s.ladder_steps
    t0 = time.perf_counter()
    if ceiling is None:
        ceiling = Ceiling.of(s)
    X = np.asarray(X, np.float64)
    # step 8's factor (docs/fitting.md, "The light's cosine"): the functions are fitted to
    # rho / fw (rho cos theta_i for "1/cos_theta_i"), and from here on the values, noise levels,
    # error units and the objective are in that unit (fw = 1 without a factor)
    factor = s.value_factor
    fw = value_factor_weights(X, factor)
    rho = np.maximum(np.asarray(rho, np.float64), 0.0) / fw[:, None]
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
            fwo = value_factor_weights(Xo[so], factor)
            yo = np.maximum(ro[so], 0.0) / fwo[:, None]
            floor = np.maximum(noise, s.relative_floor * np.median(rho, axis=0))
            wc = objective_weights(s.objective, Xo[so], wo[so], yo, floor, channel_floor, fw=fwo)   # (M, 3)
        funcs, infos = [], []
        for c in range(3):
            scale = np.maximum(np.maximum(rho[sel, c], noise[c]), channel_floor * rho[sel].max(axis=1)) * g[sel]
            if objective is not None:
                obj = (Uo, yo[:, c], wc[:, c])
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
    # one value range for every piece, the largest piece's (2 x its largest datum + 1): the range the
    # coefficient file holds (one ``value`` record) and the renderer clamps with, so that the
    # verification, the selection, the albedo policy and the image check measure the fit as it is
    # saved. A piece's own lower ceiling hid a later piece's excursion between its data points from
    # them: ilm_solo_m_68's light-fixed albedo at 75 deg was recorded 1.6 % off and is 9.6 % off
    # in the file the fit wrote (docs/fit_accuracy.md, "One value range").
    vmax_all = max(p.value_max for p in pieces)
    for p in pieces:
        p.value_max = vmax_all
    tol_all = max(r["tolerance"] for r in records)
    valid = all(r["valid"] for r in records)
    elapsed = time.perf_counter() - t0
    fit_info = {"kind": "3d", "tolerance": tol_all, "tolerance_kind": INTERVALS, "grazing_cos": grazing_cos,
                "channel_floor": channel_floor, "objective": s.objective if objective is not None else None,
                "relative_floor": s.relative_floor,
                "start_tolerance": tol, "noise": noise.tolist(), "noise_frac": noise_frac,
                "theta_max_deg": float(np.degrees(tm)), "n_points": len(X), "time_s": elapsed,
                "fitter": "fit.rational.fit3d (interval LP, constraint generation, fixed degrees)",
                "theta_h_edges": edges[1:-1], "valid": valid, "ladder_steps": int(ladder_steps),
                "value_factor": factor,
                "guarantee": "every data point (theta_i, theta_o <= theta_max: the whole measured domain and the "
                             "file's own extrapolation beyond its last incidence up to theta_max) "
                             f"within {INTERVALS}; Q > 0 certified on every piece"}
    ceiling.record(fit_info)
    src = source or {"file": "", "sha256": ""}
    if n_pieces == 1:
        model = pieces[0]
        model.fit_info, model.source, model.value_factor = fit_info, src, factor
    else:
        model = PiecewiseRationalModel(name=name, variables=_variables([(0.0, tm), (0.0, tm), (0.0, np.pi)]),
                                       split_variable="theta_h", edges=edges, pieces=pieces,
                                       fit_info=fit_info, piece_info=piece_info, source=src, value_factor=factor)
    return Fit3D(model, records, tol_all, valid, elapsed, len(X), tuple(noise.tolist()), edges=edges,
                 settings=s)


