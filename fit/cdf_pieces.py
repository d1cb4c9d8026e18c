"""Piecewise rational inverse CDFs with pieces uniform in the CDF variable (issue 6): the
``"pieces"`` layout of :mod:`fit.cdf_fit`.

Why a third layout. A sampler with ONE rational function per inverse CDF (the paper's
``"global"`` layout, or one per view row, ``"rows"``) costs one long Horner chain per sample;
on glossy materials the degree the variance target needs makes it slower than the table's
binary search (measured: ``benchmarks/experiment_cdf_cells.py``). Here each inverse CDF is
split into pieces of EQUAL MASS -- uniform in the CDF variable -- so a sample finds its piece
with one multiplication (``k = floor(mu * n_mu)``), no search, and evaluates one rational
function of degree (2, 2): constant time, a few flops.

The maps (all angles in radians, CDF variables in [0, 1]):

* ``theta_l = F_v(mu)``, one per view row ``v`` of the table (row of ``theta_v`` as
  :meth:`fit.cdf_table.CDFTable.row`), ``n_mu`` pieces;
* ``|phi_l| = G_vk(u)``, ``u = |2 tau - 1|``, one per (row ``v``, theta piece ``k``), ``n_u``
  pieces; ``phi_l < 0`` when tau < 1/2. ``G_vk`` inverts the table's conditional CDF of phi
  MIXED over the theta_l range of piece k (the table's cells weighted by their mass inside
  [F_v(k / n_mu), F_v((k + 1) / n_mu)]), so the phi map is chosen by the same index as the
  theta piece: the two coefficient loads do not wait for each other (measured, Warp CPU:
  1.59x / 1.53x the tabulated rate with it, 1.51x / 1.43x when G is indexed by the table's
  theta_l cell, coherent / random view order, 64 x 32 pieces), and the variance is no worse
  (vch_golden_yellow at theta_v = 85 deg: 1.06x the table's, 1.41x per table cell).

Piece counts: 64 theta pieces; phi pieces per map: the fewest of 16, 32, 64 that keep every row
within the variance gate (else the count with the most rational rows). Measured (gate 1.2 with
its second measurement, rational rows per count 16 / 32 / 64): paper_white, satin_rosaline and
colodur_napoli_4f 32/32 rows at 16; vch_golden_yellow 24 / 32; cc_ibiza_sunset 13 / 32;
cc_iris_purple_gem 11 / 23 / 32. Fewer phi pieces also sample faster when every sample has
another view row (the phi maps are then read at random; vch: 1.62x / 1.65x the table's rate with
32 pieces, 1.56x / 1.57x with 64, two runs each of ``benchmarks/bench_samplers.py --materials
vch_golden_yellow_rgb --n-u N``). The Warp sampler stores the phi maps as knots (value, slope;
:func:`warp_rbrdf.cdf_sampling.pieces_phi_knots`): 2 floats per piece instead of 4.

Each piece is the monotone rational-quadratic interpolant of Gregory & Delbourgo (IMA J. Numer.
Anal. 2, 1982; the "rational-quadratic spline" of neural spline flows) between two knots:
with local ``x = mu * n - k`` in [0, 1], knot values ``y_k < y_k+1`` (``h = y_k+1 - y_k``) and
knot slopes ``d_k, d_k+1 >= 0`` (dy/dmu), ``s = h n``, ``a0 = d_k / s``, ``a1 = d_k+1 / s``:

    y  = y_k + h (x^2 + a0 x(1 - x)) / (1 + (a0 + a1 - 2) x(1 - x))
    dy/dx = h (a1 x^2 + 2 x(1 - x) + a0 (1 - x)^2) / (1 + (a0 + a1 - 2) x(1 - x))^2

The denominator is >= 1/2 on [0, 1] and the derivative >= 0 whenever a0, a1 >= 0, so every
piece is monotone, has no pole, and hits both knots exactly: the map is continuous, increasing
and covers [0, span] by construction (checked again by :func:`verify_pieces`). Knot values are
the table's own inverse CDF at ``k / n``; knot slopes come from SciPy's monotone PCHIP
interpolant of those knots (Fritsch-Carlson), so the density is continuous at the knots.

``alpha = dtheta/dmu * 2 d|phi|/du * sin(theta_l)`` is the exact inverse density of the map
(derivative estimator), whatever its accuracy; accuracy only changes the variance.

**End pieces of theta in y = sin^2(theta_l).** Near mu = 0 and mu = 1 the inverse CDF of a
density ~ cos(theta) sin(theta) behaves like sqrt(mu) and pi/2 - sqrt(1 - mu): infinite slope,
which a rational piece follows badly. The first and last theta pieces therefore interpolate
``y = sin^2(theta_l)`` (in which a Lambertian's inverse CDF is the identity) and return
``theta_l = asin(sqrt(y))``, ``dtheta/dmu = (dy/dmu) / (2 sqrt(y (1 - y)))``; alpha then uses
``dtheta/dmu sin(theta_l) = (dy/dmu) / (2 cos(theta_l))``. Measured on vch_golden_yellow (64 /
32 pieces): the per-row variance ratio to the table has median 1.07 without this, 0.94 with it.

**Variance gate.** As in :mod:`fit.cdf_rows`, a row whose maps have more than
``max_variance_ratio`` times the table's variance per sample (luminance albedo estimator at
the row's view angle, :func:`fit.cdf_rows.variance_ratio`) is sampled with the table; the
per-row ratios and reasons are recorded.

Storage: the pieces are a deterministic function of the table and ``(n_mu, n_u)``, so a file
stores the table, ``n_mu``, ``n_u`` and the per-row decisions, and :func:`build_pieces`
recomputes the coefficients on load (milliseconds).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import PchipInterpolator

from .cdf_table import CDFTable

HALF_PI = 0.5 * np.pi
PIECES_DEFAULTS = dict(n_mu=64, n_u=(16, 32, 64), max_variance_ratio=1.2, gate_samples=32768, gate_recheck=8)


@dataclass
class PieceMaps:
    """Coefficients of the pieces layout.

    ``theta``: (n_v, n_mu, 4) per piece ``(y_k, h, a0, a1)`` (see the module docstring); pieces
    0 and n_mu - 1 in y = sin^2(theta_l), the others in theta_l (rad).
    ``phi``: (n_v, n_mu, n_u, 4) the same for |phi_l| (rad) on [0, pi], per theta piece.
    ``theta_knots``: (n_v, n_mu + 1) theta_l (rad) at the knots mu = k / n_mu.
    ``row_ok``: (n_v,) bool, False where the row is sampled with the table."""

    theta: np.ndarray
    phi: np.ndarray
    theta_knots: np.ndarray
    row_ok: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def n_mu(self) -> int:
        return self.theta.shape[1]

    @property
    def n_u(self) -> int:
        return self.phi.shape[2]

    def theta_map(self, v, mu):
        """``(theta_l, dtheta_l/dmu)`` of row(s) ``v`` at ``mu`` (arrays of one shape)."""
        n = self.n_mu
        k, x = _piece(mu, n)
        y, dy = rq_eval(self.theta[v, k], x)
        dy = dy * n
        end = (k == 0) | (k == n - 1)
        ye = np.clip(y, 0.0, 1.0)
        tl = np.where(end, np.arcsin(np.sqrt(ye)), y)
        with np.errstate(divide="ignore", invalid="ignore"):
            dt = np.where(end, dy / np.maximum(2.0 * np.sqrt(ye * (1.0 - ye)), 1e-300), dy)
        return tl, dt

    def theta_piece(self, v, theta_l):
        """Theta piece ``k`` of row(s) ``v`` that holds ``theta_l`` (the samplers take it from
        mu as floor(mu n_mu); this inverse is for callers that only know theta_l)."""
        kn = self.theta_knots[v]
        k = (kn[..., 1:-1] <= np.asarray(theta_l, float)[..., None]).sum(-1)
        return np.clip(k, 0, self.n_mu - 1)

    def phi_map(self, v, k, u):
        """``(|phi_l|, d|phi_l|/du)`` of row(s) ``v``, theta piece(s) ``k`` at ``u``."""
        n = self.n_u
        kp, x = _piece(u, n)
        p, dp = rq_eval(self.phi[v, k, kp], x)
        return p, dp * n


def _piece(t, n: int):
    """Piece index ``k = floor(t n)`` (clamped to [0, n - 1]) and local coordinate in [0, 1]."""
    ts = np.asarray(t, float) * n
    k = np.clip(np.floor(ts), 0, n - 1).astype(np.intp)
    return k, np.clip(ts - k, 0.0, 1.0)


def rq_eval(c, x):
    """Value and d/dx of rational-quadratic pieces ``c[..., :4] = (y_k, h, a0, a1)`` at local
    ``x`` in [0, 1]."""
    y0, h, a0, a1 = (c[..., i] for i in range(4))
    t = x * (1.0 - x)
    den = 1.0 + (a0 + a1 - 2.0) * t
    val = y0 + h * (x * x + a0 * t) / den
    der = h * (a1 * x * x + 2.0 * t + a0 * (1.0 - x) ** 2) / (den * den)
    return val, der


def rq_pieces(y: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Pieces ``(y_k, h, a0, a1)`` (shape (..., n, 4)) between knots ``y`` (..., n + 1) at
    uniform abscissae k / n with slopes ``d`` (dy/dt, same shape; negative slopes are set to 0).
    A piece with h <= 0 (no change across it) is stored as the constant y_k (a0 = a1 = 1)."""
    n = y.shape[-1] - 1
    h = np.diff(y, axis=-1)
    s = h * n
    d = np.maximum(d, 0.0)
    ok = s > 0
    safe = np.where(ok, s, 1.0)
    a0 = np.where(ok, d[..., :-1] / safe, 1.0)
    a1 = np.where(ok, d[..., 1:] / safe, 1.0)
    return np.stack([y[..., :-1], np.where(ok, h, 0.0), a0, a1], axis=-1)


def _knots(cdf: np.ndarray, span: float, n: int):
    """Knot values of the table's piecewise-linear inverse CDFs ``cdf`` (..., m + 1) at k / n
    (shape (..., n + 1)), with the ends exactly 0 and ``span``."""
    edges = np.linspace(0.0, span, cdf.shape[-1])
    k = np.linspace(0.0, 1.0, n + 1)
    flat = cdf.reshape(-1, cdf.shape[-1])
    y = np.stack([np.interp(k, c, edges) for c in flat]).reshape(cdf.shape[:-1] + (n + 1,))
    y[..., 0], y[..., -1] = 0.0, span
    return y


def _pchip_slopes(y: np.ndarray) -> np.ndarray:
    """dy/dt at the knots of SciPy's monotone PCHIP interpolant of ``y`` (..., n + 1) at t = k / n."""
    t = np.linspace(0.0, 1.0, y.shape[-1])
    return PchipInterpolator(t, y, axis=-1)(t, 1)


def build_pieces(table: CDFTable, n_mu: int = 64, n_u: int = 32, row_ok=None) -> PieceMaps:
    """The pieces of every row of ``table`` (``row_ok``: all True unless given)."""
    if n_mu < 3 or n_u < 1:
        raise ValueError(f"need n_mu >= 3 and n_u >= 1 pieces, got {n_mu}, {n_u}")
    yt = _knots(table.cdf_theta, HALF_PI, n_mu)             # (n_v, n_mu + 1)
    theta = rq_pieces(yt, _pchip_slopes(yt))
    ys = np.sin(yt) ** 2
    ys[:, 0], ys[:, -1] = 0.0, 1.0
    end = rq_pieces(ys, _pchip_slopes(ys))
    theta[:, 0], theta[:, -1] = end[:, 0], end[:, -1]
    yp = _knots(_mixed_phi_cdf(table, yt), np.pi, n_u)      # (n_v, n_mu, n_u + 1)
    phi = rq_pieces(yp, _pchip_slopes(yp))
    ok = np.ones(table.n_v, bool) if row_ok is None else np.asarray(row_ok, bool).copy()
    return PieceMaps(theta=theta, phi=phi, theta_knots=yt, row_ok=ok)


def _mixed_phi_cdf(table: CDFTable, knots: np.ndarray) -> np.ndarray:
    """(n_v, n_mu, n_p + 1): the table's conditional |phi| CDFs mixed over each theta piece
    [knots[v, k], knots[v, k + 1]] with weights = the table's theta mass of each cell inside
    the piece (its density is constant on a cell)."""
    edges = np.linspace(0.0, HALF_PI, table.n_t + 1)
    m = np.diff(table.cdf_theta, axis=1)                    # (n_v, n_t) cell masses
    lo = np.maximum(knots[:, :-1, None], edges[None, None, :-1])
    hi = np.minimum(knots[:, 1:, None], edges[None, None, 1:])
    w = np.clip(hi - lo, 0.0, None) / (edges[1] - edges[0]) * m[:, None, :]   # (n_v, n_mu, n_t)
    tot = w.sum(-1, keepdims=True)
    # a piece of zero width (all its mass at one theta_l): the cell that holds it
    j = np.clip(np.floor(knots[:, :-1] / (edges[1] - edges[0])), 0, table.n_t - 1).astype(np.intp)
    point = np.zeros_like(w)
    np.put_along_axis(point, j[..., None], 1.0, axis=-1)
    w = np.where(tot > 0, w / np.where(tot > 0, tot, 1.0), point)
    cdf = np.einsum("vkj,vjp->vkp", w, table.cdf_phi)
    cdf[..., 0], cdf[..., -1] = 0.0, 1.0
    return cdf


def verify_pieces(pm: PieceMaps, n_check: int = 9) -> dict:
    """Checks of the construction's guarantees, per row: every piece has h >= 0, a0, a1 >= 0
    (so monotone, denominator >= 1/2: no pole), consecutive pieces meet (continuity), the
    ends are 0 and pi/2 (theta) / 0 and pi (phi); plus values and derivatives on ``n_check``
    points per piece (finite, non-decreasing, derivative >= 0). Returns
    ``{"ok": bool, "rows": [bool per row], "failures": {...}}``."""
    def check(c):
        """Per map (all axes but the last two): True where a piece breaks a guarantee."""
        bad = (c[..., 1:] < 0).any(axis=(-1, -2)) | ~np.isfinite(c).all(axis=(-1, -2))
        end = c[..., :-1, 0] + c[..., :-1, 1]                 # value at x = 1 of each piece
        nxt = c[..., 1:, 0]
        bad |= ~np.all(np.abs(end - nxt) <= 1e-9 * (1.0 + np.abs(nxt)), axis=-1)
        x = np.linspace(0.0, 1.0, n_check)
        val, der = rq_eval(c[..., None, :], x)
        bad |= ~(np.isfinite(val).all(axis=(-1, -2)) & (der >= 0).all(axis=(-1, -2)))
        bad |= ~np.all(np.diff(val, axis=-1) >= -1e-12, axis=(-1, -2))
        return bad

    def near(a, b):
        return np.abs(a - b) <= 1e-9

    th, e0, e1 = pm.theta[:, 1:-1], pm.theta[:, 0], pm.theta[:, -1]
    bt = check(th) | check(e0[:, None]) | check(e1[:, None])
    bt |= ~(near(e0[:, 0], 0.0) & near(e1[:, 0] + e1[:, 1], 1.0))              # y: 0 .. 1
    bt |= ~near(np.sin(th[:, 0, 0]) ** 2, e0[:, 0] + e0[:, 1])                    # joins in y
    bt |= ~near(np.sin(th[:, -1, 0] + th[:, -1, 1]) ** 2, e1[:, 0])
    bp = check(pm.phi)
    bp |= ~(near(pm.phi[..., 0, 0], 0.0) & near(pm.phi[..., -1, 0] + pm.phi[..., -1, 1], np.pi))
    bp = bp.any(-1)
    rows = ~(bt | bp)
    return {"ok": bool(rows.all()), "rows": rows.tolist(),
            "failures": {"theta": np.flatnonzero(bt).tolist(), "phi": np.flatnonzero(bp).tolist()}}


def sample_pieces(table: CDFTable, pm: PieceMaps, theta_v, mu, tau):
    """``(theta_l, phi_l, alpha)`` of the pieces sampler (NumPy reference of the Warp one;
    rows with ``row_ok`` False use the table: alpha = 1 / its pdf)."""
    from .cdf_fit import sample_maps
    from .cdf_table import table_where

    tv, mu, tau = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_v, mu, tau)))
    v = table.row(tv)
    k = _piece(mu, pm.n_mu)[0]

    def phi_map(tl, u):
        return pm.phi_map(v, k, u)

    tl, pl, alpha = sample_maps(lambda m: pm.theta_map(v, m), phi_map, mu, tau)
    return table_where(table, ~pm.row_ok[v], tv, mu, tau, tl, pl, alpha)


def fit_pieces(table: CDFTable, evaluate=None, n_mu: int = PIECES_DEFAULTS["n_mu"],
               n_u=PIECES_DEFAULTS["n_u"],
               max_variance_ratio: float | None = PIECES_DEFAULTS["max_variance_ratio"],
               gate_samples: int = PIECES_DEFAULTS["gate_samples"],
               gate_recheck: int | None = PIECES_DEFAULTS["gate_recheck"], log=None):
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
    rows per candidate tried."""
    log = log or (lambda s: None)
    t0 = time.perf_counter()
    best, tried = None, {}
    for nu in sorted(np.atleast_1d(n_u).astype(int).tolist()):
        pm, info = _fit_pieces_once(table, evaluate, n_mu, nu, max_variance_ratio, gate_samples, gate_recheck)
        tried[nu] = info["verified_rows"]
        if best is None or info["verified_rows"] > best[1]["verified_rows"]:
            best = (pm, info)
        if not any(r.get("reason", "").startswith("variance") for r in info["rows"]):
            break
    pm, info = best
    info.update(n_u_tried=tried, time_s=time.perf_counter() - t0)
    ratios = [r["variance"]["ratio"] for r in info["rows"] if "variance" in r]
    log(f"  pieces ({n_mu} theta x {info['n_u']} phi pieces per map; phi pieces tried: rational rows "
        + ", ".join(f"{k}: {v}" for k, v in tried.items()) + f"): {info['verified_rows']}/{table.n_v} "
        "rows rational" + (f"; variance ratio to the table per row: median {np.median(ratios):.2f}, range "
                           f"{min(ratios):.2f}-{max(ratios):.2f}" if ratios else "")
        + f" ({info['time_s']:.1f} s)")
    pm.info = info
    return pm, info


def _fit_pieces_once(table, evaluate, n_mu, n_u, max_variance_ratio, gate_samples, gate_recheck=None):
    """:func:`fit_pieces` for one phi piece count."""
    from .cdf_rows import variance_ratio

    pm = build_pieces(table, n_mu, n_u)
    ver = verify_pieces(pm)
    rows = []
    ungated = PieceMaps(pm.theta, pm.phi, pm.theta_knots, np.ones(table.n_v, bool))
    for v in range(table.n_v):
        r = {"ok": bool(ver["rows"][v])}
        if not r["ok"]:
            r["reason"] = "construction check failed"
        elif table.row_fallback[v]:
            r.update(ok=False, reason="table row without BRDF mass (cosine fallback row)")
        elif max_variance_ratio is not None and evaluate is not None:
            def ratio(n):
                return variance_ratio(table, lambda tv, m, t: sample_pieces(table, ungated, tv, m, t),
                                      evaluate, v, n)
            r["variance"] = ratio(gate_samples)
            if gate_recheck and max_variance_ratio / 1.25 < r["variance"]["ratio"] <= 2.0 * max_variance_ratio:
                r["variance_first"] = r["variance"]
                r["variance"] = ratio(gate_samples * gate_recheck)
            if not r["variance"]["ratio"] <= max_variance_ratio:
                r.update(ok=False, reason=f"variance > {max_variance_ratio:g} x the table's")
        rows.append(r)
        pm.row_ok[v] = r["ok"]
    info = {"n_mu": n_mu, "n_u": n_u, "max_variance_ratio": max_variance_ratio,
            "gate_samples": gate_samples, "gate_recheck": gate_recheck,
            "verified_rows": int(pm.row_ok.sum()), "n_rows": table.n_v, "rows": rows,
            "verification": {k: ver[k] for k in ("ok", "failures")}}
    return pm, info
