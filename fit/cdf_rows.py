"""Per-view-row rational inverse CDFs (issue 6): the ``"rows"`` layout of :mod:`fit.cdf_fit`.

The paper's layout fits ONE bivariate ``F(theta_v, mu)`` and ONE trivariate
``G(theta_v, theta_l, u)`` over all view angles (:func:`fit.cdf_fit.fit_theta` /
:func:`fit.cdf_fit.fit_phi`). On the glossy RGL materials the trivariate ``G`` cannot follow
the lobe at affordable degrees: with the default (6, 4) fit the derivative estimator's
variance was 9-50x the tabulated sampler's at theta_v = 0 and 45 deg, while the bivariate
``F`` alone cost only 1.0-1.6x (measured on vch_golden_yellow, ``benchmarks/bench_samplers.py``).

This layout keeps the table's own view discretisation (rows of width (pi/2)/n_v, the row of a
view angle chosen exactly as the tabulated sampler chooses it) and fits, per row ``v``,

* ``F_v(mu)``              -> theta_l  (univariate, domain [0, 1]),
* ``G_v(theta_l, u)``      -> |phi_l|  (bivariate, domain [0, pi/2] x [0, 1]),

with the same endpoint normalisation as the global layout (exact endpoints 0 and span). The
data intervals are set in CDF space rather than in radians: the interval at ``u`` is
``[CDF^-1(u - delta), CDF^-1(u + delta)]`` (``delta_theta`` for F, ``delta_phi`` for G), so
the fitted map is, at every data point, the exact tabulated inverse CDF of a value within
``delta`` of ``u``. That makes the interval narrow where the density peaks (where accuracy
sets the variance) and wide where the map is steep (little mass), which a fixed tolerance in
radians does not.

Each row is VERIFIED on its own (Q > 0 Bernstein certificate on the row's box; derivative of
the normalised map > 0 on a dense grid: 2049 mu values for F, 65 x 513 (theta_l, u) for G).
A row whose fit fails (infeasible intervals with a fold left, no certificate, or the time
limit) is recorded as ``None`` with its reason and SAMPLED WITH THE TABLE for that row -- the
density is then the table's, exact, so nothing is biased; the CLI and renderer print how many
rows fell back. The same happens to a verified row whose derivative estimator has more than
``max_variance_ratio`` (default 1.2) times the tabulated sampler's variance at the row's view
angle (the variance gate, :func:`row_variance_ratio`; measured at fit time with the material's
own BRDF): a verified map is unbiased, but one that follows the lobe worse than the table costs
more samples than it saves.
"""
from __future__ import annotations

import time

import numpy as np

from .cdf_table import CDFTable, _inverse_phi_rows, _inverse_theta_rows
from .rational.function import RationalFunction

HALF_PI = 0.5 * np.pi
ROW_VERIFY = {"theta": 2049, "phi": (65, 513)}
ROW_DEFAULTS = dict(delta_theta=0.004, delta_phi=0.01, n_mu=65, n_theta_l=17, n_u=17,
                    max_degree_theta=10, max_degree_phi=8, row_time_limit=20.0,
                    max_variance_ratio=1.2, gate_samples=32768)


def _cheb01(n: int) -> np.ndarray:
    return 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, n)))


def _cdf_space_intervals(inv, x, delta, span, over):
    """``(y, lower, upper)`` for the inverse CDF ``inv(x)`` (last axis = CDF variable ``x``):
    ``[inv(x - delta), inv(x + delta)]``; the ends get overshoot intervals below 0 and above
    ``span`` (the normalisation then maps them exactly onto 0 and span)."""
    y = inv(x)
    lo = inv(np.clip(x - delta, 0.0, 1.0))
    hi = inv(np.clip(x + delta, 0.0, 1.0))
    lo[..., 0], hi[..., 0] = -over[1], -over[0]
    lo[..., -1], hi[..., -1] = span + over[0], span + over[1]
    hi = np.maximum(hi, lo + 1e-9)
    return y, lo, hi


def normalized_row_map(f: RationalFunction, x, span: float):
    """``(value, d value / d last variable)`` of ``span (f(x) - f(x|0)) / (f(x|1) - f(x|0))``
    for a row function (the CDF variable is the LAST one, domain [0, 1])."""
    from .cdf_fit import normalized_map

    x = np.asarray(x, float)
    var = f.n_vars - 1
    if f.n_vars > 1:
        return normalized_map(f, var, x, span)
    f0 = float(f(np.zeros((1, 1)))[0])
    f1 = float(f(np.ones((1, 1)))[0])
    den = f1 - f0
    return span * (f(x) - f0) / den, span * f.derivative(x, var) / den


def _certified(poly: RationalFunction) -> bool:
    try:
        return bool(poly.certify_denominator(max_depth=12, max_boxes=20000).certified)
    except Exception:  # noqa: BLE001 - degenerate polynomial: not certified
        return False


def verify_row(F: RationalFunction, G: RationalFunction) -> dict:
    """Row checks: Q > 0 certified for F and G; the normalised maps strictly increasing on the
    dense grids of :data:`ROW_VERIFY` (minimum derivative reported)."""
    mu = np.linspace(0.0, 1.0, ROW_VERIFY["theta"])
    _, dF = normalized_row_map(F, mu[:, None], HALF_PI)
    nt, nu = ROW_VERIFY["phi"]
    Y = np.stack(np.meshgrid(np.linspace(0, HALF_PI, nt), np.linspace(0, 1, nu), indexing="ij"), -1).reshape(-1, 2)
    _, dG = normalized_row_map(G, Y, np.pi)
    out = {"theta_q_certified": _certified(F), "phi_q_certified": _certified(G),
           "theta_min_slope": float(np.nanmin(dF)), "phi_min_slope": float(np.nanmin(dG))}
    out["theta_monotone_grid"] = bool(np.all(np.isfinite(dF)) and out["theta_min_slope"] > 0)
    out["phi_monotone_grid"] = bool(np.all(np.isfinite(dG)) and out["phi_min_slope"] > 0)
    out["ok"] = all(out[k] for k in ("theta_q_certified", "phi_q_certified", "theta_monotone_grid",
                                     "phi_monotone_grid"))
    return out


def _repair(f, var, X, lo, hi, axes, span, deadline):
    from .cdf_fit import monotone_refit

    g, info = monotone_refit(f, var, X, lo, hi, axes, span, deadline=deadline)
    return g, {k: info[k] for k in ("rounds", "status", "delta") if k in info}


def fit_row(table: CDFTable, v: int, delta_theta: float, delta_phi: float, n_mu: int, n_theta_l: int,
            n_u: int, max_degree_theta: int, max_degree_phi: int, row_time_limit: float | None):
    """Fit and verify row ``v``: ``(F, G, info)``; F or G None when its fit gave nothing."""
    from .rational.fitter import IntervalRationalFitter

    t0 = time.perf_counter()
    mu = _cheb01(n_mu)
    y, lo, hi = _cdf_space_intervals(lambda m: _inverse_theta_rows(table, m)[v], mu, delta_theta,
                                     HALF_PI, (0.002, 0.01))
    rt = IntervalRationalFitter(max_degree=max_degree_theta, domain=[[0, 1]],
                                time_limit=row_time_limit).fit(mu, y=y, lower=lo, upper=hi)
    tl = np.linspace(0.0, HALF_PI, n_theta_l)
    u = _cheb01(n_u)
    z, zlo, zhi = _cdf_space_intervals(lambda w: _inverse_phi_rows(table, tl, w)[v], u, delta_phi,
                                       np.pi, (0.002, 0.02))
    X = np.stack(np.meshgrid(tl, u, indexing="ij"), -1).reshape(-1, 2)
    rp = IntervalRationalFitter(max_degree=max_degree_phi, domain=[[0, HALF_PI], [0, 1]],
                                time_limit=row_time_limit).fit(X, y=z.ravel(), lower=zlo.ravel(),
                                                                upper=zhi.ravel())
    info = {"theta": {"degrees": [rt.num_degree, rt.den_degree], "n_coefficients": rt.n_coefficients,
                      "feasible": bool(rt.feasible)},
            "phi": {"degrees": [rp.num_degree, rp.den_degree], "n_coefficients": rp.n_coefficients,
                    "feasible": bool(rp.feasible)}}
    F, G = rt.function, rp.function
    if F is None or G is None:
        info["verification"] = {"ok": False}
        info["reason"] = "no fit"
    else:
        info["verification"] = vr = verify_row(F, G)
        # a certified fit that folds between its data points: refit the numerator under slope
        # rows on the verification grid (Q kept), as the global layout does
        deadline = None if row_time_limit is None else t0 + row_time_limit + 5.0
        if vr["theta_q_certified"] and not vr["theta_monotone_grid"]:
            F, info["theta"]["monotone_refit"] = _repair(F, 0, mu[:, None], lo, hi,
                                                         [np.linspace(0, 1, ROW_VERIFY["theta"])], HALF_PI, deadline)
        if vr["phi_q_certified"] and not vr["phi_monotone_grid"]:
            nt, nu = ROW_VERIFY["phi"]
            G, info["phi"]["monotone_refit"] = _repair(G, 1, X, zlo.ravel(), zhi.ravel(),
                                                       [np.linspace(0, HALF_PI, nt), np.linspace(0, 1, nu)],
                                                       np.pi, deadline)
        if F is None or G is None:
            info["verification"] = {"ok": False}
            info["reason"] = "monotone refit failed"
        elif "monotone_refit" in info["theta"] or "monotone_refit" in info["phi"]:
            info["verification"] = verify_row(F, G)
        if not info["verification"]["ok"] and "reason" not in info:
            bad = [k for k, val in info["verification"].items() if val is False and k != "ok"]
            info["reason"] = "not " + ", not ".join(bad)
    info["time_s"] = time.perf_counter() - t0
    return F, G, info


def variance_ratio(table: CDFTable, sample, evaluate, v: int, n: int = 32768, seed: int = 0) -> dict:
    """Variance per sample of the derivative estimator of the luminance albedo integral
    rho cos dw with ``sample(theta_v, mu, tau) -> (theta_l, phi_l, alpha)``, divided by the
    tabulated sampler's, at row ``v``'s view angle ``table.theta_v[v]`` (same n uniform
    (mu, tau) pairs for both, fixed seed). ``evaluate(wi (N, 3), wo (3,)) -> (N, 3)`` RGB BRDF
    in 1/sr (the material tabulated)."""
    from .formats.angles import spherical_to_direction
    from .cdf_table import LUMINANCE, inverse_pdf

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


def row_variance_ratio(table: CDFTable, F: RationalFunction, G: RationalFunction, evaluate, v: int,
                       n: int = 32768, seed: int = 0) -> dict:
    """:func:`variance_ratio` of row ``v``'s rational maps F_v, G_v."""
    from .cdf_fit import sample_maps

    return variance_ratio(table, lambda tv, mu, tau: sample_maps(
        lambda m: normalized_row_map(F, m[:, None], HALF_PI),
        lambda t, u: normalized_row_map(G, np.stack([t, u], -1), np.pi), mu, tau), evaluate, v, n, seed)


def fit_rows(table: CDFTable, log=None, deadline: float | None = None, evaluate=None, **kw):
    """Per-row fits of every table row: ``(rows, info)`` with ``rows[v] = (F_v, G_v)`` or None
    (row sampled with the table; ``info["rows"][v]["reason"]`` says why). Rows not started
    before ``deadline`` (a ``time.perf_counter()`` value) are None with reason "time limit".

    Variance gate: with ``evaluate`` (the tabulated material), a verified row whose derivative
    estimator has more than ``max_variance_ratio`` times the tabulated sampler's variance
    (:func:`row_variance_ratio`, ``gate_samples`` samples at the row's view angle) is ALSO
    sampled with the table: a verified map is unbiased whatever its shape, but a map that
    follows the lobe worse than the table costs more samples than it saves. ``None`` or
    ``inf`` disables the gate."""
    log = log or (lambda s: None)
    p = dict(ROW_DEFAULTS, **kw)
    gate, n_gate = p.pop("max_variance_ratio"), p.pop("gate_samples")
    rows, infos = [], []
    for v in range(table.n_v):
        if table.row_fallback[v]:
            rows.append(None)
            infos.append({"reason": "table row has no mass (cosine fallback row)"})
            continue
        if deadline is not None and time.perf_counter() > deadline:
            rows.append(None)
            infos.append({"reason": "fitting time limit reached"})
            continue
        lim = p["row_time_limit"]
        if deadline is not None:
            lim = max(0.0, min(lim or np.inf, deadline - time.perf_counter()))
        F, G, info = fit_row(table, v, **dict(p, row_time_limit=lim))
        ok = info["verification"].get("ok", False)
        if ok and evaluate is not None and gate is not None and np.isfinite(gate):
            info["variance"] = vr = row_variance_ratio(table, F, G, evaluate, v, n=n_gate)
            if not vr["ratio"] <= gate:
                ok = False
                info["reason"] = f"variance above {gate:g}x the table's"
        rows.append((F, G) if ok else None)
        infos.append(info)
        log(f"  row {v:2d} (theta_v {np.degrees(table.theta_v[v]):5.1f} deg): theta {tuple(info['theta']['degrees'])}"
            f" phi {tuple(info['phi']['degrees'])}, {info['theta']['n_coefficients'] + info['phi']['n_coefficients']}"
            f" coefficients, {info['time_s']:.1f} s, " + ("verified" if ok else f"TABLE ({info.get('reason')})")
            + (f", variance {info['variance']['ratio']:.2f}x table" if "variance" in info else "")
            + "".join(f", {w} refit margin {info[w]['monotone_refit'].get('delta', float('nan')):.2f}"
                      for w in ("theta", "phi") if "monotone_refit" in info.get(w, {})))
    n_ok = sum(r is not None for r in rows)
    p.update(max_variance_ratio=gate, gate_samples=n_gate, variance_gate=evaluate is not None)
    return rows, {"params": p, "rows": infos, "verified_rows": n_ok, "n_rows": table.n_v}
