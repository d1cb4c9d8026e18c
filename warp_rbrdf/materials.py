"""Materials as Warp functions (RGB, local shading frame: z = normal, directions away from the
surface, rho in 1/sr without the cosine; 0 when either direction is at or below the horizon).

* ``lambert``: albedo / pi.
* ``measured``: the 3-D MERL-grid table of :class:`fit.measured.MeasuredBRDF`, nearest bin
  exactly as the MERL format defines it (``theta_h`` bin ``floor(90 sqrt(theta_h / (pi/2)))``,
  ``theta_d`` bin ``floor(90 theta_d / (pi/2))``, ``phi_d`` folded into [0, pi) and binned
  ``floor(180 phi_d / pi)``).
* ``projected``: the 2-D (theta_h, theta_d) table of :class:`fit.measured.ProjectedBRDF`
  (nearest cluster; empty clusters give 0).
* ``rational``: generated code for the fitter's rational functions (see
  :mod:`warp_rbrdf.rational_material`).

Tables of all materials of one kind are concatenated into one flat ``vec3`` array; a
material's ``offset`` says where its table starts. Only the tables (and branches) of kinds a
scene uses are built.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

MAT_LAMBERT = 0
MAT_MEASURED = 1
MAT_PROJECTED = 2
MAT_RATIONAL = 3
MAT_CODES = {"lambert": MAT_LAMBERT, "measured": MAT_MEASURED, "projected": MAT_PROJECTED,
             "rational": MAT_RATIONAL}

# Per-material sampler ("which strategies estimate the direct light"):
SAMPLER_MIS = 0       # light sample + BSDF sample, power heuristic
SAMPLER_LIGHT = 1     # light (environment) sample only
SAMPLER_COSINE = 2    # BSDF sample only, cosine-weighted hemisphere
SAMPLER_UNIFORM = 3   # BSDF sample only, uniform hemisphere
SAMPLER_TABULATED = 4      # BSDF sample only, tabulated inverse CDFs (binary search), f cos / pdf
SAMPLER_RATIONAL = 5       # BSDF sample only, rational inverse CDFs, f cos / pdf (pdf = 1/alpha)
SAMPLER_RATIONAL_DERIV = 6  # BSDF sample only, rational inverse CDFs, derivative estimator f cos alpha
SAMPLER_MIS_TABULATED = 7  # light sample + tabulated BSDF sample, power heuristic
SAMPLER_MIS_RATIONAL = 8   # light sample + rational BSDF sample (MIS weights: tabulated pdf)
SAMPLER_CODES = {"mis": SAMPLER_MIS, "light": SAMPLER_LIGHT, "cosine": SAMPLER_COSINE,
                 "uniform": SAMPLER_UNIFORM, "tabulated": SAMPLER_TABULATED,
                 "rational": SAMPLER_RATIONAL, "rational-derivative": SAMPLER_RATIONAL_DERIV,
                 "mis-tabulated": SAMPLER_MIS_TABULATED, "mis-rational": SAMPLER_MIS_RATIONAL}
N_CDF_INFO = 6  # per material: off_t, off_p, n_v, n_t, n_p, rational sampler index (-1: none)

N_TH, N_TD, N_PD = 90, 90, 180
HALF_PI = 1.5707963267948966


@wp.struct
class Materials:
    kind: wp.array(dtype=int)          # MAT_* per material
    sampler: wp.array(dtype=int)       # SAMPLER_* per material
    albedo: wp.array(dtype=wp.vec3)    # lambert albedo / multiplier (scale) for tables
    offset: wp.array(dtype=int)        # start of the material's table (measured/projected),
                                       # or the rational function index
    table3d: wp.array(dtype=wp.vec3)   # concatenated (90*90*180) tables
    table2d: wp.array(dtype=wp.vec3)   # concatenated (90*90) tables
    cdf_t: wp.array(dtype=float)       # concatenated theta CDFs of tabulated samplers
    cdf_p: wp.array(dtype=float)       # concatenated phi CDFs
    cdf_info: wp.array(dtype=int)      # N_CDF_INFO ints per material
    cdf_pw: wp.array(dtype=float)      # concatenated pieces-layout inverse CDFs (cdf_sampling.pack_pieces)


@dataclass
class MaterialData:
    """NumPy side of :class:`Materials`."""
    names: list
    kind: np.ndarray
    sampler: np.ndarray
    albedo: np.ndarray
    offset: np.ndarray
    table3d: np.ndarray
    table2d: np.ndarray
    kinds_used: set = field(default_factory=set)
    rational: list = field(default_factory=list)   # RationalFunction-like objects, by index
    cdf_t: np.ndarray = field(default_factory=lambda: np.zeros(1, np.float32))
    cdf_p: np.ndarray = field(default_factory=lambda: np.zeros(1, np.float32))
    cdf_info: np.ndarray = field(default_factory=lambda: np.zeros(N_CDF_INFO, np.int32))
    cdf_fits: list = field(default_factory=list)    # verified CDFFit per rational sampler index
    cdf_pw: np.ndarray = field(default_factory=lambda: np.zeros(1, np.float32))
    cdf_pw_offsets: list = field(default_factory=list)  # per rational sampler index (-1: not pieces)
    cdf_tables: list = field(default_factory=list)  # CDFTable per material (None: no table)
    samplers_used: set = field(default_factory=set)


def make_materials_struct(md: MaterialData, device) -> Materials:
    s = Materials()
    s.kind = wp.array(md.kind.astype(np.int32), dtype=int, device=device)
    s.sampler = wp.array(md.sampler.astype(np.int32), dtype=int, device=device)
    s.albedo = wp.array(md.albedo.astype(np.float32), dtype=wp.vec3, device=device)
    s.offset = wp.array(md.offset.astype(np.int32), dtype=int, device=device)
    s.table3d = wp.array(np.ascontiguousarray(md.table3d, np.float32).reshape(-1, 3), dtype=wp.vec3, device=device)
    s.table2d = wp.array(np.ascontiguousarray(md.table2d, np.float32).reshape(-1, 3), dtype=wp.vec3, device=device)
    s.cdf_t = wp.array(np.ascontiguousarray(md.cdf_t, np.float32), dtype=float, device=device)
    s.cdf_p = wp.array(np.ascontiguousarray(md.cdf_p, np.float32), dtype=float, device=device)
    s.cdf_info = wp.array(np.ascontiguousarray(md.cdf_info, np.int32).reshape(-1), dtype=int, device=device)
    s.cdf_pw = wp.array(np.ascontiguousarray(md.cdf_pw, np.float32), dtype=float, device=device)
    return s


# --------------------------------------------------------------------------------------------
@wp.func
def half_diff(wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    """Rusinkiewicz (theta_h, theta_d, phi_d) of a local direction pair (phi_d in (-pi, pi])."""
    s = wi + wo
    ln = wp.length(s)
    h = wp.vec3(0.0, 0.0, 1.0)
    if ln > 1.0e-9:
        h = s / ln
    rxy = wp.sqrt(h[0] * h[0] + h[1] * h[1])
    theta_h = wp.atan2(rxy, h[2])  # accurate near 0, unlike acos
    cp = 1.0
    sp = 0.0
    if rxy > 1.0e-12:
        cp = h[0] / rxy
        sp = h[1] / rxy
    # rotate wi by -phi_h about z, then by -theta_h about y
    x1 = cp * wi[0] + sp * wi[1]
    y1 = -sp * wi[0] + cp * wi[1]
    z1 = wi[2]
    ct = h[2]
    st = rxy
    x2 = ct * x1 - st * z1
    z2 = st * x1 + ct * z1
    theta_d = wp.atan2(wp.sqrt(x2 * x2 + y1 * y1), z2)
    phi_d = 0.0
    if wp.abs(x2) + wp.abs(y1) > 1.0e-12:
        phi_d = wp.atan2(y1, x2)
    return wp.vec3(theta_h, theta_d, phi_d)


@wp.func
def merl_theta_h_index(theta_h: float) -> int:
    t = wp.max(theta_h, 0.0)
    return wp.clamp(int(wp.floor(wp.sqrt(t / HALF_PI) * 90.0)), 0, N_TH - 1)


@wp.func
def merl_theta_d_index(theta_d: float) -> int:
    return wp.clamp(int(wp.floor(theta_d / HALF_PI * 90.0)), 0, N_TD - 1)


@wp.func
def merl_phi_d_index(phi_d: float) -> int:
    p = phi_d
    if p < 0.0:
        p = p + wp.pi
    if p >= wp.pi:
        p = p - wp.pi
    return wp.clamp(int(wp.floor(p / wp.pi * 180.0)), 0, N_PD - 1)


@wp.func
def lambert_eval(albedo: wp.vec3, wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0)
    return albedo * (1.0 / wp.pi)


@wp.func
def measured_eval(table: wp.array(dtype=wp.vec3), offset: int, scale: wp.vec3,
                  wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0)
    a = half_diff(wi, wo)
    i = merl_theta_h_index(a[0])
    j = merl_theta_d_index(a[1])
    k = merl_phi_d_index(a[2])
    v = table[offset + (i * N_TD + j) * N_PD + k]
    return wp.cw_mul(v, scale)


@wp.func
def projected_eval(table: wp.array(dtype=wp.vec3), offset: int, scale: wp.vec3,
                   wi: wp.vec3, wo: wp.vec3) -> wp.vec3:
    if wi[2] <= 0.0 or wo[2] <= 0.0:
        return wp.vec3(0.0)
    a = half_diff(wi, wo)
    i = merl_theta_h_index(a[0])
    j = merl_theta_d_index(a[1])
    v = table[offset + i * N_TD + j]
    return wp.cw_mul(v, scale)


# --------------------------------------------------------------------------------------------
def build_material_data(scene, used_names=None) -> MaterialData:
    """Load/prepare the tables of the scene's materials (only those referenced by shapes)."""
    names = list(scene.materials) if used_names is None else list(used_names)
    n = max(len(names), 1)
    kind = np.zeros(n, np.int32)
    sampler = np.zeros(n, np.int32)
    albedo = np.ones((n, 3), np.float32)
    offset = np.zeros(n, np.int32)
    t3, t2, rational = [], [], []
    loaded = [None] * len(names)  # what each material read, reused by the samplers
    used = set()
    for i, name in enumerate(names):
        spec = scene.materials[name]
        key = f"materials.{name}"
        kind[i] = MAT_CODES[spec.type]
        sampler[i] = SAMPLER_CODES[spec.sampler]
        used.add(spec.type)
        if spec.type == "lambert":
            albedo[i] = spec.albedo
        elif spec.type == "measured":
            albedo[i] = spec.scale
            offset[i] = len(t3) * N_TH * N_TD * N_PD
            loaded[i] = _load_measured(spec, scene.path, key)
            t3.append(loaded[i].values)
        elif spec.type == "projected":
            albedo[i] = spec.scale
            offset[i] = len(t2) * N_TH * N_TD
            loaded[i] = _load_projected(spec, scene.path, key)
            t2.append(np.nan_to_num(loaded[i].value, nan=0.0))
        else:
            albedo[i] = spec.scale
            offset[i] = len(rational)
            loaded[i] = _load_rational(spec, scene.path, key)
            rational.append(loaded[i])
    t3a = np.concatenate([np.asarray(t, np.float32).reshape(-1, 3) for t in t3]) if t3 else np.zeros((1, 3), np.float32)
    t2a = np.concatenate([np.asarray(t, np.float32).reshape(-1, 3) for t in t2]) if t2 else np.zeros((1, 3), np.float32)
    md = MaterialData(names=names, kind=kind, sampler=sampler, albedo=albedo, offset=offset,
                      table3d=t3a, table2d=t2a, kinds_used=used, rational=rational)
    _build_samplers(md, scene, names, loaded)
    return md


def _build_samplers(md: MaterialData, scene, names, loaded):
    """Tables (and rational inverse CDFs) of the materials whose sampler needs them.

    ``loaded[i]``: the measured table, projection or rational model already read for material
    ``i`` (None for Lambert), so no file is read or resampled twice."""
    from . import cdf_sampling as CS

    n = len(md.kind)
    info = np.zeros((n, N_CDF_INFO), np.int32)
    info[:, 5] = -1
    ct, cp, fits, tables = [], [], [], [None] * n
    off_t = off_p = 0
    for i, name in enumerate(names):
        spec = scene.materials[name]
        if spec.sampler not in CS.TABLE_SAMPLERS:
            md.samplers_used.add(spec.sampler)
            continue
        used, fitobj, table = CS.prepare_sampler(spec, loaded[i])
        md.sampler[i] = SAMPLER_CODES[used]
        md.samplers_used.add(used)
        tables[i] = table
        info[i, :5] = (off_t, off_p, table.n_v, table.n_t, table.n_p)
        ct.append(table.cdf_theta.reshape(-1))
        cp.append(table.cdf_phi.reshape(-1))
        off_t += ct[-1].size
        off_p += cp[-1].size
        if fitobj is not None:
            info[i, 5] = len(fits)
            fits.append(fitobj)
    if ct:
        md.cdf_t = np.concatenate(ct).astype(np.float32)
        md.cdf_p = np.concatenate(cp).astype(np.float32)
    md.cdf_info = info
    md.cdf_fits = fits
    md.cdf_pw, md.cdf_pw_offsets = CS.pack_pieces(fits)
    md.cdf_tables = tables


def _load_measured(spec, file, key):
    from .errors import SceneError

    if spec.data is not None:
        return spec.data
    try:
        from fit.formats import load_measured

        return load_measured(spec.file)
    except ImportError as e:
        raise SceneError(file, f"{key}.file", f"cannot read {spec.file.name}: reader not available ({e})") from None
    except Exception as e:  # noqa: BLE001 - BRDFFileError and I/O errors, reported in one line
        raise SceneError(file, f"{key}.file", f"cannot read measured BRDF ({e})") from None


def _load_projected(spec, file, key):
    from .errors import SceneError

    if spec.data is not None:
        return spec.data
    try:
        if spec.file.suffix.lower() == ".npz":
            from fit.formats.measured import ProjectedBRDF

            return ProjectedBRDF.load(spec.file)
        from fit.projection.project import project

        return project(_load_measured(spec, file, key), statistic=spec.statistic)
    except SceneError:
        raise
    except Exception as e:  # noqa: BLE001
        raise SceneError(file, f"{key}.file", f"cannot read projected BRDF ({e})") from None


def _load_rational(spec, file, key):
    from .rational_material import load_rational

    return load_rational(spec, file, key)
