"""The chart the project exists for: per shared RGL material and environment map, the error
against the measurement (ΔE2000 mean and p99 inside the object, against the converged ``rgl``
render) against render time, for every representation, each with its best sampler, plus
Mitsuba 3's ``measured`` plugin on the same axes, and the memory of each representation.

Scene: the reference sphere of :mod:`lab.mitsuba_reference` (unit sphere, camera at (0, 0, 4),
30 deg vertical field of view, ``--res`` px square, hidden map at scale 1, direct lighting: one
environment and one BSDF sample per camera sample, power heuristic), as
:mod:`benchmarks.bench_vs_mitsuba` renders it. Representations (:data:`REPRESENTATIONS`):

* ``rgl``: the ``.bsdf`` file evaluated exactly (the format's own interpolation);
* ``measured``: its 3-D MERL-grid resampling, trilinear; ``projected``: the (θh, θd) median
  projection, nearest cluster;
* ``rational-2d``: the 2-D fit at 5 %; ``rational-3d``: the 3-D fit of (θh, θd, |φd|)
  (:mod:`benchmarks.chart_fits`: cached, shipped or made by ``rbrdf-fit brdf``);
* ``mitsuba``: Mitsuba 3's ``measured`` plugin on the same file (the ``reference`` extra; LLVM
  variant where a libLLVM is found, else ``scalar_rgb``), its ``multijitter`` sampler; skipped
  with a one-line note when Mitsuba is missing.

Best sampler: the kind's default strategy (:func:`warp_rbrdf.registry.default_strategy`: its own
importance sampling combined with one environment sample; ``rgl`` ``mis-rgl``, ``measured`` and
``projected`` ``mis-tabulated``, ``rational`` ``mis-rational`` when the fit file carries its
inverse CDFs, else ``mis-tabulated``) and our ``stratified`` pattern.

Truth: ``rgl`` with ``mis-rgl`` at ``--truth-spp`` spp, rendered as two halves (passes of at most
:data:`TRUTH_PASS_SPP` spp, seeds of their own) and cached under ``<out>/truth/`` by its inputs
(the file's and the map's SHA-256, resolution, spp, seeds); its own floor is the ΔE2000 of one
half-difference-perturbed truth against the truth (the error the truth adds to every number).

Each rung: one render at that spp (seed ``--seed`` + rung index), after an untimed warm-up;
its time is the render call (set-up — files, tables, BVH, kernel load — reported apart), its
error ΔE2000 mean and p99 over the sphere's fully covered pixels at the truth's exposure
(99th-percentile luminance -> L* = 100, :func:`studies.metrics.exposure_for`). Memory: the bytes
of the arrays the renderer uploads for the material and its sampler, and of the file it reads.
Summary (:mod:`benchmarks.chart_report`): per case which representation reaches ΔE mean <= 1
first and when; which never do, and their floor.

    RBRDF_DATA=/work/shared/data python -m benchmarks.bench_chart --docs        # full size
    python -m benchmarks.bench_chart --quick --out /tmp/chart_quick             # smoke test
    python -m benchmarks.bench_chart --materials paper_white satin_rosaline --maps studio --res 64

Outputs (``--out``, default ``results/chart``; every file written atomically): ``chart.json``,
``chart.md``, ``chart.png``; ``--docs`` also writes ``docs/chart.md`` and ``docs/images/chart.png``.
Progress lines on stderr.
"""
from __future__ import annotations

import argparse
import copy
import functools
import hashlib
import json
import os
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks import chart_fits as CF
from benchmarks import chart_report as CR

ROOT = Path(__file__).resolve().parents[1]
MAPS = {"studio": "envmaps/studio_small_03_1k.hdr", "rooitou": "envmaps/rooitou_park_1k.hdr"}
REPRESENTATIONS = ("rgl", "measured", "projected", "rational-2d", "rational-3d")
OUR_PATTERN = "stratified"
MITSUBA_SAMPLER = "multijitter"
TRUTH_PASS_SPP = 256
TRUTH_SEEDS = (7_000_001, 7_500_001)
QUICK = dict(materials=["paper_white"], maps=["studio"], res=24, spp_ladder=[2, 8], truth_spp=64)
FULL = dict(maps=["studio", "rooitou"], res=128, spp_ladder=[4, 16, 64, 256], truth_spp=4096)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _sha(path) -> str:
    return CF.file_sha256(Path(path))


# --------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=2)
def measured_data(bsdf: Path) -> tuple:
    """``(MeasuredBRDF, ProjectedBRDF)`` of an RGL file, as the ``measured`` and ``projected``
    kinds load it (``incident = "view"``, median projection); kept for the file's second map."""
    from fit.formats import load_measured
    from fit.projection.project import project

    meas = load_measured(bsdf)
    return meas, project(meas, statistic="median")


def spec_for(rep: str, bsdf: Path, fit_file: Path | None):
    """``(MaterialSpec, sampler)`` of representation ``rep`` with its best sampler."""
    from warp_rbrdf import registry
    from warp_rbrdf.scene import MaterialSpec

    kind = "rational" if rep.startswith("rational") else rep
    cdf = kind == "rational" and "sampler" in json.loads(Path(fit_file).read_text())
    sampler = registry.default_strategy(kind, cdf=cdf)
    if kind == "rational":
        return MaterialSpec(name="obj", type=kind, file=Path(fit_file), sampler=sampler), sampler
    if kind in ("measured", "projected"):
        data = measured_data(bsdf)[kind == "projected"]
        return MaterialSpec(name="obj", type=kind, data=data, sampler=sampler), sampler
    return MaterialSpec(name="obj", type=kind, file=bsdf, sampler=sampler, incident="view"), sampler


def scene_with(base, spec):
    sc = copy.copy(base)
    sc.materials = {"obj": spec}
    sc.integrator = copy.copy(base.integrator)
    sc.integrator.sampler = spec.sampler
    return sc


def memory_of(r, file: Path) -> dict:
    """Bytes of the material's device arrays (BRDF data and sampler data) and of its file."""
    m = r.materials
    brdf = ("tables", "rgl_f", "rgl_i", "coef_i", "coef_f", "coef_q", "param")
    samp = ("cdf_t", "cdf_p", "cdf_pw", "cdf_row_ok", "cdf_info", "cdf_gi", "cdf_gf", "cdf_gq")

    def nbytes(names):
        return int(sum(getattr(m, n).capacity for n in names if getattr(m, n).size > 1))

    return {"brdf_bytes": nbytes(brdf), "sampler_bytes": nbytes(samp),
            "device_bytes": nbytes(brdf) + nbytes(samp), "file_bytes": int(Path(file).stat().st_size)}


def truth(bsdf: Path, env: Path, base, a, out: Path) -> dict:
    """The converged ``rgl`` render (module docstring), cached by its inputs."""
    from fit.atomic_files import atomic_path
    from warp_rbrdf.renderer import Renderer

    key = hashlib.sha256(json.dumps([_sha(bsdf), _sha(env), a.res, a.truth_spp, TRUTH_PASS_SPP, TRUTH_SEEDS,
                                     OUR_PATTERN]).encode()).hexdigest()[:12]
    path = out / "truth" / f"{bsdf.stem}_{env.stem}_{key}.npz"
    if path.is_file():
        z = np.load(path)
        return {"img": z["img"], "delta": z["delta"], "source": "cached", "seconds": float(z["seconds"])}
    r = Renderer(base, device="cpu")
    r.compile()
    half = a.truth_spp // 2
    per = min(TRUTH_PASS_SPP, half)
    n = max(1, half // per)
    halves, t0 = [], time.perf_counter()
    for h, s0 in enumerate(TRUTH_SEEDS):
        acc = 0.0
        for k in range(n):
            acc = acc + np.asarray(r.render(spp=per, seed=s0 + k, threads=a.threads), np.float64)
        halves.append(acc / n)
        log(f"  truth half {h + 1}/2 ({n} x {per} spp) {time.perf_counter() - t0:.0f} s")
    img, delta = (halves[0] + halves[1]) / 2, (halves[0] - halves[1]) / 2
    secs = time.perf_counter() - t0
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez_compressed(f, img=img, delta=delta, seconds=secs)
    return {"img": img, "delta": delta, "source": f"rendered ({secs:.0f} s)", "seconds": secs}


def errors(img, ref, mask, expo, band) -> dict:
    """ΔE2000 mean and p99 over ``mask``, the mean over its rim ``band`` and over the rest, and
    the RGB channel-mean ratios img / ref over ``mask`` (a colour shift shows there)."""
    from studies import metrics as M

    de = M.delta_e2000(img, ref, expo)
    s = M.de_stats(de, mask)
    inner = mask & ~band
    return {"de_mean": s["mean"], "de_p99": s["p99"], "de_rim": float(de[band].mean()),
            "de_inner": float(de[inner].mean()), "mean_ratio": (img[mask].mean(0) / ref[mask].mean(0)).tolist()}


def de_stats(img, ref, mask, expo) -> tuple[float, float]:
    from studies import metrics as M

    s = M.de_stats(M.delta_e2000(img, ref, expo), mask)
    return s["mean"], s["p99"]


def ladder_ours(scene, a, ref, mask, expo, band) -> tuple[list, dict]:
    from warp_rbrdf.renderer import Renderer

    t0 = time.perf_counter()
    r = Renderer(scene, device="cpu")
    setup = time.perf_counter() - t0
    comp = r.compile()
    r.render(spp=1, seed=2**31 - 1, threads=a.threads)          # warm-up: first launches
    rungs = []
    for i, spp in enumerate(a.spp_ladder):
        t0 = time.perf_counter()
        img = np.asarray(r.render(spp=spp, seed=a.seed + i, threads=a.threads), np.float64)
        dt = time.perf_counter() - t0
        rungs.append(dict({"spp": spp, "seconds": dt}, **errors(img, ref, mask, expo, band)))
    return rungs, {"setup_s": setup + comp, "renderer": r, "notes": [n for lm in r.material_data.loaded
                                                                      for n in (lm.notes or ())]}


def ladder_mitsuba(bsdf, env, a, ref, mask, expo, band) -> tuple[list, float]:
    from lab import mitsuba_reference as MR

    t0 = time.perf_counter()
    scene = MR.timing_scene(bsdf, env, a.spp_ladder[0], a.res, sampler=MITSUBA_SAMPLER)
    setup = time.perf_counter() - t0
    rungs = []
    for i, spp in enumerate(a.spp_ladder):
        MR.render_timed(scene, spp, seed=2**31 - 1)                    # JIT compile per spp: untimed
        img, dt = MR.render_timed(scene, spp, seed=a.seed + i)
        rungs.append(dict({"spp": spp, "seconds": dt}, **errors(img, ref, mask, expo, band)))
    return rungs, setup


def run_case(mat: str, map_name: str, a, fits: dict, mitsuba: dict, out: Path) -> dict:
    from lab import mitsuba_reference as MR
    from studies import metrics as M

    data = Path(os.environ["RBRDF_DATA"])
    bsdf, env = data / "rgl" / f"{mat}_rgb.bsdf", data / MAPS[map_name]
    t_case = time.perf_counter()
    base = MR.sphere_scene(bsdf, env, a.truth_spp, a.res, pattern=OUR_PATTERN)
    from studies.fidelity import rim_band

    mask = MR.sphere_mask(a.res)
    band = rim_band(a.res, mask)          # the outer 15 px at 256 px (scaled, >= 4 px) of the disc
    tr = truth(bsdf, env, base, a, out)
    ref = tr["img"]
    expo = M.exposure_for(ref, mask)
    fm, fp = de_stats(ref + tr["delta"], ref, mask, expo)   # the truth's own error, in distribution
    case = {"material": mat, "map": map_name, "exposure": expo, "mask_pixels": int(mask.sum()),
            "truth": {"spp": a.truth_spp, "floor_mean": fm, "floor_p99": fp, "source": tr["source"]},
            "ladders": {}, "memory": {}, "setup_s": {}, "samplers": {}, "notes": {}}
    for rep in REPRESENTATIONS:
        fit_file = None
        if rep.startswith("rational"):
            fit_file, info = fits[mat][rep]
            if fit_file is None:
                case["notes"][rep] = f"no fit: {info.get('error')}"
                continue
        spec, sampler = spec_for(rep, bsdf, fit_file)
        try:
            rungs, info = ladder_ours(scene_with(base, spec), a, ref, mask, expo, band)
        except Exception as e:  # noqa: BLE001 - a representation that cannot load is reported
            case["notes"][rep] = f"{type(e).__name__}: {e}"
            continue
        used = info["renderer"].material_data.strategies[0]
        case["ladders"][rep], case["setup_s"][rep] = rungs, info["setup_s"]
        case["samplers"][rep] = used
        case["memory"][rep] = dict(memory_of(info["renderer"], fit_file or bsdf), sampler=used)
        if info["notes"]:
            case["notes"][rep] = "; ".join(info["notes"])
        log(f"  {rep} ({used}): " + ", ".join(f"{r['spp']} spp {r['seconds']:.2f} s ΔE {r['de_mean']:.2f}"
                                              for r in rungs))
    if mitsuba.get("variant"):
        try:
            rungs, setup = ladder_mitsuba(bsdf, env, a, ref, mask, expo, band)
            case["ladders"]["mitsuba"], case["setup_s"]["mitsuba"] = rungs, setup
            case["samplers"]["mitsuba"] = MITSUBA_SAMPLER
            case["memory"]["mitsuba"] = {"sampler": MITSUBA_SAMPLER, "file_bytes": int(bsdf.stat().st_size)}
            log("  mitsuba: " + ", ".join(f"{r['spp']} spp {r['seconds']:.2f} s ΔE {r['de_mean']:.2f}"
                                          for r in rungs))
        except Exception as e:  # noqa: BLE001
            case["notes"]["mitsuba"] = f"{type(e).__name__}: {e}"
    case["summary"] = CR.case_summary(case["ladders"])
    case["case_s"] = time.perf_counter() - t_case
    log(f"  -> first to ΔE <= {CR.TARGET_DE:g}: {case['summary']['first']} "
        f"({CR._t(case['summary']['seconds'])}); rational-3d: {CR.why_not(case)}")
    return case


# --------------------------------------------------------------------------------------------
def mitsuba_setup(a) -> dict:
    """``{"variant", "version"}`` of Mitsuba 3, or ``{"note"}`` when it is missing or not wanted."""
    from lab import mitsuba_reference as MR

    if a.no_mitsuba:
        return {"note": "not requested (--no-mitsuba)"}
    if not MR.available():
        return {"note": f"Mitsuba 3 not installed ({MR.INSTALL_HINT}): its line is left out"}
    try:
        variant = MR.set_variant(MR.LLVM_VARIANT)
    except MR.ReferenceUnavailable as e:
        log(f"{e}; using {MR.VARIANT}")
        variant = MR.set_variant(MR.VARIANT)
    MR.set_thread_count(a.threads)
    return {"variant": variant, "version": f"{MR.version()} {variant}"}


def machine(start_load: str) -> dict:
    proc = "?"
    try:
        proc = next(x.split(":", 1)[1].strip() for x in Path("/proc/cpuinfo").read_text().splitlines()
                    if x.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return {"cpus": os.cpu_count(), "processor": proc, "loadavg_start": start_load, "loadavg_end": _load()}


def _load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def parse(argv):
    p = argparse.ArgumentParser(prog="python -m benchmarks.bench_chart", description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="smoke test: paper_white, studio, 24 px, spp 2 8, "
                                                        "truth 64 spp, only cached fits")
    p.add_argument("--materials", nargs="+", help="RGL file stems without _rgb (default: every shared file)")
    p.add_argument("--maps", nargs="+", choices=sorted(MAPS), help="default: studio rooitou")
    p.add_argument("--res", type=int, help=f"image side in px (default {FULL['res']})")
    p.add_argument("--spp-ladder", type=int, nargs="+", help=f"default {FULL['spp_ladder']}")
    p.add_argument("--truth-spp", type=int, help=f"spp of the truth (even; default {FULL['truth_spp']})")
    p.add_argument("--seed", type=int, default=1000, help="seed of the first rung (+ rung index)")
    p.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    p.add_argument("--fit-time-limit", type=float, default=900.0, help="seconds per new fit (child process)")
    p.add_argument("--no-fit", action="store_true", help="only cached or shipped fits")
    p.add_argument("--no-mitsuba", action="store_true")
    p.add_argument("--out", default=str(ROOT / "results" / "chart"))
    p.add_argument("--docs", action="store_true", help="also write docs/chart.md and docs/images/chart.png")
    p.add_argument("--from-json", metavar="CHART_JSON", help="render nothing: write the report of an earlier "
                                                              "run's chart.json")
    a = p.parse_args(argv)
    preset = QUICK if a.quick else FULL
    a.materials = a.materials or preset.get("materials")
    a.maps = a.maps or preset["maps"]
    a.res = a.res or preset["res"]
    a.spp_ladder = sorted(a.spp_ladder or preset["spp_ladder"])
    a.truth_spp = a.truth_spp or preset["truth_spp"]
    a.no_fit = a.no_fit or a.quick
    if a.truth_spp < 2 or a.truth_spp % 2 or min(a.spp_ladder) < 1 or a.res < 8:
        p.error("--truth-spp must be even and >= 2, the ladder positive, --res >= 8")
    return a


def main(argv=None) -> int:
    from fit.atomic_files import atomic_write
    from warp_rbrdf.paths import require_data_root

    a = parse(argv)
    if a.from_json:                # only the report of an earlier run
        res = json.loads(Path(a.from_json).read_text())
        write_outputs(res, Path(a.out), a.docs)
        return 0
    start_load = _load()
    data = require_data_root("the RGL files and environment maps")
    os.environ["RBRDF_DATA"] = str(data)
    allm = sorted(p.stem.removesuffix("_rgb") for p in (data / "rgl").glob("*_rgb.bsdf"))
    a.materials = a.materials or allm
    bad = [m for m in a.materials if m not in allm]
    if bad:
        log(f"bench_chart: unknown material(s) {bad}; the shared RGL files are {allm}")
        return 2
    out = Path(a.out)
    t0 = time.perf_counter()
    mitsuba = mitsuba_setup(a)
    log(f"bench_chart: {len(a.materials)} materials x {len(a.maps)} maps, {a.res} px, ladder {a.spp_ladder}, "
        f"truth {a.truth_spp} spp; Mitsuba: {mitsuba.get('version') or mitsuba['note']}")
    fits, cases = {}, []
    for m in a.materials:          # a material's fits just before its cases (others may be made meanwhile)
        bsdf = data / "rgl" / f"{m}_rgb.bsdf"
        fits[m] = {"rational-2d": CF.fit2d(bsdf, a.fit_time_limit, not a.no_fit, log),
                   "rational-3d": CF.fit3d(bsdf, a.fit_time_limit, not a.no_fit, log)}
        log(f"fits {m}: " + "; ".join(f"{k} {v[1].get('source') or v[1].get('error')}" for k, v in fits[m].items()))
        for mp in a.maps:
            log(f"{m} / {mp}")
            cases.append(run_case(m, mp, a, fits, mitsuba, out))
    argv_used = sys.argv[1:] if argv is None else list(argv)
    res = {"command": "python -m benchmarks.bench_chart " + " ".join(shlex.quote(x) for x in argv_used),
           "date": time.strftime("%Y-%m-%d %H:%M"), "wall_s": time.perf_counter() - t0, "machine": machine(start_load),
           "mitsuba": mitsuba,
           "args": {k: getattr(a, k) for k in ("materials", "maps", "res", "spp_ladder", "truth_spp", "seed",
                                               "threads")},
           "fits": {m: {k: v[1] for k, v in f.items()} for m, f in fits.items()}, "cases": cases}
    with atomic_write(out / "chart.json") as f:
        json.dump(res, f, indent=1, default=_jsonable)
    write_outputs(res, out, a.docs)
    wins = sum(c["summary"]["first"] == "rational-3d" for c in cases)
    log(f"rational-3d first on {wins} of {len(cases)} cases; wrote {out}/chart.json, chart.md, chart.png"
        + (", docs/chart.md" if a.docs else "") + f" ({res['wall_s']:.0f} s)")
    return 0


def write_outputs(res: dict, out: Path, docs: bool) -> None:
    """``chart.png`` and ``chart.md`` in ``out``; with ``docs`` also docs/chart.md and
    docs/images/chart.png (each written atomically)."""
    from fit.atomic_files import atomic_write

    CR.plot_cases(res["cases"], out / "chart.png")
    with atomic_write(out / "chart.md") as f:
        f.write(CR.markdown(res, "chart.png"))
    if docs:
        CR.plot_cases(res["cases"], ROOT / "docs" / "images" / "chart.png")
        with atomic_write(ROOT / "docs" / "chart.md") as f:
            f.write(CR.markdown(res, "images/chart.png"))


def _jsonable(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(type(o))


if __name__ == "__main__":
    sys.exit(main())
