"""The 3-D fit of an RGL-EPFL measurement (:func:`fit_rgl`): the file sampled
(:func:`fit.rational.samples3d.sample_rgl`), fitted (:func:`fit.rational.ladder3d.fit_samples`,
with the second stage's objective points), verified between the data points
(:func:`fit.rational.verify3d.verify_and_refit`) and, last, the directional-albedo policy
(:mod:`fit.rational.albedo3d`). The method: docs/fitting.md ("The 3-D method").
"""
from __future__ import annotations

import copy
import time

import numpy as np

from ..blas_threads import one_blas_thread
from ..formats.angles import half_diff_to_directions
from ..progress import report
from .albedo3d import albedo_policy
from .ceiling import Ceiling
from .ladder3d import fit_samples
from .proved_bound import record_fit3d
from .result3d import FitData3D, Fit3D, domain_record
from .samples3d import objective_points, sample_rgl
from .settings import DEFAULT_ALBEDO_REFITS, DEFAULT_ALBEDO_RMSE_GROWTH, DEFAULT_ALBEDO_TOTAL_GROWTH, Fit3DSettings
from .verify3d import refit_between_nodes, verification_ratio, verify_and_refit


@one_blas_thread
def fit_rgl(brdf, *, settings: Fit3DSettings | None = None, name=None, ceiling=None, progress=None,
            **params) -> Fit3D:
    """:func:`fit.rational.ladder3d.fit_samples` of an :class:`fit.formats.rgl.RGLBRDF` sampled by
    :func:`fit.rational.samples3d.sample_rgl` (the sampling time counts in ``time_s``) with
    ``settings`` (:class:`fit.rational.settings.Fit3DSettings`, default its defaults; each of its
    names is also a keyword argument that overrides it; ``name`` default ``"<material>_3d"``), then
    **verified between the data points**: the fit is evaluated at ``verify`` fresh points (half
    uniform in the variables, half cosine-distributed pairs, new seed each round) and, where it
    leaves its stated bound there, the worst of them join the data and it is fitted again (at most
    ``verify_rounds`` refits: constraint generation over the sampled domain). Without it, a fit of
    satin_purple within 21 % at its 19,000 points reached 94 /sr against 0.4 in a spike between them
    (relative RMSE 1.35 on the benchmark's pairs). ``fit_info`` records the last verification
    (``verify_points``, ``verify_max_ratio``: the largest error over the stated bound there,
    ``verified``: <= 1). ``n_objective`` objective points per piece
    (:func:`fit.rational.samples3d.objective_points`, evaluated on the RGL reference) drive the
    second stage (``relax``, default 2; ``n_objective=0`` or ``relax=1``: one stage). ``albedo``
    (default on): the directional-albedo policy last (:func:`albedo_step`,
    :mod:`fit.rational.albedo3d`: measured at 0-75 deg and the last incidence, corrected where
    outside ``albedo_tol`` with at most ``albedo_refits`` channel corrections at a cost of at most
    ``albedo_rmse_growth`` of a channel's relative RMSE and ``albedo_total_growth`` of the fit's,
    what stays outside recorded in ``fit_info["albedo"]``; ``albedo``, ``model_before_albedo``).
    Every step stops on a count (docs/fitting.md, "Budgets"); ``time_limit`` (default
    :data:`fit.rational.ceiling.DEFAULT_TIME_LIMIT` = 600 CPU seconds of the process) is only the
    safety net of the whole fit (``albedo_time``: an extra one of the albedo step), and
    ``wall_limit`` (default None) a wall-clock limit a user chose, recorded as
    ``fit_info["stopped"] = "time"`` when either is passed. ``progress(stage, done, total)``
    (:mod:`fit.progress`): stages ``"sampling the file"``, ``"3-D fit"`` (functions done),
    ``"verification"`` (rounds), ``"3-D refit"``, ``"proof-guided refit"`` (rounds), ``"albedo policy"``,
    ``"proving the bound"``.
    Where the proof of the error between the grid nodes finds the fit outside its stated bound
    (spikes narrower than the fresh points see), at most ``proof_rounds`` refits add the worst
    points there (:func:`fit.rational.verify3d.refit_between_nodes`; before the albedo policy).
    ``prove_bound`` (default on): last, the error between the grid nodes of the measurement is
    proved per piece and channel in the unit of the stated tolerance (:func:`fit.rational.proved_bound.record_fit3d`: ``bounds``,
    ``fit_info["bound"]``, and ``fit_info["domain"]`` says what is proved). Every step measures
    the model its coefficient file holds: :func:`~fit.rational.ladder3d.fit_samples` gives every
    piece the file's one value range."""
    s = Fit3DSettings.resolve(settings, **params)
    t0 = time.perf_counter()
    if ceiling is None:
        ceiling = Ceiling.of(s)
    report(progress, "sampling the file", 0, 1)
    X, rho, tm = sample_rgl(brdf, s.grid, s.n_random, s.theta_fit_deg)
    report(progress, "sampling the file", 1, 1)
    src = {"file": str(getattr(brdf, "source", "") or ""), "sha256": str(getattr(brdf, "source_sha256", "") or "")}
    name = name or f"{brdf.name}_3d"
    objective = None
    if s.n_objective and s.relax > 1.0:
        edges = [0.0] + sorted(float(e) for e in (s.theta_h_edges or [])) + [tm]
        Xo, wo = objective_points(tm, edges, s.n_objective, objective=s.objective)
        wi, wo_dir = half_diff_to_directions(Xo[:, 0], 0.0, Xo[:, 1], Xo[:, 2])
        ro = np.maximum(np.asarray(brdf.evaluate(wi, wo_dir), np.float64), 0.0)
        objective = (Xo, ro, wo)
    res = fit_samples(X, rho, settings=s, name=name, theta_max=tm, source=src, objective=objective,
                      ceiling=ceiling, progress=progress)
    res.data = FitData3D(X, rho, tm, src, objective, name, progress)
    res = verify_and_refit(brdf, res, s.verify, s.verify_rounds, ceiling=ceiling, refit_above=s.verify_above)
    memo = {}               # proofs of functions no later step changes are not repeated
    if s.proof_rounds:
        res = refit_between_nodes(brdf, res, s.proof_rounds, s.proof_above, ceiling=ceiling, progress=progress,
                                  memo=memo)
    if s.albedo:
        report(progress, "albedo policy", 0, 1)
        albedo_step(brdf, res, s.albedo_tol, s.albedo_time, s.verify, s.albedo_rmse_growth, ceiling=ceiling,
                     refits=s.albedo_refits, total_growth=s.albedo_total_growth)
        report(progress, "albedo policy", 1, 1)
    ceiling.record(res.model.fit_info)
    prove_step(brdf, res, s.prove_bound, memo, progress)
    res.time_s = time.perf_counter() - t0
    res.model.fit_info["time_s"] = res.time_s
    res.model.fit_info["grid"] = list(s.grid)
    res.model.fit_info["theta_measured_deg"] = float(np.degrees(brdf.theta_i_max))
    return res


def prove_step(brdf, res, prove: bool, memo: dict, progress=None) -> None:
    """The last step of a fit: with ``prove`` (the setting ``prove_bound``), its error between the
    grid nodes proved per piece and channel (:func:`fit.rational.proved_bound.record_fit3d`, the
    proofs in ``memo`` of functions no step changed since reused), then ``fit_info["domain"]``
    (:func:`fit.rational.result3d.domain_record`: what is proved and what is only verified)."""
    if prove:
        report(progress, "proving the bound", 0, 1)
        record_fit3d(res, brdf, memo=memo)
        report(progress, "proving the bound", 1, 1)
    domain_record(res.model.fit_info)


def albedo_step(brdf, res, albedo_tol: float, albedo_time, verify: int,
                 rmse_growth: float = DEFAULT_ALBEDO_RMSE_GROWTH, ceiling=None,
                 refits: int = DEFAULT_ALBEDO_REFITS, total_growth: float = DEFAULT_ALBEDO_TOTAL_GROWTH) -> None:
    """The albedo policy (:func:`fit.rational.albedo3d.albedo_policy`) on a fit of
    :func:`fit_rgl`; where it changed a function after the verification, the verification's
    largest ratio is measured again on the last round's fresh points (no refit; the points and
    their reference values as :func:`verify_and_refit` kept them), so that ``verify_max_ratio``
    describes the fit that is returned (``verify_after_albedo``). ``res.model_before_albedo`` is
    a copy of the model the policy started from."""
    res.model_before_albedo = copy.deepcopy(res.model)
    rec = albedo_policy(brdf, res, tol=albedo_tol, time_limit=albedo_time, rmse_growth=rmse_growth,
                        total_growth=total_growth, max_refits=refits, ceiling=ceiling)
    if rec["refitted"] and verify and res.verify_points is not None:
        Xv, rv = res.verify_points
        ratio_max = float(verification_ratio(res, Xv, rv).max())
        res.model.fit_info.update(verify_max_ratio=ratio_max, verified=bool(ratio_max <= 1.0),
                                  verify_after_albedo=True)
        res.verify_max_ratio, res.verified = ratio_max, bool(ratio_max <= 1.0)
