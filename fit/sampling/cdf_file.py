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
removed per-row layout (``"layout": "rows"``) are refused with a one-line error. Loading
checks every value and size (:func:`from_dict`, :mod:`fit.limits`): the tables' shapes and
strictly increasing CDFs, the pieces' sizes before they are rebuilt, and a global layout's
verification is run again rather than read from the file (docs/robustness.md).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import jsonfields as F
from ..errors import BRDFFileError
from ..formats.angles import HALF_PI
from ..formats.measured import file_sha256
from ..inputs import read_json
from ..limits import MAX_CDF_PHI_PIECES, MAX_CDF_PIECES, MAX_CDF_ROWS, check_memory
from ..progress import Deadline
from ..rational.coefficient_file import jsonable
from .global_layout import GlobalMaps, fit_global_layout
from .maps import sample_maps
from .pieces import PieceMaps
from .table import CDFTable, check_table_size, table_where, tabulate
from .variance_gate import fit_pieces_layout

FORMAT = "rbrdf-cdf"
VERSION = 2   # 2: "layout" key (pieces or global); version-1 files (global layout) still load
DEFAULTS = dict(n_v=32, n_t=64, n_p=64, sub=3, eps=0.02, noise=1e-6)
TIME_LIMIT_S = 180.0   # default bound on fit_cdf's time (s), tabulation included
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
        """Write the ``rbrdf-cdf`` JSON file through a temporary file renamed onto ``path`` when
        complete (:func:`fit.outputs.atomic_write`)."""
        from ..outputs import atomic_write

        text = json.dumps(self.to_dict(), allow_nan=False)
        with atomic_write(Path(path)) as f:
            f.write(text + "\n")


def check_pieces_size(n_v: int, n_t: int, n_p: int, n_mu: int, n_u: int) -> None:
    """``ValueError`` when the pieces layout of ``n_mu`` theta and ``n_u`` phi pieces per map
    over an ``n_v`` x ``n_t`` x ``n_p`` table is beyond :mod:`fit.limits` (pieces per map, phi
    pieces of the file, and the estimated memory of building and verifying them)."""
    if not 3 <= n_mu <= MAX_CDF_PIECES:
        raise ValueError(f"n_mu = {n_mu} is outside [3, {MAX_CDF_PIECES}] (fit.limits.MAX_CDF_PIECES)")
    if not 1 <= n_u <= MAX_CDF_PIECES:
        raise ValueError(f"n_u = {n_u} is outside [1, {MAX_CDF_PIECES}] (fit.limits.MAX_CDF_PIECES)")
    if n_v * n_mu * n_u > MAX_CDF_PHI_PIECES:
        raise ValueError(f"n_v x n_mu x n_u = {n_v * n_mu * n_u} phi pieces, above the limit "
                         f"{MAX_CDF_PHI_PIECES} (fit.limits.MAX_CDF_PHI_PIECES)")
    # measured: 4 rows x 1024 x 512 pieces peak at 774 MB
    check_memory(8.0 * (6 * n_v * n_mu * n_t + 3 * n_v * n_mu * (n_p + 1) + 48 * n_v * n_mu * n_u),
                 f"{n_mu} x {n_u} pieces of {n_v} rows")


def _table_from_dict(td, key: str = "table_data") -> CDFTable:
    """The tabulated sampler of a file, every array checked: shapes consistent with
    ``theta_v`` (n_v,), ``cdf_theta`` (n_v, n_t + 1), ``cdf_phi`` (n_v, n_t, n_p + 1) within
    :mod:`fit.limits`; ``theta_v`` the row centres; every CDF starts at 0, ends at 1 and
    increases strictly (the eps mixture gives every cell mass; a cell of mass 0 would never be
    sampled and bias the estimates); ``eps`` in (0, 1]; albedo finite and >= 0."""
    F.obj(td, key)
    k = F.sub
    tv = F.array(F.get(td, "theta_v", key), k(key, "theta_v"), (None,))
    n_v = len(tv)
    if not 2 <= n_v <= MAX_CDF_ROWS:
        raise F.Invalid(k(key, "theta_v"), f"{n_v} rows, outside [2, {MAX_CDF_ROWS}] (fit.limits.MAX_CDF_ROWS)")
    raw_t = F.get(td, "cdf_theta", key)
    n_t = (len(raw_t[0]) - 1) if isinstance(raw_t, list) and raw_t and isinstance(raw_t[0], list) else -1
    raw_p = F.get(td, "cdf_phi", key)
    try:
        n_p = len(raw_p[0][0]) - 1
    except (TypeError, IndexError, KeyError):
        n_p = -1
    try:
        check_table_size(n_v, n_t, n_p)
    except ValueError as e:
        raise F.Invalid(key, f"table of the wrong size: {e}") from None
    ct = F.array(raw_t, k(key, "cdf_theta"), (n_v, n_t + 1))
    cp = F.array(raw_p, k(key, "cdf_phi"), (n_v, n_t, n_p + 1))
    fb = F.array(F.get(td, "row_fallback", key), k(key, "row_fallback"), (n_v,), kind="bool")
    eps = F.number(F.get(td, "eps", key), k(key, "eps"))
    if not 0.0 < eps <= 1.0:
        raise F.Invalid(k(key, "eps"), f"{eps:g} is outside (0, 1]")
    albedo = F.array(F.get(td, "albedo", key), k(key, "albedo"), (n_v,))
    if albedo.min() < 0 or albedo.max() > 1e3:
        raise F.Invalid(k(key, "albedo"), "values outside [0, 1000]")
    centres = (np.arange(n_v) + 0.5) / n_v * HALF_PI
    if not np.allclose(tv, centres, rtol=0, atol=1e-9):
        raise F.Invalid(k(key, "theta_v"), "not the row centres (i + 1/2) / n_v * pi/2")
    for name, c in (("cdf_theta", ct), ("cdf_phi", cp)):
        if np.any(np.abs(c[..., 0]) > 1e-12) or np.any(np.abs(c[..., -1] - 1.0) > 1e-9):
            raise F.Invalid(k(key, name), "a CDF does not run from 0 to 1")
        d = np.diff(c, axis=-1)
        if not np.all(d > 0):
            where = np.argwhere(~(d > 0))[0].tolist()
            raise F.Invalid(k(key, name), f"not strictly increasing (at index {where}): a decreasing CDF or a "
                                          "cell of zero mass")
    return CDFTable(theta_v=tv, cdf_theta=ct, cdf_phi=cp, row_fallback=fb, eps=eps, albedo=albedo)


def _table_params(tp, table: CDFTable, key: str = "table") -> dict:
    """The ``table`` record (the parameters the tables were built with): an object whose
    ``n_v``, ``n_t``, ``n_p`` (and ``sub``) are JSON integers and agree with the tables'
    shapes, whose ``eps`` is the table's ``eps`` and ``noise`` a number >= 0, when given."""
    tp = dict(F.obj(tp, key))
    for k, n in (("n_v", table.n_v), ("n_t", table.n_t), ("n_p", table.n_p)):
        if k in tp:
            got = F.integer(tp[k], F.sub(key, k))
            if got != n:
                raise F.Invalid(F.sub(key, k), f"{got}, but the tables in table_data have {k} = {n}")
    if "sub" in tp:
        F.integer(tp["sub"], F.sub(key, "sub"), lo=1, hi=64)
    if "eps" in tp and abs(F.number(tp["eps"], F.sub(key, "eps")) - table.eps) > 1e-12:
        raise F.Invalid(F.sub(key, "eps"), f"{tp['eps']:g}, but table_data.eps is {table.eps:g}")
    if "noise" in tp:
        F.number(tp["noise"], F.sub(key, "noise"), lo=0.0)
    return tp


def _source(src, key: str = "source") -> dict:
    """The ``source`` record (informative): ``file`` a name, ``sha256`` a hexadecimal digest,
    ``incident`` ``view`` or ``light``, when given."""
    src = F.source_record(src, key)
    if src.get("incident") is not None:
        F.string(src["incident"], F.sub(key, "incident"), choices=("view", "light"))
    return src


def _pieces_from_dict(pd, table: CDFTable, key: str = "pieces") -> PieceMaps:
    F.obj(pd, key)
    n_mu = F.integer(F.get(pd, "n_mu", key), F.sub(key, "n_mu"))
    n_u = F.integer(F.get(pd, "n_u", key), F.sub(key, "n_u"))
    try:
        check_pieces_size(table.n_v, table.n_t, table.n_p, n_mu, n_u)
    except ValueError as e:
        raise F.Invalid(key, str(e)) from None
    raw = F.get(pd, "row_ok", key)
    if isinstance(raw, list) and len(raw) != table.n_v:
        raise F.Invalid(F.sub(key, "row_ok"), f"{len(raw)} row flags for {table.n_v} table rows")
    row_ok = F.array(raw, F.sub(key, "row_ok"), (table.n_v,), kind="bool")
    out = {"n_mu": n_mu, "n_u": n_u, "row_ok": row_ok.tolist()}
    if pd.get("flat_end") is not None:
        out["flat_end"] = F.array(pd["flat_end"], F.sub(key, "flat_end"), (table.n_v,), kind="bool").tolist()
    return PieceMaps.from_dict(out, table)


def from_dict(d: dict, path=None) -> CDFFit:
    """A :class:`CDFFit` from a parsed ``rbrdf-cdf`` file, with every value checked
    (:func:`_table_from_dict`, the limits of :mod:`fit.limits`) and nothing taken on trust:
    the pieces are rebuilt from the table and verified, and a global layout's maps are
    re-verified (monotone, covering, Q > 0) unless the file falls back to the table.
    :class:`BRDFFileError` naming the file and the key on any problem."""
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise BRDFFileError(path, f"not an {FORMAT} file")
    ver = d.get("version")
    if type(ver) is not int or ver not in (1, VERSION):   # 2.0 or true is not the integer 2 or 1
        raise BRDFFileError(path, f"key version: unsupported {FORMAT} version "
                                  f"{ver if type(ver) is int else repr(ver)[:20]} (this reader knows the "
                                  f"integers 1 and {VERSION})")
    try:
        table = _table_from_dict(F.get(d, "table_data"), "table_data")
        layout = F.string(d.get("layout", "global"), "layout", choices=("pieces", "global", "rows"))
        if layout == "rows":
            raise BRDFFileError(path, "layout 'rows' is no longer supported; re-run rbrdf-fit cdf")
        fb = F.flag(F.get(d, "fallback"), "fallback")
        if layout == "pieces":
            maps = _pieces_from_dict(F.get(d, "pieces"), table) if d.get("pieces") is not None else None
        else:
            for k in ("theta", "phi"):
                if d.get(k) is not None:
                    F.obj(d[k], k)
            maps = GlobalMaps.from_dict(d, path)
            if maps is not None:
                for k, f, n in (("theta", maps.theta, 2), ("phi", maps.phi, 3)):
                    if f is not None and f.n_vars != n:
                        raise F.Invalid(k, f"the {k} map needs {n} variables, not {f.n_vars}")
        if not fb and (maps is None or not maps.complete):
            raise F.Invalid("fallback", "false, but the rational maps are missing")
        verification = dict(F.obj(d.get("verification", {}), "verification"))
        reason = F.name(d.get("reason", ""), "reason", max_len=4096)
        if not fb and layout == "global":
            # never trust the file's verdict: verify the maps again
            verification, bad, why = maps.verify(table)
            if bad:
                raise F.Invalid("fallback", f"false, but the rational maps fail verification ({why})")
        return CDFFit(table=table, table_params=_table_params(d.get("table", {}), table), maps=maps,
                      verification=verification, fallback=fb, reason=reason,
                      fit_info=dict(F.obj(d.get("fit", {}), "fit")),
                      name=F.name(d.get("name", ""), "name"),
                      source=_source(d.get("source", {})))
    except BRDFFileError:
        raise
    except F.Invalid as e:
        raise BRDFFileError(path, f"invalid {FORMAT} file: {e}") from None
    except (KeyError, TypeError, ValueError, IndexError, ArithmeticError) as e:
        raise BRDFFileError(path, f"invalid {FORMAT} file ({e.__class__.__name__}: {e})") from None


def load(path) -> CDFFit:
    """Read an ``rbrdf-cdf`` JSON file (:func:`fit.inputs.read_json`: a regular file of at most
    :data:`fit.limits.MAX_JSON_BYTES`, strict JSON) and validate it (:func:`from_dict`)."""
    return from_dict(read_json(path, "CDF file"), path)


# --------------------------------------------------------------------------------------------
def table_only(evaluate, table_params: dict | None = None, reason: str = "table only", name: str = "",
               source: dict | None = None, progress=None) -> CDFFit:
    """A :class:`CDFFit` with the tables and no rational fit (``fallback`` True: the tabulated
    samplers use it, a rational sampler falls back to them). ``progress(stage, done, total)``:
    :mod:`fit.progress`."""
    params = dict(DEFAULTS, **(table_params or {}))
    return CDFFit(table=tabulate(evaluate, **params, progress=progress), table_params=params, maps=None,
                  verification={}, fallback=True, reason=reason, name=name,
                  source=source or {"file": "", "sha256": ""})


def fit_cdf(evaluate, name: str = "", table: CDFTable | None = None, table_params: dict | None = None,
            theta_kw: dict | None = None, phi_kw: dict | None = None, refinements: int = 1,
            log=None, source: dict | None = None, monotone: bool = True,
            time_limit_s: float | None = TIME_LIMIT_S, layout: str = "pieces",
            pieces_kw: dict | None = None, progress=None, deadline: Deadline | None = None) -> CDFFit:
    """Tabulate (unless ``table`` is given), build the rational inverse CDFs of ``layout``,
    verify them, decide fallback. ``evaluate(wi, wo) -> (..., 3)`` is the material (1/sr, RGB);
    ``log(str)`` reports.

    ``layout``: ``"pieces"`` (default; :mod:`fit.sampling.pieces`, monotone rational-quadratic
    pieces uniform in mu and u per table row, built from the table (no fitting), rows above the
    variance gate sampled with the table; ``pieces_kw`` tunes it
    (:func:`fit.sampling.variance_gate.fit_pieces`); 2-21 s per material on an idle machine,
    mostly its variance gate) or ``"global"`` (the paper's F(theta_v, mu), G(theta_v, theta_l, u),
    :func:`fit.sampling.global_layout.fit_global_layout`; ``theta_kw``, ``phi_kw``,
    ``refinements``, ``monotone`` apply to it).

    ``time_limit_s`` (s, None: none) bounds the whole call, tabulation included, through one
    :class:`fit.progress.Deadline` shared by every stage (``deadline``, when given, replaces
    it: a command passes the deadline it started at). The table is always completed; once the
    deadline has passed, the rows not yet checked (pieces) or the maps not yet verified
    (global) are sampled with the table and the reason says that the time limit was reached.
    ``progress(stage, done, total)`` (:mod:`fit.progress`) is told each stage's steps:
    ``"tabulating the CDFs"`` (rows), ``"variance gate (N phi pieces)"`` (rows), ``"global
    layout fits"`` (fits and refits)."""
    log = log or (lambda s: None)
    if deadline is None:
        deadline = Deadline(time_limit_s)
    params = dict(DEFAULTS, **(table_params or {}))
    if table is None:
        table = tabulate(evaluate, **params, progress=progress)
    if layout == "pieces":
        kw = dict(pieces_kw or {}, progress=progress, deadline=deadline)
        maps, verification, fb, reason, info = fit_pieces_layout(table, evaluate, log=log, **kw)
    elif layout == "global":
        maps, verification, fb, reason, info = fit_global_layout(table, theta_kw, phi_kw, refinements, monotone,
                                                                 deadline.seconds, log, deadline=deadline,
                                                                 progress=progress)
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
