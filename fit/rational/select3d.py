"""Layout selection of 3-D fits (:func:`fit_rgl_select`): every layout of :data:`VARIANTS` (theta_h
pieces and degrees) fitted by :func:`fit.rational.rgl3d.fit_rgl`, the one with the lowest
held-out error kept (:func:`validation_score`: by the setting ``objective``, the median + 95th
percentile of the relative error, :func:`validation_relative`, or the relative RMSE of ``rho cos
cos``, :func:`validation_rmse`, at validation pairs that are neither data nor objective points),
then verified and given the albedo policy. The method: docs/fitting.md ("The 3-D method").
"""
from __future__ import annotations

import time

import numpy as np

from ..blas_threads import one_blas_thread
from ..formats.angles import cosine_directions
from ..progress import report
from .ceiling import Ceiling
from .image_check import image_check
from .result3d import Fit3D
from .rgl3d import albedo_step, fit_rgl, prove_step
from .settings import Fit3DSettings
from .variables3d import evaluate_directions
from .verify3d import refit_between_nodes, verify_and_refit

#: The theta_h edges (radians) of the pieced layouts: the peak (0.05), the lobe's shoulder (0.1)
#: and, on a doubling ladder, the off-specular body (0.2, 0.4, 0.8), whose values span three decades
#: on the glossy films; the last piece, 0.8 rad to the light's horizon, split once more near its
#: geometric middle (1.15 rad, 66 deg), where light and view are both far from the normal and on
#: the same side: the grazing light of the maps' suns at the terminator. With that edge the
#: selection renders the image target on more of the chart's cases (docs/fit_accuracy.md,
#: "Seven pieces").
PIECE_EDGES = (0.05, 0.1, 0.2, 0.4, 0.8, 1.15)
#: Degrees (numerator, denominator) of the pieces: (4, 2) for the peak, (5, 2) for the others;
#: 3 x (45 + 6 x 66) = 1,323 coefficients.
PIECE_DEGREES = ((4, 2),) + ((5, 2),) * len(PIECE_EDGES)
#: The layouts :func:`fit_rgl_select` tries by default (fit_rgl keyword arguments), in order:
#: the seven theta_h pieces of :data:`PIECE_EDGES`, then one piece of degrees (7, 3) (420) and the
#: seven pieces again, both fitted to the ``"relative"`` objective. With the default
#: ``select_by="image"`` a later one replaces the one kept so far when its image check
#: (:func:`image_score`) is lower by :data:`SELECT_MARGIN`.
#: ``"if_rmse_below"`` (not a fit_rgl argument): the layout is tried only when the best validation
#: RMSE so far is below it, which spares the materials the pieces fit worst a fit they would
#: not keep (of the 20 RGL files with seven pieces: the near-mirror chm_mint, 0.249, and
#: ilm_solo_m_68, 0.067, cc_iris_purple_gem, 0.071, and cm_toxic_green, 0.06505).
#: ``"verify_rounds"``, ``"verify_above"``: the layout's own verification budget (docs/fitting.md,
#: "Budgets": one refit, for spikes only). ``"check_unverified"``: the layout is checked before its
#: verification and verified only when it is kept. A layout is otherwise verified before its check
#: (the refits of the pieces' verification moved their check by -34 % to +46 %); the one piece's
#: spikes-only refit moved its check by -7 % to 0 on the 16 RGL files that try it, and cost up to
#: 17 CPU s each (docs/fit_accuracy.md, "Checking verified fits").
#: Every layout fits what the setting ``value_factor`` says, rho cos theta_i by default, finite
#: where the measured rho grows as 1 / cos(theta_i) towards the light's horizon. The one relative
#: piece follows the grazing light on the felts, papers and paints and is worse on the films and
#: satins; the relative pieces sit between them (the matte films and the cardboard). The image
#: check, its sun carrying most of the light as the maps' suns do, tells them apart
#: (docs/fit_accuracy.md, "Choosing by the image check", "A check with a sun", "The light's cosine").
VARIANTS = (
    {"theta_h_edges": list(PIECE_EDGES), "piece_degrees": list(PIECE_DEGREES)},
    {"theta_h_edges": [], "degrees": (7, 3), "objective": "relative", "if_rmse_below": 0.065, "verify_rounds": 1,
     "verify_above": 4.0, "check_unverified": True},
    {"theta_h_edges": list(PIECE_EDGES), "piece_degrees": list(PIECE_DEGREES), "objective": "relative",
     "if_rmse_below": 0.065},
)
#: The layouts a selection with ``target_rmse`` (the coefficient count as the dial) tries, cheapest
#: first: one piece of degrees (3, 1), (4, 2), (5, 2), (6, 3), (7, 3) (72, 135, 198, 312, 420
#: coefficients), then the seven theta_h pieces (1,323). The first whose validation RMSE is within the
#: target is kept: the fewest coefficients of the ladder that meet it (docs/fit_accuracy.md, "The
#: coefficient count as a dial", measured these rungs on three materials).
#: The keys of a :data:`VARIANTS` layout that say how the selection treats it, not how it is
#: fitted (not ``fit_rgl`` arguments): a layout fitted alone drops them.
SELECTION_KEYS = ("if_rmse_below", "check_unverified")
TARGET_LADDER = tuple({"theta_h_edges": [], "degrees": d, "verify_rounds": 1, "verify_above": 4.0}
                      for d in ((3, 1), (4, 2), (5, 2), (6, 3), (7, 3))) + (VARIANTS[0],)
#: A later layout replaces the one chosen so far only when its validation RMSE is lower by this
#: fraction: vch_golden_yellow's one piece (0.0439 against 0.0441) was chosen without it, and
#: it was 0.045 against 0.043 on the benchmark's pairs and 52.6 against 9.2 times its bound at
#: the fresh points (a spike between the data points); every other switch was by more than 20 %.
SELECT_MARGIN = 0.05
#: Settings of the selection itself (its budgets, verification and albedo policy), not of a
#: layout's fit: not listed in the layouts' ``"options"`` log.
_SELECT_SETTINGS = frozenset({"time_limit", "wall_limit", "select_share", "verify", "verify_rounds", "verify_above",
                              "proof_rounds", "proof_above", "albedo", "albedo_tol", "albedo_time",
                              "albedo_rmse_growth", "albedo_total_growth", "albedo_refits", "max_variants",
                              "target_rmse", "image_check", "select_by"})


def validation_rmse(brdf, model, n: int = 20000, seed: int = 12345) -> float:
    """Relative RMSE of ``rho cos(theta_i) cos(theta_o)`` (mean over R, G, B) of a 3-D ``model``
    against the RGL reference on ``n`` pairs of cosine-distributed directions (``seed``: not the
    benchmark's): the selection criterion of :func:`fit_rgl_select`."""
    wi, wo, t = _validation_pairs(brdf, n, seed)
    c = (wi[:, 2] * wo[:, 2])[:, None]
    t = t * c
    f = evaluate_directions(model, wi, wo) * c
    return float(np.mean(np.sqrt(np.mean((f - t) ** 2, axis=0)) / np.maximum(np.sqrt(np.mean(t ** 2, axis=0)), 1e-300)))


def _validation_pairs(brdf, n: int, seed: int):
    rng = np.random.default_rng(seed)
    wi, wo = cosine_directions(rng, n), cosine_directions(rng, n)
    return wi, wo, np.maximum(np.asarray(brdf.evaluate(wi, wo), np.float64), 0.0)


def validation_relative(brdf, model, n: int = 20000, seed: int = 12345, floor_frac: float = 0.1) -> tuple:
    """``(median, p95)`` of the relative error ``|rho_fit - rho| / max(rho, floor_frac *
    median(rho_c))`` of a 3-D ``model`` against the RGL reference at ``n`` pairs of
    cosine-distributed directions (``seed``: not the benchmark's), pooled over R, G, B: every pair
    counts, the dark ones by a tenth of the channel's median."""
    wi, wo, t = _validation_pairs(brdf, n, seed)
    f = evaluate_directions(model, wi, wo)
    floor = np.maximum(t, floor_frac * np.median(t, axis=0)[None, :])
    r = (np.abs(f - t) / np.maximum(floor, 1e-300)).reshape(-1)
    return float(np.median(r)), float(np.percentile(r, 95))


def image_score(check: dict) -> float:
    """The selection's criterion under ``select_by="image"``: ``mean + p99 / 3`` of an image
    check (:func:`fit.rational.image_check.image_check`), the image targets' two numbers (ΔE2000
    mean <= 1 and p99 <= 3) each in units of its target; lower is better."""
    return float(check["mean"] + check["p99"] / 3.0)


def validation_score(brdf, model, objective: str) -> float:
    """The selection criterion of :func:`fit_rgl_select` for ``objective``
    (:data:`fit.rational.samples3d.OBJECTIVES`): median + p95 of :func:`validation_relative`
    (``"relative"``) or :func:`validation_rmse` (``"rho_cos_cos"``); lower is better."""
    if objective == "relative":
        return float(sum(validation_relative(brdf, model)))
    return validation_rmse(brdf, model)


@one_blas_thread
def fit_rgl_select(brdf, variants=None, *, settings: Fit3DSettings | None = None, progress=None,
                   **params) -> Fit3D:
    """Fit every layout of ``variants`` (each a dict of settings that replace those of ``settings``,
    :class:`fit.rational.settings.Fit3DSettings`, default its defaults, whose names are also keyword
    arguments that override it; a layout may set its own ``objective``) with
    :func:`fit.rational.rgl3d.fit_rgl` and return the one with the lowest score: with the setting
    ``select_by="image"`` (the default) :func:`image_score` of each layout's image check (logged in
    its ``variants`` entry as ``image_check``), made once the layout is verified (its
    ``verify_rounds`` refits, below: they move what the check sees), with ``"validation"`` its
    :func:`validation_score` of the setting ``objective`` (a later layout must be
    :data:`SELECT_MARGIN` lower to replace an earlier one; a layout with ``"if_rmse_below"`` is tried
    only when the chosen one's :func:`validation_rmse` is below that RMSE); ``variants`` logs what
    each achieved (coefficients, stated bound, validation RMSE and score, seconds), ``variant`` is
    the index of the one chosen, ``validation_rmse`` and ``validation_score`` its held-out errors.
    ``variants`` None: :data:`VARIANTS`, or :data:`TARGET_LADDER` with the setting ``target_rmse``:
    then the layouts are taken as ordered cheapest first, the lowest validation RMSE so far is kept
    (no margin, no ``"if_rmse_below"``) and the next layouts are skipped ("target met") once it is
    within the target; ``fit_info["target"]`` records the target, whether it was met and the
    coefficients kept.
    The budgets are counts (docs/fitting.md, "Budgets"): at most ``max_variants`` layouts are fitted (None: all; later ones
    are logged as skipped, "budget"); every layout (``select_by="image"``) or the chosen one
    (``"validation"``, ``target_rmse``) is verified with at most ``verify_rounds`` refits
    (:func:`fit.rational.verify3d.verify_and_refit`; a layout's own ``"verify_rounds"`` entry
    overrides it); the chosen fit is then refitted where the proof between the grid nodes finds it
    outside its bound with at most ``proof_rounds`` refits (:func:`fit.rational.verify3d.refit_between_nodes`), the albedo
    policy applied with at most ``albedo_refits`` channel corrections (``albedo``, as in
    :func:`fit.rational.rgl3d.fit_rgl`), and last its error between the grid nodes proved
    (``prove_bound``, :func:`fit.rational.proved_bound.record_fit3d`). ``time_limit`` (CPU seconds of
    the process; default 600; None: none) is only the safety net of the whole selection, and
    ``wall_limit`` (s; default None) a wall-clock limit a user chose: past ``select_share`` of either
    no further layout is started (logged as skipped, "time"), past it no refit and no albedo
    round; ``fit_info["stopped"] = "time"`` and ``stopped_at`` record it. ``time_s`` is the whole
    selection. ``progress(stage, done, total)`` (:mod:`fit.progress`): each layout's stages as in
    :func:`fit.rational.rgl3d.fit_rgl` and its ``"verification"`` (the chosen one's, by
    validation), then the chosen one's ``"proof-guided refit"``, ``"albedo policy"`` and
    ``"proving the bound"``. The model returned holds the value range of its coefficient file
    (:func:`fit.rational.ladder3d.fit_samples` gives it to every piece): it evaluates as the fit saved and loaded."""
    s = Fit3DSettings.resolve(settings, **params)
    target = s.target_rmse
    if variants is None:
        variants = VARIANTS if target is None else TARGET_LADDER
    t0 = time.perf_counter()
    ceiling = Ceiling.of(s)
    common = {k: v for k, v in s.changed_params().items() if k not in _SELECT_SETTINGS}
    best, chosen, log = None, None, []
    checked = (None, None)     # the kept layout's model and its image check (select_by image)
    for k, v in enumerate(variants):
        v = dict(v)
        below = v.pop("if_rmse_below", None)
        rounds = v.pop("verify_rounds", s.verify_rounds)
        unverified = v.pop("check_unverified", False)
        above = v.pop("verify_above", s.verify_above)
        opts = dict(common, **v)
        if s.max_variants is not None and k >= int(s.max_variants):
            log.append({"variant": k, "options": _plain(opts), "skipped": "budget"})
            continue
        if target is not None and best is not None and best.validation_rmse <= target:
            log.append({"variant": k, "options": _plain(opts), "skipped": f"target RMSE {target:g} met"})
            continue
        if k and (best is None or ceiling.out("selection", s.select_share)):
            log.append({"variant": k, "options": _plain(opts), "skipped": "time"})
            continue
        if below is not None and target is None and best is not None and best.validation_rmse >= below:
            log.append({"variant": k, "options": _plain(opts), "skipped": f"validation RMSE >= {below:g}"})
            continue
        layout = s.clone(**v, verify_rounds=rounds, verify_above=above)
        res = fit_rgl(brdf, settings=layout.clone(verify=0, albedo=False, prove_bound=False, proof_rounds=0), ceiling=ceiling,
                      progress=progress)
        fit_s = res.time_s
        v_rmse = validation_rmse(brdf, res.model)
        check, verified = None, False
        if s.select_by == "image" and target is None:
            # a layout checked as it will be written: verified first, its refits move what the
            # check sees (docs/fit_accuracy.md, "Checking verified fits"); the proof-guided refit
            # (it moves the check by at most 1 %) and the albedo policy are the kept layout's only
            if not unverified:
                t1 = time.perf_counter()
                res = verify_and_refit(brdf, res, s.verify, layout.verify_rounds, ceiling=ceiling,
                                       refit_above=layout.verify_above, progress=progress)
                res.time_s = fit_s + time.perf_counter() - t1
                verified = True
            check = image_check(brdf, res.model)
        score = (image_score(check) if check is not None else v_rmse if s.objective == "rho_cos_cos"
                 else validation_score(brdf, res.model, s.objective))
        log.append({"variant": k, "options": _plain(v), "coefficients": res.n_coefficients,
                    "bound": res.tolerance, "valid": res.valid, "validation_rmse": v_rmse,
                    "validation_score": score, "time_s": res.time_s}
                   | ({"image_check": check, "checked": "verified" if verified else "before verification"}
                      if check is not None else {}))
        if target is not None:       # the dial: the lowest validation RMSE so far, no margin
            better = res.valid and (best is None or v_rmse < best.validation_rmse)
        else:
            better = res.valid and (best is None or score < (1.0 - SELECT_MARGIN) * best.validation_score)
        if better:
            best = res
            best.validation_rmse, best.validation_score, best.variant = v_rmse, score, k
            chosen, checked, chosen_verified = layout, (res.model, check), verified
    if best is None:
        raise RuntimeError(f"no valid 3-D fit of {brdf.name}")
    variant = best.variant
    if not chosen_verified:         # select_by validation, the dial, a "check_unverified" layout
        best = verify_and_refit(brdf, best, s.verify, chosen.verify_rounds, ceiling=ceiling,
                                refit_above=chosen.verify_above, progress=progress)
    memo = {}               # proofs of functions no later step changes are not repeated
    if s.proof_rounds:
        best = refit_between_nodes(brdf, best, s.proof_rounds, s.proof_above, ceiling=ceiling, progress=progress,
                                   memo=memo)
    best.variant = variant                         # a refit returns a new result
    best.validation_rmse = validation_rmse(brdf, best.model)
    best.validation_score = validation_score(brdf, best.model, s.objective)
    if s.albedo:
        report(progress, "albedo policy", 0, 1)
        albedo_step(brdf, best, s.albedo_tol, s.albedo_time, s.verify, s.albedo_rmse_growth, ceiling=ceiling,
                     refits=s.albedo_refits, total_growth=s.albedo_total_growth)
        report(progress, "albedo policy", 1, 1)
        v_after = validation_rmse(brdf, best.model) if best.albedo["refitted"] else best.validation_rmse
        best.albedo.update(validation_rmse_before=best.validation_rmse, validation_rmse=v_after)   # its record
        best.validation_rmse = v_after
        if best.albedo["refitted"]:
            best.validation_score = validation_score(brdf, best.model, s.objective)
    best.variants = log
    best.time_s = time.perf_counter() - t0
    if target is not None:
        best.model.fit_info["target"] = {"rmse": float(target), "met": bool(best.validation_rmse <= target),
                                         "coefficients": int(best.n_coefficients)}
    best.model.fit_info.update(time_s=best.time_s, variant=best.variant, variants=log,
                               validation_rmse=best.validation_rmse, objective=chosen.objective,
                               validation_score=best.validation_score,
                               select_by=s.select_by if target is None else "validation",
                               budgets={"max_variants": s.max_variants, "verify_rounds": int(chosen.verify_rounds),
                                        "albedo_refits": int(s.albedo_refits),
                                        "ladder_steps": int(s.ladder_steps)})
    if s.image_check:       # what the fit looks like against the measurement (fit.rational.image_check)
        unchanged = checked[0] is best.model and not (best.albedo or {}).get("refitted")   # no refit since
        best.model.fit_info["image_check"] = dict(checked[1]) if unchanged and checked[1] is not None \
            else image_check(brdf, best.model)
    ceiling.record(best.model.fit_info)
    prove_step(brdf, best, s.prove_bound, memo, progress)     # the chosen fit's error between the grid nodes
    best.settings = chosen
    best.data = best.verify_points = None          # the data and fresh points are not kept
    return best


def _plain(d: dict) -> dict:
    return {k: ([list(x) if isinstance(x, tuple) else x for x in v] if isinstance(v, list)
                else list(v) if isinstance(v, tuple) else v) for k, v in d.items()}
