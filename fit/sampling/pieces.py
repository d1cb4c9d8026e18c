"""Piecewise rational inverse CDFs with pieces uniform in the CDF variable: the
default ``"pieces"`` layout of :mod:`fit.sampling.cdf_file` (its construction, checks and
reference sampler; the variance gate that decides which rows use it is
:mod:`fit.sampling.variance_gate`).

Why this layout. A sampler with ONE rational function per inverse CDF (the paper's
``"global"`` layout, :mod:`fit.sampling.global_layout`, or one per view row, a ``"rows"``
layout measured and not kept) costs one long Horner chain per sample; on glossy materials the degree the
variance target needs makes it slower than the table's binary search (measured with the
per-cell experiment ``benchmarks/experiment_cdf_cells.py``, removed since). Here each inverse CDF is
split into pieces of EQUAL MASS -- uniform in the CDF variable -- so a sample finds its piece
with one multiplication (``k = floor(mu * n_mu)``), no search, and evaluates one rational
function of degree (2, 2): constant time, a few flops.

The maps (all angles in radians, CDF variables in [0, 1]):

* ``theta_l = F_v(mu)``, one per view row ``v`` of the table (row of ``theta_v`` as
  :meth:`fit.sampling.table.CDFTable.row`), ``n_mu`` pieces;
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
32 pieces, 1.56x / 1.57x with 64, two runs each of ``python -m benchmarks.bench_samplers --materials
vch_golden_yellow_rgb --n-u N``). The Warp sampler stores the phi maps as knots (value, slope;
:func:`pieces_phi_knots`): 2 floats per piece instead of 4.

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
The end knot's slope in y is PCHIP's, right for a density that vanishes like cos(theta_l) at the
horizon. Where it does not (an RGL file's f cos(theta_l) stays finite at grazing light, and the
weighted tables of :class:`fit.formats.measured.MeasuredBRDF` keep it), the table's inverse CDF
reaches y = 1 with slope 0 and PCHIP's slope puts too little density near the horizon:
satin_rosaline, 8 view rows, variance ratios 0.9-11.6 (6 rows over the gate). A row the gate
rejects is therefore built again with slope 0 at that knot (``PieceMaps.flat_end``) and
measured again; it keeps the flat end if that passes (satin_rosaline: 0.67-1.46).

Rows whose pieces fail :func:`verify_pieces`, and rows the variance gate rejects, are sampled
with the table (``PieceMaps.row_ok`` False).

Storage: the pieces are a deterministic function of the table and ``(n_mu, n_u)``: an
``rbrdf-cdf`` file stores the table, ``n_mu``, ``n_u`` and the per-row decisions, and
:func:`build_pieces` recomputes the coefficients on load, then :func:`verify_pieces` checks them.
A fit's sampler record (:mod:`fit.sampling.embedded`) stores the knots and slopes as well
(:func:`piece_knots`; :data:`fit.sampling.cdf_reader.KNOT_KEYS`): its load makes the pieces from them
(:func:`pieces_from_knots`: elementwise, no SciPy, the same floats as a rebuild) and checks their
structure (:func:`fit.sampling.cdf_reader.check_pieces`), with no rebuild and no sampled
verification.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..formats.angles import HALF_PI
from .maps import sample_maps
from .table import CDFTable, table_where


@dataclass
class PieceMaps:
    """Coefficients of the pieces layout.

    ``theta``: (n_v, n_mu, 4) per piece ``(y_k, h, a0, a1)`` (see the module docstring); pieces
    0 and n_mu - 1 in y = sin^2(theta_l), the others in theta_l (rad).
    ``phi``: (n_v, n_mu, n_u, 4) the same for |phi_l| (rad) on [0, pi], per theta piece.
    ``theta_knots``: (n_v, n_mu + 1) theta_l (rad) at the knots mu = k / n_mu.
    ``row_ok``: (n_v,) bool, False where the row is sampled with the table.
    ``flat_end``: (n_v,) bool (None: all False), True where the last theta piece ends with
    slope 0 in y = sin^2(theta_l) (the density in theta_l does not vanish at the horizon; see
    the module docstring).

    Per row: :meth:`row_theta_map`, :meth:`row_phi_map`. The layout interface of
    :class:`fit.sampling.cdf_file.CDFFit` (``theta_map``, ``phi_map``, ``table_rows``,
    ``verify``, ``to_dict`` / ``from_dict``) takes view angles and the table whose rows these
    are."""

    layout = "pieces"
    complete = True       # the layout can sample (rows it cannot are handed to the table)

    theta: np.ndarray
    phi: np.ndarray
    theta_knots: np.ndarray
    row_ok: np.ndarray
    info: dict = field(default_factory=dict)
    flat_end: np.ndarray | None = None

    def __post_init__(self):
        n_v = self.theta.shape[0]
        self.flat_end = np.zeros(n_v, bool) if self.flat_end is None else np.asarray(self.flat_end, bool).copy()

    @property
    def n_mu(self) -> int:
        return self.theta.shape[1]

    @property
    def n_u(self) -> int:
        return self.phi.shape[2]

    def row_theta_map(self, v, mu):
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

    def row_phi_map(self, v, k, u):
        """``(|phi_l|, d|phi_l|/du)`` of row(s) ``v``, theta piece(s) ``k`` at ``u``."""
        n = self.n_u
        kp, x = _piece(u, n)
        p, dp = rq_eval(self.phi[v, k, kp], x)
        return p, dp * n

    # Layout interface (fit.sampling.cdf_file.CDFFit) ---------------------------------------
    def theta_map(self, table: CDFTable, tv, mu):
        """``(theta_l, dtheta_l/dmu)`` at view angles ``tv`` and ``mu``; NaN on table rows."""
        v = table.row(tv)
        t, d = self.row_theta_map(v, mu)
        tab = ~self.row_ok[v]
        return np.where(tab, np.nan, t), np.where(tab, np.nan, d)

    def phi_map(self, table: CDFTable, tv, tl, u):
        """``(|phi_l|, d|phi_l|/du)`` at ``(tv, theta_l, u)``, with the theta piece that holds
        ``theta_l`` (:meth:`theta_piece`); NaN on table rows."""
        v = table.row(tv)
        p, d = self.row_phi_map(v, self.theta_piece(v, np.nan_to_num(tl)), u)
        tab = ~self.row_ok[v]
        return np.where(tab, np.nan, p), np.where(tab, np.nan, d)

    def table_rows(self, table: CDFTable, tv) -> np.ndarray:
        """True where the view angle's row is sampled with the table."""
        return ~self.row_ok[table.row(tv)]

    def verify(self, table: CDFTable):
        """Re-check the pieces (:func:`verify_pieces`); a row that fails is handed to the table
        (its ``row_ok`` cleared). Returns ``(verification, fallback, reason)``."""
        ver = verify_pieces(self)
        self.row_ok &= np.asarray(ver["rows"], bool)
        n_ok, n = int(self.row_ok.sum()), table.n_v
        reason = f"rational on {n_ok}/{n} view rows (others sampled with the table)" if n_ok else "no row rational"
        return {"pieces": {k: ver[k] for k in ("ok", "failures")}}, n_ok == 0, reason

    def to_dict(self, name: str = "") -> dict:
        """The CDF file's ``pieces`` entry: the pieces are rebuilt from the table on load."""
        d = {"n_mu": self.n_mu, "n_u": self.n_u, "row_ok": [bool(x) for x in self.row_ok]}
        if self.flat_end.any():       # absent in files written before it existed: all False
            d["flat_end"] = [bool(x) for x in self.flat_end]
        return {"pieces": d}

    @classmethod
    def from_dict(cls, pd: dict, table: CDFTable) -> "PieceMaps":
        """Rebuild the pieces of a CDF file's ``pieces`` entry from its table; ValueError when
        the row flags do not fit the table or a rational row's pieces fail verification (stored
        knots are read by :mod:`fit.sampling.cdf_reader`)."""
        if len(pd["row_ok"]) != table.n_v:
            raise ValueError(f"{len(pd['row_ok'])} row flags for {table.n_v} table rows")
        flat = pd.get("flat_end")
        if flat is not None and len(flat) != table.n_v:
            raise ValueError(f"{len(flat)} flat_end flags for {table.n_v} table rows")
        pm = build_pieces(table, int(pd["n_mu"]), int(pd["n_u"]), row_ok=pd["row_ok"], flat_end=flat)
        bad = ~np.asarray(verify_pieces(pm)["rows"]) & pm.row_ok
        if bad.any():
            raise ValueError(f"pieces of rows {np.flatnonzero(bad).tolist()} fail verification")
        return pm


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
    from scipy.interpolate import PchipInterpolator   # only to build pieces, never to read stored ones

    t = np.linspace(0.0, 1.0, y.shape[-1])
    return PchipInterpolator(t, y, axis=-1)(t, 1)


def piece_knots(table: CDFTable, n_mu: int, n_u: int, flat_end=None) -> dict:
    """The knots and slopes of the pieces (``theta``: theta_l at mu = k / n_mu, ``theta_slopes``,
    ``end_slopes`` in y = sin^2 theta_l, ``phi`` per theta piece, ``phi_slopes``) of every row of ``table``: the
    table's inverse CDFs at the knots and SciPy's PCHIP slopes (``flat_end``: rows whose last
    theta knot has slope 0 in y, all False unless given). :func:`pieces_from_knots` makes the
    pieces from them."""
    if n_mu < 3 or n_u < 1:
        raise ValueError(f"need n_mu >= 3 and n_u >= 1 pieces, got {n_mu}, {n_u}")
    yt = _knots(table.cdf_theta, HALF_PI, n_mu)             # (n_v, n_mu + 1)
    ds = _pchip_slopes(_end_knots(yt))
    flat = np.zeros(table.n_v, bool) if flat_end is None else np.asarray(flat_end, bool)
    ds[flat, -1] = 0.0
    yp = _knots(_mixed_phi_cdf(table, yt), np.pi, n_u)      # (n_v, n_mu, n_u + 1)
    return {"theta": yt, "theta_slopes": _pchip_slopes(yt), "end_slopes": ds,
            "phi": yp, "phi_slopes": _pchip_slopes(yp)}


def _end_knots(yt: np.ndarray) -> np.ndarray:
    """The theta knots ``yt`` in y = sin^2(theta_l), the ends exactly 0 and 1."""
    ys = np.sin(yt) ** 2
    ys[:, 0], ys[:, -1] = 0.0, 1.0
    return ys


def pieces_from_knots(knots: dict, row_ok=None, flat_end=None) -> PieceMaps:
    """The pieces made from knots and slopes (:func:`piece_knots`; elementwise, no SciPy): the
    same floats as :func:`build_pieces` of the table they came from. ``row_ok``: all True unless
    given; ``flat_end``: the rows' flags (the slopes already hold them)."""
    yt = knots["theta"]
    theta = rq_pieces(yt, knots["theta_slopes"])
    end = rq_pieces(_end_knots(yt), knots["end_slopes"])
    theta[:, 0], theta[:, -1] = end[:, 0], end[:, -1]
    phi = rq_pieces(knots["phi"], knots["phi_slopes"])
    n_v = yt.shape[0]
    ok = np.ones(n_v, bool) if row_ok is None else np.asarray(row_ok, bool).copy()
    flat = np.zeros(n_v, bool) if flat_end is None else np.asarray(flat_end, bool)
    return PieceMaps(theta=theta, phi=phi, theta_knots=yt, row_ok=ok, flat_end=flat)


def build_pieces(table: CDFTable, n_mu: int = 64, n_u: int = 32, row_ok=None, flat_end=None) -> PieceMaps:
    """The pieces of every row of ``table`` (``row_ok``: all True unless given; ``flat_end``:
    rows whose last theta piece ends with slope 0 in y, all False unless given)."""
    return pieces_from_knots(piece_knots(table, n_mu, n_u, flat_end), row_ok, flat_end)


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


def verify_pieces(pm: PieceMaps, n_check: int = 9, max_slope_ratio: float | None = None) -> dict:
    """Checks of the construction's guarantees, per row: every piece has h >= 0, a0, a1 >= 0
    (so monotone, denominator >= 1/2: no pole), consecutive pieces meet (continuity), the
    ends are 0 and pi/2 (theta) / 0 and pi (phi); plus values and derivatives on ``n_check``
    points per piece (finite, non-decreasing, derivative >= 0; none with ``n_check`` 0) and,
    with ``max_slope_ratio``, a0, a1 at most that. Returns
    ``{"ok": bool, "rows": [bool per row], "failures": {...}}``."""
    def check(c):
        """Per map (all axes but the last two): True where a piece breaks a guarantee."""
        bad = (c[..., 1:] < 0).any(axis=(-1, -2)) | ~np.isfinite(c).all(axis=(-1, -2))
        if max_slope_ratio is not None:
            bad |= (c[..., 2:] > max_slope_ratio).any(axis=(-1, -2))
        end = c[..., :-1, 0] + c[..., :-1, 1]                 # value at x = 1 of each piece
        nxt = c[..., 1:, 0]
        bad |= ~np.all(np.abs(end - nxt) <= 1e-9 * (1.0 + np.abs(nxt)), axis=-1)
        if n_check > 0:
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
    tv, mu, tau = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_v, mu, tau)))
    v = table.row(tv)
    k = _piece(mu, pm.n_mu)[0]

    def phi_map(tl, u):
        return pm.row_phi_map(v, k, u)

    tl, pl, alpha = sample_maps(lambda m: pm.row_theta_map(v, m), phi_map, mu, tau)
    return table_where(table, ~pm.row_ok[v], tv, mu, tau, tl, pl, alpha)


def pieces_phi_knots(pm: PieceMaps) -> np.ndarray:
    """(n_v, n_mu, n_u + 1, 2): the phi pieces ``(y_k, h, a0, a1)`` of ``pm`` as knots (value,
    slope dy/dx in piece-local x): the form the Warp sampler reads
    (:func:`warp_rbrdf.techniques.rational.rq_knots`; half the bytes of the pieces, which matters when
    view rows change from sample to sample: the phi maps of a material are then read at random,
    64 x 64 pieces = 2 MB as pieces, 1.06 MB as knots). Raises ValueError where a verified row's
    pieces do not share their knots (their values or slopes differ between the end of a piece
    and the start of the next)."""
    c = pm.phi
    y = np.concatenate([c[..., 0], (c[..., -1, 0] + c[..., -1, 1])[..., None]], axis=-1)
    s_start = c[..., 2] * c[..., 1]                  # a0 h: slope at x = 0 of each piece
    s_end = c[..., 3] * c[..., 1]                    # a1 h: slope at x = 1
    s = np.concatenate([s_start, s_end[..., -1:]], axis=-1)
    ok = np.asarray(pm.row_ok, bool)
    tol = 1e-9 * (1.0 + np.abs(y[..., 1:-1]))
    bad = (np.abs(c[..., :-1, 0] + c[..., :-1, 1] - y[..., 1:-1]) > tol) \
        | (np.abs(s_end[..., :-1] - s[..., 1:-1]) > 1e-9 * (1.0 + np.abs(s[..., 1:-1])))
    rows = np.flatnonzero(bad.any(axis=(-1, -2)) & ok)
    if rows.size:
        raise ValueError(f"phi pieces of rows {rows.tolist()} do not share their knots")
    return np.stack([y, s], axis=-1)
