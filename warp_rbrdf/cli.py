"""``rbrdf`` command line: render scenes with the Warp renderer.

    rbrdf render [SCENE.toml] [--spp N] [--seed S] [--out image.exr] [--device cpu|cuda]
                 [--threads T] [--exposure EV] [--resolution W H] [--no-progress]
    rbrdf scene-format        # print the scene-file reference

Without a scene, renders the embedded default (sphere on a plane under a procedural sky).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from . import registry
from .defaults import default_scene
from .errors import RenderError
from .scene import FORMAT_DOC, load_scene

DESCRIPTION = """Warp renderer of the warp-rbrdf toolkit (Rational BRDF, Pacanowski et al. 2012).
'render' writes a linear float EXR and a tone-mapped sRGB PNG (exposure in its name and
metadata), shows a progress bar over image tiles and prints the render time (compile time
reported separately), samples per second and threads. 'scene-format' prints the scene keys."""


def _registry_help() -> str:
    """The material types and samplers a scene can name (from :mod:`warp_rbrdf.registry`)."""
    return ("material types: " + ", ".join(registry.MATERIAL_NAMES) + "\n"
            "samplers (per material, [materials.NAME] sampler): " + ", ".join(registry.STRATEGY_NAMES)
            + "\n'rbrdf scene-format' explains every key.")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="rbrdf", description=DESCRIPTION,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    r = sub.add_parser("render", help="render a TOML scene (or the embedded default)",
                       description="Render a scene. Relative paths in the scene resolve against "
                                   "its folder; ${RBRDF_DATA}/... and data:... against $RBRDF_DATA "
                                   "(from a source checkout, default ../shared/data next to it; "
                                   "installed, no default).",
                       epilog=_registry_help(), formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("scene", nargs="?", help="scene file (.toml); omitted: the embedded default scene")
    r.add_argument("--spp", type=int, help="camera samples per pixel (default: the scene's integrator.spp)")
    r.add_argument("--seed", type=int, help="random seed (default: the scene's integrator.seed)")
    r.add_argument("--out", "-o", help="output EXR (default out/<scene name>.exr); the PNG goes next "
                                       "to it as <name>_ev<exposure>.png")
    r.add_argument("--device", default="cpu", help="Warp device: cpu (default), cuda or cuda:N")
    r.add_argument("--threads", type=int, default=None,
                   help=f"CPU threads for the tiles (default: all cores, {os.cpu_count()} here)")
    r.add_argument("--exposure", type=float, default=0.0, help="PNG exposure in stops (default 0)")
    r.add_argument("--resolution", type=int, nargs=2, metavar=("W", "H"), help="override camera.resolution")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    sub.add_parser("scene-format", help="print the scene-file reference")
    return p


def cmd_render(a) -> int:
    from .image_io import png_path_for, write_exr, write_png
    from .renderer import Renderer  # imports Warp: only when rendering

    if a.scene:
        scene = load_scene(a.scene)
        name = Path(a.scene).stem
    else:
        scene = default_scene()
        name = "default"
    if a.resolution:
        if min(a.resolution) < 1:
            raise RenderError("--resolution: expected positive width and height")
        scene.camera.resolution = tuple(a.resolution)
    if a.spp is not None and a.spp < 1:
        raise RenderError(f"--spp: expected an integer >= 1, got {a.spp}")
    if a.threads is not None and a.threads < 1:
        raise RenderError(f"--threads: expected an integer >= 1, got {a.threads}")
    out = Path(a.out) if a.out else Path("out") / f"{name}.exr"
    if out.suffix.lower() != ".exr":
        raise RenderError(f"--out: expected an .exr file name, got {out.name!r}")
    r = Renderer(scene, device=a.device)
    r.compile()
    img = r.render(spp=a.spp, seed=a.seed, threads=a.threads, progress=not a.no_progress)
    s = r.stats
    meta = {"rbrdf:scene": scene.path, "rbrdf:spp": str(s.spp),
            "rbrdf:seed": str(a.seed if a.seed is not None else scene.integrator.seed),
            "rbrdf:render_seconds": f"{s.render_seconds:.3f}", "rbrdf:threads": str(s.threads),
            "rbrdf:device": s.device}
    write_exr(out, img, meta)
    png = png_path_for(out, a.exposure)
    write_png(png, img, a.exposure, meta)
    print(f"scene    {scene.path}: {s.width}x{s.height}, {s.spp} spp, "
          f"{r.geometry.num_triangles} triangles, max_depth {scene.integrator.max_depth}")
    print(f"setup    {s.setup_seconds:.2f} s (files, tables, BVH)")
    print(f"compile  {s.compile_seconds:.2f} s (code generation + Warp compile or cache load)")
    print(f"render   {s.render_seconds:.3f} s on {s.device} with {s.threads} thread(s), "
          f"{s.tiles} tiles: {s.samples_per_second / 1e6:.3f} M samples/s")
    print(f"wrote    {out} (linear EXR) and {png} (sRGB, exposure {a.exposure:+.2f} EV)")
    return 0


def main(argv=None) -> int:
    p = _parser()
    a = p.parse_args(argv)
    if a.command is None:
        p.print_help()
        return 2
    try:
        if a.command == "scene-format":
            print(FORMAT_DOC)
            return 0
        return cmd_render(a)
    except RenderError as e:
        print(f"rbrdf: error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("rbrdf: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
