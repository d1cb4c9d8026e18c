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

    arrs = [wp.zeros(256, dtype=float) for _ in range(threads)]
    wp.launch(busy, dim=256, inputs=[arrs[0], 1])
    n = 20000

    def run(i):
        wp.launch(busy, dim=256, inputs=[arrs[i], n])

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


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_render", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default=str(ROOT / "scenes" / "bunny_rooitou.toml"))
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--no-embree", action="store_true")
    a = ap.parse_args(argv)

    from warp_rbrdf import load_scene
    from warp_rbrdf.renderer import Renderer

    sc = load_scene(a.scene)
    sc.camera.resolution = (a.resolution, a.resolution)
    r = Renderer(sc)
    compile_s = r.compile()
    out = {"scene": str(a.scene), "resolution": a.resolution, "spp": a.spp, "repeats": a.repeats,
           "cpu_count": os.cpu_count(), "setup_s": round(r.setup_seconds, 3), "compile_s": round(compile_s, 3),
           "triangles": r.geometry.num_triangles, "warp": {}, "embree": {}}
    print(f"scene {a.scene}: {a.resolution}x{a.resolution}, {a.spp} spp, {r.geometry.num_triangles} triangles")
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
