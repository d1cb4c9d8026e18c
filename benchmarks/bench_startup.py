"""Benchmark: start-up of ``rbrdf render`` with a rational material sampled by ``mis-rational``
(fits and inverse-CDF files are data, so a new one compiles nothing), against
a baseline revision of the renderer (default: the last one that generated code per fit).

Each run is one ``python -m warp_rbrdf render`` process (what a user pays: Python and Warp
start-up, scene setup, compile or kernel-cache load, a small render), timed from outside (wall
and CPU seconds), with the renderer's own setup / compile lines parsed. Per repeat and per
variant (this checkout; this checkout compiling Warp's backward passes too, as before the
renderer turned them off; the baseline; interleaved), with a fresh, empty kernel cache
(``WARP_CACHE_PATH``):

1. ``cold``: the scene, empty cache;
2. ``warm``: the same scene again;
3. ``new fit``: another rational fit (with its own CDF file), same cache;
4. ``new CDF file``: the first fit with another pieces-layout CDF file, same cache;
5. ``new global CDF`` (not with ``--quick``): the second fit with a global-layout CDF file (the
   paper's fitted F and G: the layout the baseline generated code for), same cache;

and, first, ``default job cold``: the README's main job ``rbrdf render --out X`` (the embedded
default scene: a rational sphere sampled with ``mis-tabulated``, 256x256, 16 spp) with its own
empty kernel cache; this tree takes the default scene's render kernel from the shipped
ahead-of-time set (``warp_rbrdf.shipped_kernels``); the variant ``no shipped`` (this tree with
``RBRDF_SHIPPED_KERNELS=""``) compiles it. ``--default-only``: only this step (and ``default
job warm``, the same job again on that cache), for this tree, ``no shipped`` and the baseline.

Then, on warm caches, interleaved: samples per second of a larger render of the scene (and the
largest pixel difference between the two trees' images: same seed, so 0 when the evaluation
and sampling give the same floats), and the time per call of the material's Warp evaluation and
BSDF sample (``Renderer.eval_material`` / ``sample_material``, one thread). Medians over ``--repeats``. The fits are the two shipped
coefficient files (``warp_rbrdf/data``); their CDF files are fitted once into the work folder
(not timed). The baseline is exported with ``git archive`` (needs this git checkout).

``--isa-levels``: instead, samples/s of the default scene (256x256, 16 spp) and of the RGL
reference sphere (satin_purple under studio_small_03, 128x128, 64 spp) with the render kernel
compiled with ``-march=native`` (Warp's default), ``-target-cpu`` each level of
``warp_rbrdf.shipped_kernels.ISA_LEVELS`` this CPU runs (x86-64-v4, x86-64-v3: the shipped
objects) and ``x86-64-v2``; one process, 2 threads,
interleaved (the order reversed every other repeat), medians of ``--repeats`` (default 5), and the largest pixel difference to native.

    python -m benchmarks.bench_startup [--quick | --default-only | --isa-levels] [--repeats 3]
                                       [--baseline 81db95c | none]
                                       [--no-adjoints] [--resolution 256] [--spp 32] [--work DIR]

Prints a table and a JSON line. The machine is shared: compare the two trees' medians within
one run, never across runs.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE = "81db95c"   # the last revision with generated, unrolled code per fit and per global CDF

SCENE = """[camera]
origin = [0.0, 1.6, 4.2]
target = [0.0, 0.8, 0.0]
fov = 35.0
resolution = [64, 64]

[integrator]
spp = 4
sampler = "mis"

[materials.coat]
type = "rational"
file = "{fit}"
sampler = "mis-rational"
cdf = "{cdf}"

[materials.floor]
type = "lambert"
albedo = 0.45

[[shapes]]
type = "sphere"
center = [0.0, 0.8, 0.0]
radius = 0.8
material = "coat"

[[shapes]]
type = "plane"
size = [8.0, 8.0]
material = "floor"

[[lights]]
type = "sky"
sun_elevation = 40.0
sun_azimuth = 140.0
"""

# ``rbrdf render`` with Warp's default of compiling backward passes (the "adjoints" variant)
ADJOINTS = """
import sys
from warp_rbrdf.runtime import init_warp
init_warp().config.enable_backward = True
from warp_rbrdf.cli import main
sys.exit(main(sys.argv[1:]))
"""

# timed in a subprocess of each tree: eval / sample per call (ns), one thread, warm cache
MICRO = """
import json, sys, time
import numpy as np
from fit.formats.angles import spherical_to_direction
from warp_rbrdf import load_scene
from warp_rbrdf.renderer import Renderer
r = Renderer(load_scene(sys.argv[1]), device="cpu")
n, reps = int(sys.argv[2]), int(sys.argv[3])
rng = np.random.default_rng(0)
wi = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
wo = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
xi = rng.random((n, 2))
out = {}
for name, call in (("eval_ns", lambda: r.eval_material("coat", wi, wo)),
                   ("sample_ns", lambda: r.sample_material("coat", wo, xi))):
    call()
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter(); call(); ts.append(time.perf_counter() - t0)
    out[name] = float(np.median(ts)) / n * 1e9
print("MICRO " + json.dumps(out))
"""


def export_baseline(rev: str, dest: Path) -> Path:
    """The tree of revision ``rev`` of this checkout, exported into ``dest``."""
    dest.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], capture_output=True)
    if archive.returncode != 0:
        raise SystemExit(f"bench_startup: cannot export baseline {rev!r}: {archive.stderr.decode().strip()} "
                         f"(use --baseline none)")
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive.stdout, check=True)
    return dest


def prepare(work: Path, quick: bool) -> dict:
    """Scene files in ``work``: ``a`` (satin fit + pieces CDF), ``b`` (paper fit + its pieces
    CDF), ``a2`` (satin fit + another pieces CDF) and, unless ``quick``, ``bg`` (paper fit +
    a global-layout CDF; None if its fit falls back)."""
    from fit.rational.coefficient_file import load as load_fit
    from fit.sampling.cdf_file import fit_cdf

    data = ROOT / "warp_rbrdf" / "data"
    fits = {"a": data / "satin_rosaline_rgb.json", "b": data / "paper_white_rgb.json"}
    small = dict(n_v=8, n_t=32, n_p=32)
    params = {"a": small if quick else {}, "a2": dict(n_v=12, n_t=48, n_p=48), "b": small if quick else {}}
    scenes = {}
    for key, tp in params.items():
        fit = fits[key[0]]
        cdf_path = work / f"cdf_{key}.json"
        if not cdf_path.exists():
            c = fit_cdf(load_fit(fit).evaluate, name=key, table_params=tp)
            c.save(cdf_path)
        scenes[key] = work / f"scene_{key}.toml"
        scenes[key].write_text(SCENE.format(fit=fit.as_posix(), cdf=cdf_path.as_posix()))
    if not quick:
        cdf_path = work / "cdf_bg.json"
        if not cdf_path.exists():
            c = fit_cdf(load_fit(fits["b"]).evaluate, name="bg", table_params=small, phi_kw=dict(degrees=(2, 1)),
                        refinements=0, layout="global", time_limit_s=120.0)
            c.save(cdf_path)
        from fit.sampling.cdf_file import load as load_cdf

        scenes["bg"] = None
        if not load_cdf(cdf_path).fallback:
            scenes["bg"] = work / "scene_bg.toml"
            scenes["bg"].write_text(SCENE.format(fit=fits["b"].as_posix(), cdf=cdf_path.as_posix()))
    return scenes


def _num(pattern: str, text: str):
    m = re.search(pattern, text)
    return float(m.group(1)) if m else None


def render_run(tree: Path, scene: Path, cache: Path, out: Path, extra=(), adjoints=False, env=None) -> dict:
    """One ``rbrdf render`` process of ``tree``: wall and CPU time (user + system: less
    sensitive than wall time to the other processes of a shared machine) and the renderer's own
    lines. ``adjoints``: compile the kernels' backward passes too (Warp's default; the
    renderer turns them off)."""
    env = dict(os.environ, WARP_CACHE_PATH=str(cache), PYTHONPATH=str(tree), **(env or {}))
    args = ["render", *([] if scene is None else [str(scene)]), "--no-progress", "--out", str(out), *extra]
    cmd = [sys.executable, "-c", ADJOINTS, *args] if adjoints else [sys.executable, "-m", "warp_rbrdf", *args]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise SystemExit(f"bench_startup: render failed in {tree}:\n{p.stdout}\n{p.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return {"wall_s": wall, "cpu_s": cpu, "setup_s": _num(r"setup\s+([\d.]+) s", p.stdout),
            "compile_s": _num(r"compile\s+([\d.]+) s", p.stdout),
            "msamples_per_s": _num(r"([\d.]+) M samples/s", p.stdout)}


def micro_run(tree: Path, scene: Path, cache: Path, n: int, reps: int) -> dict:
    env = dict(os.environ, WARP_CACHE_PATH=str(cache), PYTHONPATH=str(tree))
    p = subprocess.run([sys.executable, "-c", MICRO, str(scene), str(n), str(reps)], cwd=tree, env=env,
                       capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"bench_startup: micro-benchmark failed in {tree}:\n{p.stdout}\n{p.stderr}")
    return json.loads(p.stdout.split("MICRO ", 1)[1])


def _median(rows, key):
    vals = [r[key] for r in rows if r.get(key) is not None]
    return statistics.median(vals) if vals else None


def isa_levels(repeats: int) -> dict:
    """Samples/s of the render kernel compiled for ISA levels (see the module docstring)."""
    import numpy as np

    from benchmarks.bench_render import reference_scene
    from warp_rbrdf import Renderer
    from warp_rbrdf.defaults import default_scene
    from warp_rbrdf.runtime import init_warp
    from warp_rbrdf.shipped_kernels import ISA_LEVELS, cpu_supports_isa, portable_cpu_flags

    init_warp()
    tail = portable_cpu_flags().split(" ", 2)[2]
    variants = {"native": f"-march=native {tail}",
                **{lv: portable_cpu_flags(lv) for lv in ISA_LEVELS if cpu_supports_isa(lv)},
                "x86-64-v2": f"-target-cpu x86-64-v2 {tail}"}
    scenes = {"default": (default_scene, 16),
              "rgl sphere": (lambda: reference_scene("satin_purple_rgb", "studio_small_03_1k", 128, 64), 64)}
    from warp_rbrdf import integrator

    rs = {}
    own = integrator.render_module_options
    try:
        for sn, (make, _) in scenes.items():
            for vn, flags in variants.items():
                # the kernels take their options when they are made (module_options): each
                # variant's Renderer is made with its flags
                integrator.render_module_options = lambda f=flags: {**own(), "cpu_compiler_flags": f}
                r = Renderer(make(), device="cpu")
                if r.kernels.render_tile.module.options.get("cpu_compiler_flags") != flags:
                    raise RuntimeError(f"{vn}: the render kernel was not made with its flags")
                r.compile()
                r.render(spp=1, threads=2)
                rs[sn, vn] = r
    finally:
        integrator.render_module_options = own
    rates, imgs = {k: [] for k in rs}, {}
    for i in range(repeats):
        order = list(rs.items())
        for (sn, vn), r in (order if i % 2 == 0 else order[::-1]):   # alternate: no fixed position
            imgs[sn, vn] = r.render(spp=scenes[sn][1], seed=0, threads=2)
            rates[sn, vn].append(r.stats.samples / r.stats.render_seconds / 1e6)
    out = {"repeats": repeats, "load_average": os.getloadavg(), "rows": []}
    for sn in scenes:
        ref = statistics.median(rates[sn, "native"])
        for vn in variants:
            med = statistics.median(rates[sn, vn])
            # per repeat, against the native render of the same round (close in time)
            paired = statistics.median(x / y for x, y in zip(rates[sn, vn], rates[sn, "native"]))
            diff = float(np.abs(imgs[sn, vn] - imgs[sn, "native"]).max())
            out["rows"].append({"scene": sn, "isa": vn, "msamples_per_s": med, "ratio": med / ref,
                                "paired_ratio": paired, "max_pixel_difference": diff})
            print(f"{sn:11s} {vn:10s} {med:.3f} M samples/s, {med / ref:.3f}x native (median of per-round "
                  f"ratios {paired:.3f}), largest pixel difference {diff:.3g}")
    print(f"load average: {' '.join(f'{x:.1f}' for x in os.getloadavg())} ({os.cpu_count()} cores)")
    print(json.dumps(out))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_startup", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="one repeat, small CDF tables, no global CDF, no "
                                                        "adjoints variant, small throughput render")
    ap.add_argument("--repeats", type=int, help="default 3 (1 with --quick)")
    ap.add_argument("--baseline", default=BASELINE, help=f"git revision to compare with (default {BASELINE}, "
                                                         f"the last with generated code); 'none': this tree only")
    ap.add_argument("--no-adjoints", action="store_true", help="skip the variant of this tree that compiles "
                                                               "backward passes (Warp's default)")
    ap.add_argument("--default-only", action="store_true", help="only the README main job, cold and warm: this "
                                                                 "tree, without shipped kernels, the baseline")
    ap.add_argument("--isa-levels", action="store_true", help="only the samples/s of the render kernel compiled "
                                                               "for native, x86-64-v3 and x86-64-v2")
    ap.add_argument("--resolution", type=int, default=256, help="throughput render (default 256)")
    ap.add_argument("--spp", type=int, default=32, help="throughput render (default 32)")
    ap.add_argument("--work", help="work folder (default: a temporary one, removed)")
    a = ap.parse_args(argv)
    if a.isa_levels:
        return isa_levels(a.repeats or 5)
    repeats = a.repeats or (1 if a.quick else 3)
    res, spp = (64, 4) if a.quick else (a.resolution, a.spp)

    tmp = None if a.work else tempfile.mkdtemp(prefix="bench_startup_")
    work = Path(a.work or tmp)
    work.mkdir(parents=True, exist_ok=True)
    try:
        variants = {"current": (ROOT, False)}
        envs = {}
        if a.default_only:
            variants["no shipped"] = (ROOT, False)
            envs["no shipped"] = {"RBRDF_SHIPPED_KERNELS": ""}
        elif not (a.quick or a.no_adjoints):
            variants["adjoints"] = (ROOT, True)
        if a.baseline.lower() != "none":
            variants["baseline"] = (export_baseline(a.baseline, work / "baseline"), False)
        first = [("default job cold", "default")]
        if a.default_only:
            scenes, steps = {}, [("default job warm", "default")]
        else:
            scenes = prepare(work, a.quick)
            steps = [("cold", "a"), ("warm", "a"), ("new fit", "b"), ("new CDF file", "a2")]
        scenes["default"] = None   # the README's main job: the embedded default scene
        if scenes.get("bg") is not None:
            steps.append(("new global CDF", "bg"))
        steps = first + steps
        runs = {v: {s: [] for s, _ in steps} for v in variants}
        for r in range(repeats):
            for v, (tree, adj) in variants.items():
                cache = work / f"cache_{v}_{r}"
                shutil.rmtree(cache, ignore_errors=True)
                for step, key in first:   # its own empty kernel cache
                    dcache = work / f"cache_default_{v}_{r}"
                    shutil.rmtree(dcache, ignore_errors=True)
                    runs[v][step].append(render_run(tree, None, dcache, work / f"out_{v}.exr", adjoints=adj,
                                                    env=envs.get(v)))
                    if a.default_only:
                        cache = dcache
                for step, key in steps[len(first):]:
                    runs[v][step].append(render_run(tree, scenes[key], cache, work / f"out_{v}.exr", adjoints=adj,
                                                    env=envs.get(v)))
        # throughput and per-call costs on warm caches (the last repeat's)
        thr = {} if a.default_only else {v: [] for v in variants if v not in ("adjoints", "no shipped")}
        micro = {v: [] for v in thr}
        for _ in range(repeats):
            for v in thr:
                tree = variants[v][0]
                cache = work / f"cache_{v}_{repeats - 1}"
                thr[v].append(render_run(tree, scenes["a"], cache, work / f"thr_{v}.exr",
                                         ("--resolution", str(res), str(res), "--spp", str(spp))))
                micro[v].append(micro_run(tree, scenes["a"], cache, 20000 if a.quick else 100000, 5))
        out = {"repeats": repeats, "baseline": a.baseline, "cpu_count": os.cpu_count(),
               "load_average": os.getloadavg(), "throughput_render": {"resolution": res, "spp": spp},
               "variants": {}}
        print(f"rbrdf render, medians of {repeats}: seconds of wall time / CPU time of the whole process / "
              f"compile as the renderer prints it")
        print(f"{'':16s}" + "".join(f"{v:>26s}" for v in variants))
        for step, _ in steps:
            line = f"{step:16s}"
            for v in variants:
                rows = runs[v][step]
                line += (f"{_median(rows, 'wall_s'):>10.2f} /{_median(rows, 'cpu_s'):6.2f} /"
                         f"{_median(rows, 'compile_s'):6.2f}")
            print(line)
        for v in variants:
            out["variants"][v] = {"startup": {step: {k: _median(runs[v][step], k)
                                                     for k in ("wall_s", "cpu_s", "setup_s", "compile_s")}
                                              for step, _ in steps}}
        for v in thr:
            o = out["variants"][v]
            o.update(msamples_per_s=_median(thr[v], "msamples_per_s"), eval_ns=_median(micro[v], "eval_ns"),
                     sample_ns=_median(micro[v], "sample_ns"))
            print(f"{v:9s} throughput {res}x{res} {spp} spp: {o['msamples_per_s']:.3f} M samples/s; "
                  f"eval {o['eval_ns']:.0f} ns, mis-rational sample {o['sample_ns']:.0f} ns per call (1 thread)")
        if "baseline" in thr:
            c, b = out["variants"]["current"], out["variants"]["baseline"]
            out["ratios"] = {"throughput": c["msamples_per_s"] / b["msamples_per_s"],
                             "eval": c["eval_ns"] / b["eval_ns"], "sample": c["sample_ns"] / b["sample_ns"]}
            from warp_rbrdf.image_io import read_image

            diff = float(abs(read_image(work / "thr_current.exr") - read_image(work / "thr_baseline.exr")).max())
            out["max_pixel_difference"] = diff
            print(f"current / baseline: throughput {out['ratios']['throughput']:.2f}x, eval time "
                  f"{out['ratios']['eval']:.2f}x, sample time {out['ratios']['sample']:.2f}x; largest pixel "
                  f"difference of the throughput renders {diff:.3g}")
        print(f"load average during the run: {' '.join(f'{x:.1f}' for x in os.getloadavg())} "
              f"({os.cpu_count()} cores)")
        print(json.dumps(out))
        return out
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
