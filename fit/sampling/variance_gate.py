"""The variance gate of the pieces layout (:mod:`fit.sampling.pieces`): build, verify and gate
the pieces of a table.

A row whose maps have more than ``max_variance_ratio`` times the table's variance per sample
(the derivative estimator of the luminance albedo at the row's view angle, :func:`variance_ratio`,
measured with the material's own BRDF) is sampled with the table: a verified map is unbiased,
but one that follows the lobe worse than the table costs more samples than it saves. The
per-row ratios and reasons are recorded (:func:`fit_pieces`); :func:`fit_pieces_layout` turns
them into the CDF fit's verification, fallback flag and reason.
"""
from __future__ import annotations

import time

import numpy as np

from ..formats.angles import spherical_to_direction
from ..formats.colour import LUMINANCE
from ..progress import Deadline, report
from .pieces import PieceMaps, build_pieces, sample_pieces, verify_pieces
from .table import CDFTable, inverse_pdf

TIME_LIMIT_REASON = "time limit reached"   # the reason of a row left to the table by a deadline
PIECES_DEFAULTS = dict(n_mu=64, n_u=(16, 32, 64), max_variance_ratio=1.2, gate_samples=32768, gate_recheck=8)


def variance_ratio(table: CDFTable, sample, evaluate, v: int, n: int = 32768, seed: int = 0) -> dict:
    """Variance per sample of the derivative estimator of the luminance albedo integral
    rho cos dw with ``sample(theta_v, mu, tau) -> (theta_l, phi_l, alpha)``, divided by the
    tabulated sampler's, at row ``v``'s view angle ``table.theta_v[v]`` (same n uniform
    (mu, tau) pairs for both, fixed seed). ``evaluate(wi (N, 3), wo (3,)) -> (N, 3)`` RGB BRDF
    in 1/sr (the material tabulated)."""
    rng = np.random.default_rng(seed)
    mu, tau = rng.random(n), rng.random(n)
    tv = float(table.theta_v[v])
    wo = spherical_to_direction(tv, 0.0)

    def estimates(tl, pl, w):
        f = np.asarray(evaluate(spherical_to_direction(tl, pl), wo), float) @ LUMINANCE
        return f * np.cos(tl) * w

    e_r = estimates(*sample(np.full(n, tv), mu, tau))
    tl, pl, pdf = table.sample(np.full(n, tv), mu, tau)
    e_t = estimates(tl, pl, inverse_pdf(pdf))
    var_r, var_t = float(np.var(e_r)), float(np.var(e_t))
    ratio = var_r / var_t if var_t > 0 else (1.0 if var_r == 0 else np.inf)
    return {"theta_v_deg": float(np.degrees(tv)), "variance_rational": var_r, "variance_table": var_t,
            "ratio": float(ratio), "mean_rational": float(np.mean(e_r)), "mean_table": float(np.mean(e_t)),
            "n": n}


def fit_pieces(table: CDFTable, evaluate=None, n_mu: int = PIECES_DEFAULTS["n_mu"],
               n_u=PIECES_DEFAULTS["n_u"],
               max_variance_ratio: float | None = PIECES_DEFAULTS["max_variance_ratio"],
               gate_samples: int = PIECES_DEFAULTS["gate_samples"],
               gate_recheck: int | None = PIECES_DEFAULTS["gate_recheck"], flat_end=None, log=None,
               progress=None, deadline: Deadline | None = None):
    """Build, verify and gate the pieces of ``table``. ``evaluate(wi, wo) -> (N, 3)`` (the
    material tabulated) is needed for the variance gate (``max_variance_ratio`` None: no
    gate). A row whose ratio on ``gate_samples`` pairs lies between limit / 1.25 and twice the
    limit (0.96-2.4 for the default 1.2) is measured again on ``gate_recheck`` times as many,
    and that measurement decides (the first is kept as ``variance_first``): a few rare large
    weights decide a variance estimate, both ways (colodur_napoli_4f: three rows at 1.25-1.73x
    on 32768 pairs were 0.39-0.58x on 262144; cc_ibiza_sunset, 32 phi pieces, theta_v = 85 deg:
    1.23x on 2e5 pairs, 1.19x on 3e6). ``n_u``: phi pieces per map, or increasing candidates
    (default 16, 32, 64): the fewest that keep every row within the gate, else the count with the most rational rows
    (the smallest on ties). Returns ``(PieceMaps, info)``; ``info["rows"]`` has per row
    ``ok``, ``reason`` and the gate's ``variance`` dict, ``info["n_u_tried"]`` the rational
    rows per candidate tried. ``flat_end``: (n_v,) bool, rows built with the flat end piece from
    the start (default: none; a row over the gate is tried again with it, see
    :func:`_fit_pieces_once`). ``progress(stage, done, total)`` (:mod:`fit.progress`) is told
    the rows gated per candidate. ``deadline`` (:class:`fit.progress.Deadline`): once it has
    passed, no further candidate is tried and the rows not yet gated are sampled with the
    table (reason ``"time limit reached"``); ``info["time_limit_reached"]`` says so."""
    log = log or (lambda s: None)
    t0 = time.perf_counter()
    best, tried = None, {}
    for nu in sorted(np.atleast_1d(n_u).astype(int).tolist()):
        if best is not None and deadline is not None and deadline.passed():
            break
        pm, info = _fit_pieces_once(table, evaluate, n_mu, nu, max_variance_ratio, gate_samples, gate_recheck,
                                    flat_end, progress, deadline)
        tried[nu] = info["verified_rows"]
        if best is None or info["verified_rows"] > best[1]["verified_rows"]:
            best = (pm, info)
        if not any(r.get("reason", "").startswith("variance") for r in info["rows"]):
            break
    pm, info = best
    info.update(n_u_tried=tried, time_s=time.perf_counter() - t0,
                time_limit_reached=bool(deadline is not None and deadline.passed()))
    ratios = [r["variance"]["ratio"] for r in info["rows"] if "variance" in r]
    log(f"  pieces ({n_mu} theta x {info['n_u']} phi pieces per map; phi pieces tried: rational rows "
        + ", ".join(f"{k}: {v}" for k, v in tried.items()) + f"): {info['verified_rows']}/{table.n_v} "
        "rows rational" + (f"; variance ratio to the table per row: median {np.median(ratios):.2f}, range "
                           f"{min(ratios):.2f}-{max(ratios):.2f}" if ratios else "")
        + f" ({info['time_s']:.1f} s)")
    pm.info = info
    return pm, info


def _fit_pieces_once(table, evaluate, n_mu, n_u, max_variance_ratio, gate_samples, gate_recheck=None,
                     flat_end=None, progress=None, deadline=None):
    """:func:`fit_pieces` for one phi piece count. Rows over the gate are tried again with a
    flat end piece (:attr:`fit.sampling.pieces.PieceMaps.flat_end`; rows already built with it
    are not) and keep it if it passes. Rows reached after ``deadline`` are not gated: they
    are sampled with the table (reason ``"time limit reached"``)."""
    pm = build_pieces(table, n_mu, n_u, flat_end=flat_end)
    ver = verify_pieces(pm)

    def gate(maps, v):
        ungated = PieceMaps(maps.theta, maps.phi, maps.theta_knots, np.ones(table.n_v, bool))

        def ratio(n):
            return variance_ratio(table, lambda tv, m, t: sample_pieces(table, ungated, tv, m, t),
                                  evaluate, v, n)
        out = {"variance": ratio(gate_samples)}
        if gate_recheck and max_variance_ratio / 1.25 < out["variance"]["ratio"] <= 2.0 * max_variance_ratio:
            out["variance_first"] = out["variance"]
            out["variance"] = ratio(gate_samples * gate_recheck)
        return out

    late = (lambda: False) if deadline is None else deadline.passed
    stage = f"variance gate ({n_u} phi pieces)"
    report(progress, stage, 0, table.n_v)
    rows = []
    for v in range(table.n_v):
        r = {"ok": bool(ver["rows"][v])}
        if not r["ok"]:
            r["reason"] = "construction check failed"
        elif table.row_fallback[v]:
            r.update(ok=False, reason="table row without BRDF mass (cosine fallback row)")
        elif max_variance_ratio is not None and evaluate is not None:
            if late():
                r.update(ok=False, reason=TIME_LIMIT_REASON)
            else:
                r.update(gate(pm, v))
                if not r["variance"]["ratio"] <= max_variance_ratio:
                    r.update(ok=False, reason=f"variance > {max_variance_ratio:g} x the table's")
        rows.append(r)
        pm.row_ok[v] = r["ok"]
        report(progress, stage, v + 1, table.n_v)
    retry = [] if late() else [v for v, r in enumerate(rows)
                               if r.get("reason", "").startswith("variance") and not pm.flat_end[v]]
    if retry:
        flat = pm.flat_end.copy()
        flat[retry] = True
        alt = build_pieces(table, n_mu, n_u, flat_end=flat)
        alt_rows = verify_pieces(alt)["rows"]
        for v in retry:
            if not alt_rows[v] or late():
                continue
            g = gate(alt, v)
            rows[v]["variance_pchip_end"] = rows[v]["variance"]
            if g["variance"]["ratio"] <= max_variance_ratio:
                rows[v] = {"ok": True, "flat_end": True, **g, "variance_pchip_end": rows[v]["variance"]}
                pm.flat_end[v] = True
                pm.row_ok[v] = True
        if pm.flat_end.any():        # the kept flat ends' coefficients (only their last theta piece differs)
            pm.theta[pm.flat_end] = alt.theta[pm.flat_end]
    info = {"n_mu": n_mu, "n_u": n_u, "max_variance_ratio": max_variance_ratio,
            "gate_samples": gate_samples, "gate_recheck": gate_recheck,
            "verified_rows": int(pm.row_ok.sum()), "n_rows": table.n_v, "rows": rows,
            "flat_end_rows": int(pm.flat_end.sum()),
            "verification": {k: ver[k] for k in ("ok", "failures")}}
    return pm, info


def fit_pieces_layout(table: CDFTable, evaluate=None, log=None, **kw):
    """The pieces layout of ``table`` for :func:`fit.sampling.cdf_file.fit_cdf`: ``(maps,
    verification, fallback, reason, info)`` from :func:`fit_pieces` (``kw`` tunes it, among
    them ``progress`` and ``deadline``);
    ``maps`` None (fallback) when no row is rational. The reason says how many view rows are
    rational and why the others are sampled with the table."""
    log = log or (lambda s: None)
    pm, info = fit_pieces(table, evaluate, log=log, **kw)
    # (the construction's name as every file records it; the module is fit.sampling.pieces)
    info.update(layout="pieces", construction="fit.cdf_pieces (monotone rational-quadratic pieces)")
    n_ok, n = info["verified_rows"], info["n_rows"]
    why = "; ".join(sorted({r.get("reason", "?") for r in info["rows"] if not r["ok"]}))
    if n_ok == 0:
        reason = f"no row rational ({why})"
    elif n_ok < n:
        reason = f"rational on {n_ok}/{n} view rows; the other {n - n_ok} rows are sampled with the table ({why})"
    else:
        reason = f"rational on all {n} view rows: monotone, covering, no poles (by construction, checked)"
    log(f"  {reason}")
    return None if n_ok == 0 else pm, {"pieces": info["verification"]}, n_ok == 0, reason, info
