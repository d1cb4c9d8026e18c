"""A fit's own inverse CDFs, stored in its coefficient file: the ``sampler`` record.

A rational BRDF fit (``rbrdf-rational``, 2-D or 3-D) may carry the inverse CDFs of ρ·cos θl
made from the fit itself (:mod:`fit.sampling.model_sampler`) under the optional top-level key
``"sampler"`` (:data:`fit.rational.coefficient_format.SAMPLER_KEY`), so that a renderer samples
it with no table built at load and no source measurement: one self-contained file. The record is
an ``rbrdf-cdf`` object (:meth:`fit.sampling.cdf_fit.CDFFit.to_dict`: table parameters, the
layout and its maps, verification, fallback flag and reason) whose two CDF arrays
``table_data.cdf_theta`` (n_v, n_t + 1) and ``table_data.cdf_phi`` (n_v, n_t, n_p + 1) are
encoded arrays (:mod:`fit.sampling.binary_arrays`: base64 of little-endian float64); a pieces
layout also stores its knots and slopes, ``pieces.knots`` (:data:`fit.sampling.cdf_reader.KNOT_KEYS`,
encoded the same way: what a load would otherwise rebuild from the table with SciPy), plus

* ``fit_sha256``: :func:`fit.rational.coefficient_format.content_sha256` of the file without
  the record: the fit it was made from. The coefficient reader compares it with the file it
  reads and refuses a mismatch (coefficients edited after the sampler was made), and the writer
  refuses to write a model whose sampler was made from other coefficients;
* ``sha256``: :func:`record_sha256` of the record without this key: an edit of the record (a
  CDF value, a row flag) or damage is refused where the record is read (:func:`read`).

Reading (:func:`read`) checks the digest, then every value as an ``rbrdf-cdf`` file is checked
(:func:`fit.sampling.cdf_reader.from_dict`: sizes within :mod:`fit.limits` before anything is
decoded, strictly increasing CDFs, the pieces made from the stored knots and their structure
checked (:func:`fit.sampling.cdf_reader.check_pieces`: finite, monotone, continuous, normalised), a
global layout verified again); a record without ``pieces.knots`` (written before they were
stored) has its pieces rebuilt from the table and verified, as an ``rbrdf-cdf`` file. A renderer
that needs only the table reads only the table (``maps=False``). Every problem is one
:class:`fit.errors.BRDFFileError` line naming the file and the key (``sampler.…``).
"""
from __future__ import annotations

import hashlib
import json

from .. import jsonfields as F
from ..errors import BRDFFileError
from ..rational.coefficient_format import SAMPLER_KEY, content_sha256
from ..rational.coefficient_writer import jsonable, to_dict
from . import binary_arrays
from .cdf_fit import FORMAT, VERSION, CDFFit
from .cdf_reader import KNOT_KEYS, from_dict, table_from_dict
from .pieces import PieceMaps, piece_knots
from .table import CDFTable

KEY = SAMPLER_KEY
WHAT = "sampler record"


def record_sha256(rec: dict) -> str:
    """SHA-256 (hex) of a sampler record without its ``sha256`` key (canonical JSON: sorted
    keys, no spaces, ASCII)."""
    body = {k: v for k, v in rec.items() if k != "sha256"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def model_sha256(model) -> str:
    """:func:`fit.rational.coefficient_format.content_sha256` of ``model`` as its file would hold
    it, without a sampler record."""
    saved, model.sampler = getattr(model, "sampler", None), None
    try:
        return content_sha256(jsonable(to_dict(model)))
    finally:
        model.sampler = saved


def record(cdf: CDFFit, fit_sha256: str) -> dict:
    """The sampler record of ``cdf`` (module docstring) for the fit whose content digest is
    ``fit_sha256``."""
    d = cdf.to_dict()
    t = cdf.table
    d["table_data"] = dict(d["table_data"], cdf_theta=binary_arrays.encode(t.cdf_theta),
                           cdf_phi=binary_arrays.encode(t.cdf_phi))
    if isinstance(cdf.maps, PieceMaps):
        pm = cdf.maps
        knots = piece_knots(t, pm.n_mu, pm.n_u, pm.flat_end)     # what a load would rebuild
        d["pieces"] = dict(d["pieces"], knots={k: binary_arrays.encode(knots[k]) for k in KNOT_KEYS})
    d = jsonable(d)
    d["fit_sha256"] = fit_sha256
    d["sha256"] = record_sha256(d)
    return d


def attach(model, cdf: CDFFit):
    """Store ``cdf`` (made from ``model``: :func:`fit.sampling.model_sampler.fit_model_sampler`)
    as ``model.sampler``, bound to the model's current content; returns ``model``. Saving the
    model (:func:`fit.rational.coefficient_file.save`) writes it into the file."""
    model.sampler = record(cdf, model_sha256(model))
    return model


def _check_head(rec, path) -> dict:
    if not isinstance(rec, dict):
        raise BRDFFileError(path, f"invalid {WHAT}: key {KEY}: expected an object")
    if rec.get("format") != FORMAT or type(rec.get("version")) is not int or rec.get("version") != VERSION:
        raise BRDFFileError(path, f"invalid {WHAT}: key {KEY}.format/version: expected {FORMAT} version {VERSION}")
    sha = rec.get("sha256")
    if not isinstance(sha, str) or len(sha) != 64:
        raise BRDFFileError(path, f"invalid {WHAT}: key {KEY}.sha256: expected a SHA-256 hex digest")
    try:
        actual = record_sha256(rec)
    except (TypeError, ValueError) as e:     # a value JSON cannot hold (an in-memory record)
        raise BRDFFileError(path, f"invalid {WHAT}: key {KEY}: {e}") from None
    if actual != sha:
        raise BRDFFileError(path, f"invalid {WHAT}: key {KEY}.sha256: the record does not match its sha256 "
                                  f"(edited or damaged; make it again: rbrdf-fit cdf FIT.json --out FIT.json)")
    return rec


def read(model, path=None, maps: bool = True) -> CDFFit | CDFTable | None:
    """The sampler ``model`` carries (``model.sampler``; None when it carries none), checked
    (module docstring): a :class:`CDFFit` (``maps``: the layout's maps rebuilt and verified) or,
    with ``maps=False``, only its :class:`fit.sampling.table.CDFTable`. ``path`` names the file
    in errors (one :class:`fit.errors.BRDFFileError` line)."""
    rec = getattr(model, "sampler", None)
    if rec is None:
        return None
    _check_head(rec, path)
    if maps:
        return from_dict(rec, path, what=WHAT, prefix=KEY)
    try:
        return table_from_dict(F.get(rec, "table_data", KEY), f"{KEY}.table_data")
    except F.Invalid as e:
        raise BRDFFileError(path, f"invalid {WHAT}: {e}") from None


def load_file(path, maps: bool = True) -> CDFFit | CDFTable:
    """The sampler the coefficient file ``path`` carries, read as :func:`read` reads it (the
    file loaded with :func:`fit.rational.coefficient_file.load`); one
    :class:`fit.errors.BRDFFileError` line when the fit carries none."""
    from ..rational.coefficient_file import load

    cdf = read(load(path), path, maps=maps)
    if cdf is None:
        raise BRDFFileError(path, f"the fit carries no {WHAT} (key {KEY}); store one with "
                                  f"`rbrdf-fit cdf FIT.json --out FIT.json`")
    return cdf
