"""The paper's "global" layout of rational inverse CDFs (Pacanowski et al. 2012,
supplementary sec. 2).

From a tabulated sampler (:mod:`fit.sampling.table`) two rational functions are fitted with the
project's interval fitter (:class:`fit.rational.fitter.IntervalRationalFitter`):

* ``F(theta_v, mu)``            -> theta_l  (CDF^-1_v(mu), bivariate),
* ``G(theta_v, theta_l, u)``    -> |phi_l|  (half-range CDF^-1_v(tau | theta_l), trivariate),

and the sampler (:mod:`fit.sampling.maps`) uses their endpoint-normalized maps

    theta_l = pi/2 (F(theta_v, mu) - F(theta_v, 0)) / (F(theta_v, 1) - F(theta_v, 0))
    |phi_l| = pi (G(theta_v, theta_l, u) - G(.., 0)) / (G(.., 1) - G(.., 0)),  u = |2 tau - 1|

(phi_l measured from the view's azimuth, negative when tau < 1/2; the sampled density is
symmetric in phi_l like the table's), with the derivative estimator's weight

    alpha = dtheta_l/dmu * dphi_l/dtau * sin(theta_l) = dF~/dmu * 2 dG~/du * sin(theta_l)

(F~, G~ the normalized maps) in place of 1 / pdf. The normalized maps take the values 0 and
pi/2 (theta) / 0 and pi (phi) at the ends of the CDF variable exactly, by construction, for any
coefficients: no endpoint certificate is needed. (The fits' data intervals still ask for an
overshoot at both ends, ``F(theta_v, 0) < 0`` and ``F(theta_v, 1) > pi/2``, likewise G; the
normalization maps the ends onto 0 and the span whatever their values.) Together with
monotonicity this makes the map a bijection from the (mu, tau) square onto the whole hemisphere
(it covers every direction), so ``E[f(l) alpha] = integral of f`` exactly, whatever the fit's
accuracy: accuracy only changes the variance. A map that folds (dF~/dmu <= 0 or dG~/du <= 0) would be biased, so every fit is
VERIFIED (:func:`verify_theta`, :func:`verify_phi`):

* Q > 0 on the whole domain box: the fitter's exact Bernstein certificate (no poles);
* monotonicity: dF~/dmu > 0 and dG~/du > 0 at every point of a dense grid (``VERIFY_GRID``:
  theta 257 x 2049 (theta_v, mu); phi 33 x 65 x 513 (theta_v, theta_l, u)), the minimum over
  the grid reported;
* covering: the endpoint values on the grid (``covers_grid``, a check of the construction).

A fit whose Q is certified but that folds is repaired by :mod:`fit.sampling.monotone`. If a fit
fails any check after ``refinements`` rounds (denser data, tighter intervals), the material
FALLS BACK to the tabulated sampler (:class:`fit.sampling.cdf_file.CDFFit`: ``fallback`` True
with the reason, printed by the CLI and by the renderer, recorded in the CDF file). Never
silently.
"""
from __future__ import annotations

import time

import numpy as np

from ..formats.angles import HALF_PI
from ..rational.coefficient_file import from_dict as model_from_dict
from ..rational.coefficient_file import to_dict as model_to_dict
from ..rational.fitter import IntervalRationalFitter
from ..rational.function import RationalFunction
from ..rational.model import RationalModel, Variable
from .maps import normalized_map
from .monotone import monotone_refit
from ..progress import report
from .table import CDFTable, inverse_cdf_phi, inverse_cdf_theta

GLOBAL_STAGE = "global layout fits"   # the progress stage of fit_global_layout

VERIFY_GRID = {"theta": (257, 2049), "phi": (33, 65, 513)}


def verify_axes(what: str) -> list:
    """The 1-D axes of the verification grid of ``"theta"`` (theta_v, mu) or ``"phi"``
    (theta_v, theta_l, u), sizes :data:`VERIFY_GRID`."""
    n = VERIFY_GRID[what]
    ranges = [(0, HALF_PI), (0, 1)] if what == "theta" else [(0, HALF_PI), (0, HALF_PI), (0, 1)]
    return [np.linspace(a, b, k) for (a, b), k in zip(ranges, n)]


def _cheb_points(n: int) -> np.ndarray:
    """n Chebyshev-Lobatto points on [0, 1] (denser at the ends, where inverse CDFs are steep)."""
    return 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, n)))


def _monotone_intervals(y, tol, lo_end, hi_end, over):
    """Intervals around increasing rows ``y[..., k]`` (last axis = the CDF variable) that are
    disjoint and increasing along the last axis (so the data alone are monotone), width <= 2 tol;
    the end points get overshoot intervals ``[lo_end - over[1], lo_end - over[0]]`` and
    ``[hi_end + over[0], hi_end + over[1]]``."""
    y = np.asarray(y, float)
    lo = y - tol
    hi = y + tol
    mid = 0.5 * (y[..., 1:] + y[..., :-1])
    gap = 0.05 * (y[..., 1:] - y[..., :-1])
    lo[..., 1:] = np.maximum(lo[..., 1:], mid + gap)
    hi[..., :-1] = np.minimum(hi[..., :-1], mid - gap)
    lo[..., 0], hi[..., 0] = lo_end - over[1], lo_end - over[0]
    lo[..., -1], hi[..., -1] = hi_end + over[0], hi_end + over[1]
    lo[..., 1] = np.maximum(lo[..., 1], hi[..., 0] + 1e-6)
    hi[..., -2] = np.minimum(hi[..., -2], lo[..., -1] - 1e-6)
    hi = np.maximum(hi, lo + 1e-9)
    return lo, hi


def verify_theta(F: RationalFunction) -> dict:
    """Checks of the theta map's normalized form on the grid :func:`verify_axes` ``("theta")``:
    Q > 0 certified, derivative > 0 wherever the map is unclamped and globally (no fold), the
    endpoint values (0 and pi/2, exact by construction) recorded as ``covers_grid``."""
    tv, mu = verify_axes("theta")
    nv, nm = len(tv), len(mu)
    dmin_all, dmin_in, folds = np.inf, np.inf, 0
    end0 = end1 = None
    for chunk in np.array_split(tv, 8):
        X = np.stack(np.meshgrid(chunk, mu, indexing="ij"), -1)
        val, d = normalized_map(F, 1, X, HALF_PI)
        inside = (val > 0) & (val < HALF_PI)
        dmin_all = min(dmin_all, float(d.min()))
        if inside.any():
            dmin_in = min(dmin_in, float(d[inside].min()))
        folds += int(((d <= 0) & inside).sum())
        e0, e1 = float(val[:, 0].max()), float(val[:, -1].min())
        end0 = e0 if end0 is None else max(end0, e0)
        end1 = e1 if end1 is None else min(end1, e1)
    qcert = F.certify_denominator(max_depth=12)
    ok = bool(qcert.certified and folds == 0 and dmin_all > 0)
    return {"ok": ok, "grid": [nv, nm], "q_certified": bool(qcert.certified),
            "q_lower_bound": float(qcert.lower_bound) if qcert.certified else None,
            "monotone_grid": folds == 0, "fold_points": folds,
            "min_derivative_unclamped": dmin_in, "min_derivative_global": dmin_all,
            "max_value_at_mu0": end0, "min_value_at_mu1": end1,
            "covers_grid": bool(abs(end0) < 1e-9 and abs(end1 - HALF_PI) < 1e-9)}


def verify_phi(G: RationalFunction) -> dict:
    """:func:`verify_theta` for the phi map on the grid :func:`verify_axes` ``("phi")`` (endpoints
    0 and pi)."""
    tv, tl, u = verify_axes("phi")
    nv, nt, nu = len(tv), len(tl), len(u)
    dmin_all, dmin_in, folds = np.inf, np.inf, 0
    end0, end1 = -np.inf, np.inf
    for a in tv:
        X = np.stack(np.meshgrid([a], tl, u, indexing="ij"), -1)[0]
        val, d = normalized_map(G, 2, X, np.pi)
        inside = (val > 0) & (val < np.pi)
        dmin_all = min(dmin_all, float(d.min()))
        if inside.any():
            dmin_in = min(dmin_in, float(d[inside].min()))
        folds += int(((d <= 0) & inside).sum())
        end0 = max(end0, float(val[:, 0].max()))
        end1 = min(end1, float(val[:, -1].min()))
    qcert = G.certify_denominator(max_depth=12)
    ok = bool(qcert.certified and folds == 0 and dmin_all > 0)
    return {"ok": ok, "grid": [nv, nt, nu], "q_certified": bool(qcert.certified),
            "q_lower_bound": float(qcert.lower_bound) if qcert.certified else None,
            "monotone_grid": folds == 0, "fold_points": folds,
            "min_derivative_unclamped": dmin_in, "min_derivative_global": dmin_all,
            "max_value_at_u0": end0, "min_value_at_u1": end1,
            "covers_grid": bool(abs(end0) < 1e-9 and abs(end1 - np.pi) < 1e-9)}


class GlobalMaps:
    """The global layout's maps: ``theta`` = F(theta_v, mu) and ``phi`` = G(theta_v, theta_l, u)
    (:class:`fit.rational.function.RationalFunction`; either may be None when its fit gave
    nothing). The layout interface of :class:`fit.sampling.cdf_file.CDFFit`: ``theta_map``,
    ``phi_map``, ``table_rows``, ``verify``, ``to_dict`` / ``from_dict`` (all rows rational: the
    table is never used for sampling)."""

    layout = "global"

    def __init__(self, theta: RationalFunction | None, phi: RationalFunction | None):
        self.theta = theta
        self.phi = phi

    @property
    def complete(self) -> bool:
        """Both maps are present (the layout can sample)."""
        return self.theta is not None and self.phi is not None

    def _need(self, f):
        if f is None:
            raise ValueError("no rational fit (fallback); use .table")
        return f

    def theta_map(self, table: CDFTable, tv, mu):
        """``(theta_l, dtheta_l/dmu)`` of the normalized F at view angles ``tv``, ``mu``."""
        return normalized_map(self._need(self.theta), 1, np.stack([tv, mu], -1), HALF_PI)

    def phi_map(self, table: CDFTable, tv, tl, u):
        """``(|phi_l|, d|phi_l|/du)`` of the normalized G at ``(tv, theta_l, u)``."""
        return normalized_map(self._need(self.phi), 2, np.stack([tv, tl, u], -1), np.pi)

    def table_rows(self, table: CDFTable, tv) -> np.ndarray:
        """No sample is handed to the table."""
        return np.zeros(np.shape(tv), bool)

    def verify(self, table: CDFTable):
        """``(verification, fallback, reason)`` of :func:`verify_theta` and :func:`verify_phi`."""
        vt = verify_theta(self.theta) if self.theta is not None else {"ok": False}
        vp = verify_phi(self.phi) if self.phi is not None else {"ok": False}
        reasons = [f"{w} verification failed" for w, v in (("theta", vt), ("phi", vp)) if not v["ok"]]
        return ({"theta": vt, "phi": vp}, bool(reasons),
                "; ".join(reasons) if reasons else "verified: monotone, covering, no poles")

    def to_dict(self, name: str) -> dict:
        """The CDF file's ``theta`` and ``phi`` entries: ``rbrdf-rational`` function files."""
        def model(f, names, out, rng):
            if f is None:
                return None
            m = RationalModel(name=f"{name}:{out}", kind="function",
                              variables=[Variable(n, "1" if n in ("mu", "u") else "rad", "identity", tuple(d))
                                         for n, d in zip(names, f.domain)],
                              functions=[f], outputs=(out,), value_min=None, value_name=out,
                              value_unit="rad",
                              domain_policy={"outside": "clamp", "value": f"clamp to {rng}"})
            return model_to_dict(m)

        return {"theta": model(self.theta, ("theta_v", "mu"), "theta_l", "[0, pi/2]"),
                "phi": model(self.phi, ("theta_v", "theta_l", "u"), "phi_abs", "[0, pi]")}

    @classmethod
    def from_dict(cls, d: dict, path=None):
        """The maps of a CDF file's ``theta`` / ``phi`` entries; None when it stores neither."""
        theta = model_from_dict(d["theta"], path).functions[0] if d.get("theta") else None
        phi = model_from_dict(d["phi"], path).functions[0] if d.get("phi") else None
        return None if theta is None and phi is None else cls(theta, phi)


def fit_theta(table: CDFTable, tol: float = 0.03, n_theta_v: int = 0, n_mu: int = 33,
              max_degree: int = 10, over=(-0.01, 0.01), time_limit: float | None = None):
    """Fit F(theta_v, mu) ~ CDF^-1_v(mu). Returns (FitResult, data info, (X, lower, upper))."""
    tv = np.concatenate([[0.0], table.theta_v, [HALF_PI]]) if n_theta_v <= 0 else np.linspace(0, HALF_PI, n_theta_v)
    mu = _cheb_points(n_mu)
    Y = inverse_cdf_theta(table, tv, mu)
    lo, hi = _monotone_intervals(Y, tol, 0.0, HALF_PI, over)
    X = np.stack(np.meshgrid(tv, mu, indexing="ij"), -1).reshape(-1, 2)
    f = IntervalRationalFitter(max_degree=max_degree, domain=[[0, HALF_PI], [0, 1]], time_limit=time_limit)
    r = f.fit(X, y=Y.ravel(), lower=lo.ravel(), upper=hi.ravel())
    return r, {"points": int(len(X)), "tol_rad": tol, "n_mu": n_mu, "n_theta_v": len(tv)}, (X, lo.ravel(), hi.ravel())


def fit_phi(table: CDFTable, tol: float = 0.15, n_theta_v: int = 9, n_theta_l: int = 9, degrees=(6, 4),
            n_u: int = 9, max_degree: int = 8, over=(-0.02, 0.02), time_limit: float | None = None):
    """Fit G(theta_v, theta_l, u) ~ |phi_l| = CDF^-1_v(u | theta_l) (half range).

    Fixed total degrees (6, 4) by default: the fitter's degree search on the trivariate data
    takes minutes (measured: 540 s without reaching a certified fit on vch_golden_yellow), so
    the default fits one degree pair and returns the least-violating fit when the intervals
    cannot all be met -- accuracy only affects variance; monotonicity, covering and Q > 0 are
    verified afterwards and decide the fallback. ``degrees=None`` runs the full search.
    Returns (FitResult, data info, (X, lower, upper))."""
    tv = np.linspace(0, HALF_PI, n_theta_v)
    tl = np.linspace(0, HALF_PI, n_theta_l)
    u = _cheb_points(n_u)
    Y = inverse_cdf_phi(table, tv, tl, u)
    lo, hi = _monotone_intervals(Y, tol, 0.0, np.pi, over)
    X = np.stack(np.meshgrid(tv, tl, u, indexing="ij"), -1).reshape(-1, 3)
    f = IntervalRationalFitter(max_degree=max_degree, domain=[[0, HALF_PI], [0, HALF_PI], [0, 1]], degrees=degrees, max_iter=25,
                               time_limit=time_limit)
    r = f.fit(X, y=Y.ravel(), lower=lo.ravel(), upper=hi.ravel())
    return r, {"points": int(len(X)), "tol_rad": tol, "grid": [n_theta_v, n_theta_l, n_u]}, (X, lo.ravel(), hi.ravel())


def _summary(r) -> dict:
    return {"num_degree": r.num_degree, "den_degree": r.den_degree, "n_coefficients": r.n_coefficients,
            "feasible": bool(r.feasible), "valid": bool(r.valid), "time_s": r.time_s,
            "max_error_ratio": r.max_error_ratio, "message": r.message}


def _refit(f, var, data, span, verify, log, what, deadline=None):
    """Monotone refit of a folding fit on its verification grid; returns (f, verification, info)."""
    X, lo, hi = data
    t0 = time.perf_counter()
    g, info = monotone_refit(f, var, X, lo, hi, verify_axes(what), span, deadline=deadline)
    info["time_s"] = time.perf_counter() - t0
    if g is None:
        log(f"  {what}: monotone refit failed ({info.get('status')})")
        return f, verify(f), info
    v = verify(g)
    log(f"  {what}: monotone refit (Q kept, numerator refitted under slope >= 0 rows on the "
        f"verification grid): {info['rounds']} rounds, {info['slope_rows']} slope rows, margin "
        f"{info['delta']:.3g}, {info['time_s']:.1f} s, verified {v['ok']}")
    return g, v, info


def fit_global_layout(table: CDFTable, theta_kw: dict | None = None, phi_kw: dict | None = None,
                      refinements: int = 1, monotone: bool = True, time_limit_s: float | None = None,
                      log=None, deadline=None, progress=None):
    """Fit both inverse CDFs of ``table``, verify, decide fallback: ``(maps, verification,
    fallback, reason, info)`` with ``maps`` the :class:`GlobalMaps` (kept, recorded in the file,
    even when they fail verification; None when nothing was fitted).

    Each refinement round that fails verification doubles the data density along the CDF
    variable (tighter monotone intervals) and halves the tolerance. With ``monotone`` (default)
    a fit whose Q is certified but that folds is first repaired by
    :func:`fit.sampling.monotone.monotone_refit` on the verification grid (numerator refitted, Q
    kept) and verified again. ``time_limit_s`` bounds the fitting time: fits and refits stop
    when it is reached, and whatever is not verified by then falls back (the reason says so).
    A sharp lobe can otherwise take many minutes (measured, near-mirror Blinn-Phong n = 5000:
    the theta refit alone ran 233 s with its LP re-solved from scratch every round).
    ``deadline`` (:class:`fit.progress.Deadline`), when given, is the end instead of
    ``time_limit_s`` from now (shared with the caller's earlier stages). ``log(str)`` reports;
    ``progress(stage, done, total)`` (:mod:`fit.progress`) counts the fits of the rounds,
    stage ``"global layout fits"``."""
    log = log or (lambda s: None)
    theta_kw = dict(theta_kw or {})
    phi_kw = dict(phi_kw or {})
    # (the fitter's name as every file records it; the module is fit.rational.fitter)
    info: dict = {"fitter": "fit.fitter.IntervalRationalFitter", "rounds": []}
    t0 = time.perf_counter()
    if deadline is not None:
        time_limit_s = deadline.seconds
        deadline = deadline.end
    else:
        deadline = None if time_limit_s is None else t0 + float(time_limit_s)
    total_fits = 2 * (refinements + 1)
    report(progress, GLOBAL_STAGE, 0, total_fits)

    def left():
        return None if deadline is None else max(deadline - time.perf_counter(), 0.0)

    def late():
        return deadline is not None and time.perf_counter() > deadline

    F = G = None
    vt = vp = {"ok": False}
    for rnd in range(refinements + 1):
        report(progress, GLOBAL_STAGE, 2 * rnd, total_fits)
        if not vt.get("ok") and not late():
            rt, dt, data_t = fit_theta(table, **theta_kw, time_limit=left())
            F = rt.function
            vt = verify_theta(F) if F is not None else {"ok": False, "error": "no fit"}
            info["theta"] = dict(_summary(rt), data=dt)
            log(f"  theta fit (round {rnd}): degrees ({rt.num_degree}, {rt.den_degree}), "
                f"{rt.n_coefficients} coefficients, {rt.time_s:.1f} s, verified {vt['ok']}")
            if F is not None and vt.get("q_certified") and not vt.get("ok") and monotone and not late():
                F, vt, info["theta"]["monotone_refit"] = _refit(F, 1, data_t, HALF_PI, verify_theta, log,
                                                                "theta", deadline)
        if not vp.get("ok") and not late():
            rp, dp, data_p = fit_phi(table, **phi_kw, time_limit=left())
            G = rp.function
            vp = verify_phi(G) if G is not None else {"ok": False, "error": "no fit"}
            info["phi"] = dict(_summary(rp), data=dp)
            log(f"  phi fit (round {rnd}): degrees ({rp.num_degree}, {rp.den_degree}), "
                f"{rp.n_coefficients} coefficients, {rp.time_s:.1f} s, verified {vp['ok']}")
            if G is not None and vp.get("q_certified") and not vp.get("ok") and monotone and not late():
                G, vp, info["phi"]["monotone_refit"] = _refit(G, 2, data_p, np.pi, verify_phi, log,
                                                              "phi", deadline)
        info["rounds"].append({"theta_ok": vt.get("ok"), "phi_ok": vp.get("ok")})
        if (vt.get("ok") and vp.get("ok")) or late():
            report(progress, GLOBAL_STAGE, total_fits, total_fits)
            break
        theta_kw["n_mu"] = 2 * theta_kw.get("n_mu", 33) - 1
        theta_kw["tol"] = 0.5 * theta_kw.get("tol", 0.03)
        phi_kw["n_u"] = 2 * phi_kw.get("n_u", 9) - 1
        phi_kw["tol"] = 0.5 * phi_kw.get("tol", 0.15)
    info["time_limit_s"] = time_limit_s
    info["time_limit_reached"] = bool(late())
    info["time_s"] = time.perf_counter() - t0
    reasons = []
    for what, v in (("theta", vt), ("phi", vp)):
        if not v.get("ok"):
            bad = [k for k in ("q_certified", "monotone_grid", "covers_grid") if v.get(k) is False]
            reasons.append(f"{what}: " + (", ".join(f"not {b}" for b in bad) or v.get("error", "failed")))
    if reasons and info["time_limit_reached"]:
        reasons.append(f"fitting time limit {time_limit_s:g} s reached")
    fb = bool(reasons)
    maps = GlobalMaps(F, G) if F is not None or G is not None else None
    return (maps, {"theta": vt, "phi": vp}, fb,
            "; ".join(reasons) if fb else "verified: monotone, covering, no poles", info)
