"""Benchmark: shaded samples per second of the Warp renderer at 1 and 2 threads, and the rate
at which Embree (pip ``embreex``) casts the same rays on this machine.

One shaded sample (scene sampler "mis", max_depth 1) = one camera ray (closest hit) and, where it
hits a surface, one environment-sample shadow ray and one BSDF-sample ray (any-hit), plus the
material lookups, the CMJ sample generation and the environment CDF sampling.
The Embree reference casts, for the same number of samples, the same camera rays (closest hit,
``intersect``) and two occlusion rays per hit (``occluded``) with no shading at all.

    python -m benchmarks.bench_render [--scene scenes/bunny_rooitou.toml] [--resolution 128]
                                      [--spp 16] [--repeats 5]

Prints a table and a JSON line. Times are wall-clock medians over ``--repeats`` renders after
the kernels are compiled and warmed up.

Further comparisons, each interleaved render by render (the machine is shared: medians of
alternating runs, ratios measured side by side):

* ``--scene reference``: Mitsuba's reference sphere scene (:mod:`lab.mitsuba_reference`:
  unit sphere, camera at (0, 0, 4), 30 deg, hidden environment map, direct lighting with one
  environment and one BSDF sample, power heuristic) with ``--material`` (an RGL file name of
  the shared data, or ``lambert``) under ``--envmap``;
* ``--icosphere``: the same scene with its spheres tessellated (``Renderer(...,
  analytic_spheres=False)``) against the analytic spheres;
* ``--mitsuba``: Mitsuba 3's samples/s on the reference scene (its ``direct`` integrator, all
  cores), in a worker process, variant ``llvm_ad_rgb`` when a libLLVM that Mitsuba renders with
  is found (``DRJIT_LIBLLVM_PATH``, else :func:`lab.mitsuba_reference.find_libllvm`),
  else ``scalar_rgb``;
* ``--bvh``: the BVH of the scene's triangles with Warp's constructors and leaf sizes
  (1 thread, CPU time of the rendering thread).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def machine_scaling(threads=2, repeats=3):
    """Attainable speed-up of a compute-only Warp kernel launched from ``threads`` threads
    (no memory traffic, no rays): the ceiling the machine itself puts on thread scaling."""
    import warp as wp

    from warp_rbrdf.runtime import init_warp

    init_warp()

    @wp.kernel
    def busy(a: wp.array(dtype=float), n: int):
        i = wp.tid()
        s = float(0.0)
        for k in range(n):
            s = s + wp.sin(float(k) * 0.001 + s)
        a[i] = s

    arrs = [wp.zeros(256, dtype=float, device="cpu") for _ in range(threads)]
    wp.launch(busy, dim=256, inputs=[arrs[0], 1], device="cpu")
    n = 20000

    def run(i):
        wp.launch(busy, dim=256, inputs=[arrs[i], n], device="cpu")

    ratios = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for i in range(threads):
            run(i)
        serial = time.perf_counter() - t0
        with ThreadPoolExecutor(threads) as ex:
            t0 = time.perf_counter()
            list(ex.map(run, range(threads)))
            par = time.perf_counter() - t0
        ratios.append(serial / par)
    return statistics.median(ratios)


def warp_rate(renderer, spp, threads, repeats):
    renderer.render(spp=spp, threads=threads)  # warm-up
    times = []
    for i in range(repeats):
        renderer.render(spp=spp, seed=i, threads=threads)
        times.append(renderer.stats.render_seconds)
    n = renderer.stats.samples
    return n / statistics.median(times), statistics.median(times)


def _timed(renderer, spp, threads, seed):
    renderer.render(spp=spp, seed=seed, threads=threads)
    return renderer.stats.render_seconds


def embree_rays(renderer, spp, seed=0):
    """Camera rays of the scene (jittered per sample), as float32 arrays."""
    from warp_rbrdf.camera import camera_rays_numpy

    cam = renderer.scene.camera
    W, H = cam.resolution
    rng = np.random.default_rng(seed)
    py, px = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    px = (np.repeat(px.ravel(), spp) + rng.random(W * H * spp))
    py = (np.repeat(py.ravel(), spp) + rng.random(W * H * spp))
    d = camera_rays_numpy(cam, px, py).astype(np.float32)
    o = np.broadcast_to(np.asarray(cam.origin, np.float32), d.shape).copy()
    return o, d


def embree_rate(renderer, spp, threads, repeats):
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    g = renderer.geometry
    tris = g.points[g.indices.reshape(-1, 3)].astype(np.float32)
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, tris)
    o, d = embree_rays(renderer, spp)
    n = len(o)
    rng = np.random.default_rng(1)
    eps = renderer.ray_epsilon

    def chunk_run(fn, *arrays):
        if threads == 1:
            return fn(*arrays)
        parts = np.array_split(np.arange(len(arrays[0])), threads * 4)
        with ThreadPoolExecutor(threads) as ex:
            res = list(ex.map(lambda idx: fn(*(a[idx] for a in arrays)), parts))
        return res

    def one():
        t0 = time.perf_counter()
        hits = chunk_run(lambda oo, dd: scene.run(oo, dd, output=1), o, d)
        t1 = time.perf_counter()
        if isinstance(hits, list):
            tfar = np.concatenate([h["tfar"] for h in hits])
            ng = np.concatenate([h["Ng"] for h in hits])
            gid = np.concatenate([h["geomID"] for h in hits])
        else:
            tfar, ng, gid = hits["tfar"], hits["Ng"], hits["geomID"]
        hit = gid >= 0
        p = o[hit] + d[hit] * tfar[hit, None]
        nrm = ng[hit] / np.linalg.norm(ng[hit], axis=1, keepdims=True)
        nrm = np.where((np.sum(nrm * d[hit], axis=1) > 0)[:, None], -nrm, nrm).astype(np.float32)
        # two occlusion rays per hit: random upper-hemisphere directions (not timed: set-up)
        dirs = rng.normal(size=(2 * len(p), 3)).astype(np.float32)
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        n2 = np.repeat(nrm, 2, axis=0)
        dirs = np.where((np.sum(dirs * n2, axis=1) < 0)[:, None], -dirs, dirs)
        org = (np.repeat(p, 2, axis=0) + n2 * eps * 10).astype(np.float32)
        t2 = time.perf_counter()
        chunk_run(lambda oo, dd: scene.run(oo, dd, query="OCCLUDED"), org, dirs)
        t3 = time.perf_counter()
        return (t1 - t0) + (t3 - t2), int(hit.sum())

    one()
    res = [one() for _ in range(repeats)]
    t = statistics.median(r[0] for r in res)
    rays = n + 2 * res[0][1]
    return n / t, t, rays / t

DATA = Path(os.environ.get("RBRDF_DATA", ROOT.parent / "shared" / "data"))


def reference_scene(material, envmap, resolution, spp):
    """Mitsuba's reference sphere scene for our renderer (``material``: an RGL file name of the
    shared data or ``lambert``)."""
    from lab import mitsuba_reference as MR

    return MR.sphere_scene(_reference_material(material), DATA / "envmaps" / f"{envmap}.hdr", spp, resolution)


def _reference_material(material):
    if material == "lambert":
        return ("lambert", (0.5, 0.5, 0.5))
    return DATA / "rgl" / f"{material}.bsdf"


def mitsuba_worker(argv):
    """Worker process: ``--mitsuba-worker MATERIAL ENVMAP RESOLUTION SPP``; prints its variant,
    then renders once per line read (the line is the seed) and prints the seconds."""
    material, envmap, res, spp = argv[0], argv[1], int(argv[2]), int(argv[3])
    from lab import mitsuba_reference as MR

    llvm = MR.find_libllvm()      # one Mitsuba renders with (some LLVM versions abort on Dr.Jit's kernels)
    if llvm:
        os.environ["DRJIT_LIBLLVM_PATH"] = llvm

    d = MR.mitsuba_scene_dict(_reference_material(material), DATA / "envmaps" / f"{envmap}.hdr", spp, res)
    import drjit as dr
    import mitsuba as mi

    variant = "scalar_rgb"
    if llvm:
        try:
            mi.set_variant("llvm_ad_rgb")
            variant = "llvm_ad_rgb"
        except Exception:  # noqa: BLE001 - no usable LLVM: the scalar variant
            mi.set_variant("scalar_rgb")
    else:
        mi.set_variant("scalar_rgb")
    d["sensor"]["to_world"] = mi.ScalarTransform4f().look_at(
        origin=list(MR.CAMERA_ORIGIN), target=list(MR.CAMERA_TARGET), up=list(MR.CAMERA_UP))
    scene = mi.load_dict(d)

    def run(seed):
        t0 = time.perf_counter()
        img = mi.render(scene, spp=spp, seed=seed)
        dr.eval(img)
        dr.sync_thread()
        return time.perf_counter() - t0

    run(0)   # compile (llvm) and warm up
    print(f"{variant} {mi.__version__}", flush=True)
    for line in sys.stdin:
        print(run(int(line) + 1), flush=True)


class MitsubaProcess:
    def __init__(self, material, envmap, res, spp):
        import subprocess

        self.p = subprocess.Popen([sys.executable, "-m", "benchmarks.bench_render", "--mitsuba-worker",
                                   material, envmap, str(res), str(spp)], cwd=ROOT,
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.variant = self.p.stdout.readline().strip()
        if not self.variant:
            raise RuntimeError("the Mitsuba worker failed to start (is Mitsuba 3 installed?)")

    def render(self, seed):
        self.p.stdin.write(f"{seed}\n")
        self.p.stdin.flush()
        return float(self.p.stdout.readline())

    def close(self):
        self.p.stdin.close()
        self.p.wait()


def interleaved(runs, repeats, pause=0.5):
    """Median seconds of each of ``runs`` (name -> callable(seed) -> seconds), run in turn with
    ``pause`` seconds between runs (Dr.Jit's worker threads keep spinning for a while after a
    Mitsuba render and would slow down the run after it)."""
    times = {k: [] for k in runs}
    for i in range(repeats):
        for k, f in runs.items():
            time.sleep(pause)
            times[k].append(f(i))
    return {k: statistics.median(v) for k, v in times.items()}, times


def bvh_rates(scene, spp, repeats, configs=(("sah", 1), ("sah", 2), ("sah", 4), ("sah", 8),
                                            ("median", 1), ("median", 4))):
    """Samples/s (1 thread, CPU time of the rendering thread) of ``scene`` with its triangles'
    BVH built by each (constructor, leaf size), interleaved; and each build's seconds."""
    from warp_rbrdf import geometry
    from warp_rbrdf.renderer import Renderer

    r = Renderer(scene, device="cpu")
    if r.mesh is None:
        return {}
    r.compile()
    built = {}
    for c, leaf in configs:
        t0 = time.perf_counter()
        built[(c, leaf)] = (geometry.make_warp_mesh(r.geometry, r.device, c, leaf), time.perf_counter() - t0)
    sg = r.scene_geometry

    def one(mesh):
        def f(seed):
            sg.mesh = r.wp.uint64(mesh.id)
            t0 = time.thread_time()
            r.render(spp=spp, seed=seed, threads=1)
            return time.thread_time() - t0
        return f

    one(built[configs[0]][0])(99)
    med, _ = interleaved({k: one(m) for k, (m, _) in built.items()}, repeats)
    n = r.stats.samples
    return {f"{c} leaf {leaf}": {"samples_per_s": n / med[(c, leaf)], "build_s": built[(c, leaf)][1]}
            for c, leaf in configs}


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_render", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "bunny_rooitou.toml"))
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--no-embree", action="store_true")
    ap.add_argument("--material", default="cc_ibiza_sunset_rgb",
                    help="--scene reference: an RGL file name of the shared data, or lambert")
    ap.add_argument("--envmap", default="studio_small_03_1k", help="--scene reference: map name")
    ap.add_argument("--icosphere", action="store_true",
                    help="also time the scene with its spheres tessellated (interleaved)")
    ap.add_argument("--mitsuba", action="store_true",
                    help="also time Mitsuba 3 on the reference scene (interleaved)")
    ap.add_argument("--bvh", action="store_true", help="compare BVH constructors and leaf sizes")
    if argv is None:
        argv = sys.argv[1:]
    if argv and argv[0] == "--mitsuba-worker":
        return mitsuba_worker(argv[1:])
    a = ap.parse_args(argv)

    from warp_rbrdf import load_scene
    from warp_rbrdf.renderer import Renderer

    if a.scene == "reference":
        sc = reference_scene(a.material, a.envmap, a.resolution, a.spp)
    else:
        sc = load_scene(a.scene)
        sc.camera.resolution = (a.resolution, a.resolution)
    if a.mitsuba and a.scene != "reference":
        ap.error("--mitsuba needs --scene reference")
    if a.bvh:
        rates = bvh_rates(sc, a.spp, a.repeats)
        for k, v in rates.items():
            print(f"BVH {k:12s}: {v['samples_per_s'] / 1e6:7.3f} M samples/s (1 thread, CPU time), "
                  f"build {v['build_s']:.2f} s")
        print(json.dumps({"scene": str(a.scene), "bvh": rates}))
        return 0
    r = Renderer(sc, device="cpu")
    compile_s = r.compile()
    out = {"scene": str(a.scene), "resolution": a.resolution, "spp": a.spp, "repeats": a.repeats,
           "cpu_count": os.cpu_count(), "setup_s": round(r.setup_seconds, 3), "compile_s": round(compile_s, 3),
           "triangles": r.geometry.num_triangles, "spheres": r.geometry.num_spheres, "warp": {}, "embree": {}}
    if a.scene == "reference":
        out.update(material=a.material, envmap=a.envmap)
    print(f"scene {a.scene}: {a.resolution}x{a.resolution}, {a.spp} spp, {r.geometry.num_triangles} triangles, "
          f"{r.geometry.num_spheres} analytic spheres")
    print(f"setup {r.setup_seconds:.2f} s, compile {compile_s:.2f} s")
    for t in a.threads:
        rate, sec = warp_rate(r, a.spp, t, a.repeats)
        out["warp"][t] = {"samples_per_s": rate, "seconds": sec}
        print(f"warp    {t} thread(s): {rate / 1e6:7.3f} M shaded samples/s  ({sec:.3f} s)")
    if len(a.threads) >= 2:
        t0, t1 = a.threads[0], a.threads[-1]
        out["scaling"] = out["warp"][t1]["samples_per_s"] / out["warp"][t0]["samples_per_s"]
        print(f"scaling {t0} -> {t1} threads: {out['scaling']:.2f}x")
    if len(a.threads) >= 2:
        out["machine_scaling"] = machine_scaling(max(a.threads))
        print(f"machine ceiling: a compute-only Warp kernel on {max(a.threads)} threads runs "
              f"{out['machine_scaling']:.2f}x faster than serially")
    if a.icosphere or a.mitsuba:
        t = max(a.threads)
        runs = {"warp": lambda i: _timed(r, a.spp, t, i)}
        if a.icosphere:
            ri = Renderer(sc, device="cpu", analytic_spheres=False)
            ri.compile()
            ri.render(spp=a.spp, threads=t)
            runs["warp icosphere"] = lambda i: _timed(ri, a.spp, t, i)
            out["icosphere_triangles"] = ri.geometry.num_triangles
        mp = None
        if a.mitsuba:
            mp = MitsubaProcess(a.material, a.envmap, a.resolution, a.spp)
            runs[f"mitsuba {mp.variant}"] = mp.render
        try:
            med, allt = interleaved(runs, a.repeats)
        finally:
            if mp is not None:
                mp.close()
        n = r.stats.samples
        out["interleaved"] = {k: {"samples_per_s": n / v, "seconds": v, "all_s": allt[k]} for k, v in med.items()}
        print(f"interleaved, {t} threads, median of {a.repeats}:")
        for k, v in med.items():
            print(f"  {k:28s} {n / v / 1e6:7.3f} M samples/s  ({v:.3f} s)  warp ÷ this: {v / med['warp']:.2f}")
    if not a.no_embree:
        for t in a.threads:
            rate, sec, rays = embree_rate(r, a.spp, t, a.repeats)
            out["embree"][t] = {"samples_per_s": rate, "seconds": sec, "rays_per_s": rays}
            print(f"embree  {t} thread(s): {rate / 1e6:7.3f} M samples/s of rays "
                  f"({rays / 1e6:.2f} M rays/s, {sec:.3f} s)")
        best_t = max(a.threads)
        eb = max(v["samples_per_s"] for v in out["embree"].values())
        out["warp_over_embree"] = out["warp"][best_t]["samples_per_s"] / eb
        print(f"warp ({best_t} threads) / best embree rate: {out['warp_over_embree']:.2f}")
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
