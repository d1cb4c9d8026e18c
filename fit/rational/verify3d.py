"""The verification of a 3-D fit between its data points: :func:`verification_ratio` (each
point's error over the stated bound of the piece and channel that evaluates it) and
:func:`verify_and_refit` (fresh points; where the fit leaves its bound there, the worst join the
data and the functions outside it are fitted again: constraint generation over the sampled
domain, within a count of refits). The method: docs/fitting.md ("The 3-D method").
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..formats.angles import half_diff_to_directions
from ..progress import report
from .ceiling import Ceiling
from .ladder3d import fit_samples
from .model import value_factor_weights
from .samples3d import grazing_weight, sample_grid
from .settings import DEFAULT_CHANNEL_FLOOR, DEFAULT_GRAZING_COS, DEFAULT_VERIFY


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
        edges = res.edges
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
        res.verify_max_ratio, res.verified, res.verify_points_added = ratio_max, bool(ratio_max <= 1.0), n_added
    res.model.fit_info.update(verify_rounds=int(verify_rounds), verify_refit_above=float(refit_above),
                              verify_refitted=refitted)
    ceiling.record(res.model.fit_info)
    res.verify_s = time.perf_counter() - t0
    return res
