"""``rbrdf`` command line: render scenes with the Warp renderer.

    rbrdf render [SCENE.toml] [--spp N] [--seed S] [--out image.exr] [--device cpu|cuda]
                 [--threads T] [--exposure EV] [--resolution W H] [--no-progress]
    rbrdf scene-format        # print the scene-file reference

Without a scene, renders the embedded default (sphere on a plane under a procedural sky).

Bad input (docs/robustness.md): one line on stderr, ``rbrdf: error: ...`` naming the file and
key, the flag or the output path, exit status 2, no traceback and no warnings; flags are typed
and bounded by :mod:`warp_rbrdf.limits` (``rbrdf render: error: argument --spp: ...``). The
output paths are checked before the scene is read; the EXR and the PNG are staged as temporary
files, read back (a full disk, an I/O error or a short file is one line naming the output, exit
status 2) and renamed into place together only when the render is complete, every pixel is
finite and both files are whole (:class:`fit.outputs.OutputSet`): a failing run leaves every
existing file as it was.
"""
from __future__ import annotations

import argparse
import os
import re
import sys
import warnings
from pathlib import Path

import numpy as np

from fit.cli.flags import OneLineParser, integer, number, quiet_stdout
from fit.errors import FlagError, RbrdfError, display_path
from fit.outputs import OutputSet, check_output_file

from . import limits, registry
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
            + "\n'rbrdf scene-format' explains every key.\n"
            "environment: RBRDF_DEVICE (the device when --device is not given); RBRDF_CPU_ISA (the CPU "
            "kernels' instruction set, by default x86-64-v4 with AVX-512, else x86-64-v3: x86-64-v3 "
            "gives the same images on every machine, native compiles for this CPU).")


def device_name(text: str) -> str:
    """Converter of ``--device``: ``cpu``, ``cuda`` or ``cuda:N`` (whether it exists is checked
    when the renderer starts)."""
    name = text.strip().lower()
    if not re.fullmatch(r"cpu|cuda(:\d{1,3})?", name):
        raise argparse.ArgumentTypeError(f"unknown device {text[:40]!r}; expected 'cpu', 'cuda' or 'cuda:N'")
    return name


def _parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="rbrdf", description=DESCRIPTION,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    r = sub.add_parser("render", help="render a TOML scene (or the embedded default)",
                       description="Render a scene. Relative paths in the scene resolve against "
                                   "its folder; ${RBRDF_DATA}/... and data:... against $RBRDF_DATA "
                                   "(from a source checkout, default ../shared/data next to it; "
                                   "installed, no default).",
                       epilog=_registry_help(), formatter_class=argparse.RawDescriptionHelpFormatter)
    r.add_argument("scene", nargs="?", help="scene file (.toml); omitted: the embedded default scene")
    r.add_argument("--spp", type=integer(1, limits.MAX_SPP),
                   help=f"camera samples per pixel, 1-{limits.MAX_SPP} (default: the scene's integrator.spp)")
    r.add_argument("--seed", type=integer(0, 2**32 - 1), help="random seed in [0, 2^32) (default: the "
                                                               "scene's integrator.seed)")
    r.add_argument("--out", "-o", help="output EXR (default out/<scene name>.exr); the PNG goes next "
                                       "to it as <name>_ev<exposure>.png")
    r.add_argument("--device", default=None, type=device_name,
                   help="Warp device: cpu, cuda or cuda:N (default: $RBRDF_DEVICE, else cpu)")
    r.add_argument("--threads", type=integer(1, limits.MAX_THREADS), default=None,
                   help=f"CPU threads for the tiles (default: all cores, {os.cpu_count()} here)")
    r.add_argument("--exposure", type=number(-limits.MAX_EXPOSURE_EV, limits.MAX_EXPOSURE_EV), default=0.0,
                   help="PNG exposure in stops (default 0)")
    r.add_argument("--resolution", type=integer(1, limits.MAX_RESOLUTION_SIDE), nargs=2, metavar=("W", "H"),
                   help="override camera.resolution")
    r.add_argument("--no-progress", action="store_true",
                   help="no progress on stderr (setup stages, kernel load and image tiles)")
    sub.add_parser("scene-format", help="print the scene-file reference")
    return p


def output_paths(a, name: str) -> tuple:
    """``(exr, png)``: the output paths of a render, checked before anything is read or
    rendered (a folder or special file as the target, a parent that is a file, a read-only
    place, a wrong suffix: one-line :class:`fit.errors.OutputError`)."""
    given = Path(a.out) if a.out is not None else Path("out") / f"{name}.exr"
    if a.out is not None and not a.out:
        raise FlagError("--out", "empty path")
    png = png_path_for_name(given, a.exposure)
    return check_output_file(given, "--out", (".exr",)), check_output_file(png, "--out", (".png",))


def png_path_for_name(exr: Path, exposure: float) -> Path:
    from .image_io import png_path_for

    return png_path_for(exr, exposure)


def _init_warp_quietly() -> None:
    """Initialise Warp with the C-level stderr silenced: on a machine without a CUDA driver its
    native code prints "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver" to
    file descriptor 2, a warning that is no message to the user (``--device cuda`` there is a
    one-line error of :func:`warp_rbrdf.runtime.get_device`)."""
    from .runtime import init_warp

    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):
        init_warp()
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
            try:
                init_warp()
            finally:
                os.dup2(saved, 2)
    finally:
        os.close(saved)


def seen_at(r, x: int, y: int) -> str:
    """``", where the camera sees material 'NAME'"`` (or the environment) through the centre
    of pixel (``x``, ``y``) of the renderer ``r``: a NumPy cast of the primary ray against its
    spheres and triangles (in blocks of 2^20 triangles), for the message about a non-finite
    image. Diagnostic only: "" when it cannot tell."""
    from .camera import camera_rays_numpy

    try:
        cam = r.scene.camera
        o = np.asarray(cam.origin, float)
        d = camera_rays_numpy(cam, x + 0.5, y + 0.5)
        g = r.geometry
        best_t, best_m = np.inf, -1
        if g.num_spheres:
            c, rad = g.spheres[:, :3].astype(float), g.spheres[:, 3].astype(float)
            oc = o - c
            b = oc @ d
            disc = b * b - ((oc * oc).sum(axis=1) - rad * rad)
            sq = np.sqrt(np.maximum(disc, 0.0))
            t = np.where(-b - sq > 1e-9, -b - sq, -b + sq)
            t = np.where((disc >= 0) & (t > 1e-9), t, np.inf)
            i = int(np.argmin(t))
            if t[i] < best_t:
                best_t, best_m = t[i], int(g.sphere_material[i])
        pts, tris = g.points.astype(float), g.indices.reshape(-1, 3)
        for s0 in range(0, len(tris), 1 << 20):
            tri = tris[s0:s0 + (1 << 20)]
            v0 = pts[tri[:, 0]]
            e1, e2 = pts[tri[:, 1]] - v0, pts[tri[:, 2]] - v0
            p = np.cross(d, e2)
            det = (e1 * p).sum(axis=1)
            inv = 1.0 / np.where(np.abs(det) > 1e-300, det, 1.0)
            tv = o - v0
            u = (tv * p).sum(axis=1) * inv
            q = np.cross(tv, e1)
            v = (q @ d) * inv
            t = (e2 * q).sum(axis=1) * inv
            t = np.where((np.abs(det) > 1e-300) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9), t, np.inf)
            i = int(np.argmin(t))
            if t[i] < best_t:
                best_t, best_m = t[i], int(g.material[s0 + i])
        if best_m < 0:
            return ", where the camera sees the environment"
        return f", where the camera sees material {r.material_data.names[best_m]!r}"
    except Exception:  # noqa: BLE001 - a diagnostic must not turn the one-line error into a traceback
        return ""


def cmd_render(a) -> int:
    from .image_io import nonfinite_pixels, write_exr, write_png

    name = Path(a.scene).stem if a.scene else "default"
    out, png = output_paths(a, name)
    if a.scene is not None and not a.scene:
        raise FlagError("SCENE", "empty path")
    scene = load_scene(a.scene) if a.scene else default_scene()
    if a.resolution:
        scene.camera.resolution = tuple(a.resolution)
    W, H = scene.camera.resolution
    spp = a.spp if a.spp is not None else scene.integrator.spp
    problem = limits.check_render_size(W, H, spp)
    if problem:
        flags = [f for f, v in (("--resolution", a.resolution), ("--spp", a.spp)) if v is not None]
        raise FlagError("/".join(flags) or "camera.resolution x integrator.spp", problem)
    problem = limits.check_tiles(W, H, scene.integrator.tile_size)
    if problem:
        raise FlagError("--resolution" if a.resolution else "integrator.tile_size", problem)

    _init_warp_quietly()
    from .renderer import Renderer  # imports Warp: only when rendering

    from fit.progress import CLIProgress

    setup_progress = CLIProgress("rbrdf render", enabled=not a.no_progress)
    r = Renderer(scene, device=a.device, progress=setup_progress)
    r.compile()
    setup_progress.close()
    img = r.render(spp=spp, seed=a.seed, threads=a.threads, progress=not a.no_progress)
    n_bad, first = nonfinite_pixels(img)
    if n_bad:
        mats = ", ".join(r.material_data.names) or "none"
        seen = seen_at(r, first[1], first[0])
        raise RenderError(f"{display_path(scene.path)}: the rendered image has {n_bad} of {W * H} pixels "
                          f"that are NaN or infinite (first at x {first[1]}, y {first[0]}{seen}; "
                          f"materials: {mats}); nothing written")
    s = r.stats
    meta = {"rbrdf:scene": display_path(scene.path), "rbrdf:spp": str(s.spp),
            "rbrdf:seed": str(a.seed if a.seed is not None else scene.integrator.seed),
            "rbrdf:render_seconds": f"{s.render_seconds:.3f}", "rbrdf:threads": str(s.threads),
            "rbrdf:device": s.device}
    with OutputSet("--out") as outputs:       # both read back, then renamed together
        with outputs.writing(out) as tmp:
            write_exr(tmp, img, meta, atomic=False)
        with outputs.writing(png) as tmp:
            write_png(tmp, img, a.exposure, meta, atomic=False)
        outputs.commit()
    print(f"scene    {display_path(scene.path)}: {s.width}x{s.height}, {s.spp} spp, "
          f"{r.geometry.num_triangles} triangles, max_depth {scene.integrator.max_depth}")
    print(f"setup    {s.setup_seconds:.2f} s (files, tables, BVH)")
    how = {"shipped": "kernel shipped with the package, nothing compiled",
           "cache": "kernel loaded from the Warp cache",
           "compiled": "kernel compiled and cached"}.get(r.kernel_source, "Warp compile or cache load")
    print(f"compile  {s.compile_seconds:.2f} s ({how})")
    print(f"render   {s.render_seconds:.3f} s on {s.device} with {s.threads} thread(s), "
          f"{s.tiles} tiles: {s.samples_per_second / 1e6:.3f} M samples/s")
    print(f"wrote    {display_path(out)} (linear EXR) and {display_path(png)} "
          f"(sRGB, exposure {a.exposure:+.2f} EV)")
    return 0


def main(argv=None) -> int:
    """Run ``rbrdf`` with ``argv`` (default ``sys.argv[1:]``); returns the exit status: 0
    success, 2 bad input (one line on stderr; also a bare ``rbrdf``, which prints its usage on
    stderr), 130 interrupted."""
    p = _parser()
    try:
        a = p.parse_args(argv)
    except SystemExit as e:          # --help (0) or a one-line flag error (2)
        return e.code if isinstance(e.code, int) else 2
    if a.command is None:
        p.print_usage(sys.stderr)
        print("rbrdf: error: a command is required: render or scene-format (see rbrdf --help)", file=sys.stderr)
        return 2
    try:
        # NumPy and library warnings are not messages to the user: what matters is checked and
        # reported in one line
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            if a.command == "scene-format":
                print(FORMAT_DOC)
                return 0
            return cmd_render(a)
    except RbrdfError as e:          # RenderError, SceneError and the fitter's readers' errors
        print(f"rbrdf: error: {e}", file=sys.stderr)
        return 2
    except MemoryError:
        print("rbrdf: error: out of memory (no output written); the scene asks for more than the "
              "limits of warp_rbrdf.limits foresee", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("rbrdf: interrupted (no output written)", file=sys.stderr)
        return 130
    except BrokenPipeError:          # stdout closed early (rbrdf scene-format | head -1)
        quiet_stdout()
        return 141                   # as a tool killed by SIGPIPE; the outputs were committed


if __name__ == "__main__":
    sys.exit(main())
