"""Build a scene's :class:`~warp_rbrdf.materials.data.MaterialData`: load each material with its
kind module (:data:`warp_rbrdf.registry.MATERIALS`), prepare the inverse-CDF data its strategy's
technique needs (:mod:`warp_rbrdf.techniques.cdf_data`) and pack everything into flat arrays.
Only the materials referenced by shapes are loaded; only the tables they use are built."""
from __future__ import annotations

import numpy as np

from fit.progress import report

from .. import registry
from ..techniques import cdf_data
from .data import MaterialData, Pool

LOAD_STAGE = "loading materials"   # the progress stage of build_material_data


def build_material_data(scene, used_names=None, log=print, progress=None) -> MaterialData:
    """Load and pack the materials ``used_names`` (default: all of the scene's) in that order.
    ``progress(stage, done, total)`` (:mod:`fit.progress`) is told ``"loading materials"``
    (materials done) and the inverse-CDF builds' own stages (rows)."""
    names = list(scene.materials) if used_names is None else list(used_names)
    n = max(len(names), 1)
    kind = np.zeros(n, np.int32)
    technique = np.zeros(n, np.int32)
    combine = np.zeros(n, np.int32)
    scale = np.ones((n, 3), np.float32)
    offset = np.zeros(n, np.int32)
    param = np.zeros(n, np.int32)
    tables = Pool(width=3)
    rgl_f, rgl_i = Pool(), Pool(dtype=np.int32)
    loaded, strategies, cdfs = [], [], []
    index_of_kind: dict = {}
    budget = cdf_data.BuildBudget()   # inverse-CDF builds this load may start
    report(progress, LOAD_STAGE, 0, len(names))
    for i, name in enumerate(names):
        spec = scene.materials[name]
        key = f"materials.{name}"
        kd = registry.material(spec.type)
        lm = kd.impl().load(spec, scene.path, key)
        for note in lm.notes:
            log(f"material {name!r}: {note}")
        kind[i] = kd.code
        scale[i] = lm.scale
        param[i] = lm.param
        if lm.fallback_table is not None:   # e.g. rational: the projected table where flagged
            param[i] = tables.add(lm.fallback_table)
        if lm.rgl is not None:   # floats, then the header with its offsets made absolute
            floats, header = lm.rgl
            base = rgl_f.add(floats)
            offset[i] = rgl_i.add(header(base))
        elif lm.table is not None:
            offset[i] = tables.add(lm.table)
        else:   # kinds without a table index their own functions
            offset[i] = index_of_kind.get(kd.code, 0)
            index_of_kind[kd.code] = offset[i] + 1
        strat, cdf = cdf_data.prepare(spec, lm, scene.path, key, log, budget, progress=progress)
        technique[i] = registry.technique(strat.technique).code
        combine[i] = registry.combine_code(strat)
        loaded.append(lm)
        strategies.append(strat.name)
        cdfs.append(cdf)
        report(progress, LOAD_STAGE, i + 1, len(names))
    md = MaterialData(names=names, kind=kind, technique=technique, combine=combine, scale=scale,
                      offset=offset, tables=tables.array(), loaded=loaded, strategies=strategies,
                      cdf=cdfs, param=param, rgl_f=rgl_f.array(), rgl_i=rgl_i.array())
    for k, v in cdf_data.pack(cdfs).items():
        setattr(md, k, v)
    return md
