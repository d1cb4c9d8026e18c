"""Cost per sample on meshes: our renderer against Mitsuba 3 on the same scene, one interleaved run.

    python -m benchmarks.bench_mesh_vs_mitsuba                              # CPU: Warp CPU vs llvm_ad_rgb
    python -m benchmarks.bench_mesh_vs_mitsuba --device cuda --variant cuda_ad_rgb   # a GPU: vs OptiX

The scene is the Mitsuba reference scene of :mod:`lab.mitsuba_reference` (camera at (0, 0, 4)
looking at the origin, 30 deg vertical field of view, the environment map hidden, direct
lighting: per camera sample one environment sample and one BSDF sample, each with a shadow ray,
power heuristic, independent samples on both sides) with one of three objects:

* ``sphere``: the analytic unit sphere (ours: closed-form intersection; Mitsuba: its ``sphere``);
* ``bunny``: the Stanford bunny (69,451 triangles), ``teapot``: the teapot (6,320 triangles),
  each scaled to 1.8 units and centred at the origin: ours traces Warp's BVH, Mitsuba Embree
  (CPU) or OptiX (CUDA). Both read the same triangles with the same vertex normals: the mesh is
  loaded once with our loader and written as a binary PLY for Mitsuba.

The material is an RGL file (ours: ``rgl`` with ``mis-rgl``, the format's own sampling;
Mitsuba: ``measured``) or ``lambert`` (0.5; ``mis`` / ``diffuse``). For each case both renderers
are warmed up (compile / JIT), then ``--rounds`` renders of each, alternating, at
``--resolution``² pixels and ``--spp`` samples per pixel with seeds 1..rounds. From the rounds:

* **samples/s**: camera samples per second of render call (median round), the image's transfer
  to NumPy included (it forces a JIT variant to finish);
* **variance per sample**: per pixel and channel, the variance over rounds of the pixel's
  estimate × spp, averaged over the object's pixels (both images non-zero) and divided by the
  squared mean over them: the relative variance of one sample, v; the samples per pixel for a
  1 % relative RMSE over the object are v / 10⁻⁴;
* **time to 1 %** = (seconds per sample per pixel) × v / 10⁻⁴, and the ratio ours ÷ Mitsuba
  (< 1: ours reaches 1 % sooner). Reported, never asserted;
* **agreement**: the relative difference of the two images' means over the object, with its
  standard error from the two variances (the scenes are the same up to each renderer's ray
  offsets and shading-normal handling).

Results print as a table and are written as JSON with ``--out``. Needs the ``reference`` extra
(Mitsuba 3); the LLVM variant a shared libLLVM (:func:`lab.mitsuba_reference.find_libllvm`).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import struct
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: Objects: None is the analytic sphere; else the mesh file under $RBRDF_DATA.
OBJECTS = {"sphere": None, "bunny": "meshes/bun_zipper.ply", "teapot": "meshes/teapot.obj"}
#: Materials: RGL files under $RBRDF_DATA/rgl, or "lambert".
MATERIALS = ("lambert", "paper_white_rgb", "cc_ibiza_sunset_rgb")
#: Environment map (under $RBRDF_DATA).
ENVMAP = "envmaps/studio_small_03_1k.hdr"
#: A mesh's largest extent after scaling (units; the unit sphere's is 2).
MESH_EXTENT = 1.8


def mesh_to_world(vertices: np.ndarray) -> np.ndarray:
    """4×4 matrix scaling the mesh's bounding box to :data:`MESH_EXTENT` and centring it."""
    lo, hi = vertices.min(0), vertices.max(0)
    s = MESH_EXTENT / float((hi - lo).max())
    m = np.eye(4)
    m[:3, :3] *= s
    m[:3, 3] = -s * (lo + hi) / 2
    return m


def write_ply(path: Path, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray) -> None:
    """A binary little-endian PLY of float32 positions and normals and int32 triangles."""
    head = ("ply\nformat binary_little_endian 1.0\n"
            f"element vertex {len(vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
            "property float nx\nproperty float ny\nproperty float nz\n"
            f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    v = np.hstack([vertices, normals]).astype("<f4")
    f = np.empty(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
    f["n"], f["i"] = 3, faces
    with open(path, "wb") as fh:
        fh.write(head.encode())
        fh.write(v.tobytes())
        fh.write(f.tobytes())


def material_spec(name: str, data: Path):
    return ("lambert", 0.5) if name == "lambert" else data / "rgl" / f"{name}.bsdf"


def build_case(obj: str, material: str, data: Path, resolution: int, spp: int, device: str,
               variant: str, tmp: Path):
    """(our Renderer, Mitsuba scene) of one case."""
    from lab import mitsuba_reference as MR
    from warp_rbrdf.geometry import load_mesh_file
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import ShapeSpec

    mat, env = material_spec(material, data), data / ENVMAP
    ours = MR.sphere_scene(mat, env, spp, resolution, pattern="independent")
    MR.set_variant(variant)
    d = MR.mitsuba_scene_dict(mat, env, spp, resolution)
    if OBJECTS[obj] is not None:
        path = data / OBJECTS[obj]
        v, f, n = load_mesh_file(path)
        m = mesh_to_world(v)
        ours.shapes = [ShapeSpec(type="mesh", material="obj", file=path, transform=m)]
        ply = tmp / f"{obj}.ply"
        if not ply.exists():
            write_ply(ply, v @ m[:3, :3].T + m[:3, 3], f, n)
        # the object's entry keeps the reference dictionary's key ("sphere") and its BSDF
        d["sphere"] = {"type": "ply", "filename": str(ply), "bsdf": d["sphere"]["bsdf"]}
    scene = MR._load_scene(d, mat)
    return Renderer(ours, device=device), scene


def run_case(obj, material, a, tmp) -> dict:
    from lab import mitsuba_reference as MR

    r, scene = build_case(obj, material, a.data, a.resolution, a.spp, a.device, a.variant, tmp)
    r.render(spp=max(a.spp // 8, 1), seed=0, threads=a.threads)      # compile, first launch
    MR.render_timed(scene, a.spp, 0)                                  # JIT for this spp
    imgs = {"ours": [], "mitsuba": []}
    secs = {"ours": [], "mitsuba": []}
    for k in range(1, a.rounds + 1):
        imgs["ours"].append(r.render(spp=a.spp, seed=k, threads=a.threads).astype(np.float64))
        secs["ours"].append(r.stats.render_seconds)
        img, t = MR.render_timed(scene, a.spp, k)
        imgs["mitsuba"].append(img)
        secs["mitsuba"].append(t)
    mean = {k: np.mean(v, axis=0) for k, v in imgs.items()}
    mask = np.all(mean["ours"] > 0, axis=-1) & np.all(mean["mitsuba"] > 0, axis=-1)
    px = a.resolution ** 2
    out = {"object": obj, "material": material, "pixels_on_object": int(mask.sum())}
    for k in imgs:
        st = np.stack(imgs[k])[:, mask]                 # (rounds, n, 3)
        v = float(st.var(axis=0, ddof=1).mean() * a.spp / st.mean() ** 2)
        t = statistics.median(secs[k])
        out[k] = {"seconds": t, "samples_per_s": px * a.spp / t, "rel_variance_per_sample": v,
                  "time_to_1pct_s": t / a.spp * v / 1e-4, "seconds_all": secs[k]}
    out["speed_ratio"] = out["ours"]["samples_per_s"] / out["mitsuba"]["samples_per_s"]
    out["variance_ratio"] = out["ours"]["rel_variance_per_sample"] / out["mitsuba"]["rel_variance_per_sample"]
    out["time_to_1pct_ratio"] = out["ours"]["time_to_1pct_s"] / out["mitsuba"]["time_to_1pct_s"]
    out["mean_rel_diff"] = float(mean["ours"][mask].mean() / mean["mitsuba"][mask].mean() - 1)
    # its standard error from the two sides' variances (channels counted as one: conservative)
    n = mask.sum() * a.spp * a.rounds
    out["mean_rel_diff_se"] = float(np.sqrt(sum(out[k]["rel_variance_per_sample"] for k in imgs) / max(n, 1)))
    return out


def machine(a) -> dict:
    import warp as wp

    d = wp.get_device(a.device)
    return {"device": str(d), "name": getattr(d, "name", ""), "warp": wp.config.version,
            "variant": a.variant, "cpus": os.cpu_count(), "threads": a.threads, "host": platform.node(),
            "load": os.getloadavg(), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu", help="our Warp device (default cpu)")
    ap.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant (default llvm_ad_rgb; cuda_ad_rgb on a GPU)")
    ap.add_argument("--objects", default="sphere,bunny,teapot")
    ap.add_argument("--materials", default=",".join(MATERIALS))
    ap.add_argument("--resolution", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--rounds", type=int, default=4, help="timed renders of each side per case (>= 2)")
    ap.add_argument("--threads", type=int, default=None, help="CPU threads of both (default: all cores)")
    ap.add_argument("--data", type=Path, default=Path(os.environ.get("RBRDF_DATA", ROOT.parent / "shared" / "data")))
    ap.add_argument("--out", type=Path, help="write the results as JSON")
    a = ap.parse_args(argv)
    if a.rounds < 2:
        ap.error("--rounds must be at least 2 (the variance is taken over rounds)")
    a.threads = a.threads or os.cpu_count()

    from lab import mitsuba_reference as MR
    from warp_rbrdf.runtime import init_warp

    init_warp()
    MR.set_variant(a.variant)
    if not a.variant.startswith("cuda"):
        MR.set_thread_count(a.threads)
    res = {"machine": machine(a), "args": {k: str(v) for k, v in vars(a).items()}, "cases": []}
    print(json.dumps(res["machine"]), flush=True)
    print(f"{'case':32s} {'ours M/s':>9s} {'Mitsuba M/s':>11s} {'speed':>6s} {'var':>6s} {'t(1%) ratio':>11s} {'dmean':>7s}")
    with tempfile.TemporaryDirectory() as tmp:
        for obj in a.objects.split(","):
            for mat in a.materials.split(","):
                try:
                    c = run_case(obj, mat, a, Path(tmp))
                except Exception as e:  # noqa: BLE001 - one failing case is a result, not the end of the run
                    c = {"object": obj, "material": mat, "error": f"{type(e).__name__}: {e}"}
                    print(f"{obj + '/' + mat:32s} ERROR {c['error'][:200]}", flush=True)
                else:
                    print(f"{obj + '/' + mat:32s} {c['ours']['samples_per_s'] / 1e6:9.2f} "
                          f"{c['mitsuba']['samples_per_s'] / 1e6:11.2f} {c['speed_ratio']:6.2f} "
                          f"{c['variance_ratio']:6.2f} {c['time_to_1pct_ratio']:11.2f} {c['mean_rel_diff']:+7.3f}",
                          flush=True)
                res["cases"].append(c)
                if a.out:
                    a.out.write_text(json.dumps(res, indent=1))
    ok = [c for c in res["cases"] if "error" not in c]
    if ok:
        by = lambda key: statistics.median(c[key] for c in ok)  # noqa: E731
        print(f"median over {len(ok)} cases: speed ours/Mitsuba {by('speed_ratio'):.2f}, "
              f"variance {by('variance_ratio'):.2f}, time to 1 % {by('time_to_1pct_ratio'):.2f}")
    return 0 if len(ok) == len(res["cases"]) else 1


if __name__ == "__main__":
    sys.exit(main())
