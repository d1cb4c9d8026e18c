"""Benchmark and check of the renderer's CUDA path: every material kind and sampler family
rendered on a Warp device, compared with the CPU renders of the same scenes (same seed, same
samples per pixel), and timed.

    python -m benchmarks.bench_cuda --write-reference DIR        # on the CPU: the references
    python -m benchmarks.bench_cuda --device cuda --reference DIR --out RESULT.json

The cases (:data:`MATERIALS` × :data:`SCENES`) are a sphere on a plane under the procedural sky
and the teapot under the rooitou_park map (small strong sun). Each material is one kind: Lambert,
``rgl`` (exact, with the format's own sampling, ``mis-rgl``), ``measured`` and ``projected``
(``mis-tabulated``), ``rational`` 2-D and 3-D fits (their default sampler). The 3-D fit is the
chart's fit of satin_rosaline made by today's fitter (``--fits-3d``, default the chart's fit
folder; :func:`benchmarks.chart_fits.fit3d_path`: its name follows the fitter's defaults).

Per case it reports:

* **agreement** of the device's image with the CPU image at ``--check-resolution`` pixels and
  ``--check-spp`` samples: the relative difference of the image means, and per pixel
  z = (a − b) / sqrt((var_a + var_b) / spp) from each render's own per-pixel variance: mean z²
  is ≈ 2 for two independent estimates of one expectation (the two variances are counted),
  ≈ 0 when both devices draw the same sample streams, and grows without bound for a bias.
  A case *agrees* when mean z² ≤ 3 and the fraction of pixels with |z| > 6 is ≤ 10⁻³;
* **evaluation and sampling** at 4096 random direction pairs: the device's ``eval_material``,
  ``sample_material`` and ``pdf_material`` against the CPU's (largest relative difference of the
  values, fraction of sampled directions more than 10⁻³ apart);
* **speed**: shaded samples per second (camera rays × spp; one shaded sample = one camera ray,
  one environment sample and one BSDF sample with their shadow rays) at ``--resolution`` and
  ``--spp``, median of ``--repeats`` renders after a warm-up, the kernel's compile time apart.

A reference folder holds one ``CASE.npz`` per case (image, variance, the evaluation and sampling
arrays) and ``reference.json`` (the CPU's samples/s at the check size, the machine); when the CPU
device is available in the same process and no ``--reference`` is given, the CPU references are
rendered in the run. Results print as a table and are written as JSON with ``--out``.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
import traceback
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: Material tables (TOML body of ``[materials.obj]``) by case name; ``{fits}`` is ``--fits``,
#: ``{fit3d}`` the chart's 3-D fit of satin_rosaline in ``--fits-3d`` (:func:`chart_fit3d`).
MATERIALS = {
    "lambert": 'type = "lambert"\nalbedo = 0.6',
    "rgl-satin": 'type = "rgl"\nfile = "${RBRDF_DATA}/rgl/satin_rosaline_rgb.bsdf"',
    "rgl-paper": 'type = "rgl"\nfile = "${RBRDF_DATA}/rgl/paper_white_rgb.bsdf"',
    "measured-satin": 'type = "measured"\nfile = "${RBRDF_DATA}/rgl/satin_rosaline_rgb.bsdf"',
    "projected-satin": 'type = "projected"\nfile = "${RBRDF_DATA}/rgl/satin_rosaline_rgb.bsdf"',
    "rational2d-satin": 'type = "rational"\nfile = "{fits}/satin_rosaline_rgb_tol0p1_cli.json"',
    "rational3d-satin": 'type = "rational"\nfile = "{fit3d}"',
}

_SPHERE = """
[[shapes]]
type = "sphere"
center = [0.0, 0.8, 0.0]
radius = 0.8
material = "obj"
"""
_TEAPOT = """
[[shapes]]
type = "mesh"
file = "${RBRDF_DATA}/meshes/teapot.obj"
material = "obj"
transform = { scale = 0.5 }
"""
def _body(origin, target, shape: str, light: str) -> str:
    """A scene body: the camera (at ``origin``, looking at ``target``, 35 deg), the object, the light."""
    return (f"\n[camera]\norigin = {list(origin)}\ntarget = {list(target)}\nfov = 35.0\n"
            "resolution = [64, 64]\n" + shape + light)


#: Scene bodies: camera, object, floor, light (the material table is appended).
SCENES = {
    "sphere-sky": _body((0.0, 1.6, 4.2), (0.0, 0.8, 0.0), _SPHERE, """
[[lights]]
type = "sky"
sun_elevation = 40.0
sun_azimuth = 140.0
"""),
    "teapot-env": _body((0.0, 2.0, 5.5), (0.0, 0.6, 0.0), _TEAPOT, """
[[lights]]
type = "envmap"
file = "${RBRDF_DATA}/envmaps/rooitou_park_1k.hdr"
rotate = [80.0, 0.0, 1.0, 0.0]
"""),
}
_FLOOR = """
[materials.floor]
type = "lambert"
albedo = 0.45

[[shapes]]
type = "plane"
size = [8.0, 8.0]
material = "floor"
"""

#: Agreement thresholds (see the module docstring).
MAX_MEAN_Z2 = 3.0
MAX_OUTLIER_FRACTION = 1e-3
N_PAIRS = 4096


def chart_fit3d(fits3d: Path | None = None) -> Path:
    """The chart's 3-D fit of satin_rosaline in ``fits3d`` (default the chart's fit folder) under
    the cache key of today's fitter defaults (:func:`benchmarks.chart_fits.fit3d_path`; the
    measurement in the shared data folder the scenes' ``${RBRDF_DATA}`` names,
    :func:`warp_rbrdf.paths.require_data_root`)."""
    from benchmarks.chart_fits import FIT3D_DIR, fit3d_path
    from warp_rbrdf.paths import require_data_root

    bsdf = require_data_root("the 3-D case's measurement") / "rgl" / "satin_rosaline_rgb.bsdf"
    return fit3d_path(bsdf, fit_dir=fits3d or FIT3D_DIR)


def scene_text(scene: str, material: str, fits: Path, resolution: int, spp: int, fit3d: Path | None = None) -> str:
    """TOML text of case (``scene``, ``material``) at ``resolution``² pixels and ``spp``; ``fit3d``
    the 3-D fit file (:func:`chart_fit3d`) of a material that names ``{fit3d}``."""
    body = SCENES[scene].replace("resolution = [64, 64]", f"resolution = [{resolution}, {resolution}]")
    mat = MATERIALS[material].replace("{fits}", str(fits))
    if "{fit3d}" in mat:
        mat = mat.replace("{fit3d}", str(fit3d))
    return (body + f"\n[integrator]\nspp = {spp}\n\n[materials.obj]\n{mat}\n" + _FLOOR)


def make_renderer(scene: str, material: str, fits: Path, resolution: int, spp: int, device: str,
                  fit3d: Path | None = None):
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene.parse import parse_scene

    sc = parse_scene(scene_text(scene, material, fits, resolution, spp, fit3d), base_dir=ROOT)
    return Renderer(sc, device=device)


def direction_pairs(n: int = N_PAIRS, seed: int = 3):
    """``n`` local direction pairs (wi, wo), cosine-distributed above the surface, and
    uniforms (n, 2) for the BSDF samples: the same arrays on every machine."""
    rng = np.random.default_rng(seed)

    def hemi(u):
        r, ph = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
        return np.stack([r * np.cos(ph), r * np.sin(ph), np.sqrt(np.maximum(1 - u[:, 0], 0))], -1)

    return hemi(rng.random((n, 2))), hemi(rng.random((n, 2))), rng.random((n, 2))


def probe(renderer, resolution: int, spp: int, seed: int = 7) -> dict:
    """Image, variance, evaluation and sampling arrays of material ``obj`` on the renderer's
    device, at the check size."""
    img, var = renderer.render(spp=spp, seed=seed, return_variance=True)
    wi, wo, xi = direction_pairs()
    out = {"image": img, "variance": var, "eval": renderer.eval_material("obj", wi, wo)}
    try:
        s_wi, s_w = renderer.sample_material("obj", wo, xi)
        out.update(sample_wi=s_wi, sample_weight=s_w, pdf=renderer.pdf_material("obj", wi, wo))
    except Exception as e:  # noqa: BLE001 - a material with no BSDF sampler: evaluation only
        out["sample_error"] = str(e)
    out["samples_per_s"] = renderer.stats.samples / renderer.stats.render_seconds
    out["spp"] = spp
    return out


def _rel(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    scale = max(float(np.abs(b).max()), 1e-12)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-3 * scale))) if a.size else 0.0


def compare(dev: dict, ref: dict) -> dict:
    """Agreement of a device probe with the CPU reference probe (see the module docstring)."""
    spp = ref["spp"]
    d = dev["image"].astype(np.float64) - ref["image"]
    se = np.sqrt((dev["variance"].astype(np.float64) + ref["variance"]) / spp)
    ok = se > 0
    z = np.where(ok, d / np.where(ok, se, 1.0), np.where(np.abs(d) > 1e-6, np.inf, 0.0))
    out = {
        "mean_rel_diff": float(dev["image"].mean() / max(float(ref["image"].mean()), 1e-12) - 1.0),
        "mean_z2": float(np.mean(np.minimum(z * z, 1e6))),
        "outlier_fraction": float(np.mean(np.abs(z) > 6)),
        "max_abs_diff": float(np.abs(d).max()),
        "eval_max_rel": _rel(dev["eval"], ref["eval"]),
    }
    if "sample_wi" in dev and "sample_wi" in ref:
        moved = np.linalg.norm(dev["sample_wi"] - ref["sample_wi"], axis=1) > 1e-3
        out.update(sample_moved_fraction=float(moved.mean()),
                   sample_weight_max_rel=_rel(dev["sample_weight"][~moved], ref["sample_weight"][~moved]),
                   pdf_max_rel=_rel(dev["pdf"], ref["pdf"]))
    out["agrees"] = bool(out["mean_z2"] <= MAX_MEAN_Z2 and out["outlier_fraction"] <= MAX_OUTLIER_FRACTION
                         and np.isfinite(dev["image"]).all())
    return out


def speed(renderer, spp: int, repeats: int) -> dict:
    renderer.render(spp=max(spp // 8, 1), seed=0)   # warm-up (compile and first launch)
    times = []
    for i in range(repeats):
        renderer.render(spp=spp, seed=i + 1)
        times.append(renderer.stats.render_seconds)
    t = statistics.median(times)
    return {"samples_per_s": renderer.stats.samples / t, "seconds": t, "samples": renderer.stats.samples,
            "compile_s": renderer.compile_seconds, "setup_s": renderer.setup_seconds}


def device_facts(device: str) -> dict:
    import warp as wp

    d = wp.get_device(device)
    facts = {"device": str(d), "name": getattr(d, "name", ""), "warp": wp.config.version,
             "host": platform.node(), "cpus": os.cpu_count()}
    if d.is_cuda:
        facts.update(arch=d.arch, sm_count=getattr(d, "sm_count", None))
    return facts


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cuda", help="Warp device to check and time (default cuda)")
    ap.add_argument("--reference", type=Path, help="folder of CPU references (--write-reference)")
    ap.add_argument("--write-reference", type=Path, help="render the CPU references into this folder and stop")
    ap.add_argument("--fits", type=Path, default=ROOT / "results" / "fits",
                    help="folder of the rational fit files named in MATERIALS")
    ap.add_argument("--fits-3d", dest="fits_3d", type=Path, default=None,
                    help="folder of the chart's 3-D fits (default results/chart/fits): the 3-D case's file")
    ap.add_argument("--cases", default="all", help="comma-separated material names (default all)")
    ap.add_argument("--scenes", default="all", help="comma-separated scene names (default all)")
    ap.add_argument("--check-resolution", type=int, default=96)
    ap.add_argument("--check-spp", type=int, default=64)
    ap.add_argument("--resolution", type=int, default=1024, help="timed renders: pixels per side")
    ap.add_argument("--spp", type=int, default=256, help="timed renders: samples per pixel")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, help="write the results as JSON")
    a = ap.parse_args(argv)

    from warp_rbrdf.runtime import init_warp

    init_warp()
    mats = list(MATERIALS) if a.cases == "all" else a.cases.split(",")
    scenes = list(SCENES) if a.scenes == "all" else a.scenes.split(",")
    cases = [(s, m) for s in scenes for m in mats]
    fit3d = chart_fit3d(a.fits_3d) if any("{fit3d}" in MATERIALS.get(m, "") for m in mats) else None   # hashed once

    if a.write_reference:
        a.write_reference.mkdir(parents=True, exist_ok=True)
        meta = {"machine": device_facts("cpu"), "check_resolution": a.check_resolution,
                "check_spp": a.check_spp, "cases": {}}
        for s, m in cases:
            t0 = time.perf_counter()
            r = make_renderer(s, m, a.fits, a.check_resolution, a.check_spp, "cpu", fit3d)
            p = probe(r, a.check_resolution, a.check_spp)
            np.savez_compressed(a.write_reference / f"{s}__{m}.npz",
                                **{k: v for k, v in p.items() if isinstance(v, np.ndarray)}, spp=p["spp"])
            meta["cases"][f"{s}/{m}"] = {"samples_per_s": p["samples_per_s"], "sample_error": p.get("sample_error"),
                                         "wall_s": time.perf_counter() - t0}
            print(f"{s}/{m}: {p['samples_per_s'] / 1e6:.2f} M samples/s (cpu)", flush=True)
        (a.write_reference / "reference.json").write_text(json.dumps(meta, indent=1))
        return 0

    import warp as wp

    cpu_here = wp.is_cpu_available() and a.reference is None
    result = {"machine": device_facts(a.device), "args": {k: str(v) for k, v in vars(a).items()}, "cases": {}}
    if a.reference is not None and (a.reference / "reference.json").is_file():
        result["reference_machine"] = json.loads((a.reference / "reference.json").read_text())["machine"]
    print(json.dumps(result["machine"]), flush=True)
    for s, m in cases:
        key = f"{s}/{m}"
        row: dict = {}
        try:
            r = make_renderer(s, m, a.fits, a.check_resolution, a.check_spp, a.device, fit3d)
            p = probe(r, a.check_resolution, a.check_spp)
            row["first_compile_s"], row["first_setup_s"] = r.compile_seconds, r.setup_seconds
            if cpu_here:
                ref = probe(make_renderer(s, m, a.fits, a.check_resolution, a.check_spp, "cpu", fit3d),
                            a.check_resolution, a.check_spp)
            else:
                z = np.load(a.reference / f"{s}__{m}.npz")
                ref = {k: z[k] for k in z.files}
                ref["spp"] = int(ref["spp"])
            row["agreement"] = compare(p, ref)
            row["sample_error"] = p.get("sample_error")
            big = make_renderer(s, m, a.fits, a.resolution, a.spp, a.device, fit3d)
            row["speed"] = speed(big, a.spp, a.repeats)
        except Exception as e:  # noqa: BLE001 - one failing case is a result, not the end of the run
            row["error"] = f"{type(e).__name__}: {e}"
            row["traceback"] = traceback.format_exc()[-3000:]
        result["cases"][key] = row
        ag, sp = row.get("agreement", {}), row.get("speed", {})
        print(f"{key:28s} agrees={ag.get('agrees')} z2={ag.get('mean_z2', float('nan')):.3g} "
              f"out={ag.get('outlier_fraction', float('nan')):.2g} dmean={ag.get('mean_rel_diff', float('nan')):+.2e} "
              f"eval={ag.get('eval_max_rel', float('nan')):.2g} pdf={ag.get('pdf_max_rel', float('nan')):.2g} "
              f"moved={ag.get('sample_moved_fraction', float('nan')):.2g} "
              f"{sp.get('samples_per_s', float('nan')) / 1e6:.1f} M/s compile {sp.get('compile_s', float('nan')):.1f} s"
              + (f"  ERROR {row['error']}" if "error" in row else ""), flush=True)
        if a.out:
            a.out.write_text(json.dumps(result, indent=1))
    bad = [k for k, v in result["cases"].items() if "error" in v or not v["agreement"]["agrees"]]
    print(f"{len(cases) - len(bad)}/{len(cases)} cases agree; failing: {bad}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
