"""Scene files (TOML): parsing, validation and defaults.

A scene states only what it uses; everything else has a default. See :data:`FORMAT_DOC`
(also printed by ``rbrdf scene-format``) for the keys. Errors raise
:class:`~warp_rbrdf.errors.SceneError` with the file, the key and what was expected.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import registry, transforms
from .errors import SceneError
from .paths import resolve_path

MATERIAL_TYPES = registry.MATERIAL_NAMES
SAMPLERS = registry.STRATEGY_NAMES
PATTERNS = ("stratified", "independent")
SHAPE_TYPES = ("mesh", "sphere", "plane")
LIGHT_TYPES = ("directional", "envmap", "constant", "sky")
ENV_TYPES = ("envmap", "constant", "sky")

FORMAT_DOC = """\
Scene file format (TOML). Every table and key is optional unless marked required.

[camera]
  origin = [0, 1, 4]        target = [0, 0.5, 0]      up = [0, 1, 0]      (look_at)
  fov = 40.0                full angle in degrees along fov_axis
  fov_axis = "x"            "x" or "y"
  resolution = [256, 256]   [width, height] in pixels

[integrator]
  spp = 16                  camera samples per pixel
  seed = 0                  same seed -> same image
  max_depth = 1             1 = direct lighting; >1 adds indirect bounces
  sampler = "mis"           default per-material sampler: mis | light | cosine | uniform
  pattern = "stratified"    sample generator: stratified (correlated multi-jitter) | independent
  hide_environment = false  camera rays that miss all shapes return 0 instead of the environment
  tile_size = 32            image tiles (pixels per side) launched from the thread pool
  ray_epsilon = 0           shadow/bounce ray offset; 0 = automatic (1e-5 x scene size)

[materials.NAME]            one table per material, referenced by name from shapes
  type = "lambert"          lambert | measured | projected | rational   (required)
  sampler = <integrator.sampler>   also: tabulated | rational | rational-derivative |
                            mis-tabulated | mis-rational  (inverse-CDF BRDF samplers)
  cdf = "..."               rbrdf-cdf .json from `rbrdf-fit cdf` (tables + rational inverse
                            CDFs); without it tables are built (and rational CDFs fitted) at load
  albedo = 0.8              lambert: number or [r, g, b]
  file = "..."              measured/projected: .binary (MERL) or .bsdf (RGL); projected also
                            accepts an .npz from ProjectedBRDF.save; rational: coefficient .json
  statistic = "median"      projected (from a 3-D file): median | mean | geometric | harmonic | rms
  scale = 1.0               measured/projected/rational: number or [r, g, b] multiplier

[[shapes]]                  any number
  type = "mesh"             mesh | sphere | plane   (required)
  material = "NAME"         (required)
  file = "..."              mesh: OBJ / PLY / GLB / STL (loaded with trimesh)
  smooth_normals = true     mesh: interpolate vertex normals (false: flat facets)
  center = [0, 0, 0]        sphere / plane
  radius = 1.0              sphere
  subdivisions = 5          sphere: icosphere level
  size = [2, 2]             plane: extent along x and z; its normal is +Y before transform
  transform = { scale = 1, rotate = [angle_deg, ax, ay, az] (or a list of them),
                translate = [x, y, z] }     or  transform = { matrix = [[4x4]] }

[[lights]]                  any number of directional lights, at most one environment
  type = "directional"      directional | envmap | constant | sky   (required)
  irradiance = [1, 1, 1]    directional: W/m^2 on a surface facing the light
  direction = [0, -1, 0]    directional: direction the light travels
  colinear_with_view = false  directional: light travels along the view (target - origin)
  file = "..."              envmap: lat-long .hdr / .exr (read with OpenImageIO)
  scale = 1.0               envmap / sky: radiance multiplier
  rotate = [angle_deg, ax, ay, az]   envmap / sky: rotation of the map (or a list of them)
  radiance = [1, 1, 1]      constant: uniform environment radiance
  sun_elevation = 35.0      sky: degrees above the horizon
  sun_azimuth = 135.0       sky: degrees, 0 = -Z, 90 = +X (the lat-long u convention)
  resolution = [512, 256]   sky: size of the tabulated map

Paths: "${RBRDF_DATA}/x" or "data:x" resolve through $RBRDF_DATA (default ../shared/data next
to the project); "pkg:x" is warp_rbrdf/data/x; other relative paths are relative to the scene.
"""


@dataclass
class CameraSpec:
    origin: tuple = (0.0, 1.0, 4.0)
    target: tuple = (0.0, 0.5, 0.0)
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = 40.0
    fov_axis: str = "x"
    resolution: tuple = (256, 256)


@dataclass
class IntegratorSpec:
    spp: int = 16
    seed: int = 0
    max_depth: int = 1
    sampler: str = "mis"
    pattern: str = "stratified"
    hide_environment: bool = False
    tile_size: int = 32
    ray_epsilon: float = 0.0


@dataclass
class MaterialSpec:
    name: str
    type: str
    sampler: str = "mis"
    albedo: tuple = (0.8, 0.8, 0.8)
    file: Path | None = None
    statistic: str = "median"
    scale: tuple = (1.0, 1.0, 1.0)
    data: Any = None          # in-memory table / rational function (Python API only)
    cdf: Any = None           # rbrdf-cdf file path or in-memory fit.cdf_fit.CDFFit


@dataclass
class ShapeSpec:
    type: str
    material: str
    transform: np.ndarray = field(default_factory=lambda: np.eye(4))
    file: Path | None = None
    smooth_normals: bool = True
    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 1.0
    subdivisions: int = 5
    size: tuple = (2.0, 2.0)


@dataclass
class LightSpec:
    type: str
    irradiance: tuple = (1.0, 1.0, 1.0)
    direction: tuple = (0.0, -1.0, 0.0)
    colinear_with_view: bool = False
    file: Path | None = None
    scale: float = 1.0
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    radiance: tuple = (1.0, 1.0, 1.0)
    sun_elevation: float = 35.0
    sun_azimuth: float = 135.0
    resolution: tuple = (512, 256)
    image: Any = None         # in-memory (H, W, 3) map (Python API only)


@dataclass
class Scene:
    camera: CameraSpec = field(default_factory=CameraSpec)
    integrator: IntegratorSpec = field(default_factory=IntegratorSpec)
    materials: dict = field(default_factory=dict)
    shapes: list = field(default_factory=list)
    lights: list = field(default_factory=list)
    path: str = "<scene>"

    @property
    def environment(self) -> LightSpec | None:
        envs = [l for l in self.lights if l.type in ENV_TYPES]
        return envs[0] if envs else None

    @property
    def directional_lights(self) -> list:
        return [l for l in self.lights if l.type == "directional"]


# --------------------------------------------------------------------------------------------
class _Table:
    """Typed access to one TOML table, with errors naming the file and the key."""

    def __init__(self, data, file, prefix: str, base_dir: Path | None):
        self.file, self.prefix, self.base_dir = file, prefix, base_dir
        if not isinstance(data, dict):
            raise SceneError(file, prefix, f"expected a table, got {_show(data)}")
        self.data = data
        self.used: set[str] = set()

    def key(self, k: str) -> str:
        return f"{self.prefix}.{k}" if self.prefix else k

    def error(self, k: str, problem: str):
        return SceneError(self.file, self.key(k) if k else self.prefix, problem)

    def has(self, k):
        return k in self.data

    def _get(self, k, default, required):
        self.used.add(k)
        if k not in self.data:
            if required:
                raise self.error(k, "missing required key")
            return _MISSING
        return self.data[k]

    def number(self, k, default=None, lo=None, hi=None, lo_open=False, hi_open=False,
               required=False, integer=False):
        v = self._get(k, default, required)
        if v is _MISSING:
            return default
        kind = "an integer" if integer else "a number"
        ok = (isinstance(v, int) if integer else isinstance(v, (int, float))) and not isinstance(v, bool)
        rng = ""
        if lo is not None or hi is not None:
            rng = " in " + ("(" if lo_open else "[") + (str(lo) if lo is not None else "-inf") + ", " \
                  + (str(hi) if hi is not None else "inf") + (")" if hi_open or hi is None else "]")
        if ok and math.isfinite(v):
            if lo is not None and (v < lo or (lo_open and v == lo)):
                ok = False
            if hi is not None and (v > hi or (hi_open and v == hi)):
                ok = False
        else:
            ok = False
        if not ok:
            raise self.error(k, f"expected {kind}{rng}, got {_show(v)}")
        return int(v) if integer else float(v)

    def vector(self, k, n, default=None, required=False, allow_scalar=False, nonneg=False, lengths=None):
        v = self._get(k, default, required)
        if v is _MISSING:
            return default
        what = f"a list of {n} numbers" + (" (or one number)" if allow_scalar else "") \
            + (" >= 0" if nonneg else "")
        if allow_scalar and isinstance(v, (int, float)) and not isinstance(v, bool):
            v = [v] * n
        if not (isinstance(v, list) and len(v) == n
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                        for x in v)):
            raise self.error(k, f"expected {what}, got {_show(v)}")
        if nonneg and any(x < 0 for x in v):
            raise self.error(k, f"expected {what}, got {_show(v)}")
        return tuple(float(x) for x in v)

    def string(self, k, default=None, choices=None, required=False):
        v = self._get(k, default, required)
        if v is _MISSING:
            return default
        if not isinstance(v, str) or (choices and v not in choices):
            exp = "one of " + ", ".join(repr(c) for c in choices) if choices else "a string"
            raise self.error(k, f"expected {exp}, got {_show(v)}")
        return v

    def boolean(self, k, default=None):
        v = self._get(k, default, False)
        if v is _MISSING:
            return default
        if not isinstance(v, bool):
            raise self.error(k, f"expected true or false, got {_show(v)}")
        return v

    def path(self, k, required=False, must_exist=True, what="file"):
        v = self.string(k, None, required=required)
        if v is None:
            return None
        p = resolve_path(v, self.base_dir)
        if must_exist and not p.is_file():
            hint = " (set RBRDF_DATA to the shared data folder)" if ("RBRDF_DATA" in v or v.startswith("data:")) else ""
            raise self.error(k, f"{what} not found: {p}{hint}")
        return p

    def rotation(self, k):
        v = self._get(k, None, False)
        if v is _MISSING:
            return np.eye(3)
        try:
            m = transforms.compose(rotate=_rotation_list(v))
        except (TypeError, ValueError, IndexError):
            raise self.error(k, f"expected [angle_deg, ax, ay, az] or a list of them, got {_show(v)}") from None
        return m[:3, :3]

    def transform(self, k):
        v = self._get(k, None, False)
        if v is _MISSING:
            return np.eye(4)
        t = _Table(v, self.file, self.key(k), self.base_dir)
        if t.has("matrix"):
            m = t._get("matrix", None, True)
            try:
                arr = np.asarray(m, dtype=float)
                if arr.shape != (4, 4) or not np.all(np.isfinite(arr)):
                    raise ValueError
            except (TypeError, ValueError):
                raise t.error("matrix", f"expected a 4x4 list of numbers, got {_show(m)}") from None
            if abs(np.linalg.det(arr[:3, :3])) < 1e-12:
                raise t.error("matrix", "matrix is singular")
            t.finish(allowed=("matrix",))
            return arr
        scale = None
        if t.has("scale"):
            scale = t.vector("scale", 3, allow_scalar=True)
            if any(s == 0 for s in scale):
                raise t.error("scale", "expected non-zero scale factors")
        rot = None
        if t.has("rotate"):
            rv = t._get("rotate", None, True)
            try:
                rot = _rotation_list(rv)
                transforms.compose(rotate=rot)
            except (TypeError, ValueError, IndexError):
                raise t.error("rotate", f"expected [angle_deg, ax, ay, az] or a list of them, got {_show(rv)}") from None
        tr = t.vector("translate", 3) if t.has("translate") else None
        t.finish()
        return transforms.compose(scale=scale, rotate=rot, translate=tr)

    def finish(self, allowed=None):
        allowed = set(allowed) if allowed is not None else self.used
        extra = [k for k in self.data if k not in allowed]
        if extra:
            raise self.error(extra[0], "unknown key; expected one of "
                             + ", ".join(sorted(allowed)) if allowed else "unknown key")


_MISSING = object()


def _rotation_list(v):
    if not isinstance(v, list) or not v:
        raise ValueError
    rots = v if isinstance(v[0], list) else [v]
    for r in rots:
        if not (isinstance(r, list) and len(r) == 4
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in r)):
            raise ValueError
        if all(x == 0 for x in r[1:]):
            raise ValueError
    return rots


def _show(v) -> str:
    s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


# --------------------------------------------------------------------------------------------
def load_scene(path) -> Scene:
    """Read and validate a TOML scene file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        raise SceneError(path, None, f"cannot read scene file ({e.strerror or e})") from None
    return parse_scene(text, path=path)


def parse_scene(text: str, path=None, base_dir: Path | None = None) -> Scene:
    """Parse TOML ``text``; ``path`` names it in errors and sets the base of relative paths."""
    file = str(path) if path is not None else "<scene>"
    if base_dir is None and path is not None:
        base_dir = Path(path).resolve().parent
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(file, None, f"invalid TOML: {e}") from None
    return scene_from_dict(data, file=file, base_dir=base_dir)


def scene_from_dict(data: dict, file="<scene>", base_dir: Path | None = None) -> Scene:
    root = _Table(data, file, "", base_dir)
    sc = Scene(path=file)

    # camera --------------------------------------------------------------------------------
    c = _Table(root._get("camera", None, False) if root.has("camera") else {}, file, "camera", base_dir)
    d = CameraSpec()
    cam = CameraSpec(
        origin=c.vector("origin", 3, d.origin), target=c.vector("target", 3, d.target),
        up=c.vector("up", 3, d.up),
        fov=c.number("fov", d.fov, 0, 180, lo_open=True, hi_open=True),
        fov_axis=c.string("fov_axis", d.fov_axis, ("x", "y")),
    )
    res = c._get("resolution", None, False)
    if res is not _MISSING:
        if not (isinstance(res, list) and len(res) == 2
                and all(isinstance(x, int) and not isinstance(x, bool) and 1 <= x <= 16384 for x in res)):
            raise c.error("resolution", f"expected [width, height], integers in [1, 16384], got {_show(res)}")
        cam.resolution = (res[0], res[1])
    fwd = np.subtract(cam.target, cam.origin)
    if np.linalg.norm(fwd) == 0:
        raise c.error("target", "must differ from camera.origin")
    if np.linalg.norm(np.cross(fwd, cam.up)) < 1e-9 * np.linalg.norm(fwd) * max(np.linalg.norm(cam.up), 1e-30):
        raise c.error("up", "must not be parallel to the view direction (target - origin)")
    c.finish()
    sc.camera = cam

    # integrator ----------------------------------------------------------------------------
    it = _Table(root._get("integrator", None, False) if root.has("integrator") else {}, file, "integrator", base_dir)
    di = IntegratorSpec()
    sc.integrator = IntegratorSpec(
        spp=it.number("spp", di.spp, 1, 1 << 20, integer=True),
        seed=it.number("seed", di.seed, 0, 2**32 - 1, integer=True),
        max_depth=it.number("max_depth", di.max_depth, 1, 64, integer=True),
        sampler=it.string("sampler", di.sampler, SAMPLERS),
        pattern=it.string("pattern", di.pattern, PATTERNS),
        hide_environment=it.boolean("hide_environment", di.hide_environment),
        tile_size=it.number("tile_size", di.tile_size, 1, 4096, integer=True),
        ray_epsilon=it.number("ray_epsilon", di.ray_epsilon, 0.0),
    )
    it.finish()

    # materials -----------------------------------------------------------------------------
    mats = _Table(root._get("materials", None, False) if root.has("materials") else {}, file, "materials", base_dir)
    for name, mdata in mats.data.items():
        m = _Table(mdata, file, f"materials.{name}", base_dir)
        mtype = m.string("type", None, MATERIAL_TYPES, required=True)
        spec = MaterialSpec(name=name, type=mtype,
                            sampler=m.string("sampler", sc.integrator.sampler, SAMPLERS))
        if m.has("cdf"):
            spec.cdf = m.path("cdf", what="CDF file")
            if spec.cdf.suffix.lower() != ".json":
                raise m.error("cdf", f"expected an rbrdf-cdf .json file, got {spec.cdf.name!r}")
        if mtype == "lambert":
            spec.albedo = m.vector("albedo", 3, (0.8, 0.8, 0.8), allow_scalar=True, nonneg=True)
        else:
            spec.file = m.path("file", required=True, what="material file")
            spec.scale = m.vector("scale", 3, (1.0, 1.0, 1.0), allow_scalar=True, nonneg=True)
            suffix = spec.file.suffix.lower()
            allowed = {"measured": (".binary", ".bsdf"), "projected": (".binary", ".bsdf", ".npz"),
                       "rational": (".json",)}[mtype]
            if suffix not in allowed:
                raise m.error("file", f"expected a {' / '.join(allowed)} file for a {mtype} material, "
                                      f"got {spec.file.name!r}")
            if mtype == "projected":
                spec.statistic = m.string("statistic", "median",
                                          ("median", "mean", "geometric", "harmonic", "rms"))
        m.finish()
        sc.materials[name] = spec
    mats.used.update(mats.data)

    # shapes --------------------------------------------------------------------------------
    shapes = root._get("shapes", None, False) if root.has("shapes") else []
    if not isinstance(shapes, list):
        raise root.error("shapes", f"expected an array of tables ([[shapes]]), got {_show(shapes)}")
    for i, sdata in enumerate(shapes):
        s = _Table(sdata, file, f"shapes[{i}]", base_dir)
        stype = s.string("type", None, SHAPE_TYPES, required=True)
        mat = s.string("material", None, required=True)
        if mat not in sc.materials:
            known = ", ".join(sorted(sc.materials)) or "none defined"
            raise s.error("material", f"unknown material {mat!r} (known: {known})")
        spec = ShapeSpec(type=stype, material=mat, transform=s.transform("transform"))
        if stype == "mesh":
            spec.file = s.path("file", required=True, what="mesh file")
            spec.smooth_normals = s.boolean("smooth_normals", True)
        elif stype == "sphere":
            spec.center = s.vector("center", 3, (0.0, 0.0, 0.0))
            spec.radius = s.number("radius", 1.0, 0.0, lo_open=True)
            spec.subdivisions = s.number("subdivisions", 5, 1, 8, integer=True)
        else:
            spec.center = s.vector("center", 3, (0.0, 0.0, 0.0))
            spec.size = s.vector("size", 2, (2.0, 2.0), allow_scalar=True)
            if min(spec.size) <= 0:
                raise s.error("size", f"expected positive sizes, got {list(spec.size)}")
        s.finish()
        sc.shapes.append(spec)

    # lights --------------------------------------------------------------------------------
    lights = root._get("lights", None, False) if root.has("lights") else []
    if not isinstance(lights, list):
        raise root.error("lights", f"expected an array of tables ([[lights]]), got {_show(lights)}")
    n_env = 0
    for i, ldata in enumerate(lights):
        l = _Table(ldata, file, f"lights[{i}]", base_dir)
        ltype = l.string("type", None, LIGHT_TYPES, required=True)
        spec = LightSpec(type=ltype)
        if ltype == "directional":
            if l.has("radiance"):
                raise l.error("radiance", "a directional light is stated by its 'irradiance' "
                                          "(W/m^2 on a surface facing the light), not radiance")
            spec.irradiance = l.vector("irradiance", 3, (1.0, 1.0, 1.0), allow_scalar=True, nonneg=True)
            spec.colinear_with_view = l.boolean("colinear_with_view", False)
            if l.has("direction"):
                if spec.colinear_with_view:
                    raise l.error("direction", "give either direction or colinear_with_view = true, not both")
                spec.direction = l.vector("direction", 3)
                if np.linalg.norm(spec.direction) == 0:
                    raise l.error("direction", "expected a non-zero vector")
            elif not spec.colinear_with_view:
                spec.direction = (0.0, -1.0, 0.0)
        else:
            n_env += 1
            if n_env > 1:
                raise l.error("type", "only one environment light (envmap, constant or sky) per scene")
            if ltype == "envmap":
                spec.file = l.path("file", required=True, what="environment map")
                if spec.file.suffix.lower() not in (".hdr", ".exr"):
                    raise l.error("file", f"expected a lat-long .hdr or .exr file, got {spec.file.name!r}")
                spec.scale = l.number("scale", 1.0, 0.0)
                spec.rotation = l.rotation("rotate")
            elif ltype == "constant":
                spec.radiance = l.vector("radiance", 3, (1.0, 1.0, 1.0), allow_scalar=True, nonneg=True)
            else:
                spec.scale = l.number("scale", 1.0, 0.0)
                spec.rotation = l.rotation("rotate")
                spec.sun_elevation = l.number("sun_elevation", 35.0, -90.0, 90.0)
                spec.sun_azimuth = l.number("sun_azimuth", 135.0)
                spec.resolution = l.vector("resolution", 2, (512, 256))
                spec.resolution = (int(spec.resolution[0]), int(spec.resolution[1]))
                if min(spec.resolution) < 2:
                    raise l.error("resolution", "expected [width, height] >= 2")
        l.finish()
        sc.lights.append(spec)

    root.finish(allowed=("camera", "integrator", "materials", "shapes", "lights"))
    if not sc.shapes and sc.environment is None:
        pass  # an empty scene renders black; allowed
    return sc
