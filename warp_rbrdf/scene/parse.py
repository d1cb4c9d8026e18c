"""Scene files (TOML): parsing and validation into :class:`~.specs.Scene`. A scene states only
what it uses; everything else has a default (:data:`~.format_doc.FORMAT_DOC`, also printed by
``rbrdf scene-format``). Material types and samplers come from :mod:`warp_rbrdf.registry`."""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from fit.errors import BRDFFileError
from fit.inputs import nesting_depth, read_bytes

from .. import limits, registry
from ..errors import SceneError
from .specs import (
    INCIDENT_ROLES,
    INTERPOLATIONS,
    LIGHT_TYPES,
    MATERIAL_TYPES,
    PATTERNS,
    SAMPLERS,
    SHAPE_TYPES,
    STATISTICS,
    UNVOUCHED,
    CameraSpec,
    IntegratorSpec,
    LightSpec,
    MaterialSpec,
    Scene,
    ShapeSpec,
)
from .toml_table import MISSING, Table, show


# --------------------------------------------------------------------------------------------
def load_scene(path) -> Scene:
    """Read and validate a TOML scene file: a regular file (a named pipe or folder is refused
    before it is opened) of at most :data:`warp_rbrdf.limits.MAX_SCENE_BYTES`, UTF-8."""
    path = Path(path)
    try:
        data = read_bytes(path, limits.MAX_SCENE_BYTES, "scene file")
    except BRDFFileError as e:
        raise SceneError(path, None, f"cannot read scene file: {e.problem}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise SceneError(path, None, f"scene file is not UTF-8 text (byte {e.start})") from None
    return parse_scene(text, path=path)


def parse_scene(text: str, path=None, base_dir: Path | None = None) -> Scene:
    """Parse TOML ``text``; ``path`` names it in errors and sets the base of relative paths."""
    file = str(path) if path is not None else "<scene>"
    if base_dir is None and path is not None:
        base_dir = Path(path).resolve().parent
    if len(text) > limits.MAX_SCENE_BYTES:
        raise SceneError(file, None, f"scene text of {len(text)} characters is above the limit "
                                     f"{limits.MAX_SCENE_BYTES} (warp_rbrdf.limits.MAX_SCENE_BYTES)")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(file, None, f"invalid TOML: {e}") from None
    except RecursionError:
        raise SceneError(file, None, "invalid TOML: nested too deeply") from None
    return scene_from_dict(data, file=file, base_dir=base_dir)


def scene_from_dict(data: dict, file="<scene>", base_dir: Path | None = None) -> Scene:
    """Validate parsed TOML ``data`` (nested dicts and lists) into a :class:`Scene`; every
    number finite and within :mod:`warp_rbrdf.limits`, every size bounded."""
    if nesting_depth(data, limits.MAX_TOML_DEPTH) > limits.MAX_TOML_DEPTH:
        raise SceneError(file, None, f"tables and arrays nested more than {limits.MAX_TOML_DEPTH} "
                                     "levels deep (warp_rbrdf.limits.MAX_TOML_DEPTH)")
    root = Table(data, file, "", base_dir)
    sc = Scene(path=file)

    # camera --------------------------------------------------------------------------------
    c = Table(root._get("camera", None, False) if root.has("camera") else {}, file, "camera", base_dir)
    d = CameraSpec()
    cam = CameraSpec(
        origin=c.vector("origin", 3, d.origin), target=c.vector("target", 3, d.target),
        up=c.vector("up", 3, d.up),
        fov=c.number("fov", d.fov, 0, 180, lo_open=True, hi_open=True),
        fov_axis=c.string("fov_axis", d.fov_axis, ("x", "y")),
    )
    res = c._get("resolution", None, False)
    side = limits.MAX_RESOLUTION_SIDE
    if res is not MISSING:
        if not (isinstance(res, list) and len(res) == 2
                and all(isinstance(x, int) and not isinstance(x, bool) and 1 <= x <= side for x in res)):
            raise c.error("resolution", f"expected [width, height], integers in [1, {side}], got {show(res)}")
        cam.resolution = (res[0], res[1])
    fwd = np.subtract(cam.target, cam.origin)
    if np.linalg.norm(fwd) == 0:
        raise c.error("target", "must differ from camera.origin")
    if np.linalg.norm(np.cross(fwd, cam.up)) < 1e-9 * np.linalg.norm(fwd) * max(np.linalg.norm(cam.up), 1e-30):
        raise c.error("up", "must not be parallel to the view direction (target - origin)")
    c.finish()
    sc.camera = cam

    # integrator ----------------------------------------------------------------------------
    it = Table(root._get("integrator", None, False) if root.has("integrator") else {}, file, "integrator", base_dir)
    di = IntegratorSpec()
    sc.integrator = IntegratorSpec(
        spp=it.number("spp", di.spp, 1, limits.MAX_SPP, integer=True),
        seed=it.number("seed", di.seed, 0, 2**32 - 1, integer=True),
        max_depth=it.number("max_depth", di.max_depth, 1, 64, integer=True),
        sampler=it.string("sampler", di.sampler, SAMPLERS),
        pattern=it.string("pattern", di.pattern, PATTERNS),
        hide_environment=it.boolean("hide_environment", di.hide_environment),
        tile_size=it.number("tile_size", di.tile_size, 1, 4096, integer=True),
        ray_epsilon=it.number("ray_epsilon", di.ray_epsilon, 0.0, limits.MAX_RAY_EPSILON),
        mis_compensation=it.number("mis_compensation", di.mis_compensation, 0.0, 1.0),
    )
    it.finish()
    problem = limits.check_render_size(*sc.camera.resolution, sc.integrator.spp)
    if problem:
        key = ("integrator.spp" if problem.startswith("spp") else
               "camera.resolution x integrator.spp" if " spp = " in problem else "camera.resolution")
        raise SceneError(file, key, problem)
    problem = limits.check_tiles(*sc.camera.resolution, sc.integrator.tile_size)
    if problem:
        raise SceneError(file, "integrator.tile_size", problem)

    # materials -----------------------------------------------------------------------------
    mats = Table(root._get("materials", None, False) if root.has("materials") else {}, file, "materials", base_dir)
    if len(mats.data) > limits.MAX_MATERIALS:
        raise mats.error("", f"{len(mats.data)} materials, above the limit {limits.MAX_MATERIALS} "
                             "(warp_rbrdf.limits.MAX_MATERIALS)")
    for name, mdata in mats.data.items():
        m = Table(mdata, file, f"materials.{name}", base_dir)
        mtype = m.string("type", None, MATERIAL_TYPES, required=True)
        cdf = None
        if m.has("cdf"):
            cdf = m.path("cdf", what="CDF file")
            if cdf.suffix.lower() != ".json":
                raise m.error("cdf", f"expected an rbrdf-cdf .json file, got {cdf.name!r}")
        # the material's sampler, else the integrator's, else the kind's own default
        spec = MaterialSpec(name=name, type=mtype, cdf=cdf,
                            sampler=m.string("sampler", sc.integrator.sampler, SAMPLERS))
        kind = registry.material(mtype)
        if "albedo" in kind.keys:
            spec.albedo = m.vector("albedo", 3, (0.8, 0.8, 0.8), allow_scalar=True, nonneg=True,
                                   max_abs=limits.MAX_ALBEDO)
        if "file" in kind.keys:
            spec.file = m.path("file", required=True, what="material file")
            if spec.file.suffix.lower() not in kind.suffixes:
                raise m.error("file", f"expected a {' / '.join(kind.suffixes)} file for a {mtype} material, "
                                      f"got {spec.file.name!r}")
        if "scale" in kind.keys:
            spec.scale = m.vector("scale", 3, (1.0, 1.0, 1.0), allow_scalar=True, nonneg=True,
                                  max_abs=limits.MAX_MATERIAL_SCALE)
        if "statistic" in kind.keys:
            spec.statistic = m.string("statistic", "median", STATISTICS)
        if "incident" in kind.keys:
            spec.incident = m.string("incident", "view", INCIDENT_ROLES)
        if "interpolation" in kind.keys:
            spec.interpolation = m.string("interpolation", "linear", INTERPOLATIONS)
        if "unvouched" in kind.keys:
            spec.unvouched = m.string("unvouched", "projected", UNVOUCHED)
        tech = registry.technique(registry.strategy(spec.sampler).technique)
        if tech.material is not None and tech.material != mtype:
            raise m.error("sampler", f"sampler {spec.sampler!r} draws from the {tech.material!r} "
                                     f"material's own tables; a {mtype!r} material cannot use it")
        m.finish()
        sc.materials[name] = spec
    mats.used.update(mats.data)

    # shapes --------------------------------------------------------------------------------
    shapes = root._get("shapes", None, False) if root.has("shapes") else []
    if not isinstance(shapes, list):
        raise root.error("shapes", f"expected an array of tables ([[shapes]]), got {show(shapes)}")
    if len(shapes) > limits.MAX_SHAPES:
        raise root.error("shapes", f"{len(shapes)} shapes, above the limit {limits.MAX_SHAPES} "
                                   "(warp_rbrdf.limits.MAX_SHAPES)")
    for i, sdata in enumerate(shapes):
        s = Table(sdata, file, f"shapes[{i}]", base_dir)
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
            spec.radius = s.number("radius", 1.0, limits.MIN_LENGTH, limits.MAX_LENGTH)
            spec.subdivisions = s.number("subdivisions", 5, 1, 8, integer=True)
        else:
            spec.center = s.vector("center", 3, (0.0, 0.0, 0.0))
            spec.size = s.vector("size", 2, (2.0, 2.0), allow_scalar=True, max_abs=limits.MAX_LENGTH)
            if min(spec.size) < limits.MIN_LENGTH:
                raise s.error("size", f"expected sizes in [{limits.MIN_LENGTH:g}, {limits.MAX_LENGTH:g}], "
                                      f"got {list(spec.size)}")
        s.finish()
        sc.shapes.append(spec)

    # lights --------------------------------------------------------------------------------
    lights = root._get("lights", None, False) if root.has("lights") else []
    if not isinstance(lights, list):
        raise root.error("lights", f"expected an array of tables ([[lights]]), got {show(lights)}")
    if len(lights) > limits.MAX_DIRECTIONAL_LIGHTS + 1:
        raise root.error("lights", f"{len(lights)} lights, above the limit of "
                                   f"{limits.MAX_DIRECTIONAL_LIGHTS} directional lights and one environment "
                                   "(warp_rbrdf.limits.MAX_DIRECTIONAL_LIGHTS)")
    n_env = 0
    for i, ldata in enumerate(lights):
        l = Table(ldata, file, f"lights[{i}]", base_dir)
        ltype = l.string("type", None, LIGHT_TYPES, required=True)
        spec = LightSpec(type=ltype)
        if ltype == "directional":
            if l.has("radiance"):
                raise l.error("radiance", "a directional light is stated by its 'irradiance' "
                                          "(W/m^2 on a surface facing the light), not radiance")
            spec.irradiance = l.vector("irradiance", 3, (1.0, 1.0, 1.0), allow_scalar=True, nonneg=True,
                                       max_abs=limits.MAX_IRRADIANCE)
            spec.colinear_with_view = l.boolean("colinear_with_view", False)
            if l.has("direction"):
                if spec.colinear_with_view:
                    raise l.error("direction", "give either direction or colinear_with_view = true, not both")
                spec.direction = l.vector("direction", 3)
                if np.linalg.norm(spec.direction) < 1e-30:
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
                spec.scale = l.number("scale", 1.0, 0.0, limits.MAX_ENV_SCALE)
                spec.rotation = l.rotation("rotate")
            elif ltype == "constant":
                spec.radiance = l.vector("radiance", 3, (1.0, 1.0, 1.0), allow_scalar=True, nonneg=True,
                                         max_abs=limits.MAX_RADIANCE)
            else:
                spec.scale = l.number("scale", 1.0, 0.0, limits.MAX_ENV_SCALE)
                spec.rotation = l.rotation("rotate")
                spec.sun_elevation = l.number("sun_elevation", 35.0, -90.0, 90.0)
                spec.sun_azimuth = l.number("sun_azimuth", 135.0, -limits.MAX_ANGLE_DEG, limits.MAX_ANGLE_DEG)
                spec.resolution = l.vector("resolution", 2, (512, 256), integer=True, nonneg=True,
                                           max_abs=limits.MAX_RESOLUTION_SIDE)
                if min(spec.resolution) < 2:
                    raise l.error("resolution", "expected [width, height] >= 2")
                problem = limits.check_env_size(*spec.resolution)
                if problem:
                    raise l.error("resolution", problem)
        l.finish()
        sc.lights.append(spec)

    root.finish(allowed=("camera", "integrator", "materials", "shapes", "lights"))
    if not sc.shapes and sc.environment is None:
        pass  # an empty scene renders black; allowed
    return sc
