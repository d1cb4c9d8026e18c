"""Shared helpers of the studies: data paths, in-memory scenes, sampler discovery, timed renders,
image metrics (RMSE on an object mask, CIE ΔE2000 with colour-science), small writers and
:func:`publish_docs` (each study's ``--docs``: charts to ``docs/images/``, the full report to
``docs/study_<name>.md`` and the study's block in ``docs/results.md`` between its markers).

The studies are run as modules from the checkout root (``python -m studies.convergence ...``);
colour-science comes with the ``studies`` extra (``pip install -e ".[studies]"``).

Every study builds its scenes in memory (no TOML files), with the object alone in front of a
hidden environment (``hide_environment = true``) so that errors are measured on the object's
pixels only; :func:`object_mask` gives those pixels.
"""
from __future__ import annotations

import csv
import json
import os
import shlex
import shutil
import sys
import time
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
    """Every sampler of the renderer's registry (base ones first)."""
    from warp_rbrdf.registry import STRATEGY_NAMES as names

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
CDF_TIME_LIMIT_S: float | None = None   # bound on each rational CDF fit (None: fit_cdf's default)
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
        kw = {} if CDF_TIME_LIMIT_S is None else {"time_limit_s": CDF_TIME_LIMIT_S}
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


def rmse(img, ref, mask) -> float:
    d = (np.asarray(img, np.float64) - np.asarray(ref, np.float64))[mask]
    return float(np.sqrt(np.mean(d * d))) if d.size else float("nan")


# --------------------------------------------------------------------------------------------
# Colour: linear Rec.709 -> XYZ -> CIE Lab -> ΔE2000, all with colour-science.
def exposure_for(ref, mask, percentile: float = 99.0) -> float:
    """Scale that maps the ``percentile`` of the reference's luminance on ``mask`` to Y = 1
    (the Lab white), so ΔE is measured at a fixed, stated exposure per scene."""
    Y = np.asarray(ref, np.float64)[mask] @ np.array([0.2126, 0.7152, 0.0722])
    v = np.percentile(Y, percentile) if Y.size else 1.0
    return float(1.0 / v) if v > 0 else 1.0


def rgb_to_lab(img, exposure: float = 1.0) -> np.ndarray:
    import colour

    cs = colour.RGB_COLOURSPACES["ITU-R BT.709"]
    rgb = np.asarray(img, np.float64) * exposure
    xyz = colour.RGB_to_XYZ(rgb, cs, illuminant=cs.whitepoint, chromatic_adaptation_transform=None,
                            apply_cctf_decoding=False)
    return colour.XYZ_to_Lab(xyz, cs.whitepoint)


def delta_e2000(img, ref, exposure: float = 1.0) -> np.ndarray:
    """Per-pixel CIE ΔE2000 between two linear Rec.709 images at the same exposure."""
    import colour

    return colour.delta_E(rgb_to_lab(img, exposure), rgb_to_lab(ref, exposure), method="CIE 2000")


def de_stats(de, mask) -> dict:
    v = np.asarray(de)[mask]
    return {"mean": float(v.mean()), "p99": float(np.percentile(v, 99)), "max": float(v.max())} if v.size \
        else {"mean": float("nan"), "p99": float("nan"), "max": float("nan")}


# --------------------------------------------------------------------------------------------
# Writers
def write_csv(path, rows: list[dict]):
    path = Path(path)
    keys = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def write_json(path, obj):
    Path(path).write_text(json.dumps(obj, indent=1, default=_json_default))


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(type(o))


def md_table(rows: list[list], header: list[str]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join(" --- " for _ in header) + "|"]
    for r in rows:
        out.append("| " + " | ".join(_fmt(x) for x in r) + " |")
    return "\n".join(out) + "\n"


def _fmt(x):
    if isinstance(x, float):
        if not np.isfinite(x):
            return "–"
        a = abs(x)
        if a != 0 and (a < 1e-3 or a >= 1e5):
            return f"{x:.2e}"
        return f"{x:.3g}" if a < 100 else f"{x:.0f}"
    return str(x)


def save_png(path, img, exposure=1.0):
    """sRGB PNG of a linear image (exposure stated by the caller)."""
    import matplotlib.image as mpimg

    x = np.clip(np.asarray(img, np.float64) * exposure, 0, None)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    mpimg.imsave(str(path), np.clip(srgb, 0, 1))


def machine_info() -> dict:
    import platform

    return {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
            "time": time.strftime("%Y-%m-%d %H:%M:%S")}


def progress(iterable=None, **kw):
    from tqdm import tqdm

    kw.setdefault("leave", False)
    kw.setdefault("file", sys.stderr)
    return tqdm(iterable, **kw)


# --------------------------------------------------------------------------------------------
# Publishing (``--docs``): docs/images/study_*.png, docs/study_<name>.md and the study's block in
# docs/results.md
RESULTS_PAGE = Path("docs") / "results.md"
DOCS_HELP = ("also write docs/images/study_*.png, docs/study_<name>.md and the study's block in "
             "docs/results.md (between its BEGIN/END study markers)")


def add_docs_arguments(parser):
    """``--docs`` (and ``--docs-root``, the folder holding docs/) for a study's CLI."""
    parser.add_argument("--docs", action="store_true", help=DOCS_HELP)
    parser.add_argument("--docs-root", default=str(ROOT),
                        help="folder holding docs/ (docs/results.md with the studies' markers, docs/images/, "
                             "docs/study_<name>.md); default: the repository root")


def publish_run(args, res: dict, block_table, script, argv, docs: dict):
    """A study's ``--docs`` step after its run: :func:`publish_docs` of the run ``res`` (its
    ``markdown`` and ``meta``) with ``block_table(res)``, the command rebuilt from ``script`` and
    ``argv``, and the study's ``docs`` dict (name, title, charts); nothing without ``--docs``."""
    if not args.docs:
        return None
    pub = publish_docs(out=args.out, summary_md=res["markdown"], meta=res["meta"], block_table=block_table(res),
                       command=command_line(script, argv), docs_root=args.docs_root, **docs)
    n = len(pub["images"])
    print(f"published {pub['doc']}, {n} chart{'s' if n != 1 else ''} and the block in {pub['results']}")
    return pub


def command_line(script, argv=None) -> str:
    """The command that ran a study, as ``python -m studies.<name> ARGS`` (``script``: the study's
    file, e.g. its ``__file__`` or ``sys.argv[0]``; ``argv``: the arguments, default
    ``sys.argv[1:]``). A script outside the repository is given as ``python PATH ARGS``."""
    script = Path(script).resolve()
    args = sys.argv[1:] if argv is None else list(argv)
    try:
        rel = script.relative_to(ROOT)
    except ValueError:
        return shlex.join(["python", str(script), *map(str, args)])
    return shlex.join(["python", "-m", ".".join(rel.with_suffix("").parts), *map(str, args)])


def block_markers(name: str) -> tuple[str, str]:
    """The study's BEGIN / END markers in docs/results.md."""
    return f"<!-- BEGIN study:{name} -->", f"<!-- END study:{name} -->"


def replace_block(text: str, name: str, block: str, where: str = str(RESULTS_PAGE)) -> str:
    """``text`` with what lies between the study's two markers replaced by ``block`` (the markers
    and everything outside them unchanged). A marker that is missing, repeated or out of order is a
    ``ValueError`` naming it (and ``where``, the file the text comes from)."""
    begin, end = block_markers(name)
    for m in (begin, end):
        n = text.count(m)
        if n != 1:
            raise ValueError(f"{where}: marker {m!r} " + ("not found" if n == 0 else f"found {n} times")
                             + f": add the pair {begin!r} ... {end!r} where the study's block goes")
    i = text.index(begin) + len(begin)
    j = text.index(end)
    if j < i:
        raise ValueError(f"{where}: marker {end!r} comes before {begin!r}")
    return text[:i] + "\n" + block.strip("\n") + "\n" + text[j:]


def _run_line(meta: dict) -> tuple[str, str]:
    """(long, short) description of the run: wall seconds and machine."""
    wall = meta.get("wall_seconds")
    m = meta.get("machine") or machine_info()
    w = f"{wall:.0f} s" if isinstance(wall, (int, float)) else "–"
    return (f"Wall time: {w} (the study's run, charts excluded). Machine: {m.get('cpus')} CPUs, "
            f"{m.get('platform')}, Python {m.get('python')}; finished {m.get('time')}.",
            f"{w} on {m.get('cpus')} CPUs, {str(m.get('time', ''))[:10]}")


def publish_docs(name: str, title: str, out, summary_md: str, meta: dict, charts: dict,
                 block_table: str, command: str | None = None, docs_root=None,
                 block_charts=None) -> dict:
    """Publish one study's run (its ``--docs``).

    ``name``: the study's key (markers ``<!-- BEGIN study:<name> -->`` /
    ``<!-- END study:<name> -->`` in ``docs/results.md``, report ``docs/study_<name>.md``);
    ``out``: the folder the run wrote its charts to; ``charts``: {file in ``out``: name under
    ``docs/images/``}, in display order; ``block_charts``: the subset (of those names) shown in
    the results page's block (default: all); ``summary_md``: the study's full markdown summary;
    ``meta``: its meta (``wall_seconds``, ``machine``); ``block_table``: the compact markdown of
    key numbers for the block; ``command``: the command line (default: rebuilt from
    ``sys.argv``); ``docs_root``: folder holding ``docs/`` (default: the repository root).

    The block's links are relative to ``docs/`` (``images/<chart>``, ``study_<name>.md``).
    Everything is checked (charts present, ``docs/results.md`` present with the study's markers
    once each) before anything is written, so a failure leaves the docs as they were. Returns
    the paths written (``images``, ``doc``, ``results``) and the ``block``."""
    root = Path(docs_root) if docs_root is not None else ROOT
    if meta.get("preset") == "smoke" and root.resolve() == ROOT.resolve():
        raise ValueError(f"study {name}: a --smoke run would overwrite the repository's docs (docs/results.md "
                         "block, docs/study_*.md); give --docs-root another folder")
    out = Path(out)
    command = command or command_line(sys.argv[0])
    results = root / RESULTS_PAGE
    missing = [str(out / s) for s in charts if not (out / s).is_file()]
    if missing:
        raise FileNotFoundError(f"study {name}: chart(s) not written by this run: {', '.join(missing)}")
    if not results.is_file():
        raise FileNotFoundError(f"no {RESULTS_PAGE.as_posix()} in {root}")
    with open(results, encoding="utf-8", newline="") as f:
        text = f.read()
    long_run, short_run = _run_line(meta)
    shown = [d for d in charts.values() if block_charts is None or d in block_charts]
    block = "\n".join([f"**{title}** · `{command}` ({short_run})", "",
                       *[f"![{Path(d).stem}](images/{d})" for d in shown], "",
                       block_table.strip("\n"), "",
                       f"Generated by `--docs`; the full report with every table: "
                       f"[study_{name}.md](study_{name}.md)."])
    new_text = replace_block(text, name, block, where=str(results))
    images = root / "docs" / "images"
    images.mkdir(parents=True, exist_ok=True)
    written = []
    for src, dst in charts.items():
        shutil.copyfile(out / src, images / dst)
        written.append(images / dst)
    doc = root / "docs" / f"study_{name}.md"
    doc.write_text("\n".join([f"# {title}", "",
                              "Generated by the study's `--docs` (edits here are overwritten: re-run the "
                              "command).", "",
                              f"Command: `{command}`", "", long_run, "",
                              *[f"![{Path(d).stem}](images/{d})\n" for d in charts.values()],
                              summary_md.strip("\n"), ""]), encoding="utf-8")
    if new_text != text:
        with open(results, "w", encoding="utf-8", newline="") as f:
            f.write(new_text)
    return dict(images=written, doc=doc, results=results, block=block)
