"""Rational inverse CDFs of one material for importance sampling: the
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

The modules: :mod:`fit.sampling.cdf_fit` (:class:`CDFFit`, the format's name and version, writing),
:mod:`fit.sampling.cdf_reader` (:func:`from_dict`, :func:`load`, :func:`check_pieces_size`) and
this one (:func:`fit_cdf`, :func:`table_only`, :func:`verify`, :func:`file_source`, the defaults),
which also gives the names of the other two.
"""
from __future__ import annotations

from pathlib import Path

from ..blas_threads import one_blas_thread
from ..formats.measured import file_sha256
from ..progress import Deadline
from .cdf_fit import FORMAT, SAMPLER, VERSION, CDFFit
from .cdf_reader import check_pieces_size, from_dict, load
from .global_layout import GlobalMaps, fit_global_layout
from .table import CDFTable, tabulate
from .variance_gate import fit_pieces_layout

__all__ = ["DEFAULTS", "FORMAT", "LAYOUTS", "SAMPLER", "TIME_LIMIT_S", "VERSION", "CDFFit", "check_pieces_size",
           "file_source", "fit_cdf", "from_dict", "load", "table_only", "verify"]

DEFAULTS = dict(n_v=32, n_t=64, n_p=64, sub=3, eps=0.02, noise=1e-6)
TIME_LIMIT_S = 180.0   # default bound on fit_cdf's time (s), tabulation included
LAYOUTS = ("pieces", "global")


def table_only(evaluate, table_params: dict | None = None, reason: str = "table only", name: str = "",
               source: dict | None = None, progress=None) -> CDFFit:
    """A :class:`CDFFit` with the tables and no rational fit (``fallback`` True: the tabulated
    samplers use it, a rational sampler falls back to them). ``progress(stage, done, total)``:
    :mod:`fit.progress`."""
    params = dict(DEFAULTS, **(table_params or {}))
    return CDFFit(table=tabulate(evaluate, **params, progress=progress), table_params=params, maps=None,
                  verification={}, fallback=True, reason=reason, name=name,
                  source=source or {"file": "", "sha256": ""})


@one_blas_thread
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
