"""Benchmark of the rational BRDF fitter.

For each material and tolerance: fit time of the three channels (median of --repeat runs; run
it under ``taskset -c 0`` for one core), coefficients, the guaranteed theta_d core, whether the
grazing band met its intervals, max / RMS relative error on the core; a coefficients-vs-tolerance
chart; and the evaluation throughput of a fitted model (NumPy, points per second, median of 5).
``--transforms`` instead compares the value / theta_h transforms (log or linear value, sqrt or
identity theta_h) at the first tolerance.

    taskset -c 0 python -m benchmarks.bench_fit --tols 0.01 0.05 0.1 \
        --chart docs/images/fit_coefficients_vs_tol.png --json results/bench_fit.json
    taskset -c 0 python -m benchmarks.bench_fit --tols 0.05 --transforms --json results/fit_transforms.json
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

ROOT = Path(__file__).resolve().parents[1]


def warp_throughput(model, n: int = 1_000_000) -> float:
    """Evaluations per second of the rational material's Warp evaluation (one launch, one
    CPU thread, median of 5, host<->device copies included)."""
    from fit.formats.angles import spherical_to_direction
    from lab import testing as T
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import MaterialSpec

    r = Renderer(T.plane_scene(MaterialSpec(name="m", type="rational", data=model), [T.constant_env(1.0)],
                               resolution=4, spp=1))
    rng = np.random.default_rng(1)
    wi = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    wo = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    r.eval_material("m", wi[:10], wo[:10])
    ts = []
    for _ in range(5):
        t0 = time.perf_counter()
        r.eval_material("m", wi, wo)
        ts.append(time.perf_counter() - t0)
    rate = n / statistics.median(ts)
    print(f"\nevaluation throughput (Warp CPU, one launch, RGB, {model.n_coefficients} coefficients): "
          f"{rate / 1e6:.2f} M evaluations/s (median of 5)")
    return rate


def plot(rows, path, what: str) -> None:
    """Coefficients (R+G+B, all pieces) against tolerance, one line per material; o: guaranteed
    core, x: not guaranteed."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.6), dpi=120)
    for mat in dict.fromkeys(x["material"] for x in rows):
        r = sorted((x for x in rows if x["material"] == mat), key=lambda x: x["tol"])
        line, = ax.plot([x["tol"] * 100 for x in r], [x["n_coef"] for x in r], "-", label=mat)
        for x in r:
            ax.plot(x["tol"] * 100, x["n_coef"], "o" if x["core_valid"] else "x", color=line.get_color())
    ax.set_xlabel("relative tolerance (%)")
    ax.set_ylabel("coefficients (R+G+B, all pieces)")
    ax.set_xscale("log")
    ax.legend(fontsize=6)
    ax.set_title(f"Rational BRDF fits ({what}; o guaranteed, x not)", fontsize=7)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    print(f"wrote {path}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_fit", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=os.environ.get("RBRDF_DATA", str(ROOT.parent / "shared" / "data")))
    ap.add_argument("--materials", nargs="+", default=["paper_white_rgb", "satin_rosaline_rgb",
                    "colodur_napoli_4f_rgb", "vch_golden_yellow_rgb", "cc_ibiza_sunset_rgb",
                    "cc_iris_purple_gem_rgb"])
    ap.add_argument("--tols", nargs="+", type=float, default=[0.01, 0.05, 0.1])
    ap.add_argument("--intervals", default="tol", choices=("tol", "tol+spread"), help="core intervals")
    ap.add_argument("--value", default="log", choices=("log", "linear"))
    ap.add_argument("--theta-h", default="sqrt", choices=("sqrt", "identity"))
    ap.add_argument("--warp", action="store_true",
                    help="also time the Warp evaluation of the last model (CPU device, one thread)")
    ap.add_argument("--transforms", action="store_true",
                    help="compare log/linear value x sqrt/identity theta_h at the first tolerance")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--chart", default=None, help="PNG of coefficients vs tolerance")
    ap.add_argument("--json", default=None, help="write all rows as JSON")
    ap.add_argument("--plot", nargs="+", default=None, metavar="JSON",
                    help="only draw --chart from the rows of earlier --json files")
    args = ap.parse_args(argv)
    if args.plot:
        rows = [r for f in args.plot for r in json.loads(Path(f).read_text())]
        plot(rows, args.chart or "fit_coefficients_vs_tol.png", "log value, sqrt theta_h")
        return 0

    from fit.formats import load_measured
    from fit.rational.brdf_fit import fit_brdf

    rows = []
    model = None
    combos = ([(v, t) for v in ("log", "linear") for t in ("sqrt", "identity")] if args.transforms
              else [(args.value, args.theta_h)])
    tols = args.tols[:1] if args.transforms else args.tols
    print("| material | tol | value | theta_h | coefficients | guaranteed core (theta_d) | grazing band | "
          "max / RMS rel. error (core) | fit time (s, 3 ch.) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for mat in args.materials:
        b = load_measured(Path(args.data) / "rgl" / f"{mat}.bsdf")
        for tol in tols:
            for value, theta_h in combos:
                times = []
                for _ in range(args.repeat):
                    fit = fit_brdf(b, tol=tol, intervals=args.intervals, value_transform=value,
                                   theta_h_transform=theta_h)
                    times.append(fit.time_s)
                model = fit.model
                core = fit.pieces[0].theta_d_range_deg[1]
                row = {"material": mat, "tol": tol, "value": value, "theta_h": theta_h,
                       "n_coef": fit.n_coefficients,
                       "n_coef_pieces": [[r.n_coefficients for r in pc.results] for pc in fit.pieces],
                       "core_theta_d_deg": core, "core_valid": fit.valid,
                       "band_valid": fit.pieces[-1].valid if len(fit.pieces) > 1 else None,
                       "max_rel": max(e["max_rel_error"] for e in fit.errors),
                       "rms_rel": max(e["rms_rel_error"] for e in fit.errors),
                       "time_s": statistics.median(times)}
                rows.append(row)
                band = {None: "-", True: "met", False: "NOT met"}[row["band_valid"]]
                guar = f"0-{core:g} deg" if fit.valid else f"NOT met (tried down to {core:g} deg)"
                print(f"| {mat} | {tol:g} | {value} | {theta_h} | {row['n_coef']} | {guar} | {band} | "
                      f"{100 * row['max_rel']:.1f} / {100 * row['rms_rel']:.2f} % | {row['time_s']:.1f} |",
                      flush=True)
    if model is not None and args.warp:
        warp_throughput(model)
    if model is not None:
        rng = np.random.default_rng(0)
        n = 1_000_000
        th = rng.random(n) * np.pi / 2
        td = rng.random(n) * np.pi / 2
        ts = []
        for _ in range(5):
            t0 = time.perf_counter()
            model.evaluate_brdf(th, td)
            ts.append(time.perf_counter() - t0)
        print(f"\nevaluation throughput (NumPy, RGB, {model.n_coefficients} coefficients): "
              f"{n / statistics.median(ts) / 1e6:.2f} M evaluations/s (median of 5)")
    if args.chart:
        plot(rows, args.chart, f"{args.intervals} core, {args.value} value, {args.theta_h} theta_h")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
