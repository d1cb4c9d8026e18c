"""The verification of a 3-D fit between its data points: :func:`verification_ratio` (each
point's error over the stated bound of the piece and channel that evaluates it) and
:func:`verify_and_refit` (fresh points; where the fit leaves its bound there, the worst join the
data and the functions outside it are fitted again: constraint generation over the sampled
domain, within a count of refits). The method: docs/fitting.md ("The 3-D method").
"""
from __future__ import annotations

import time
from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from ..formats.angles import half_diff_to_directions
from ..progress import report
from .ceiling import Ceiling
from .ladder3d import fit_samples
from .model import invert_input_transform, value_factor_weights
from .samples3d import grazing_weight, sample_grid
from .settings import (DEFAULT_CHANNEL_FLOOR, DEFAULT_GRAZING_COS, DEFAULT_PROOF_ABOVE, DEFAULT_PROOF_ROUNDS,
                       DEFAULT_VERIFY)


def verification_ratio(res, X, rho, per_channel: bool = False) -> np.ndarray:
    """Per point of ``X`` ``(N, 3)`` with values ``rho`` ``(N, 3)``: the largest over R, G, B of
    ``|fit - rho| / (s * tol_piece_channel)`` (``s`` the error unit of
    :func:`fit.rational.ladder3d.fit_samples` with the fit's noise levels and policies, ``tol`` the
    stated tolerance of the piece and channel that evaluates the point); <= 1 where the fit is
    within its stated bound. ``per_channel``: the ``(N, 3)`` ratios of R, G, B instead of their
    largest. Measured in the functions' unit (``rho`` over the value factor's weight, as the fit
    was made: :func:`fit.rational.ladder3d.fit_samples`)."""
    fi = res.model.fit_info
    noise = np.asarray(res.noise)
    fw = value_factor_weights(X, getattr(res.model, "value_factor", "none"))
    rho = np.asarray(rho, np.float64) / fw[:, None]
    g = grazing_weight(X, float(fi.get("grazing_cos", DEFAULT_GRAZING_COS)))
    s = np.maximum(np.maximum(rho, noise[None, :]), float(fi.get("channel_floor", DEFAULT_CHANNEL_FLOOR))
                   * rho.max(axis=1, keepdims=True)) * g[:, None]
    edges = res.edges
    k = np.searchsorted(np.asarray(edges[1:-1]), np.clip(X[:, 0], edges[0], edges[-1]), side="left")
    tol = np.zeros((len(edges) - 1, 3))
    for r in res.records:
        tol[r["piece"], "RGB".index(r["channel"])] = r["tolerance"]
    err = np.abs(res.model.values(X) - rho) / s
    ratio = err / np.maximum(tol[k], 1e-12)
    return ratio if per_channel else np.max(ratio, axis=1)


def _refit(res, X, rho, X_new, ratio_new, refit_all: bool, ceiling):
    """``(fit, redo)``: ``res`` fitted again on the data ``X``, ``rho`` (its data with the points
    ``X_new`` added, whose per-channel ratios over the stated bound are ``ratio_new`` (M, 3)): the
    functions (piece, channel) with an added point outside their bound (``refit_all``: every
    function) are fitted again, the others kept (:func:`fit.rational.ladder3d.fit_samples`'s
    ``keep``), with the noise levels of the first fit; ``redo`` the set of ``(piece, channel)``
    fitted again."""
    data, edges = res.data, res.edges
    pieces = list(res.model.pieces) if hasattr(res.model, "pieces") else [res.model]
    redo = set()
    for k in range(len(edges) - 1):
        inside = (X_new[:, 0] >= edges[k] - 1e-12) & (X_new[:, 0] <= edges[k + 1] + 1e-12)
        for c in range(3):
            if refit_all or np.any(ratio_new[inside, c] > 1.0):
                redo.add((k, c))
    keep = {(r["piece"], "RGB".index(r["channel"])): (None, r) for r in res.records}
    for (k, c), (_, r) in keep.items():
        if (k, c) not in redo:
            keep[(k, c)] = (pieces[k].functions[c], r)
    new = fit_samples(X, rho, settings=res.settings, name=data.name, theta_max=data.theta_max, source=data.source,
                      objective=data.objective, ceiling=ceiling, noise=res.noise, keep=keep, progress=data.progress)
    new.data = replace(data, X=X, rho=rho)
    if "grid" in res.model.fit_info:     # the data grid the fit was made on (a proof read back uses it)
        new.model.fit_info["grid"] = list(res.model.fit_info["grid"])
    return new, redo


def verify_and_refit(brdf, res, verify: int = DEFAULT_VERIFY, verify_rounds: int = 2, time_limit=None,
                     ceiling=None, refit_all: bool = False, refit_above: float = 1.0, progress=None):
    """The verification of :func:`fit.rational.rgl3d.fit_rgl` on a fit made by it (its data in
    ``res.data``): returns the fit after at most ``verify_rounds`` refits (the budget: a count). A
    refit adds the worst (at most 2,000) fresh points more than ``refit_above`` times outside the
    stated bound (1: any; 4: spikes only) to the data and fits again only the functions (piece,
    channel) that are outside their bound at one of them (the others are kept, their records
    measured again on the enlarged data; ``refit_all``: every function), with the noise levels of
    the first fit; ``fit_info["verify_refitted"]`` lists them per round. ``time_limit`` (CPU s; None:
    none) or a caller's ``ceiling`` (:class:`fit.rational.ceiling.Ceiling`) is only the
    safety net: once passed, no further refit is started (``fit_info["stopped"]``).
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
        res.verify_round = rnd
        res.verify_points = (Xv, rv)    # the fresh points the returned fit was checked at
        bad = np.flatnonzero(ratio > refit_above)
        if len(bad) == 0 or rnd == verify_rounds or ceiling.out("verification"):
            break
        worst = bad[np.argsort(-ratio[bad])[:2000]]
        X, rho = np.concatenate([X, Xv[worst]]), np.concatenate([rho, rv[worst]])
        n_added += len(worst)
        res, redo = _refit(res, X, rho, Xv[worst], ratio_c[worst], refit_all, ceiling)
        refitted.append([f"{k}{'RGB'[c]}" for k, c in sorted(redo)])
        data = res.data
    if ratio_max is not None:
        res.model.fit_info.update(verify_points=int(verify // 2 * 2), verify_max_ratio=ratio_max,
                                  verified=bool(ratio_max <= 1.0), verify_points_added=n_added)
        res.verify_max_ratio, res.verified, res.verify_points_added = ratio_max, bool(ratio_max <= 1.0), n_added
    res.model.fit_info.update(verify_rounds=int(verify_rounds), verify_refit_above=float(refit_above),
                              verify_refitted=refitted)
    ceiling.record(res.model.fit_info)
    res.verify_s = time.perf_counter() - t0
    return res


#: :func:`refit_between_nodes` keeps a later round's fit unless an earlier one's proved bound is
#: lower by more than this factor (on ilm_solo_m_68 the rounds' bounds were 7.35, 7.35, 7.36x the
#: stated one, and the first of them was 5.28x its bound at the fresh points, the last 3.12x)
KEEP_WITHIN = 1.05
#: Points per axis at which :func:`refit_between_nodes` looks for a spike in a cell the proof
#: could not bound: ``LATTICE**n`` interior points at ``(i + 0.5) / LATTICE`` of each side, and
#: as many on the cell's faces, edges and corners (:data:`FACE_INSET`)
LATTICE = 3
#: The faces' points lie this fraction of the cell's side inside it (0 and 1 would put a point
#: on a theta_h piece's edge, which the neighbouring piece evaluates). A spike at a corner of the
#: measured domain (theta_d = 0, phi_d = 0 at a piece's first theta_h: vch_golden_yellow, 22.9x
#: its stated bound) is 0.97x at the interior points and 21x at the corner.
FACE_INSET = 1e-3


def _cell_points(leaf, cells: dict, lattice: int = LATTICE) -> np.ndarray:
    """``(N * P, n)``: points of the proof's cells ``cells`` (``lo``, ``hi`` in the leaf's
    transformed coordinates) in the fit's variables (theta_h, theta_d, |phi_d|, radians): the
    ``lattice**n`` interior points of each and the ``lattice**n - 1`` others of the lattice through
    its faces, edges and corners (:data:`FACE_INSET`); ``P = 2 lattice**n - 1`` (the centre once)."""
    lo, hi = np.asarray(cells["lo"]), np.asarray(cells["hi"])
    n = lo.shape[1]
    inner = (np.arange(lattice) + 0.5) / lattice
    outer = np.linspace(FACE_INSET, 1.0 - FACE_INSET, lattice)
    grid = np.unique(np.concatenate([np.stack(np.meshgrid(*([f] * n), indexing="ij"), axis=-1).reshape(-1, n)
                                     for f in (inner, outer)]), axis=0)
    U = (lo[:, None, :] + grid[None, :, :] * (hi - lo)[:, None, :]).reshape(-1, n)
    return np.stack([invert_input_transform(U[:, v], var.transform) for v, var in enumerate(leaf.variables)],
                    axis=1)


def refit_between_nodes(brdf, res, rounds: int = DEFAULT_PROOF_ROUNDS, above: float = DEFAULT_PROOF_ABOVE,
                        max_points: int = 2000, ceiling=None, progress=None, memo: dict | None = None):
    """Constraint generation from the proof (docs/fit_accuracy.md, "The proof-guided refit"): returns
    the fit of the lowest proved bound (over the stated one) among the fit and its at most
    ``rounds`` refits (a count; a refit can raise the bound elsewhere), the later one where two
    are within :data:`KEEP_WITHIN` of each other. A round proves the error of every piece and
    channel between the grid nodes of the measurement in the unit of the stated tolerance
    (:func:`fit.rational.proved_bound.prove_fit3d`, ``grazing=True``), takes every cell whose proved
    bound is above ``above`` times the stated tolerance (the proof halves the cells around a spike
    until its bound is near the error at their centre), evaluates the fit and the measurement (the
    RGL reference, not the interpolant) at points inside each and on its faces, edges and corners
    (:func:`_cell_points`), adds the worst
    (at most ``max_points``) points more than ``above`` times outside the stated bound to the data,
    and fits again the functions outside their bound at one of them (as
    :func:`verify_and_refit`). The random points of the verification miss such spikes: a fit of
    vch_golden_yellow verified at 40,000 fresh points gave 165 1/sr (rho cos theta_i) against the
    measurement's 0.014 between two grid nodes. ``fit_info["proof_refit"]`` records per round the
    largest proved bound over the stated one (None: Q inconclusive), the cells and points found
    and the functions refitted, and ``kept``, the round whose fit is returned (the last entry
    proves the last refit). The setting ``prove_bound`` records the proof of the fit returned
    after the albedo policy. ``ceiling``: the safety net, as for :func:`verify_and_refit`;
    ``memo``: the proofs of functions a round did not change are reused
    (:class:`fit.rational.proved_bound.Fit3DProof`; a caller's dict carries them on to its own
    proof of the result)."""
    from .proved_bound import Fit3DProof
    t0 = time.perf_counter()
    first = res
    memo = {} if memo is None else memo
    if ceiling is None:
        ceiling = Ceiling(None)
    progress = progress if progress is not None else res.data.progress
    log, best = [], (np.inf, res, 0)
    for rnd in range(rounds + 1):       # the last pass proves the last refit only
        if ceiling.out("proof-guided refit"):
            break
        report(progress, "proof-guided refit", rnd, rounds)
        proof = Fit3DProof(res, brdf, grazing=True, memo=memo)
        bounds = [proof.prove(k, c, keep_above=above) for k in range(len(proof.leaves)) for c in range(3)]
        ratio_proved = [None if b.proved is None else b.proved / max(b.tolerance, 1e-12) for b in bounds]
        over = np.inf if any(r is None for r in ratio_proved) else max(ratio_proved, default=0.0)
        if over <= KEEP_WITHIN * best[0]:         # a later round (on more data) within 5 % of the
            best = (over, res, rnd)               # best so far replaces it
        found = [(proof.originals[b.piece], b.worst_cells) for b, r in zip(bounds, ratio_proved)
                 if b.worst_cells is not None and len(b.worst_cells["lo"]) and (r is None or r > above)]
        pts = [_cell_points(leaf, cells) for leaf, cells in found]
        entry = {"round": rnd, "proved_over_stated": None if not np.isfinite(over) else float(over),
                 "cells": int(sum(len(cells["lo"]) for _, cells in found)), "points_added": 0, "refitted": []}
        log.append(entry)
        if not pts or rnd == rounds:
            break
        Xc = np.concatenate(pts)
        wi, wo = half_diff_to_directions(Xc[:, 0], 0.0, Xc[:, 1], Xc[:, 2])
        rc = np.maximum(np.asarray(brdf.evaluate(wi, wo), np.float64), 0.0)
        ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        held = SimpleNamespace(model=proof.model, noise=res.noise, edges=res.edges, records=res.records)
        ratio_c = verification_ratio(held, Xc, rc, per_channel=True)      # as the file evaluates
        ratio = np.where(ok, np.max(ratio_c, axis=1), 0.0)
        bad = np.flatnonzero(ratio > above)
        if len(bad) == 0:
            break
        worst = bad[np.argsort(-ratio[bad])[:max_points]]
        X = np.concatenate([res.data.X, Xc[worst]])
        rho = np.concatenate([res.data.rho, rc[worst]])
        res, redo = _refit(res, X, rho, Xc[worst], ratio_c[worst], False, ceiling)
        entry.update(points_added=int(len(worst)), largest_found=float(ratio[worst[0]]),
                     refitted=[f"{k}{'RGB'[c]}" for k, c in sorted(redo)])
    report(progress, "proof-guided refit", rounds, rounds)
    res = best[1]                       # a refit can raise the bound elsewhere: the lowest proved kept
    if res is not first:
        _carry_verification(first, res)
    res.model.fit_info["proof_refit"] = {"rounds": int(rounds), "above": float(above), "log": log, "kept": best[2],
                                         "seconds": time.perf_counter() - t0}
    ceiling.record(res.model.fit_info)
    return res


def _carry_verification(old, new) -> None:
    """The verification's record of ``old`` (:func:`verify_and_refit`) onto its refit ``new``:
    the fresh points kept, the largest ratio measured again on them (no refit), the other
    ``verify_*`` entries of ``fit_info`` as they were."""
    fi = new.model.fit_info
    for k, v in old.model.fit_info.items():
        if k.startswith("verif") and k not in fi:
            fi[k] = v
    new.verify_points, new.verify_round = old.verify_points, old.verify_round
    new.verify_points_added, new.verify_s = old.verify_points_added, old.verify_s
    if old.verify_points is not None:
        ratio_max = float(verification_ratio(new, *old.verify_points).max())
        fi.update(verify_max_ratio=ratio_max, verified=bool(ratio_max <= 1.0))
        new.verify_max_ratio, new.verified = ratio_max, bool(ratio_max <= 1.0)
