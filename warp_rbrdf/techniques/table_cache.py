"""Inverse-CDF tables (:class:`fit.sampling.table.CDFTable`) tabulated at load, remembered on disk.

Tabulating a material's table (:func:`fit.sampling.table.tabulate`: 32 view rows x 64 x 64 cells,
9 evaluations per cell) takes 4-6 s for a rational fit on this 2-core machine: most of the cold
start of ``rbrdf render`` on the embedded default scene before this module. The table depends
only on the material's file and its spec fields, so it is stored once under a key:

* ``key``: SHA-256 of the table's inputs: the material's type, the bytes of its file, its other
  spec fields that change the BRDF (``albedo``, ``statistic``, ``scale``, ``incident``,
  ``interpolation``, ``unvouched``), :data:`VERSION`, and the tabulation's parameters (the
  defaults of :func:`fit.sampling.table.tabulate`: ``n_v``, ``n_t``, ``n_p``, ``sub``, ``eps``,
  ``noise``) and version (:data:`fit.sampling.table.TABULATION_VERSION`), not the bytes of its
  source; a material given in memory (``spec.data``) or without a readable file is never cached.
* where: the shipped tables of the shipped fits, ``warp_rbrdf/data/tables/<key>.npz`` (written
  by ``python -m tools.ship_tables`` in a checkout, with one BLAS thread), then the user cache
  ``<Warp kernel cache>/rbrdf-tables/<key>.npz`` (written atomically after a tabulation; it goes
  with the kernel cache, so emptying one empties both).

A stored table is the tabulated one bit for bit (float64 arrays, ``np.savez_compressed``);
``tests/test_table_cache.py`` checks it and that the shipped tables match the current key.
Bump :data:`VERSION` when the evaluation of a material kind changes what a file means, and
:data:`fit.sampling.table.TABULATION_VERSION` when the tabulation changes.
"""
from __future__ import annotations

import hashlib
import inspect
import json
import os
from pathlib import Path

import numpy as np

from fit.errors import RbrdfError
from fit.outputs import atomic_write
from fit.sampling import table as table_mod
from fit.sampling.table import CDFTable, tabulate

from ..paths import PACKAGE_DATA

#: Bump when a material kind's evaluation changes what the same file and spec mean.
VERSION = 3    # 2: rational fits evaluated on their measured domain (materials/rational.py);
               # 3: measured tables read trilinearly by default (``interpolation``)
SHIPPED = PACKAGE_DATA / "tables"
_SPEC_FIELDS = ("albedo", "statistic", "scale", "incident", "interpolation", "unvouched")
_ARRAYS = ("theta_v", "cdf_theta", "cdf_phi", "row_fallback", "albedo")
#: The parameters of :func:`fit.sampling.table.tabulate` that change the table (not
#: ``chunk_rows``, ``progress``: how the same table is computed and reported).
TABLE_PARAMS = ("n_v", "n_t", "n_p", "sub", "eps", "noise")


def table_inputs() -> dict:
    """The tabulation's part of the key: :data:`fit.sampling.table.TABULATION_VERSION` and the
    defaults of :func:`fit.sampling.table.tabulate` for :data:`TABLE_PARAMS` (the table
    :func:`cached_tabulate` makes)."""
    sig = inspect.signature(table_mod.tabulate).parameters
    return {"version": table_mod.TABULATION_VERSION, **{k: sig[k].default for k in TABLE_PARAMS}}


def key(spec) -> str | None:
    """Hex key of the default-size table of material ``spec`` (a
    :class:`warp_rbrdf.scene.specs.MaterialSpec`), or None when it cannot be cached (in-memory
    data, no file, unreadable file)."""
    if getattr(spec, "data", None) is not None:
        return None
    f = getattr(spec, "file", None)
    h = hashlib.sha256()
    if f is not None:
        try:
            h.update(Path(f).read_bytes())
        except OSError:
            return None
    fields = {k: _plain(getattr(spec, k, None)) for k in _SPEC_FIELDS}
    head = {"version": VERSION, "type": spec.type, "fields": fields, "table": table_inputs(),
            "file": h.hexdigest() if f is not None else None}
    return hashlib.sha256(json.dumps(head, sort_keys=True).encode()).hexdigest()[:32]


def _plain(v):
    if isinstance(v, (tuple, list, np.ndarray)):
        return [float(x) for x in np.asarray(v, float).ravel()]
    return v if v is None or isinstance(v, (str, int, float, bool)) else str(v)


def user_dir() -> Path | None:
    """``<Warp kernel cache>/rbrdf-tables``, or None before Warp knows its cache folder."""
    try:
        import warp as wp
    except ImportError:   # pragma: no cover - warp is a dependency of warp_rbrdf
        return None
    base = getattr(wp.config, "kernel_cache_dir", None) or os.environ.get("WARP_CACHE_PATH")
    return Path(base) / "rbrdf-tables" if base else None


def read(path: Path) -> CDFTable | None:
    """The table stored at ``path``, or None when it is missing or unreadable."""
    try:
        with np.load(path) as z:
            return CDFTable(**{k: np.array(z[k]) for k in _ARRAYS}, eps=float(z["eps"]))
    except (OSError, KeyError, ValueError):
        return None


def write(path: Path, t: CDFTable) -> None:
    """Store ``t`` at ``path`` atomically (:func:`fit.outputs.atomic_write`: a temporary file in
    the same folder, every byte checked on disk, then renamed); a failure is a one-line
    :class:`fit.errors.OutputError` and leaves ``path`` as it was."""
    with atomic_write(path, "wb") as f:
        np.savez_compressed(f, **{k: getattr(t, k) for k in _ARRAYS}, eps=np.float64(t.eps))


def cached_tabulate(spec, evaluate, before_build=None, progress=None) -> CDFTable:
    """:func:`fit.sampling.table.tabulate` of ``evaluate`` (the material of ``spec``), read from
    the shipped or the user cache when stored there, else tabulated and stored in the user
    cache (a cache that cannot be written is skipped silently: the table is still correct).
    ``before_build()``, when given, is called just before a table is tabulated (not on a cache
    hit): the scene's load-time budget (:class:`warp_rbrdf.techniques.cdf_data.BuildBudget`).
    ``progress(stage, done, total)`` (:mod:`fit.progress`) is told the tabulation's rows."""
    k = key(spec)
    if k is None:
        if before_build is not None:
            before_build()
        return tabulate(evaluate, progress=progress)
    udir = user_dir()
    for d in (SHIPPED, udir):
        if d is not None:
            t = read(d / f"{k}.npz")
            if t is not None:
                return t
    if before_build is not None:
        before_build()
    t = tabulate(evaluate, progress=progress)
    if udir is not None:
        try:
            write(udir / f"{k}.npz", t)
        except (OSError, RbrdfError):     # a full or read-only cache: the table is still correct
            pass
    return t
