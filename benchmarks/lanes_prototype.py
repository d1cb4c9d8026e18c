"""Prototype: the render kernel's sample over K lanes per Warp thread, against one sample per
thread, on Warp's CPU backend (samples/s, same image, vector instructions in the object).
Results and conclusion: docs/cpu_lanes.md.

    python -m benchmarks.lanes_prototype [--quick] [--material cc_ibiza_sunset_rgb]
        [--envmap studio_small_03_1k] [--resolution 128] [--spp 64] [--repeats 5]
        [--lanes 1 4 8 16] [--kinds lanes loop hybrid gather slp] [--no-guided]
        [--threads 1 2] [--breakdown VARIANT ...] [--remarks VARIANT] [--wavefront] [--json FILE]

The scene is the reference sphere of ``benchmarks/bench_vs_mitsuba.py`` (unit sphere, camera at
z = 4, 30 deg vertical field of view, hidden map, direct light): per camera sample one
environment sample and one BSDF sample of the ``rgl`` material, two shadow rays, MIS
(:mod:`benchmarks.lanes_kernels`, :mod:`benchmarks.lanes_scene`, :mod:`benchmarks.lanes_shading`).
Variants:

* ``scalar``: one sample per loop iteration with the production ``rgl`` functions and the
  distribution module's 2-D sampler (branches, early-exit binary searches), as the integrator;
* ``lanes K=k``: ``k`` samples of a pixel per step, branch-free, the searches as fixed halving
  steps over all lanes at once, the lane loops unrolled by Warp (``K=1``: the same branch-free
  code, one sample per step); ``slp K=k``: the same with LLVM's default SLP depth;
* ``loop K=k``: the lane loops left as loops (LLVM's loop vectorizer); ``hybrid K=k``: loops,
  the scalar kernel's branches kept around each lane's shading; ``gather K=k``: loops, LLVM
  allowed to emit gathers (``+fast-gather``);
* ``unguided`` / ``guided``: one sample per iteration, the same shading with branches, the
  binary searches over every interval / started from guide tables (:mod:`benchmarks.lanes_guides`);
* ``wavefront``: the scalar kernel's sample cut into breadth-first stages, a kernel per stage
  over every sample of a tile, the state between them in arrays
  (:mod:`benchmarks.lanes_wavefront`; ``--wavefront``).

Each variant renders the same image (same seed) through 16-px tiles launched from a thread pool
(``--threads``, as the renderer's ``launch_tiles``); the timings are interleaved (every repeat
runs every variant and thread count, the variants' order rotated). The table gives the median
camera samples (hits and misses) per second: per CPU second of the launching thread on one
thread, and per second of wall clock on each ``--threads``; the ratios to ``scalar`` in the
same run; the image's agreement with ``scalar``'s (same random numbers: the same values up to
float rounding); instruction counts of the compiled object (:mod:`benchmarks.lanes_codegen`).
``--breakdown``: those variants also stopped after the setup and after the environment sample
(ns per sample per stage). ``--remarks``: LLVM's loop-vectorizer remarks for one variant, by
Warp source line. Every kernel has the render kernels' module options
(:func:`warp_rbrdf.shipped_kernels.render_module_options`: ``-target-cpu`` of the CPU's ISA
level, x86-64-v4 with AVX-512, else x86-64-v3; ``--target-cpu`` picks another).

``--quick``: 32 px, 16 spp, ``loop K=4``, ``hybrid K=4``, the guide variants and ``wavefront``,
1 thread, 1 repeat (the smoke test). Needs ``$RBRDF_DATA`` (``rgl/<material>.bsdf``, ``envmaps/<map>.hdr``)
and, for the instruction counts, ``objdump``.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shlex
import statistics
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.lanes_codegen import instruction_counts, object_file, vectorizer_remarks

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("RBRDF_DATA", ROOT.parent / "shared" / "data"))
TILE = 16
FOV_Y_DEG = 30.0


# --------------------------------------------------------------------------------------------
# scene data
def env_distribution(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(marg (H + 1), cond (H (W + 1))) float32 CDFs of the H x W texel cells weighted by
    luminance x sin(theta) of the row's centre (a row of no mass gets a uniform conditional)."""
    H, W = image.shape[:2]
    lum = np.maximum(image[..., :3].astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722]), 0.0)
    w = lum * np.sin(np.pi * (np.arange(H) + 0.5) / H)[:, None]
    rows = w.sum(1)
    cond = np.zeros((H, W + 1))
    cond[:, 1:] = np.cumsum(np.where(rows[:, None] > 0, w, 1.0), 1)
    cond /= cond[:, -1:]
    marg = np.concatenate([[0.0], np.cumsum(rows)]) / rows.sum()
    cond[:, -1] = 1.0
    marg[-1] = 1.0
    return marg.astype(np.float32), cond.astype(np.float32).ravel()


def load_scene(material: Path, envmap: Path):
    """``(tables, materials, env, guides)``: the lane kernels'
    :class:`~benchmarks.lanes_scene.Tables`, the production
    :class:`~warp_rbrdf.materials.data.Materials` of the same material (index 0), the map's
    :class:`~benchmarks.lanes_scene.Env` and the guide tables of both
    (:class:`~benchmarks.lanes_guides.Guides`)."""
    import warp as wp

    from benchmarks import lanes_scene as S
    from benchmarks.lanes_guides import make_guides
    from fit.formats.rgl import read_rgl
    from warp_rbrdf.image_io import read_image
    from warp_rbrdf.materials import rgl as R
    from warp_rbrdf.materials.data import Materials
    from warp_rbrdf.registry import material as kind_of

    floats, header = R.pack(read_rgl(material))
    h = header(0)
    if h[R.RGL_N_THETA] < 2 or h[R.RGL_JACOBIAN] != 1 or h[R.RGL_VIEW_INCIDENT] != 1:
        raise SystemExit(f"{material.name}: the prototype needs >= 2 theta_i slices, the Jacobian "
                         f"and the view as incident direction")
    f = wp.array(floats, dtype=float)
    tb = S.Tables()
    tb.f = f
    names = ("n_theta theta vndf_ny vndf_nx vndf_data vndf_cond vndf_marg lum_ny lum_nx lum_data lum_cond "
             "lum_marg rgb ndf_ny ndf_nx ndf sigma_ny sigma_nx sigma").split()
    for i, name in enumerate(names):
        setattr(tb, name, int(h[i]))
    m = Materials()
    ints = {"kind": [kind_of("rgl").code], "technique": [0], "combine": [0], "offset": [0], "param": [0],
            "rgl_i": h, "cdf_row_ok": [0], "cdf_info": [0], "coef_i": [0], "cdf_gi": [0]}
    for name, v in ints.items():
        setattr(m, name, wp.array(np.asarray(v, np.int32), dtype=int))
    m.scale = wp.array(np.ones((1, 3), np.float32), dtype=wp.vec3)
    m.tables = wp.zeros(1, dtype=wp.vec3)
    m.rgl_f = f
    for name in ("cdf_t", "cdf_p", "cdf_pw"):
        setattr(m, name, wp.zeros(1, dtype=float))
    m.coef_f = wp.zeros(1, dtype=wp.float64)
    m.cdf_gf = wp.zeros(1, dtype=wp.float64)
    m.coef_q = wp.zeros(1, dtype=Materials.vars["coef_q"].type.dtype)
    m.cdf_gq = wp.zeros(1, dtype=wp.vec2d)
    image = read_image(envmap)
    marg, cond = env_distribution(image)
    env = S.Env()
    env.rgb = wp.array(np.ascontiguousarray(image[..., :3], np.float32).ravel(), dtype=float)
    env.marg = wp.array(marg, dtype=float)
    env.cond = wp.array(cond, dtype=float)
    env.h, env.w = image.shape[:2]
    return tb, m, env, make_guides(floats, h, marg, cond, env.h, env.w, R)


# --------------------------------------------------------------------------------------------
# variants
#: lane variants: (Warp unrolls the lane loops, branches around the per-lane shading, the
#: compiler flags from the render kernels'): Warp-unrolled, as loops, as loops with the
#: scalar kernel's branches in the shading, as loops with LLVM allowed to emit gathers
#: (``fast-gather``: an x86-64-v3 target has none), Warp-unrolled with LLVM's default SLP
#: depth (the render kernels' flags limit it to 4)
KINDS = {
    "lanes": (True, False, lambda f: f),
    "loop": (False, False, lambda f: f),
    "hybrid": (False, True, lambda f: f),
    "gather": (False, False, lambda f: f + " -target-feature +fast-gather"),
    "slp": (True, False, lambda f: f.replace("-slp-recursion-max-depth=4", "-slp-recursion-max-depth=12")),
}
#: the kinds run by default
DEFAULT_KINDS = ("lanes", "loop", "hybrid", "gather")


def variant_names(lanes, kinds, guided: bool = False, wavefront: bool = False) -> list[str]:
    return (["scalar"] + [f"{kind} K={k}" for kind in kinds for k in lanes if kind == "lanes" or k > 1]
            + (["unguided", "guided"] if guided else []) + (["wavefront"] if wavefront else []))


def build(name: str, stages: int = 3, extra_flags: str = "", target_cpu: str | None = None):
    """The kernel of variant ``name`` with the render kernels' module options (``stages``:
    the cost breakdown's early stop, :func:`benchmarks.lanes_kernels.make_scalar_kernel`;
    ``extra_flags`` appended to the compiler flags; ``target_cpu``: LLVM's CPU in place of the
    render kernels' ISA level on this CPU, e.g. ``x86-64-v3`` or ``x86-64-v4``)."""
    from benchmarks import lanes_kernels as LK
    from warp_rbrdf.shipped_kernels import render_module_options

    opts = render_module_options()
    opts["cpu_compiler_flags"] = opts.get("cpu_compiler_flags", "") + extra_flags
    if target_cpu:
        base = re.sub(r"-target-cpu \S+\s*", "", opts["cpu_compiler_flags"])
        opts["cpu_compiler_flags"] = f"-target-cpu {target_cpu} {base}".strip()
    if name == "scalar":
        return LK.make_scalar_kernel(opts, stages)
    if name == "wavefront":
        from benchmarks.lanes_wavefront import WavefrontRenderer

        return WavefrontRenderer(opts, TILE)
    if name in ("guided", "unguided"):
        from benchmarks.lanes_guides import make_guided_kernel

        return make_guided_kernel(opts, stages, name == "guided")
    kind, k = name.split(" K=")
    k = int(k)
    unroll, branchy, flags = KINDS[kind]
    opts["max_unroll"] = max(k, 16) if unroll else 0
    opts["cpu_compiler_flags"] = flags(opts["cpu_compiler_flags"])
    return LK.make_lane_kernel(k, opts, stages, branchy)


def render(kernel, first_arg, env, view, threads: int, extra=()) -> np.ndarray:
    """(res, res, 3) image of one variant: 16-px tiles on ``threads`` threads (``extra``: the
    kernel's arguments after the image)."""
    import warp as wp

    res = view.res
    out = wp.zeros(res * res, dtype=wp.vec3)
    tiles = [(x, y, min(TILE, res - x), min(TILE, res - y)) for y in range(0, res, TILE) for x in range(0, res, TILE)]

    def one(t):
        if hasattr(kernel, "launch"):     # a variant of several kernels (wavefront)
            kernel.launch(first_arg, env, view, t[0], t[1], t[2], t[3], out)
            return
        wp.launch(kernel, dim=t[2] * t[3], inputs=[first_arg, env, view, t[0], t[1], t[2]],
                  outputs=[out, *extra])

    if threads <= 1:
        for t in tiles:
            one(t)
    else:
        with ThreadPoolExecutor(max_workers=threads) as ex:
            list(ex.map(one, tiles))
    wp.synchronize()
    return out.numpy().reshape(res, res, 3)


def agreement(img: np.ndarray, ref: np.ndarray) -> dict:
    """How one image differs from the reference rendered with the same random numbers."""
    scale = float(np.mean(ref))
    d = np.abs(img - ref)
    return {"mean_rel": float(d.mean() / scale), "max_rel": float(d.max() / scale),
            "pixels_off": int(np.count_nonzero(d.max(-1) > 1e-4 * scale)),
            "image_mean_ratio": float(np.mean(img) / scale)}


# --------------------------------------------------------------------------------------------
def machine() -> dict:
    import warp as wp

    cpu = ""
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                   if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "warp": wp.config.version,
            "date": time.strftime("%Y-%m-%d %H:%M")}


def timed_render(kernel, first_arg, env, view, threads: int, extra=()) -> tuple[np.ndarray, float, float]:
    """``(image, wall s, cpu s)``; the CPU time is the calling thread's, which runs every
    launch when ``threads`` is 1 (unlike the wall clock, it leaves out the other processes'
    share of a loaded machine)."""
    w0, c0 = time.perf_counter(), time.thread_time()
    img = render(kernel, first_arg, env, view, threads, extra)
    return img, time.perf_counter() - w0, time.thread_time() - c0


def run(a) -> dict:
    from benchmarks.lanes_scene import View
    from warp_rbrdf.runtime import init_warp

    init_warp().set_device("cpu")   # a CPU study: its arrays and launches on the CPU whatever the machine has
    tb, mats, env, guides = load_scene(DATA / "rgl" / f"{a.material}.bsdf", DATA / "envmaps" / f"{a.envmap}.hdr")
    if any(a.spp % k for k in a.lanes):
        raise SystemExit(f"--spp {a.spp} must be a multiple of every K")
    view = View()
    view.res, view.spp, view.seed = a.resolution, a.spp, 7
    view.tan_half = float(np.tan(np.radians(FOV_Y_DEG / 2)))

    def args(name):
        """A variant's launch arguments: ((tables, map, view), arguments after the image)."""
        return ({"scalar": mats, "wavefront": mats}.get(name, tb), env, view), (guides,) if name.endswith("guided") else ()

    names = variant_names(a.lanes, a.kinds, not a.no_guided, a.wavefront)
    # (variant, stages): the full kernels, and the early stops of the breakdown
    jobs = [(n, 3) for n in names] + [(n, st) for n in (a.breakdown or []) for st in (1, 2)]
    kernels, compile_s, ref = {}, {}, None
    for job in jobs:
        t0 = time.perf_counter()
        kernels[job] = build(*job, target_cpu=a.target_cpu)
        first, extra = args(job[0])
        img = render(kernels[job], *first, 1, extra)   # compiles, warms up
        compile_s[job] = time.perf_counter() - t0
        print(f"{job[0]} (stages {job[1]}): compiled and rendered in {compile_s[job]:.1f} s", file=sys.stderr,
              flush=True)
        if job == ("scalar", 3):
            ref = img
    load_before = os.getloadavg()
    wall = {(j, t): [] for j in jobs for t in a.threads}
    stage_cpu = {}
    cpu = {j: [] for j in jobs}
    images = {}
    for rep in range(a.repeats):
        order = jobs[rep % len(jobs):] + jobs[:rep % len(jobs)]
        for job in order:
            for th in (a.threads if job[1] == 3 else [1]):
                first, extra = args(job[0])
                stages_before = dict(getattr(kernels[job], "stage_seconds", {}))
                img, w, c = timed_render(kernels[job], *first, th, extra)
                wall[job, th].append(w)
                if th == 1:
                    cpu[job].append(c)
                    for k, v in getattr(kernels[job], "stage_seconds", {}).items():   # the wavefront's stages
                        stage_cpu[k] = stage_cpu.get(k, 0.0) + v - stages_before[k]
                images[job] = img
    n = a.resolution ** 2 * a.spp
    rows = []
    for name in names:
        job = (name, 3)
        rate = {th: n / statistics.median(wall[job, th]) for th in a.threads}
        base = {th: n / statistics.median(wall[("scalar", 3), th]) for th in a.threads}
        row = {"variant": name, "samples_per_s": rate, "ratio": {th: rate[th] / base[th] for th in a.threads},
               "agreement": agreement(images[job], ref), "compile_s": compile_s[job],
               "counts": {} if name == "wavefront" else instruction_counts(object_file(kernels[job]))}
        if cpu[job]:
            row["cpu_samples_per_s"] = n / statistics.median(cpu[job])
            row["cpu_ratio"] = statistics.median(cpu[("scalar", 3)]) / statistics.median(cpu[job])
        rows.append(row)
    breakdown = {name: [statistics.median(cpu[name, st]) / n * 1e9 for st in (1, 2, 3)]
                 for name in (a.breakdown or []) if cpu[name, 1]}
    # the wavefront's stages: CPU ns per camera sample of its one-thread renders
    breakdown_wf = {k: v / (a.repeats * n) * 1e9 for k, v in stage_cpu.items()}
    return {"machine": machine(), "load": [load_before, os.getloadavg()],
            "command": "python -m benchmarks.lanes_prototype " + shlex.join(a.argv or []),
            "settings": {"material": a.material, "envmap": a.envmap, "resolution": a.resolution, "spp": a.spp,
                         "repeats": a.repeats, "threads": a.threads, "target_cpu": a.target_cpu},
            "rows": rows, "breakdown_ns": breakdown, "wavefront_stage_ns": breakdown_wf,
            "image_mean": float(ref.mean())}


def table(res: dict) -> str:
    """The results as a Markdown table (rates in millions of camera samples per second)."""
    th = res["settings"]["threads"]
    head = (["variant", "M/s per CPU s, 1 thr", "ratio"] + [f"M/s wall, {t} thr" for t in th]
            + [f"ratio, {t} thr" for t in th]
            + ["ymm / zmm", "packed ps (ymm / zmm)", "gathers", "scalar ss", "image vs scalar (mean / max rel.)"])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in res["rows"]:
        c = r["counts"]
        g = r["agreement"]
        cells = ([r["variant"], f"{r.get('cpu_samples_per_s', 0) / 1e6:.2f}", f"{r.get('cpu_ratio', 0):.2f}"]
                 + [f"{r['samples_per_s'][t] / 1e6:.2f}" for t in th]
                 + [f"{r['ratio'][t]:.2f}" for t in th]
                 + [f"{c.get('ymm', '-')} / {c.get('zmm', '-')}",
                    f"{c.get('packed_ps', '-')} ({c.get('packed_ps_ymm', '-')} / {c.get('packed_ps_zmm', '-')})",
                    str(c.get("gathers", "-")), str(c.get("scalar_ss", "-")),
                    f"{g['mean_rel']:.1e} / {g['max_rel']:.1e}"])
        lines.append("| " + " | ".join(cells) + " |")
    if res.get("wavefront_stage_ns"):
        w = res["wavefront_stage_ns"]
        lines += ["", "wavefront stages, CPU ns per camera sample (one thread): "
                  + ", ".join(f"{k} {v:.0f}" for k, v in w.items()) + f"; total {sum(w.values()):.0f}"]
    if res["breakdown_ns"]:
        lines += ["", "| variant | camera, hit, frame (ns/sample) | + environment sample | + BSDF sample (all) |",
                  "|---|---|---|---|"]
        for name, v in res["breakdown_ns"].items():
            lines.append(f"| {name} | {v[0]:.0f} | {v[1] - v[0]:+.0f} | {v[2] - v[1]:+.0f} ({v[2]:.0f}) |")
    return "\n".join(lines)


def print_remarks(a) -> int:
    """``--remarks``: the loop vectorizer's decisions for one variant, by Warp source line."""
    from benchmarks.lanes_scene import View
    from warp_rbrdf.runtime import init_warp

    init_warp().set_device("cpu")   # a CPU study: its arrays and launches on the CPU whatever the machine has
    tb, mats, env, guides = load_scene(DATA / "rgl" / f"{a.material}.bsdf", DATA / "envmaps" / f"{a.envmap}.hdr")
    view = View()
    view.res, view.spp, view.seed, view.tan_half = 16, 16, 7, float(np.tan(np.radians(FOV_Y_DEG / 2)))
    first = (mats if a.remarks == "scalar" else tb, env, view)
    extra = (guides,) if a.remarks.endswith("guided") else ()
    remarks = vectorizer_remarks(lambda flags: build(a.remarks, 3, flags),
                                 lambda k: render(k, *first, 1, extra))
    for (where, msg), count in sorted(remarks.items()):
        print(f"{count:3d}  {where}: {msg}")
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.lanes_prototype",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="32 px, 16 spp, loop and hybrid K = 4, 1 thread, 1 repeat")
    p.add_argument("--material", default="cc_ibiza_sunset_rgb")
    p.add_argument("--envmap", default="studio_small_03_1k")
    p.add_argument("--resolution", type=int, default=128)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--lanes", type=int, nargs="+", default=[1, 4, 8, 16])
    p.add_argument("--kinds", nargs="+", choices=list(KINDS), default=list(DEFAULT_KINDS),
                   help="lane variants: Warp-unrolled, loop, loop with branches, loop with gathers, "
                        "Warp-unrolled with LLVM's default SLP depth")
    p.add_argument("--no-guided", action="store_true", help="leave out the guide-table variants")
    p.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    p.add_argument("--breakdown", nargs="*", metavar="VARIANT",
                   help="variants (e.g. scalar 'hybrid K=16') also timed stopped after each stage")
    p.add_argument("--remarks", metavar="VARIANT",
                   help="compile VARIANT (e.g. 'loop K=8') with the loop vectorizer's remarks, print them, exit")
    p.add_argument("--target-cpu", dest="target_cpu", default=None, metavar="CPU",
                   help="LLVM target CPU of every variant in place of the render kernels' ISA level on "
                        "this CPU (e.g. x86-64-v3, or x86-64-v4 or znver4: AVX-512; the machine must run it)")
    p.add_argument("--wavefront", action="store_true",
                   help="also the wavefront variant: the scalar kernel's stages as kernels over a tile's samples")
    p.add_argument("--json", type=Path)
    a = p.parse_args(argv)
    a.argv = list(sys.argv[1:] if argv is None else argv)
    if a.quick:
        a.resolution, a.spp, a.lanes, a.threads, a.repeats = 32, 16, [4], [1], 1
        a.kinds, a.breakdown, a.no_guided, a.wavefront = ["loop", "hybrid"], [], False, True
    if a.remarks:
        return print_remarks(a)
    res = run(a)
    m = res["machine"]
    print(f"{m['cpu']} ({m['cores']} cores), warp {m['warp']}, {m['date']}, "
          f"load {res['load'][0][0]:.1f} -> {res['load'][1][0]:.1f}")
    print(table(res))
    if a.json:
        a.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
