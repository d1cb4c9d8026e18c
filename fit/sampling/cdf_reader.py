"""Reading ``rbrdf-cdf`` files (:func:`load`, :func:`from_dict`): every value and size checked
(:mod:`fit.limits`: the tables' shapes and strictly increasing CDFs, the pieces' sizes before they
are rebuilt, :func:`check_pieces_size`), the pieces rebuilt from the table and verified (or, where
the record stores their knots and slopes, ``pieces.knots`` as a fit's sampler record does, made
from those and their structure checked: :func:`check_pieces`), a global
layout's verification run again rather than read from the file; files of the removed per-row
layout (``"layout": "rows"``) refused. Every problem is one :class:`fit.errors.BRDFFileError`
line naming the file and the key (docs/robustness.md). Reading a pieces-layout or table-only
record imports neither SciPy nor the fitter (:mod:`fit.sampling.global_layout` is imported for a
global layout only).
"""
from __future__ import annotations

import numpy as np

from .. import jsonfields as F
from ..errors import BRDFFileError
from ..formats.angles import HALF_PI
from ..inputs import read_json
from ..limits import MAX_CDF_PHI_PIECES, MAX_CDF_PIECES, MAX_CDF_ROWS, check_memory
from . import binary_arrays
from .cdf_fit import FORMAT, VERSION, CDFFit
from .pieces import PieceMaps, pieces_from_knots, verify_pieces
from .table import CDFTable, check_table_size


#: The knots and slopes of the pieces (:func:`fit.sampling.pieces.piece_knots`), with their shapes for ``n_v`` rows,
#: ``n_mu`` theta and ``n_u`` phi pieces: ``theta`` the knots theta_l (rad) at mu = k / n_mu,
#: ``theta_slopes`` their slopes d theta_l / dmu, ``end_slopes`` the slopes d y / dmu in
#: y = sin^2(theta_l) (the end pieces; 0 at the last knot of a ``flat_end`` row), ``phi`` the
#: knots |phi_l| (rad) at u = j / n_u per theta piece and ``phi_slopes`` their slopes.
KNOT_KEYS = ("theta", "theta_slopes", "end_slopes", "phi", "phi_slopes")


def knot_shapes(n_v: int, n_mu: int, n_u: int) -> dict:
    """The shape of each array of :data:`KNOT_KEYS`."""
    t = (n_v, n_mu + 1)
    p = (n_v, n_mu, n_u + 1)
    return {"theta": t, "theta_slopes": t, "end_slopes": t, "phi": p, "phi_slopes": p}


#: The largest slope ratio ``a0``, ``a1`` (knot slope / the piece's secant slope) of a piece made
#: from PCHIP slopes: Fritsch-Carlson slopes are at most 3x the secant of either side (SciPy's
#: end slopes included), so a stored piece above it was not made by :func:`fit.sampling.pieces.piece_knots`; the bound
#: also keeps every value and derivative finite (:func:`check_pieces`). The margin is rounding.
MAX_SLOPE_RATIO = 3.0 + 1e-9


def check_pieces(pm: PieceMaps) -> dict:
    """The structural check of pieces made from stored knots (:func:`fit.sampling.pieces.pieces_from_knots`), as
    :func:`fit.sampling.pieces.verify_pieces` returns it, without evaluating a piece: h >= 0 and
    0 <= a0, a1 <= :data:`MAX_SLOPE_RATIO` (every piece monotone, finite, without a pole: the
    denominator 1 + (a0 + a1 - 2) x(1 - x) lies in [1/2, 2]), pieces that meet (continuous)
    and the ends 0 and pi/2 (theta) / 0 and pi (phi) (normalised). That is what the sampled
    checks of :func:`fit.sampling.pieces.verify_pieces` test at points; it costs one pass over the coefficients."""
    return verify_pieces(pm, n_check=0, max_slope_ratio=MAX_SLOPE_RATIO)


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
    raw_p = F.get(td, "cdf_phi", key)
    if binary_arrays.is_encoded(raw_t):
        n_t = binary_arrays.encoded_shape(raw_t, k(key, "cdf_theta"))[-1] - 1
    else:
        n_t = (len(raw_t[0]) - 1) if isinstance(raw_t, list) and raw_t and isinstance(raw_t[0], list) else -1
    try:
        n_p = (binary_arrays.encoded_shape(raw_p, k(key, "cdf_phi"))[-1] - 1 if binary_arrays.is_encoded(raw_p)
               else len(raw_p[0][0]) - 1)
    except (TypeError, IndexError, KeyError):
        n_p = -1
    try:
        check_table_size(n_v, n_t, n_p)
    except ValueError as e:
        raise F.Invalid(key, f"table of the wrong size: {e}") from None
    ct = _float_array(raw_t, k(key, "cdf_theta"), (n_v, n_t + 1))
    cp = _float_array(raw_p, k(key, "cdf_phi"), (n_v, n_t, n_p + 1))
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


def _float_array(raw, key: str, shape: tuple) -> np.ndarray:
    """A table's float array: nested JSON lists, or an encoded array object
    (:mod:`fit.sampling.binary_arrays`: a coefficient file's sampler record), of ``shape``."""
    if binary_arrays.is_encoded(raw):
        return binary_arrays.decode(raw, key, shape, max_size=int(np.prod(shape)))
    return F.array(raw, key, shape)


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
    if pd.get("knots") is None:
        return PieceMaps.from_dict(out, table)          # rebuilt from the table and verified
    knots = _knots_from_dict(pd["knots"], F.sub(key, "knots"), table.n_v, n_mu, n_u, out.get("flat_end"))
    pm = pieces_from_knots(knots, row_ok=out["row_ok"], flat_end=out.get("flat_end"))
    bad = ~np.asarray(check_pieces(pm)["rows"]) & pm.row_ok
    if bad.any():
        raise F.Invalid(F.sub(key, "knots"), f"stored pieces of rows {np.flatnonzero(bad).tolist()} fail the "
                                             "check (not monotone, finite and normalised)")
    return pm


def _knots_from_dict(kd, key: str, n_v: int, n_mu: int, n_u: int, flat_end) -> dict:
    """The ``pieces.knots`` record (a fit's sampler record: the knots and slopes of the pieces,
    :data:`KNOT_KEYS`): every array of its shape (sizes checked before
    decoding), finite; the knots of every map from exactly 0 to pi/2 (theta) or pi (phi), as
    :func:`fit.sampling.pieces.piece_knots` makes them; a ``flat_end`` row's last end slope 0."""
    F.obj(kd, key)
    extra = sorted(set(kd) - set(KNOT_KEYS))
    if extra:
        raise F.Invalid(F.sub(key, extra[0]), f"unknown key (expected {', '.join(KNOT_KEYS)})")
    shapes = knot_shapes(n_v, n_mu, n_u)
    out = {k: _float_array(F.get(kd, k, key), F.sub(key, k), shapes[k]) for k in KNOT_KEYS}
    for k, span in (("theta", HALF_PI), ("phi", np.pi)):
        if np.any(out[k][..., 0] != 0.0) or np.any(out[k][..., -1] != span):
            raise F.Invalid(F.sub(key, k), f"a map's knots do not run from 0 to {span:.17g}")
    if flat_end is not None and np.any(out["end_slopes"][np.asarray(flat_end, bool), -1] != 0.0):
        raise F.Invalid(F.sub(key, "end_slopes"), "a flat_end row's last slope is not 0")
    return out


def _prefixed(e: F.Invalid, prefix: str) -> str:
    """The message of ``e`` with its key under ``prefix`` (a record inside another file)."""
    if not prefix or not e.key:
        return str(e)
    return f"key {prefix}.{e.key}: {str(e)[len(f'key {e.key}: '):]}"


def from_dict(d: dict, path=None, what: str = f"{FORMAT} file", prefix: str = "") -> CDFFit:
    """A :class:`CDFFit` from a parsed ``rbrdf-cdf`` file, with every value checked
    (:func:`_table_from_dict`, the limits of :mod:`fit.limits`) and nothing taken on trust:
    the pieces are rebuilt from the table and verified, and a global layout's maps are
    re-verified (monotone, covering, Q > 0) unless the file falls back to the table.
    :class:`BRDFFileError` naming the file and the key on any problem: ``what`` names the
    record (an ``rbrdf-cdf`` file, or a coefficient file's sampler record) and ``prefix`` is
    put before its keys (``sampler``)."""
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
            from .global_layout import GlobalMaps   # the fitter and SciPy: only for this layout

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
        raise BRDFFileError(path, f"invalid {what}: {_prefixed(e, prefix)}") from None
    except (KeyError, TypeError, ValueError, IndexError, ArithmeticError) as e:
        raise BRDFFileError(path, f"invalid {what} ({e.__class__.__name__}: {e})") from None


def table_from_dict(td, key: str = "table_data") -> CDFTable:
    """The tabulated sampler of a file's ``table_data`` record, every array checked (the
    ``_table_from_dict`` checks); :class:`fit.jsonfields.Invalid` naming the key."""
    return _table_from_dict(td, key)


def load(path) -> CDFFit:
    """Read an ``rbrdf-cdf`` JSON file (:func:`fit.inputs.read_json`: a regular file of at most
    :data:`fit.limits.MAX_JSON_BYTES`, strict JSON) and validate it (:func:`from_dict`)."""
    return from_dict(read_json(path, "CDF file"), path)
