"""The projected fallback table of a flagged 2-D BRDF fit, and its record in the coefficient file.

A 2-D (theta_h, theta_d) fit whose record flags a channel of a piece as not within its
intervals (:func:`fit.rational.flagged.flagged_regions`) is not rendered from its function
there: the renderer (:mod:`warp_rbrdf.materials.rational`) shows the fit's own median projection
instead, :func:`fallback_table` of :func:`fit.rational.brdf_fit.project_for_fit` with the fit's
grazing cut-off (empty clusters filled from the nearest measured cluster), clamped to the
piece's ``measured_range``. So that such a file renders without its source measurement, the
fitter writes the part of that table the renderer reads into the file's optional top-level key
``"fallback"`` (:func:`fallback_record`; the format: :mod:`fit.rational.coefficient_file`)::

    "fallback": {"kind": "projected median table",
                 "grid": "merl 90x90: theta_h index floor(90 sqrt(theta_h / (pi/2))), theta_d index floor(90 theta_d / (pi/2))",
                 "grazing_cutoff_deg": 79.0,          # = the fit's fit.grazing_cutoff_deg
                 "shape": [90, 90, 3], "dtype": "<f4", "encoding": "base64", "fill": 0.0,
                 "blocks": [{"theta_h_index": [i0, i1], "theta_d_index": [j0, j1],   # inclusive
                             "channels": [2],
                             "data": "..."}],          # base64 of table[i0:i1+1, j0:j1+1, channels],
                                                       # little-endian float32, C order
                 "source": {"file": "satin_rosaline_rgb.bsdf", "sha256": "hex"}}

One block per flagged piece: the clusters of its box (one more cluster on each side, for the
float32 index at a box edge) and its flagged channels; the rest of the table is ``fill`` (0),
never read. :func:`table_from_record` rebuilds the (90, 90, 3) float32 table and checks
everything: kind, grid shape, dtype, cut-off (equal to the fit's), block ranges, base64 and
byte length, finite values >= 0, and that the blocks cover every flagged piece's clusters and
channels, which must record their ``measured_range``. The values the renderer reads are
bit-identical to those it computes from the source measurement.
"""
from __future__ import annotations

import base64
import binascii

import numpy as np

from .. import jsonfields as F
from ..formats.grid import (
    N_THETA_D,
    N_THETA_H,
    theta_d_centres,
    theta_d_index,
    theta_h_centres,
    theta_h_index,
)
from .domain import GRAZING_CUTOFF_DEG
from .flagged import flagged_regions
from .model import measured_range

KEY = "fallback"
KIND = "projected median table"
GRID = ("merl 90x90: theta_h index floor(90 sqrt(theta_h / (pi/2))), "
        "theta_d index floor(90 theta_d / (pi/2))")
SHAPE = (N_THETA_H, N_THETA_D, 3)
DTYPE = "<f4"


def fallback_table(p) -> np.ndarray:
    """The (90, 90, 3) float32 table of a projection (values below 0 as 0) with every empty
    cluster given the value of the nearest (in theta_h, theta_d radians) non-empty cluster of
    the same channel: beyond the fit's grazing cut-off many clusters are empty, and 0 there
    would be a black rim, not a measurement."""
    from scipy.spatial import cKDTree

    v = np.maximum(np.array(p.value, dtype=np.float64), 0.0)
    th, td = np.meshgrid(theta_h_centres(), theta_d_centres(), indexing="ij")
    pts = np.stack([th, td], axis=-1)
    for c in range(v.shape[-1]):
        ch = v[..., c]
        bad = ~np.isfinite(ch)
        if bad.any() and (~bad).any():
            _, idx = cKDTree(pts[~bad]).query(pts[bad])
            ch[bad] = ch[~bad][idx]
    return np.nan_to_num(v, nan=0.0).astype(np.float32)


def fit_cutoff_deg(model) -> float:
    """The grazing cut-off (degrees) of the projection the renderer's fallback table of
    ``model`` is made with: the fit's ``fit_info["grazing_cutoff_deg"]``, or
    :data:`GRAZING_CUTOFF_DEG` when it records none."""
    return float((getattr(model, "fit_info", None) or {}).get("grazing_cutoff_deg") or GRAZING_CUTOFF_DEG)


def _is_2d_brdf(model) -> bool:
    return model.kind == "brdf" and [v.name for v in model.variables] == ["theta_h", "theta_d"]


def region_blocks(model) -> list:
    """``[((i0, i1), (j0, j1), channels)]``: per flagged piece of ``model`` the inclusive
    theta_h and theta_d index ranges of the table clusters the renderer may read there (the
    clusters of its box, one more on each side) and its flagged channels."""
    out = []
    for r in flagged_regions(model):
        (hlo, hhi), (dlo, dhi) = r["theta_h"], r["theta_d"]
        i0, i1 = int(theta_h_index(hlo)), int(theta_h_index(hhi))
        j0, j1 = int(theta_d_index(dlo)), int(theta_d_index(dhi))
        out.append(((max(i0 - 1, 0), min(i1 + 1, N_THETA_H - 1)),
                    (max(j0 - 1, 0), min(j1 + 1, N_THETA_D - 1)), tuple(int(c) for c in r["channels"])))
    return out


def fallback_record(p, model) -> dict | None:
    """The ``"fallback"`` record of a 2-D BRDF fit ``model`` made from the projection ``p``
    (module docstring), or None when no piece is flagged (the file is then written as before)
    or the model is not a 2-D (theta_h, theta_d) BRDF."""
    if not _is_2d_brdf(model):
        return None
    blocks = region_blocks(model)
    if not blocks:
        return None
    table = fallback_table(p)
    recs = []
    for (i0, i1), (j0, j1), chans in blocks:
        part = np.ascontiguousarray(table[i0:i1 + 1, j0:j1 + 1][..., list(chans)], dtype=DTYPE)
        recs.append({"theta_h_index": [i0, i1], "theta_d_index": [j0, j1], "channels": list(chans),
                     "data": base64.b64encode(part.tobytes()).decode("ascii")})
    src = getattr(model, "source", None) or {}
    return {"kind": KIND, "grid": GRID, "grazing_cutoff_deg": fit_cutoff_deg(model), "shape": list(SHAPE),
            "dtype": DTYPE, "encoding": "base64", "fill": 0.0, "blocks": recs,
            "source": {"file": str(src.get("file", "")), "sha256": str(src.get("sha256", ""))}}


def _index_range(v, key: str, n: int) -> tuple:
    if not (isinstance(v, list) and len(v) == 2 and all(isinstance(x, int) and not isinstance(x, bool) for x in v)):
        raise F.Invalid(key, "expected two integer indices [first, last]")
    a, b = v
    if not 0 <= a <= b < n:
        raise F.Invalid(key, f"[{a}, {b}] is not a range inside [0, {n - 1}]")
    return a, b


def table_from_record(rec, model, key: str = KEY) -> np.ndarray:
    """The (90, 90, 3) float32 fallback table of a ``"fallback"`` record ``rec`` of ``model``
    (module docstring): the blocks' values, ``fill`` elsewhere. :class:`fit.jsonfields.Invalid`
    naming the key on any problem: not a 2-D BRDF, another kind, grid shape, dtype or cut-off
    than the fit's, a block out of range, data that are not base64 of the block's size, values
    not finite or below 0, a flagged piece or channel the blocks do not cover, a flagged channel
    without ``measured_range``."""
    F.obj(rec, key)
    if not _is_2d_brdf(model):
        raise F.Invalid(key, "a fallback table belongs only to a 2-D (theta_h, theta_d) BRDF fit")
    kind = F.string(F.get(rec, "kind", key), F.sub(key, "kind"), max_len=64)
    if kind != KIND:
        raise F.Invalid(F.sub(key, "kind"), f"expected {KIND!r}, got {kind[:40]!r}")
    if F.get(rec, "shape", key) != list(SHAPE):
        raise F.Invalid(F.sub(key, "shape"), f"expected {list(SHAPE)}, got {str(rec['shape'])[:40]}")
    if F.get(rec, "dtype", key) != DTYPE:
        raise F.Invalid(F.sub(key, "dtype"), f"expected {DTYPE!r} (little-endian float32), got {str(rec['dtype'])[:20]!r}")
    if rec.get("encoding", "base64") != "base64":
        raise F.Invalid(F.sub(key, "encoding"), f"expected 'base64', got {str(rec['encoding'])[:20]!r}")
    cut = F.number(F.get(rec, "grazing_cutoff_deg", key), F.sub(key, "grazing_cutoff_deg"))
    want = fit_cutoff_deg(model)
    if cut != want:
        raise F.Invalid(F.sub(key, "grazing_cutoff_deg"), f"{cut:g} deg, not the fit's grazing cut-off {want:g} deg")
    fill = F.number(rec.get("fill", 0.0), F.sub(key, "fill"), lo=0.0)
    table = np.full(SHAPE, fill, np.float32)
    covered = np.zeros(SHAPE, bool)
    kb = F.sub(key, "blocks")
    blocks = F.get(rec, "blocks", key)
    if not isinstance(blocks, list) or len(blocks) > 64:
        raise F.Invalid(kb, "expected a list of at most 64 blocks")
    for n, b in enumerate(blocks):
        k = F.sub(kb, n)
        F.obj(b, k)
        i0, i1 = _index_range(F.get(b, "theta_h_index", k), F.sub(k, "theta_h_index"), N_THETA_H)
        j0, j1 = _index_range(F.get(b, "theta_d_index", k), F.sub(k, "theta_d_index"), N_THETA_D)
        chans = F.get(b, "channels", k)
        if (not isinstance(chans, list) or not 1 <= len(chans) <= 3 or len(set(map(repr, chans))) != len(chans)
                or not all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c < 3 for c in chans)):
            raise F.Invalid(F.sub(k, "channels"), "expected a list of distinct channel indices in 0, 1, 2")
        data = F.get(b, "data", k)
        if not isinstance(data, str):
            raise F.Invalid(F.sub(k, "data"), "expected a base64 string")
        try:
            raw = base64.b64decode(data.encode("ascii"), validate=True)
        except (binascii.Error, UnicodeEncodeError, ValueError):
            raise F.Invalid(F.sub(k, "data"), "not valid base64") from None
        shape = (i1 - i0 + 1, j1 - j0 + 1, len(chans))
        if len(raw) != 4 * int(np.prod(shape)):
            raise F.Invalid(F.sub(k, "data"), f"{len(raw)} bytes, expected {4 * int(np.prod(shape))} "
                                              f"(float32 of {shape[0]} x {shape[1]} clusters x {shape[2]} channels)")
        vals = np.frombuffer(raw, dtype=DTYPE).reshape(shape)
        if not np.isfinite(vals).all() or (vals < 0).any():
            raise F.Invalid(F.sub(k, "data"), "holds values that are not finite or below 0")
        for m, c in enumerate(chans):
            table[i0:i1 + 1, j0:j1 + 1, c] = vals[..., m]
            covered[i0:i1 + 1, j0:j1 + 1, c] = True
    for n, ((i0, i1), (j0, j1), chans) in enumerate(region_blocks(model)):
        if not covered[i0:i1 + 1, j0:j1 + 1][..., list(chans)].all():
            raise F.Invalid(kb, f"the blocks do not cover flagged piece {n + 1} (theta_h index {i0}-{i1}, "
                                f"theta_d index {j0}-{j1}, channels {list(chans)})")
    for r in flagged_regions(model):
        for c in r["channels"]:
            if measured_range(r["model"].function_info[c]) is None:
                raise F.Invalid(key, f"flagged piece {r['leaf'] + 1} channel {c} records no measured_range "
                                     "(a file with an embedded table records it)")
    return table
