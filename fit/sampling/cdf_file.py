"""Rational inverse CDFs of one material for importance sampling (issue 6): the
:class:`CDFFit` (tables + maps + verification + fallback decision), how it is made
(:func:`fit_cdf`, :func:`table_only`), re-verified (:func:`verify`) and stored (``rbrdf-cdf``
JSON files: :meth:`CDFFit.save`, :func:`load`).

A fit holds the tabulated sampler (:class:`fit.sampling.table.CDFTable`) and, unless it is
table-only or fell back, the maps of one layout, each a small class with the same interface
(``theta_map``, ``phi_map``, ``table_rows``, ``verify``, ``to_dict`` / ``from_dict``):

* ``"pieces"`` (default, :class:`fit.sampling.pieces.PieceMaps`): per view row of the table,
  monotone rational-quadratic pieces uniform in mu and u, built from the table (no fitting);
  rows that fail their checks or the variance gate (:mod:`fit.sampling.variance_gate`) are
  sampled with the table;
* ``"global"`` (the paper's, :class:`fit.sampling.global_layout.GlobalMaps`): F(theta_v, mu)
  and G(theta_v, theta_l, u) fitted with the interval fitter and verified.

Fallback policy: if the maps fail verification (every row, for the pieces layout), the
material FALLS BACK to the tabulated sampler: ``CDFFit.fallback`` is True with the reason, it
is printed by the CLI and by the renderer, and recorded in the CDF file. Never silently.

File: format ``rbrdf-cdf`` version 2 (version-1 files, global layout, still load): the table's
parameters and data, ``layout``, the layout's entries (``theta`` / ``phi`` rational-function
files, or ``pieces``: ``n_mu``, ``n_u``, ``row_ok``, rebuilt from the table on load), the
verification, fallback flag and reason, the fit's record and the source file. Files of the
removed per-row layout (``"layout": "rows"``) are refused with a one-line error.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import BRDFFileError
from ..formats.angles import HALF_PI
from ..formats.measured import file_sha256
from ..rational.coefficient_file import jsonable
from .global_layout import GlobalMaps, fit_global_layout
from .maps import sample_maps
from .pieces import PieceMaps
from .table import CDFTable, table_where, tabulate
from .variance_gate import fit_pieces_layout

FORMAT = "rbrdf-cdf"
VERSION = 2   # 2: "layout" key (pieces or global); version-1 files (global layout) still load
DEFAULTS = dict(n_v=32, n_t=64, n_p=64, sub=3, eps=0.02, noise=1e-6)
TIME_LIMIT_S = 180.0   # default bound on fit_cdf's fitting time (s)
LAYOUTS = ("pieces", "global")
#: The file's description of the sampler, as files have always stated it: its "rows" entry
#: describes the removed per-row layout (readers refuse "rows" files) and its "pieces" entry
#: names build_pieces by its old module (now fit.sampling.pieces.build_pieces); both stay so
#: that files written for the same input keep their content.
SAMPLER = {
    "theta_l": "pi/2 (F(theta_v, mu) - F(theta_v, 0)) / (F(theta_v, 1) - F(theta_v, 0))",
    "phi_l": "sign(tau - 1/2) pi (G(theta_v, theta_l, u) - G(.., 0)) / (G(.., 1) - G(.., 0)), u = |2 tau - 1|",
    "alpha": "dtheta_l/dmu * dphi_l/dtau * sin(theta_l)",
    "phi_origin": "azimuth of the view direction",
    "rows": "layout 'rows': row v = floor(theta_v / (pi/2) * n_v) uses F_v(mu), G_v(theta_l, u) "
            "in the same formulas; a null row is sampled with the table",
    "pieces": "layout 'pieces': rational-quadratic pieces uniform in mu / u, rebuilt from "
              "table_data by fit.cdf_pieces.build_pieces(n_mu, n_u); rows with row_ok false "
              "are sampled with the table",
}


@dataclass
class CDFFit:
    """Rational inverse CDFs of one material, with their verification and the table they fit.

    ``maps``: the layout's maps (:class:`fit.sampling.pieces.PieceMaps` or
    :class:`fit.sampling.global_layout.GlobalMaps`), None for a table-only fit or a pieces fit
    without a rational row. ``fallback`` True: the rational sampler must not be used;
    renderers use ``table``."""

    table: CDFTable
    table_params: dict
    maps: PieceMaps | GlobalMaps | None
    verification: dict
    fallback: bool
    reason: str = ""
    fit_info: dict = field(default_factory=dict)
    name: str = ""
    source: dict = field(default_factory=lambda: {"file": "", "sha256": ""})

    @property
    def layout(self) -> str:
        """``"pieces"`` or ``"global"`` (also without maps: what the files have always said)."""
        return "global" if self.maps is None else self.maps.layout

    # Sampling (NumPy reference of the Warp sampler) ------------------------------------------
    def _maps(self):
        if self.maps is None:
            raise ValueError("no rational fit (fallback); use .table")
        return self.maps

    def _theta_map(self, tv, mu):
        """(theta_l, dtheta_l/dmu) of the rational map; NaN on table rows."""
        return self._maps().theta_map(self.table, tv, mu)

    def _phi_map(self, tv, tl, u):
        return self._maps().phi_map(self.table, tv, tl, u)

    def _table_rows(self, tv) -> np.ndarray:
        """True where the sample's row is sampled with the table (pieces layout, failed row)."""
        return self._maps().table_rows(self.table, tv)

    def inverse_theta(self, theta_v, mu) -> np.ndarray:
        """theta_l = the rational CDF^-1_v(mu) (rad); NaN on table rows."""
        tv, mu = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(mu, float))
        return self._theta_map(tv, mu)[0]

    def inverse_phi(self, theta_v, theta_l, u) -> np.ndarray:
        """|phi_l| = the rational CDF^-1_v(u | theta_l) (rad, u = |2 tau - 1|); NaN on table rows."""
        tv, tl, u = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_v, theta_l, u)))
        return self._phi_map(tv, tl, u)[0]

    def sample(self, theta_v, mu, tau):
        """``(theta_l, phi_l, alpha)``; alpha = dtheta/dmu * dphi/dtau * sin(theta_l) (= 1/pdf
        in 1/sr^-1), 0 where a clamp is active. Rows without a rational map are sampled with the
        table (alpha = 1 / the table's pdf)."""
        maps = self._maps()
        tv, mu, tau = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(mu, float),
                                          np.asarray(tau, float))
        tl, pl, alpha = sample_maps(lambda m: self._theta_map(tv, m), lambda t, u: self._phi_map(tv, t, u),
                                    mu, tau)
        return table_where(self.table, maps.table_rows(self.table, tv), tv, mu, tau, tl, pl, alpha)

    def theta_cdf(self, theta_v, theta_l, iters: int = 40) -> np.ndarray:
        """P(theta <= theta_l) under the rational sampler (bisection of the monotone F; the
        table's CDF on table rows)."""
        tv, t = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(theta_l, float))
        lo, hi = np.zeros(t.shape), np.ones(t.shape)
        for _ in range(iters):
            m = 0.5 * (lo + hi)
            below = self._theta_map(tv, m)[0] <= t
            lo, hi = np.where(below, m, lo), np.where(below, hi, m)
        out = 0.5 * (lo + hi)
        tab = self._table_rows(tv)
        if tab.any():
            edges = np.linspace(0.0, HALF_PI, self.table.n_t + 1)
            v = self.table.row(tv)
            for r in np.unique(v[tab]):
                k = tab & (v == r)
                out[k] = np.interp(t[k], edges, self.table.cdf_theta[r])
        return np.where(t >= HALF_PI, 1.0, np.where(t <= 0, 0.0, out))

    def phi_cdf_half(self, theta_v, theta_l, phi_abs, iters: int = 40) -> np.ndarray:
        """P(|phi| <= phi_abs | theta_l) under the rational sampler (bisection in u)."""
        tv, tl, p = np.broadcast_arrays(np.asarray(theta_v, float), np.asarray(theta_l, float),
                                        np.asarray(phi_abs, float))
        lo, hi = np.zeros(p.shape), np.ones(p.shape)
        for _ in range(iters):
            m = 0.5 * (lo + hi)
            below = self._phi_map(tv, tl, m)[0] <= p
            lo, hi = np.where(below, m, lo), np.where(below, hi, m)
        out = 0.5 * (lo + hi)
        tab = self._table_rows(tv)
        if tab.any():
            edges = np.linspace(0.0, np.pi, self.table.n_p + 1)
            v = self.table.row(tv)
            j = np.clip(np.floor(tl / (HALF_PI / self.table.n_t)), 0, self.table.n_t - 1).astype(np.intp)
            for r, c in {(int(a), int(b)) for a, b in zip(v[tab], j[tab])}:
                k = tab & (v == r) & (j == c)
                out[k] = np.interp(p[k], edges, self.table.cdf_phi[r, c])
        return np.where(p >= np.pi, 1.0, np.where(p <= 0, 0.0, out))

    # Persistence ------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        t = self.table
        d = {
            "format": FORMAT, "version": VERSION, "name": self.name,
            "sampler": dict(SAMPLER),
            "table": dict(self.table_params),
            "table_data": {"theta_v": t.theta_v.tolist(), "cdf_theta": t.cdf_theta.tolist(),
                           "cdf_phi": t.cdf_phi.tolist(), "row_fallback": t.row_fallback.tolist(),
                           "eps": t.eps, "albedo": t.albedo.tolist()},
            "theta": None, "phi": None,            # global layout: rational-function files
            "layout": self.layout,
            "pieces": None,                        # pieces layout: n_mu, n_u, row_ok
            "rows": None,                          # (the removed per-row layout; always null)
            "verification": jsonable(self.verification),
            "fallback": bool(self.fallback),
            "reason": self.reason,
            "fit": jsonable(self.fit_info),
            "source": dict(self.source),
        }
        if self.maps is not None:
            d.update(self.maps.to_dict(self.name))
        return d

    def save(self, path) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), allow_nan=False) + "\n", encoding="utf-8")


def from_dict(d: dict, path=None) -> CDFFit:
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise BRDFFileError(path, f"not an {FORMAT} file")
    if d.get("version") not in (1, VERSION):
        raise BRDFFileError(path, f"unsupported {FORMAT} version {d.get('version')!r} (this reader knows {VERSION})")
    try:
        td = d["table_data"]
        table = CDFTable(theta_v=np.asarray(td["theta_v"], float), cdf_theta=np.asarray(td["cdf_theta"], float),
                         cdf_phi=np.asarray(td["cdf_phi"], float),
                         row_fallback=np.asarray(td["row_fallback"], bool), eps=float(td["eps"]),
                         albedo=np.asarray(td["albedo"], float))
        layout = d.get("layout", "global")
        if layout == "rows":
            raise BRDFFileError(path, "layout 'rows' is no longer supported; re-run rbrdf-fit cdf")
        if layout == "pieces":
            maps = PieceMaps.from_dict(d["pieces"], table)
        else:
            maps = GlobalMaps.from_dict(d, path)
        fb = bool(d["fallback"])
        if not fb and (maps is None or not maps.complete):
            raise ValueError("no fallback but rational functions missing")
        return CDFFit(table=table, table_params=dict(d.get("table", {})), maps=maps,
                      verification=dict(d.get("verification", {})), fallback=fb,
                      reason=str(d.get("reason", "")), fit_info=dict(d.get("fit", {})),
                      name=str(d.get("name", "")), source=dict(d.get("source", {})))
    except BRDFFileError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise BRDFFileError(path, f"invalid {FORMAT} file ({e.__class__.__name__}: {e})") from None


def load(path) -> CDFFit:
    path = Path(path)
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BRDFFileError(path, "no such file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise BRDFFileError(path, f"cannot read CDF file ({e.__class__.__name__}: {e})") from None
    return from_dict(d, path)


# --------------------------------------------------------------------------------------------
def table_only(evaluate, table_params: dict | None = None, reason: str = "table only", name: str = "",
               source: dict | None = None) -> CDFFit:
    """A :class:`CDFFit` with the tables and no rational fit (``fallback`` True: the tabulated
    samplers use it, a rational sampler falls back to them)."""
    params = dict(DEFAULTS, **(table_params or {}))
    return CDFFit(table=tabulate(evaluate, **params), table_params=params, maps=None,
                  verification={}, fallback=True, reason=reason, name=name,
                  source=source or {"file": "", "sha256": ""})


def fit_cdf(evaluate, name: str = "", table: CDFTable | None = None, table_params: dict | None = None,
            theta_kw: dict | None = None, phi_kw: dict | None = None, refinements: int = 1,
            log=None, source: dict | None = None, monotone: bool = True,
            time_limit_s: float | None = TIME_LIMIT_S, layout: str = "pieces",
            pieces_kw: dict | None = None) -> CDFFit:
    """Tabulate (unless ``table`` is given), build the rational inverse CDFs of ``layout``,
    verify them, decide fallback. ``evaluate(wi, wo) -> (..., 3)`` is the material (1/sr, RGB);
    ``log(str)`` reports.

    ``layout``: ``"pieces"`` (default; :mod:`fit.sampling.pieces`, monotone rational-quadratic
    pieces uniform in mu and u per table row, built from the table (no fitting), rows above the
    variance gate sampled with the table; ``pieces_kw`` tunes it
    (:func:`fit.sampling.variance_gate.fit_pieces`); it has no time limit, 2-21 s per material,
    mostly its variance gate) or ``"global"`` (the paper's F(theta_v, mu), G(theta_v, theta_l, u),
    :func:`fit.sampling.global_layout.fit_global_layout`; ``theta_kw``, ``phi_kw``,
    ``refinements``, ``monotone`` apply to it, and ``time_limit_s`` bounds its fitting time,
    tabulation excluded)."""
    log = log or (lambda s: None)
    params = dict(DEFAULTS, **(table_params or {}))
    if table is None:
        table = tabulate(evaluate, **params)
    if layout == "pieces":
        maps, verification, fb, reason, info = fit_pieces_layout(table, evaluate, log=log, **(pieces_kw or {}))
    elif layout == "global":
        maps, verification, fb, reason, info = fit_global_layout(table, theta_kw, phi_kw, refinements, monotone,
                                                                 time_limit_s, log)
    else:
        raise ValueError(f"layout must be one of {', '.join(map(repr, LAYOUTS))}, not {layout!r}")
    return CDFFit(table=table, table_params=params, maps=maps, verification=verification, fallback=fb,
                  reason=reason, fit_info=info, name=name, source=source or {"file": "", "sha256": ""})


def verify(fit: CDFFit) -> CDFFit:
    """Re-run the verification of ``fit`` (e.g. after editing coefficients); updates
    ``verification``, ``fallback`` and ``reason``. Pieces layout: a row that fails is handed to
    the table (its ``row_ok`` cleared)."""
    maps = fit.maps if fit.maps is not None else GlobalMaps(None, None)
    fit.verification, fit.fallback, fit.reason = maps.verify(fit.table)
    return fit


def file_source(path) -> dict:
    """``{"file": name, "sha256": hex}`` of a source file, as recorded in CDF files (from an RGL
    file, ``rbrdf-fit cdf`` adds ``"incident"``: the roles its tables were built with)."""
    p = Path(path)
    return {"file": p.name, "sha256": file_sha256(p)}
