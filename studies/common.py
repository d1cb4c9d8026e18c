"""Shared helpers of the studies: data paths, in-memory scenes and materials, sampler discovery,
the cached inverse-CDF tables and fits, object masks, timed renders and progress bars. Image
metrics are in :mod:`studies.metrics`, writers and ``--docs`` publishing in
:mod:`studies.publish`.

The studies are run as modules from the checkout root (``python -m studies.convergence ...``);
colour-science comes with the ``studies`` extra (``pip install -e ".[studies]"``).

Every study builds its scenes in memory (no TOML files), with the object alone in front of a
hidden environment (``hide_environment = true``) so that errors are measured on the object's
pixels only; :func:`object_mask` gives those pixels.
"""
from __future__ import annotations

import os
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp_cache"))

from warp_rbrdf.paths import data_root, require_data_root  # noqa: E402
from warp_rbrdf.scene import (CameraSpec, IntegratorSpec, LightSpec, MaterialSpec,  # noqa: E402
                              Scene, ShapeSpec)

#: The samplers that need no inverse-CDF data, in the studies' display order (the others of
#: ``warp_rbrdf.registry.STRATEGIES`` follow them).
BASE_SAMPLERS = ("uniform", "cosine", "light", "mis")

MATERIALS = {
    "ibiza": "rgl/cc_ibiza_sunset_rgb.bsdf",      # glossy vinyl
    "satin": "rgl/satin_rosaline_rgb.bsdf",       # glossy satin
    "paper": "rgl/paper_white_rgb.bsdf",          # diffuse
    "gold": "rgl/vch_golden_yellow_rgb.bsdf",
    "napoli": "rgl/colodur_napoli_4f_rgb.bsdf",
    "iris": "rgl/cc_iris_purple_gem_rgb.bsdf",
}
ENVMAPS = {
    "rooitou": "envmaps/rooitou_park_1k.hdr",      # tiny, very bright sun
    "studio": "envmaps/studio_small_03_1k.hdr",
    "potsdamer": "envmaps/potsdamer_platz_1k.hdr",
}
#: Rotation (degrees about +Y) of each map so that its brightest light faces the camera side.
ENV_ROTATION = {"rooitou": 80.0, "studio": 0.0, "potsdamer": 0.0}


def data_path(rel: str) -> Path:
    p = require_data_root(f"study data {rel!r}") / rel
    if not p.exists():
        raise FileNotFoundError(f"shared data file missing: {p} (set RBRDF_DATA)")
    return p


def has_data(*rels) -> bool:
    root = data_root()
    return root is not None and all((root / r).exists() for r in rels)


def all_samplers() -> tuple:
    """Every sampler of the renderer's registry that works with any material (base ones
    first); the samplers of one kind's own tables (``rgl``, ``mis-rgl``: the RGL format's
    warps, ``rgl`` materials only) are left to the studies of that kind (studies.fidelity)."""
    from warp_rbrdf import registry

    names = tuple(s.name for s in registry.STRATEGIES
                  if registry.technique(s.technique).material is None)
    return tuple(s for s in BASE_SAMPLERS if s in names) + tuple(s for s in names if s not in BASE_SAMPLERS)


# --------------------------------------------------------------------------------------------
# Materials
@lru_cache(maxsize=16)
def measured(name: str):
    """The 3-D MERL-grid table (fit.formats.measured.MeasuredBRDF) of a material key or a file path."""
    from fit.formats import load_measured

    path = data_path(MATERIALS[name]) if name in MATERIALS else Path(name)
    return load_measured(path)


@lru_cache(maxsize=16)
def projected(name: str, statistic: str = "median"):
    from fit.projection.project import project

    return project(measured(name), statistic=statistic)


def material_spec(kind: str, data, sampler: str = "mis", scale=1.0, name="obj") -> MaterialSpec:
    """``kind``: lambert (data = albedo), measured, projected, rational (data = in-memory object)."""
    sc = tuple(np.broadcast_to(np.asarray(scale, float), 3))
    if kind == "lambert":
        return MaterialSpec(name=name, type="lambert", albedo=tuple(np.broadcast_to(np.asarray(data, float), 3)),
                            sampler=sampler)
    return MaterialSpec(name=name, type=kind, data=data, sampler=sampler, scale=sc)


# --------------------------------------------------------------------------------------------
# Scenes
GEOMETRY = {
    # object, camera origin, target, fov
    "sphere": dict(origin=(0.0, 0.9, 3.6), target=(0.0, 0.0, 0.0), fov=34.0),
    "bunny": dict(origin=(0.0, 0.95, 3.4), target=(0.0, 0.72, 0.0), fov=30.0),
    # a plane seen at a grazing angle (view ~80 deg from the normal at the image centre)
    "grazing_plane": dict(origin=(0.0, 0.35, 2.0), target=(0.0, 0.0, 0.0), fov=30.0),
    # the same plane seen from above (view ~10 deg from the normal)
    "normal_plane": dict(origin=(0.0, 2.0, 0.35), target=(0.0, 0.0, 0.0), fov=30.0),
}


def make_scene(geometry: str, light: str, material: MaterialSpec, resolution: int = 64,
               spp: int = 16, seed: int = 0, light_scale: float = 1.0, sun_dir=None) -> Scene:
    """One object with ``material``; ``light``: an ENVMAPS key, ``"colinear"`` (one directional
    light travelling along the view, irradiance 3) or ``"directional"`` (direction ``sun_dir``)."""
    g = GEOMETRY[geometry]
    cam = CameraSpec(origin=g["origin"], target=g["target"], up=(0.0, 1.0, 0.0), fov=g["fov"],
                     resolution=(int(resolution), int(resolution)))
    if geometry == "sphere":
        shapes = [ShapeSpec(type="sphere", material=material.name, center=(0.0, 0.0, 0.0), radius=0.8,
                            subdivisions=6)]
    elif geometry == "bunny":
        from warp_rbrdf import transforms

        shapes = [ShapeSpec(type="mesh", material=material.name, file=data_path("meshes/bun_zipper.ply"),
                            transform=transforms.compose(scale=(10.0, 10.0, 10.0),
                                                         translate=(0.17, -0.33, 0.0)))]
    else:
        shapes = [ShapeSpec(type="plane", material=material.name, size=(6.0, 6.0))]
    if light == "colinear":
        lights = [LightSpec(type="directional", irradiance=(3.0, 3.0, 3.0), colinear_with_view=True)]
    elif light == "directional":
        d = -np.asarray(sun_dir, float)
        lights = [LightSpec(type="directional", irradiance=(3.0, 3.0, 3.0),
                            direction=tuple(d / np.linalg.norm(d)))]
    else:
        from warp_rbrdf import transforms

        rot = transforms.compose(rotate=[[ENV_ROTATION.get(light, 0.0), 0.0, 1.0, 0.0]])[:3, :3]
        lights = [LightSpec(type="envmap", file=data_path(ENVMAPS[light]), scale=float(light_scale),
                            rotation=rot)]
    return Scene(camera=cam,
                 integrator=IntegratorSpec(spp=spp, seed=seed, max_depth=1, sampler=material.sampler,
                                           hide_environment=True, tile_size=16),
                 materials={material.name: material}, shapes=shapes, lights=lights,
                 path=f"<study {geometry}/{light}>")


_TABLES: dict = {}
_FITS: dict = {}
CDF_TIME_LIMIT_S: float | None = None   # bound on each rational CDF fit (s; None: fit_cdf's default; 0: none)
CDF_PIECES_KW: dict | None = None       # pieces layout options of the fits (None: fit_cdf's defaults)
#: Pieces layout options of the smoke-size presets: one phi-piece count and no re-measurement of
#: the variance gate's borderline rows (fit.sampling.variance_gate.fit_pieces). On the failure
#: map's mirror lobe about 1 s instead of about 30 s, with the same kind of outcome (some rows
#: rational, the others sampled with the table, with the reason).
SMALL_CDF_PIECES = dict(n_u=(16,), gate_recheck=None)


def cdf_for(spec: MaterialSpec, rational: bool):
    """The inverse-CDF table (``rational`` False) or table + verified rational fit of an
    in-memory material, as a ``fit.sampling.cdf_file.CDFFit``, made once per (data, type, scale) in this
    process and shared by every scene and sampler that uses it (the renderer would otherwise
    tabulate, and fit, again for each one); the fit with :data:`CDF_TIME_LIMIT_S` and
    :data:`CDF_PIECES_KW` (a fit made with other values is not reused). ``None`` for materials
    without in-memory data."""
    if spec.type == "lambert" or spec.data is None or isinstance(spec.data, (str, Path)):
        return None
    from fit.sampling.cdf_file import fit_cdf, table_only
    from warp_rbrdf import registry

    key = (id(spec.data), spec.type, tuple(np.broadcast_to(np.asarray(spec.scale, float), 3)))
    evaluate = registry.material(spec.type).impl().load(spec).evaluate   # scale applied
    if key not in _TABLES:   # the data object is kept alive with its entry, so its id stays unique
        _TABLES[key] = (table_only(evaluate, reason="table only (studies cache)", name=spec.name), spec.data)
    if not rational:
        return _TABLES[key][0]
    fit_key = key + (CDF_TIME_LIMIT_S, repr(sorted((CDF_PIECES_KW or {}).items())))
    if fit_key not in _FITS:
        kw = {} if CDF_TIME_LIMIT_S is None else {"time_limit_s": CDF_TIME_LIMIT_S or None}
        _FITS[fit_key] = fit_cdf(evaluate, name=spec.name, table=_TABLES[key][0].table,
                                 pieces_kw=CDF_PIECES_KW, **kw)
    return _FITS[fit_key]


def with_sampler(scene: Scene, sampler: str) -> Scene:
    """A copy of ``scene`` whose materials use ``sampler``; inverse-CDF samplers get the
    material's cached tables / fits (:func:`cdf_for`)."""
    import copy

    from warp_rbrdf.registry import RATIONAL_STRATEGIES, TABLE_STRATEGIES

    sc = copy.copy(scene)
    sc.materials = {k: copy.copy(v) for k, v in scene.materials.items()}
    for m in sc.materials.values():
        m.sampler = sampler
        if sampler in TABLE_STRATEGIES and m.cdf is None:
            m.cdf = cdf_for(m, sampler in RATIONAL_STRATEGIES)
    sc.integrator = copy.copy(scene.integrator)
    sc.integrator.sampler = sampler if sampler in BASE_SAMPLERS else sc.integrator.sampler
    return sc


def with_material(scene: Scene, material: MaterialSpec) -> Scene:
    import copy

    sc = copy.copy(scene)
    material = copy.copy(material)
    material.name = next(iter(scene.materials))
    sc.materials = {material.name: material}
    return sc


_MASKS: dict = {}


def object_mask(scene: Scene, renderer=None) -> np.ndarray:
    """Boolean (H, W): pixels fully covered by the object (all 4x4 sub-pixel camera rays hit it),
    so silhouette pixels, whose anti-aliasing noise is the same for every sampler and
    representation, are left out. Cached per camera and geometry."""
    key = (scene.camera.origin, scene.camera.target, scene.camera.fov, scene.camera.resolution,
           tuple((s.type, str(s.file), s.size, s.radius) for s in scene.shapes))
    if key not in _MASKS:
        from studies.coverage import coverage

        if renderer is None:
            from warp_rbrdf import Renderer

            renderer = Renderer(scene)
        _MASKS[key] = coverage(renderer, 4) >= 1.0
    return _MASKS[key]


# --------------------------------------------------------------------------------------------
# Rendering
def renderer(scene: Scene):
    """A compiled :class:`warp_rbrdf.Renderer`; returns (renderer, compile_seconds)."""
    from warp_rbrdf import Renderer

    r = Renderer(scene)
    c = r.compile()
    return r, c


def timed_render(r, spp: int, seed: int, threads: int | None = None, variance: bool = False):
    """Render once; returns (image, render_seconds[, variance])."""
    out = r.render(spp=spp, seed=seed, threads=threads, return_variance=variance)
    if variance:
        img, var = out
        return img, r.stats.render_seconds, var
    return out, r.stats.render_seconds


def progress(iterable=None, **kw):
    from tqdm import tqdm

    kw.setdefault("leave", False)
    kw.setdefault("file", sys.stderr)
    return tqdm(iterable, **kw)
