"""NumPy side of the inverse-CDF techniques: which tables and fits a scene's materials need,
where they come from, and how they are packed into :class:`warp_rbrdf.materials.data.Materials`.

A material whose strategy's technique needs a table (``tabulated``, ``rational``) gets one:
from its ``cdf = "file.json"`` (an ``rbrdf-cdf`` file of ``rbrdf-fit cdf``), else from the
sampler record its rational fit carries (:mod:`fit.sampling.embedded`: nothing is built, no
source file is read, the pieces are made from the record's knots and checked; a grey ``scale``
only), or tabulated from the material itself at load
(remembered on disk: :mod:`.table_cache`). A technique that needs verified rational inverse CDFs gets them
from the same file or the fit's record, or fitted at load (printed: it takes seconds). A fit that failed its
verification (``CDFFit.fallback``) switches the material to its strategy's ``fallback``
(printed, never silent).

Everything is packed as data (:func:`pack`): the pieces layout's knots into ``cdf_pw``, the
global layout's F and G as packed Chebyshev polynomials (:func:`pack_global`,
:mod:`warp_rbrdf.chebyshev`) into ``cdf_gi`` / ``cdf_gf`` / ``cdf_gq``, so a new CDF file
compiles nothing.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from fit.sampling.table import CDFTable

from .. import registry
from ..chebyshev import FlatData
from ..errors import SceneError
from ..materials.data import (
    CDF_LAYOUT,
    CDF_MAPS,
    CDF_N_MU,
    CDF_N_P,
    CDF_N_T,
    CDF_N_U,
    CDF_N_V,
    CDF_OFF_P,
    CDF_OFF_ROWS,
    CDF_OFF_T,
    LAYOUT_GLOBAL,
    LAYOUT_NONE,
    LAYOUT_PIECES,
    N_CDF_INFO,
    Pool,
)
from .table_cache import cached_tabulate


def _read_cdf(spec, scene_file, key):
    cdf = getattr(spec, "cdf", None)
    if cdf is None or not isinstance(cdf, (str, bytes, Path)):
        return cdf
    from fit.sampling.cdf_file import (
        load as load_cdf,  # the fitter's modules: imported only when needed
    )

    try:
        return load_cdf(cdf)
    except Exception as e:  # noqa: BLE001 - BRDFFileError and I/O errors, one line
        raise SceneError(scene_file, f"{key}.cdf", f"cannot read CDF file ({e})") from None


def _own_sampler(spec, loaded, scene_file, key, maps: bool):
    """The inverse CDFs a rational fit carries in its file (:mod:`fit.sampling.embedded`): a
    :class:`fit.sampling.cdf_file.CDFFit` (``maps``) or its :class:`CDFTable`, None when it
    carries none or when the material's ``scale`` is not grey (the luminance of a tinted fit is
    another density: its table is tabulated as for any material). A damaged or edited record is a
    one-line :class:`SceneError` naming the file."""
    model = getattr(loaded, "data", None)
    if getattr(model, "sampler", None) is None:
        return None
    scale = np.asarray(getattr(spec, "scale", (1.0, 1.0, 1.0)), float).ravel()
    if scale.size and not np.all(scale == scale[0]):
        return None
    from fit.sampling.embedded import read   # no SciPy: the pieces are read from the record

    try:
        return read(model, getattr(spec, "file", None), maps=maps)
    except Exception as e:  # noqa: BLE001 - BRDFFileError, one line
        raise SceneError(scene_file, f"{key}.file", f"the fit's sampler record is unusable ({e})") from None


class BuildBudget:
    """How many inverse-CDF builds (a table tabulated, rational inverse CDFs fitted) a scene's
    load may still start: :data:`warp_rbrdf.limits.MAX_CDF_BUILDS_AT_LOAD` by default. A build
    past it is refused with a one-line :class:`SceneError` naming the material's ``cdf`` key."""

    def __init__(self, limit: int | None = None):
        from ..limits import MAX_CDF_BUILDS_AT_LOAD

        self.limit = MAX_CDF_BUILDS_AT_LOAD if limit is None else int(limit)
        self.used = 0

    def take(self, scene_file, key: str, what: str) -> None:
        """Count one build of ``what`` for the material at ``key``; raise past the limit."""
        if self.used >= self.limit:
            raise SceneError(scene_file, f"{key}.cdf",
                             f"{what} at load would be build number {self.used + 1} of this scene, "
                             f"more than {self.limit} (warp_rbrdf.limits.MAX_CDF_BUILDS_AT_LOAD: "
                             f"each takes seconds to minutes); make a CDF file once with "
                             f"`rbrdf-fit cdf` and give it as cdf = \"file.json\"")
        self.used += 1


def prepare(spec, loaded, scene_file="<scene>", key="materials", log=print, budget=None, progress=None):
    """``(strategy actually used, inverse-CDF data)`` of one material: data None (hemisphere
    techniques), a :class:`fit.sampling.table.CDFTable` (tabulated) or a verified
    :class:`fit.sampling.cdf_file.CDFFit` (rational). ``budget`` (a :class:`BuildBudget`, one
    per scene load; default: a fresh one) bounds the builds a scene's load may start.
    ``progress(stage, done, total)`` (:mod:`fit.progress`) is passed to the tabulation and the
    fit of the inverse CDFs when one is built."""
    budget = BuildBudget() if budget is None else budget
    strat = registry.strategy(spec.sampler)
    tech = registry.technique(strat.technique)
    if not tech.needs_table:
        return strat, None
    fitobj = _read_cdf(spec, scene_file, key)
    if fitobj is None:
        own = _own_sampler(spec, loaded, scene_file, key, tech.needs_fit)
        if isinstance(own, CDFTable):
            return strat, own
        fitobj = own
    made_with = (getattr(fitobj, "source", None) or {}).get("incident")
    if made_with is not None and made_with != getattr(spec, "incident", "view"):
        raise SceneError(scene_file, f"{key}.cdf", f"the CDF file was built with incident = "
                                                   f"{made_with!r}, the material has "
                                                   f"{getattr(spec, 'incident', 'view')!r}")
    if tech.needs_fit:
        if fitobj is None:
            budget.take(scene_file, key, "fitting rational inverse CDFs")
            log(f"material {spec.name!r}: fitting rational inverse CDFs (give `cdf = \"file.json\"` "
                f"from `rbrdf-fit cdf` to skip this)")
            from fit.sampling.cdf_file import fit_cdf

            fitobj = fit_cdf(loaded.evaluate, name=spec.name, progress=progress)
        if fitobj.fallback:
            fb = registry.strategy(strat.fallback)
            log(f"material {spec.name!r}: rational sampler FALLBACK to {fb.name!r} ({fitobj.reason})")
            return fb, fitobj.table
        return strat, fitobj
    if fitobj is not None:
        return strat, fitobj.table
    return strat, cached_tabulate(spec, loaded.evaluate,
                                  before_build=lambda: budget.take(scene_file, key,
                                                                   "tabulating inverse CDFs"),
                                  progress=progress)


def pack(cdfs) -> dict:
    """Pack the materials' inverse-CDF data (one entry per material: None, a CDFTable or a
    CDFFit) into the flat arrays of :class:`Materials`: ``cdf_t``, ``cdf_p``, ``cdf_pw``
    (pieces: theta pieces (n_v, n_mu, 4) then phi knots (n_v, n_mu, n_u + 1, 2), see
    :func:`.rational.pieces_sample`), ``cdf_row_ok``, ``cdf_info`` (n, N_CDF_INFO), ``cdf_gi``
    / ``cdf_gf`` / ``cdf_gq`` (the global-layout maps, :func:`pack_global`; ``CDF_MAPS``: a
    record's start)
    and ``global_fits`` (the global-layout fits, in packing order)."""
    info = np.zeros((max(len(cdfs), 1), N_CDF_INFO), np.int32)
    ct, cp, pw, rows = Pool(), Pool(), Pool(), Pool(dtype=np.int32)
    global_fits, gd = [], FlatData(2)
    for m, cdf in enumerate(cdfs):
        if cdf is None:
            continue
        table = getattr(cdf, "table", cdf)
        info[m, CDF_OFF_T] = ct.add(table.cdf_theta)
        info[m, CDF_OFF_P] = cp.add(table.cdf_phi)
        info[m, [CDF_N_V, CDF_N_T, CDF_N_P]] = table.n_v, table.n_t, table.n_p
        info[m, CDF_LAYOUT] = LAYOUT_NONE
        if cdf is table:
            continue
        from fit.sampling.pieces import (  # only with a fit
            PieceMaps,
            pieces_phi_knots,
        )

        if isinstance(cdf.maps, PieceMaps):
            pm = cdf.maps
            info[m, CDF_LAYOUT] = LAYOUT_PIECES
            info[m, CDF_MAPS] = pw.add(np.concatenate([pm.theta.ravel(), pieces_phi_knots(pm).ravel()]))
            info[m, [CDF_N_MU, CDF_N_U]] = pm.n_mu, pm.n_u
            info[m, CDF_OFF_ROWS] = rows.add(np.asarray(pm.row_ok, np.int32))
        else:
            info[m, CDF_LAYOUT] = LAYOUT_GLOBAL
            info[m, CDF_MAPS] = pack_global(gd, cdf.maps)
            global_fits.append(cdf)
    gi, gf, gq = gd.arrays()
    return dict(cdf_t=ct.array(), cdf_p=cp.array(), cdf_pw=pw.array(), cdf_row_ok=rows.array(),
                cdf_info=info, global_fits=global_fits, cdf_gi=gi, cdf_gf=gf, cdf_gq=gq)


# global-layout record: GLOBAL_INTS ints per map (F, then G): the int and row offsets of
# (P, Q) as one packed group (:func:`warp_rbrdf.chebyshev.cheb_sum2_d`), and the float offset
# of the map's domain data: the scale 2 / (b - a) of the CDF variable (the last), then
# (a + b, 1 / (b - a)) per variable
GLOBAL_INTS = 3
GLOBAL_THETA, GLOBAL_PHI = 0, GLOBAL_INTS


def pack_global(fd: FlatData, maps) -> int:
    """Append the record of a :class:`fit.sampling.global_layout.GlobalMaps` (F(theta_v, mu),
    G(theta_v, theta_l, u); the CDF variable is the last of each) to ``fd``; returns its int
    offset (:func:`.rational.global_sample` reads it)."""
    g = fd.add_ints([0] * (2 * GLOBAL_INTS))
    for r, f, nv in ((GLOBAL_THETA, maps.theta, 2), (GLOBAL_PHI, maps.phi, 3)):
        if f is None or f.n_vars != nv:
            raise ValueError(f"global-layout map with {None if f is None else f.n_vars} variables, expected {nv}")
        dom = np.asarray(f.domain, np.float64)
        head = [2.0 / (dom[-1, 1] - dom[-1, 0])]
        for a, b in dom:
            head += [a + b, 1.0 / (b - a)]
        fd.ints[g + r:g + r + 2] = fd.add_polynomials([(f.num_exponents, f.num_coef),
                                                        (f.den_exponents, f.den_coef)], nv)
        fd.ints[g + r + 2] = fd.add_floats(head)
    return g
