"""What the kernels know about a scene's materials: the :class:`Materials` Warp struct and its
NumPy side :class:`MaterialData`.

One entry per material used by a shape (index ``m``):

* ``kind[m]``: :attr:`warp_rbrdf.registry.MaterialKind.code`;
* ``technique[m]``: :attr:`warp_rbrdf.registry.Technique.code` of its BSDF sample, and
  ``combine[m]``: how its samples are combined (``registry.COMBINE_*``);
* ``scale[m]``: RGB multiplier (the Lambert albedo, or the ``scale`` of a table / fit);
* ``offset[m]``: where the material's table starts in ``tables`` (in RGB entries), the start
  of its header in ``rgl_i`` (rgl), or its index among the scene's materials of its kind
  (kinds without a table; unused by the kernels);
* ``param[m]``: one integer option of the material's kind (measured: the number of phi_d bins
  of its table, 180 when folded by reciprocity, 360 over the full circle; rational with a
  fallback table: where that table starts in ``tables``; 0 otherwise);
* ``rgl_f`` / ``rgl_i``: the tables (float32) and headers (:data:`N_RGL_INFO` ints per
  material, fields ``RGL_*`` of :mod:`warp_rbrdf.materials.rgl`) of the ``rgl`` materials;
* ``tables``: every material table of the scene, concatenated (RGB, 1/sr);
* ``coef_i`` / ``coef_f`` / ``coef_q``: the coefficient data of the kinds that evaluate
  coefficients (rational fits, :func:`warp_rbrdf.materials.rational.pack_model`): ints, float64
  values and rows of six float64 coefficients (:mod:`warp_rbrdf.chebyshev`); ``coef_i[3 m]``,
  ``coef_i[3 m + 1]``, ``coef_i[3 m + 2]`` are where material ``m``'s start in each (its
  records hold offsets relative to those), then the materials' ints;
* the inverse-CDF data of the materials whose technique needs it: ``cdf_t`` (theta CDFs),
  ``cdf_p`` (phi CDFs), ``cdf_pw`` (rational pieces), ``cdf_row_ok`` (1: the row has a verified
  rational map, 0: sampled with the table), ``cdf_gi`` / ``cdf_gf`` / ``cdf_gq`` (global-layout
  maps as packed Chebyshev polynomials: ints, float64, rows of (P, Q) coefficients,
  :func:`warp_rbrdf.techniques.cdf_data.pack_global`)
  and ``cdf_info`` (:data:`N_CDF_INFO` ints per material, fields ``CDF_*``).

The kernels' source depends on none of these values (only on which kinds and techniques a scene
uses): new files or fits reuse the compiled kernels.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

from ..chebyshev import vec6d

# cdf_info fields, per material (N_CDF_INFO ints at m * N_CDF_INFO)
CDF_OFF_T = 0        # start of the material's theta CDFs in cdf_t
CDF_OFF_P = 1        # start of its phi CDFs in cdf_p
CDF_N_V = 2          # view rows
CDF_N_T = 3          # theta_l cells
CDF_N_P = 4          # |phi_l| cells
CDF_LAYOUT = 5       # rational maps: LAYOUT_NONE (table only), LAYOUT_PIECES or LAYOUT_GLOBAL
CDF_MAPS = 6         # pieces: start in cdf_pw; global: start of its record in cdf_gi
CDF_N_MU = 7         # pieces: theta pieces per row
CDF_N_U = 8          # pieces: phi pieces per map
CDF_OFF_ROWS = 9     # pieces: start of its row flags in cdf_row_ok
N_CDF_INFO = 10

LAYOUT_NONE = 0
LAYOUT_PIECES = 1
LAYOUT_GLOBAL = 2


@wp.struct
class Materials:
    kind: wp.array(dtype=int)
    technique: wp.array(dtype=int)
    combine: wp.array(dtype=int)
    scale: wp.array(dtype=wp.vec3)
    offset: wp.array(dtype=int)
    param: wp.array(dtype=int)
    tables: wp.array(dtype=wp.vec3)
    rgl_f: wp.array(dtype=float)
    rgl_i: wp.array(dtype=int)
    cdf_t: wp.array(dtype=float)
    cdf_p: wp.array(dtype=float)
    cdf_pw: wp.array(dtype=float)
    cdf_row_ok: wp.array(dtype=int)
    cdf_info: wp.array(dtype=int)
    coef_i: wp.array(dtype=int)
    coef_f: wp.array(dtype=wp.float64)
    coef_q: wp.array(dtype=vec6d)
    cdf_gi: wp.array(dtype=int)
    cdf_gf: wp.array(dtype=wp.float64)
    cdf_gq: wp.array(dtype=wp.vec2d)


@dataclass
class LoadedMaterial:
    """One material as its kind module loaded it.

    ``data``: the NumPy object read from the file (a :class:`fit.formats.measured.MeasuredBRDF`,
    ``ProjectedBRDF``, ``RationalModel``, ``RGLBRDF``; None for Lambert); ``evaluate(wi, wo) ->
    (..., 3)``: rho in 1/sr with ``scale`` applied (NumPy reference of the kernel, used to
    tabulate the sampling CDFs); ``scale``: the RGB multiplier the kernel applies
    (``Materials.scale``); ``table``: RGB entries the kind puts into ``Materials.tables`` (None:
    none); ``param``: ``Materials.param``; ``rgl``: ``(floats, header)`` the kind puts into
    ``Materials.rgl_f`` / ``rgl_i`` (header offsets relative to the start of its floats);
    ``fallback_table``: RGB entries put into ``Materials.tables`` besides the kind's own
    indexing, their start in ``Materials.param`` (rational: the projected table where the fit
    is flagged); ``notes``: lines the scene load logs, prefixed with the material's name;
    ``coefficients``: ``(ints int32, floats float64, rows float64 (n, 6))`` the kind puts into
    ``Materials.coef_i`` / ``coef_f`` / ``coef_q`` (offsets relative to the material's own start
    there; rational: its packed fit)."""

    spec: object
    data: object
    evaluate: object
    scale: tuple = (1.0, 1.0, 1.0)
    table: np.ndarray | None = None
    param: int = 0
    rgl: tuple | None = None
    fallback_table: np.ndarray | None = None
    notes: tuple = ()
    coefficients: tuple | None = None


class Pool:
    """Concatenation of flat arrays; :meth:`add` returns where an array starts."""

    def __init__(self, width: int = 1, dtype=np.float32):
        self.parts, self.size, self.width, self.dtype = [], 0, width, dtype

    def add(self, a) -> int:
        a = np.asarray(a, self.dtype).reshape(-1, self.width) if self.width > 1 else \
            np.asarray(a, self.dtype).reshape(-1)
        off = self.size
        self.parts.append(a)
        self.size += len(a)
        return off

    def array(self) -> np.ndarray:
        if not self.parts:   # Warp arrays need at least one element
            return np.zeros((1, self.width) if self.width > 1 else 1, self.dtype)
        return np.concatenate(self.parts)


@dataclass
class MaterialData:
    """NumPy side of :class:`Materials` plus what the kernels are specialised on."""

    names: list                      # material names, index m
    kind: np.ndarray                 # (n,) int32
    technique: np.ndarray            # (n,) int32
    combine: np.ndarray              # (n,) int32
    scale: np.ndarray                # (n, 3) float32
    offset: np.ndarray               # (n,) int32
    tables: np.ndarray               # (N, 3) float32
    loaded: list                     # LoadedMaterial per material
    strategies: list                 # strategy name actually used per material (after fallbacks)
    cdf: list = field(default_factory=list)       # per material: CDFTable / CDFFit / None
    cdf_t: np.ndarray = field(default_factory=lambda: np.zeros(1, np.float32))
    cdf_p: np.ndarray = field(default_factory=lambda: np.zeros(1, np.float32))
    cdf_pw: np.ndarray = field(default_factory=lambda: np.zeros(1, np.float32))
    cdf_row_ok: np.ndarray = field(default_factory=lambda: np.zeros(1, np.int32))
    cdf_info: np.ndarray = field(default_factory=lambda: np.zeros((1, N_CDF_INFO), np.int32))
    global_fits: list = field(default_factory=list)   # CDFFits of the global layout, in packing order
    cdf_gi: np.ndarray = field(default_factory=lambda: np.zeros(1, np.int32))
    cdf_gf: np.ndarray = field(default_factory=lambda: np.zeros(1, np.float64))
    cdf_gq: np.ndarray = field(default_factory=lambda: np.zeros((1, 2), np.float64))
    param: np.ndarray = field(default_factory=lambda: np.zeros(1, np.int32))
    rgl_f: np.ndarray = field(default_factory=lambda: np.zeros(1, np.float32))
    rgl_i: np.ndarray = field(default_factory=lambda: np.zeros(1, np.int32))

    def kinds_used(self) -> list:
        """Registry codes of the material kinds used, ascending."""
        return sorted({int(k) for k in self.kind})

    def techniques_used(self) -> list:
        return sorted({int(t) for t in self.technique})

    def coefficients(self) -> tuple:
        """``(coef_i, coef_f, coef_q)`` of :class:`Materials`: a header of three ints per material
        (where its ints, floats and rows start), then each material's
        :attr:`LoadedMaterial.coefficients`."""
        n = len(self.loaded)
        head = np.zeros(3 * n, np.int32)
        ints, floats, rows = [head], [np.zeros(0)], [np.zeros((0, 6))]
        start = np.array([3 * n, 0, 0])
        for m, lm in enumerate(self.loaded):
            if lm.coefficients is None:
                continue
            parts = [np.asarray(lm.coefficients[0], np.int32), np.asarray(lm.coefficients[1], np.float64),
                     np.asarray(lm.coefficients[2], np.float64).reshape(-1, 6)]
            head[3 * m:3 * m + 3] = start
            for out, part in zip((ints, floats, rows), parts):
                out.append(part)
            start += [len(p) for p in parts]
        ci, cf, cq = np.concatenate(ints), np.concatenate(floats), np.concatenate(rows)
        # Warp arrays need at least one element
        return (ci if len(ci) else np.zeros(1, np.int32), cf if len(cf) else np.zeros(1),
                cq if len(cq) else np.zeros((1, 6)))

    def loaded_of_kind(self, code: int) -> list:
        """The loaded materials of kind ``code`` in the order of their ``offset`` index."""
        ms = [m for m in range(len(self.names)) if int(self.kind[m]) == code]
        return [self.loaded[m] for m in sorted(ms, key=lambda m: int(self.offset[m]))]


def make_materials_struct(md: MaterialData, device) -> Materials:
    s = Materials()

    def arr(a, dtype, np_dtype):
        return wp.array(np.ascontiguousarray(a, np_dtype), dtype=dtype, device=device)

    s.kind = arr(md.kind, int, np.int32)
    s.technique = arr(md.technique, int, np.int32)
    s.combine = arr(md.combine, int, np.int32)
    s.scale = arr(md.scale, wp.vec3, np.float32)
    s.offset = arr(md.offset, int, np.int32)
    s.param = arr(md.param, int, np.int32)
    s.rgl_f = arr(md.rgl_f, float, np.float32)
    s.rgl_i = arr(md.rgl_i, int, np.int32)
    s.tables = arr(np.asarray(md.tables).reshape(-1, 3), wp.vec3, np.float32)
    s.cdf_t = arr(md.cdf_t, float, np.float32)
    s.cdf_p = arr(md.cdf_p, float, np.float32)
    s.cdf_pw = arr(md.cdf_pw, float, np.float32)
    s.cdf_row_ok = arr(md.cdf_row_ok, int, np.int32)
    s.cdf_info = arr(np.asarray(md.cdf_info).reshape(-1), int, np.int32)
    coef_i, coef_f, coef_q = md.coefficients()
    s.coef_i = arr(coef_i, int, np.int32)
    s.coef_f = arr(coef_f, wp.float64, np.float64)
    s.coef_q = arr(coef_q, vec6d, np.float64)
    s.cdf_gi = arr(md.cdf_gi, int, np.int32)
    s.cdf_gf = arr(md.cdf_gf, wp.float64, np.float64)
    s.cdf_gq = arr(md.cdf_gq, wp.vec2d, np.float64)
    return s
