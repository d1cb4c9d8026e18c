"""Benchmark: the noise of MIS-compensated environment samples (``integrator.mis_compensation``)
against the full luminance, per material and map, on the reference sphere.

    python -m benchmarks.bench_mis_compensation [--materials paper_white_rgb ...]
        [--maps studio rooitou potsdamer] [--fractions 0 0.25 0.5 1] [--spp 16 64]
        [--resolution 128] [--pairs 3] [--json FILE] [--docs] [--quick]

The scene is :func:`lab.mitsuba_reference.sphere_scene` (the scene of
``benchmarks/bench_vs_mitsuba.py``: unit sphere, camera at z = 4, hidden map, direct light) with
the RGL file's ``rgl`` material and its default ``mis-rgl`` sampler (``lambert`` with ``mis``
for the name ``lambert``), the ``stratified`` pattern, two threads. Per case, fraction and spp:
the relative RMSE of one render from ``--pairs`` seed pairs (sqrt(mean((X1 - X2)^2) / 2) over
the pixels inside the sphere and the channels, over the mean there; the median of the pairs),
the image mean, and the render time (median). *variance ratio*: (RMSE at 0 / RMSE at the
fraction)^2, the factor in samples (hence time at equal cost per sample) that the compensation
saves; > 1: better. The maps: the benchmark's two (studio, rooitou) and one no benchmark of the
project tunes on (potsdamer), to check that a fraction chosen on the first two holds elsewhere.
``--docs`` writes the table between the markers of docs/sampling.md.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from warp_rbrdf.paths import require_data_root

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "sampling.md"
MARK = ("<!-- bench_mis_compensation: begin -->", "<!-- bench_mis_compensation: end -->")
MAPS = {"studio": "studio_small_03_1k.hdr", "rooitou": "rooitou_park_1k.hdr",
        "potsdamer": "potsdamer_platz_1k.hdr"}
MATERIALS = ("paper_white_rgb", "cardboard_rgb", "acrylic_felt_green_rgb", "satin_rosaline_rgb",
             "aurora_white_rgb", "cc_ibiza_sunset_rgb", "vch_golden_yellow_rgb", "chm_mint_rgb")


def run_case(material: str, envmap: Path, fractions, spp_list, resolution: int, pairs: int, threads: int) -> dict:
    """``{spp: {fraction: {"rel_rmse", "mean", "seconds"}}}`` of one material under one map."""
    from lab import mitsuba_reference as MR
    from warp_rbrdf.renderer import Renderer

    m = ("lambert", 0.5) if material == "lambert" else require_data_root("bench_mis_compensation") / "rgl" / f"{material}.bsdf"
    mask = MR.sphere_mask(resolution)
    out = {}
    for f in fractions:
        sc = MR.sphere_scene(m, envmap, 1, resolution, pattern="stratified")
        sc.integrator.mis_compensation = float(f)
        r = Renderer(sc, device="cpu")
        r.render(spp=1, seed=2**31, threads=threads)        # compile and first launches
        for spp in spp_list:
            errs, means, secs = [], [], []
            for k in range(pairs):
                imgs = []
                for s in (2 * k + 1, 2 * k + 2):
                    t0 = time.perf_counter()
                    imgs.append(np.asarray(r.render(spp=spp, seed=s, threads=threads), np.float64)[mask])
                    secs.append(time.perf_counter() - t0)
                a, b = imgs
                mean = float(np.mean(0.5 * (a + b)))
                errs.append(math.sqrt(float(np.mean((a - b) ** 2)) / 2) / mean)
                means.append(mean)
            out.setdefault(spp, {})[f] = {"rel_rmse": statistics.median(errs), "mean": float(np.mean(means)),
                                          "seconds": statistics.median(secs), "compensated": r.mis_compensated}
    return out


def _by_fraction(row: dict) -> dict:
    """A rung's results keyed by the fraction as a float (JSON keys are strings)."""
    return {float(k): v for k, v in row.items()}


def markdown(res: dict) -> str:
    fr = [f for f in res["fractions"] if f != 0]
    head = ["material", "map", "spp", "rel. RMSE, full luminance"] + [f"variance ratio at {f:g}" for f in fr] \
        + [f"time ratio at {f:g}" for f in fr]
    L = [f"{res['machine']}, {res['date']}; {res['resolution']}², {res['pairs']} seed pairs, "
         f"{res['threads']} threads, `{res['command']}`", "",
         "| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for c in res["cases"]:
        for spp, row in c["spp"].items():
            row = _by_fraction(row)
            base = row[0.0]
            L.append(f"| {c['material']} | {c['map']} | {spp} | {base['rel_rmse']:.4f} | "
                     + " | ".join(f"{(base['rel_rmse'] / row[f]['rel_rmse']) ** 2:.2f}" for f in fr) + " | "
                     + " | ".join(f"{row[f]['seconds'] / base['seconds']:.2f}" for f in fr) + " |")
    L += ["", "Geometric mean of the variance ratios per map and fraction (all spp):", "",
          "| map | " + " | ".join(f"{f:g}" for f in fr) + " |", "|" + " --- |" * (len(fr) + 1)]
    for mp in res["maps"]:
        vals = []
        for f in fr:
            r = [(row[0.0]["rel_rmse"] / row[f]["rel_rmse"]) ** 2
                 for c in res["cases"] if c["map"] == mp for row in map(_by_fraction, c["spp"].values())]
            vals.append(math.exp(sum(map(math.log, r)) / len(r)) if r else float("nan"))
        L.append(f"| {mp} | " + " | ".join(f"{v:.2f}" for v in vals) + " |")
    return "\n".join(L)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_mis_compensation",
                                 description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="+", default=list(MATERIALS),
                    help="RGL file stems, or lambert (default: eight of the shared files)")
    ap.add_argument("--maps", nargs="+", default=list(MAPS), choices=list(MAPS))
    ap.add_argument("--fractions", type=float, nargs="+", default=[0.0, 0.25, 0.5, 1.0],
                    help="compensation fractions in [0, 1]; 0 (the reference) is always added")
    ap.add_argument("--spp", type=int, nargs="+", default=[16, 64])
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--pairs", type=int, default=3, help="seed pairs per rung (median)")
    ap.add_argument("--threads", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--docs", action="store_true", help=f"write the table between the markers of {DOCS.name}")
    ap.add_argument("--quick", action="store_true", help="tiny renders (a smoke test; no numbers worth reading)")
    a = ap.parse_args(argv)
    if any(not 0.0 <= f <= 1.0 for f in a.fractions):
        ap.error(f"--fractions {a.fractions}: expected numbers in [0, 1]")
    if a.resolution < 8 or a.pairs < 1 or min(a.spp) < 1:
        ap.error("--resolution >= 8, --pairs >= 1 and positive --spp expected")
    if a.quick:
        a.resolution, a.spp, a.pairs = 16, [4], 1
    fractions = sorted(set([0.0] + a.fractions))
    from benchmarks.bench_eval import machine
    from warp_rbrdf.runtime import init_warp

    init_warp()
    env_dir = require_data_root("bench_mis_compensation") / "envmaps"
    m = machine()
    res = {"machine": f"{m['cpu']}, {m['cores']} cores, Warp {m['warp']}",
           "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
           "command": "python -m benchmarks.bench_mis_compensation " + " ".join(argv if argv is not None else sys.argv[1:]),
           "resolution": a.resolution, "pairs": a.pairs, "threads": a.threads, "fractions": fractions,
           "maps": a.maps, "cases": []}
    for mp in a.maps:
        for mat in a.materials:
            t0 = time.perf_counter()
            r = run_case(mat, env_dir / MAPS[mp], fractions, a.spp, a.resolution, a.pairs, a.threads)
            res["cases"].append({"material": mat, "map": mp, "spp": r})
            for spp, row in r.items():
                print(f"{mat:24s} {mp:10s} {spp:5d} spp: " + "  ".join(
                    f"{f:g}: {v['rel_rmse']:.4f}" for f, v in row.items()) + f"  ({time.perf_counter() - t0:.0f} s)",
                    flush=True)
    text = markdown(res)
    print(text)
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps(res, indent=1))
    if a.docs:
        doc = DOCS.read_text()
        i, j = doc.index(MARK[0]), doc.index(MARK[1])
        DOCS.write_text(doc[:i] + MARK[0] + "\n" + text + "\n" + doc[j:])
    return 0


if __name__ == "__main__":
    sys.exit(main())
