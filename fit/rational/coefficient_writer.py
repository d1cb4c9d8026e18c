"""Writing ``rbrdf-rational`` coefficient files: :func:`to_dict` (a model as the file's JSON
object: version 1, 2 or 3), :func:`jsonable` and :func:`save` (atomic: a temporary file renamed
onto the path when complete). The format: docs/formats.md ("Rational coefficients").
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .coefficient_format import (
    FORMAT,
    SAMPLER_KEY,
    VERSION,
    VERSION_3D,
    VERSION_3D_FACTOR,
    VERSION_PIECEWISE,
    content_sha256,
    is_3d,
)
from .model import PiecewiseRationalModel


def to_dict(model) -> dict:
    """The file's JSON object of ``model``: version 1 for a :class:`RationalModel`, version 2 for
    a :class:`PiecewiseRationalModel` (pieces may be piecewise again)."""
    d = _piecewise_to_dict(model) if isinstance(model, PiecewiseRationalModel) else _model_to_dict(model)
    if is_3d(model):
        d["version"] = VERSION_3D
    factor = getattr(model, "value_factor", "none")
    if factor != "none":            # step 8: a version the readers without it refuse
        d["version"] = VERSION_3D_FACTOR
        d["value"] = dict(d["value"], factor=factor)
    if getattr(model, "fallback", None) is not None:    # only flagged 2-D fits: others as before
        d["fallback"] = jsonable(model.fallback)
    sampler = getattr(model, "sampler", None)
    if sampler is not None:     # the fit's own inverse CDFs (fit.sampling.embedded), made from d
        if sampler.get("fit_sha256") != content_sha256(jsonable(d)):
            raise ValueError("the model's sampler was made from other coefficients: make it again "
                             "(fit.sampling.embedded.attach)")
        d[SAMPLER_KEY] = sampler
    return d


def _model_to_dict(model) -> dict:
    funcs = []
    for out, f, info in zip(model.outputs, model.functions, model.function_info):
        d = {"output": out}
        fd = f.to_dict()
        fd.pop("basis")
        d.update(fd)
        d["n_coefficients"] = f.n_coefficients
        d.update(jsonable(info))
        funcs.append(d)
    return {
        "format": FORMAT,
        "version": VERSION,
        "name": model.name,
        "kind": model.kind,
        "variables": [{"name": v.name, "unit": v.unit, "transform": v.transform,
                       "domain": list(v.domain)} for v in model.variables],
        "value": {"name": model.value_name, "unit": model.value_unit,
                  "transform": model.value_transform, "offset": model.value_offset,
                  "min": model.value_min, "max": model.value_max},
        "basis": "chebyshev",
        "outputs": list(model.outputs),
        "functions": funcs,
        "domain_policy": jsonable(model.domain_policy),
        "fit": jsonable(model.fit_info),
        "source": jsonable(model.source),
    }


def _piecewise_to_dict(model) -> dict:
    base = to_dict(model.pieces[0])
    pieces = []
    for piece, info in zip(model.pieces, model.piece_info):
        d = to_dict(piece)
        body = ({"functions": d["functions"]} if "functions" in d
                else {"split": d["split"], "pieces": d["pieces"]})   # nested piecewise piece
        pieces.append({"variables": d["variables"], **body, "info": jsonable(info)})
    return {
        "format": FORMAT, "version": VERSION_PIECEWISE, "name": model.name, "kind": model.kind,
        "variables": [{"name": v.name, "unit": v.unit, "transform": v.transform,
                       "domain": list(v.domain)} for v in model.variables],
        "value": base["value"], "basis": base["basis"], "outputs": base["outputs"],
        "split": {"variable": model.split_variable, "edges": list(model.edges)},
        "pieces": pieces,
        "domain_policy": jsonable(model.domain_policy),
        "fit": jsonable(model.fit_info),
        "source": jsonable(model.source),
    }


def jsonable(obj):
    """``obj`` with NumPy scalars and arrays as Python numbers and lists, non-finite floats as
    None (JSON has no NaN), dict keys as strings."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if math.isfinite(f) else None
    return obj


def save(model, path) -> None:
    """Write ``model`` as an ``rbrdf-rational`` JSON file (version 1, or 2 if piecewise),
    through a temporary file renamed onto ``path`` when complete (an existing file is never
    left half-written). The text is read back first with the reader's checks
    (:func:`fit.rational.coefficient_reader.from_dict`, Q > 0 not proved again): a model the
    reader would refuse raises its :class:`~fit.errors.BRDFFileError` and nothing is written."""
    from ..outputs import atomic_write
    from .coefficient_reader import from_dict

    text = json.dumps(to_dict(model), indent=1, allow_nan=False)
    from_dict(json.loads(text), path, certify=False)
    with atomic_write(Path(path)) as f:
        f.write(text + "\n")
