"""What the render kernel's lanes buy (:mod:`warp_rbrdf.lanes`): the reference sphere scene
rendered with each representation, its samples of a pixel taken one at a time (``LANES`` 0)
and 16 at a time (the default), in one process, interleaved.

    python -m benchmarks.bench_lanes [--cases rgl rational-2d ...] [--maps studio rooitou]
        [--object sphere|bunny|teapot] [--resolution 64] [--spp 64] [--repeats 7] [--lanes 16] [--json FILE]
        [--docs]

The scene: :func:`lab.mitsuba_reference.sphere_scene` (unit sphere, camera at z = 4, hidden map,
direct light). Cases (``--cases``; each material with its default sampler, so the lanes draw
what a user's render draws): ``rgl`` (cc_ibiza_sunset's file, ``mis-rgl``: environment and BSDF
samples both in lanes), ``rational-2d`` (the shipped 2-D satin fit, ``mis-tabulated``),
``rational-3d`` (a 3-D satin fit, ``--fit3d``; the chart's cache file when there is one, else
the case is left out), ``projected`` (satin's median projection, ``mis-tabulated``), ``lambert``
(``mis``: the environment samples only). Timing: one thread, each render's CPU seconds of the
launching thread (the machine may be shared), the two kernels in turn render by render, the
median over ``--repeats``; both kernels are compiled before the first timed render. Each case
also compares the two images (same seed): the lanes draw the one-at-a-time samples, so the
images agree to float rounding (a search stopping on the other side of a tie).
Needs ``$RBRDF_DATA`` (``rgl/``, ``envmaps/``).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from warp_rbrdf.paths import require_data_root

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "cpu_lanes.md"
MARK = ("<!-- bench_lanes: begin -->", "<!-- bench_lanes: end -->")
MAPS = {"studio": "studio_small_03_1k.hdr", "rooitou": "rooitou_park_1k.hdr"}
CASES = ("rgl", "rational-2d", "rational-3d", "projected", "lambert")


def default_fit3d() -> Path | None:
    """The chart's cached 3-D satin fit (the newest), if any."""
    files = sorted((ROOT / "results" / "chart" / "fits").glob("satin_rosaline_rgb_3d_*.json"),
                   key=lambda p: p.stat().st_mtime)
    return files[-1] if files else None


def scene_of(case: str, envmap: Path, spp: int, resolution: int, fit3d: Path | None, obj: str = "sphere"):
    """The reference scene with the case's material (named ``obj``) on the analytic sphere, or on
    the bunny or the teapot of :mod:`benchmarks.bench_mesh_vs_mitsuba` (``obj``)."""
    sc = _scene_of(case, envmap, spp, resolution, fit3d)
    if obj != "sphere":
        from benchmarks.bench_mesh_vs_mitsuba import OBJECTS, mesh_to_world
        from warp_rbrdf.geometry import load_mesh_file
        from warp_rbrdf.scene import ShapeSpec

        path = require_data_root("bench_lanes") / OBJECTS[obj]
        sc.shapes = [ShapeSpec(type="mesh", material="obj", file=path, transform=mesh_to_world(load_mesh_file(path)[0]))]
    return sc


def _scene_of(case: str, envmap: Path, spp: int, resolution: int, fit3d: Path | None):
    from fit.formats import load_measured
    from fit.projection.project import project
    from lab.mitsuba_reference import sphere_scene
    from warp_rbrdf.paths import PACKAGE_DATA
    from warp_rbrdf.scene import MaterialSpec

    rgl = require_data_root("bench_lanes") / "rgl"
    if case == "rgl":
        return sphere_scene(rgl / "cc_ibiza_sunset_rgb.bsdf", envmap, spp, resolution=resolution)
    sc = sphere_scene(("lambert", (0.5, 0.5, 0.5)), envmap, spp, resolution=resolution)
    if case == "rational-2d":
        sc.materials["obj"] = MaterialSpec(name="obj", type="rational", file=PACKAGE_DATA / "satin_rosaline_rgb.json")
    elif case == "rational-3d":
        sc.materials["obj"] = MaterialSpec(name="obj", type="rational", file=fit3d)
    elif case == "projected":
        sc.materials["obj"] = MaterialSpec(name="obj", type="projected",
                                           data=project(load_measured(rgl / "satin_rosaline_rgb.bsdf")))
    return sc


def run_case(scene, lanes: int, spp: int, repeats: int) -> dict:
    """Both kernels of ``scene`` (lanes 0 and ``lanes``), timed in turn; their images compared."""
    from warp_rbrdf import lanes as L
    from warp_rbrdf.renderer import Renderer

    saved = L.LANES
    renderers = {}
    try:
        for k in (0, lanes):
            L.LANES = k
            r = Renderer(scene, device="cpu")
            r.compile()
            renderers[k] = r
    finally:
        L.LANES = saved
    times = {k: [] for k in renderers}
    images = {}
    for rep in range(repeats):
        for k in (list(renderers) if rep % 2 == 0 else list(renderers)[::-1]):
            c0 = time.thread_time()
            images[k] = renderers[k].render(spp=spp, seed=3, threads=1)
            times[k].append(time.thread_time() - c0)
    n = scene.camera.resolution[0] * scene.camera.resolution[1] * spp
    one, many = images[0], images[lanes]
    d = np.abs(many - one).max(-1) / max(float(np.abs(one).mean()), 1e-30)
    t0, t1 = statistics.median(times[0]), statistics.median(times[lanes])
    return {"one_at_a_time_msps": n / t0 / 1e6, "lanes_msps": n / t1 / 1e6, "speedup": t0 / t1,
            "image_mean_rel_diff": float(d.mean()), "image_max_rel_diff": float(d.max()),
            "pixels_above_1e-4": int(np.count_nonzero(d > 1e-4)), "pixels": int(d.size)}


def markdown(res: dict) -> str:
    lines = [f"{res.get('object', 'sphere')}; {res['machine']}, {res['date']}; `uptime` at the start: {res['load_start']}, "
             f"at the end: {res['load_end']}; {res['resolution']}², {res['spp']} spp, one thread, median of "
             f"{res['repeats']} renders, lanes {res['lanes']}",
             "",
             "| case | map | M samples / CPU s, one at a time | with lanes | speed-up | image: mean / max relative difference | pixels > 10⁻⁴ |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for key, r in res["cases"].items():
        case, m = key.split("/")
        lines.append(f"| {case} | {m} | {r['one_at_a_time_msps']:.3f} | {r['lanes_msps']:.3f} | **{r['speedup']:.2f}** | "
                     f"{r['image_mean_rel_diff']:.1e} / {r['image_max_rel_diff']:.1e} | {r['pixels_above_1e-4']} of {r['pixels']} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_lanes",
                                 description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    ap.add_argument("--maps", nargs="+", default=list(MAPS), choices=list(MAPS))
    ap.add_argument("--object", default="sphere", choices=("sphere", "bunny", "teapot"),
                    help="the analytic sphere (default) or a mesh of bench_mesh_vs_mitsuba")
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--lanes", type=int, default=16, help="the lane count measured against one at a time")
    ap.add_argument("--fit3d", type=Path, default=None, help="the 3-D fit of case rational-3d (default: the chart's)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--docs", action="store_true", help=f"write the table between the markers of {DOCS.name}")
    ap.add_argument("--quick", action="store_true", help="tiny renders (a smoke test; no timing worth reading)")
    args = ap.parse_args(argv)
    from warp_rbrdf.runtime import init_warp

    init_warp()
    if args.quick:
        args.resolution, args.spp, args.repeats = 8, 20, 1
    fit3d = args.fit3d or default_fit3d()
    from benchmarks.bench_eval import machine

    m = machine()
    res = {"machine": f"{m['cpu']}, {m['cores']} cores, Warp {m['warp']}", "object": args.object,
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
           "load_start": os.getloadavg(), "resolution": args.resolution, "spp": args.spp, "repeats": args.repeats,
           "lanes": args.lanes, "cases": {}}
    for m in args.maps:
        envmap = require_data_root("bench_lanes") / "envmaps" / MAPS[m]
        for case in args.cases:
            if case == "rational-3d" and fit3d is None:
                print(f"{case}: no 3-D fit (give --fit3d); left out", file=sys.stderr)
                continue
            r = run_case(scene_of(case, envmap, args.spp, args.resolution, fit3d, args.object), args.lanes, args.spp,
                         args.repeats)
            res["cases"][f"{case}/{m}"] = r
            print(f"{case:12s} {m:8s} {r['one_at_a_time_msps']:.3f} -> {r['lanes_msps']:.3f} M samples / CPU s "
                  f"({r['speedup']:.2f}x); images: mean rel. diff {r['image_mean_rel_diff']:.1e}", flush=True)
    res["load_end"] = os.getloadavg()
    res["load_start"] = " ".join(f"{x:.2f}" for x in res["load_start"])
    res["load_end"] = " ".join(f"{x:.2f}" for x in res["load_end"])
    print(markdown(res))
    if args.docs:
        text = DOCS.read_text()
        a, b = text.index(MARK[0]), text.index(MARK[1])
        DOCS.write_text(text[:a] + MARK[0] + "\n" + markdown(res) + "\n" + text[b:])
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
