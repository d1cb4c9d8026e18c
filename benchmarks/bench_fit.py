"""Benchmark of the rational BRDF fitter.

For each material and tolerance: fit time of the three channels (median of --repeat runs, one
core), coefficient counts, max / RMS relative error; a coefficients-vs-tolerance chart; and the
evaluation throughput of a fitted model (NumPy, points per second, median of 5).

    python benchmarks/bench_fit.py --materials satin_rosaline_rgb paper_white_rgb \
        --tols 0.01 0.05 0.1 --chart docs/images/fit_coefficients_vs_tol.png
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
sys.path.insert(0, str(ROOT))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=os.environ.get("RBRDF_DATA", str(ROOT.parent / "shared" / "data")))
    ap.add_argument("--materials", nargs="+", default=["paper_white_rgb", "satin_rosaline_rgb"])
    ap.add_argument("--tols", nargs="+", type=float, default=[0.01, 0.05, 0.1])
    ap.add_argument("--intervals", default="tol+spread", choices=("tol", "tol+spread"))
    ap.add_argument("--value", default="log", choices=("log", "linear"))
    ap.add_argument("--theta-h", default="sqrt", choices=("sqrt", "identity"))
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--chart", default=None, help="PNG of coefficients vs tolerance")
    ap.add_argument("--json", default=None, help="write all rows as JSON")
    args = ap.parse_args(argv)

    from fit.brdf_fit import fit_brdf
    from fit.io import load_measured

    rows = []
    model = None
    print("| material | tol | coefficients (R/G/B) | max rel. error | RMS rel. error | guaranteed | fit time (s, 3 ch.) |")
    print("|---|---|---|---|---|---|---|")
    for mat in args.materials:
        b = load_measured(Path(args.data) / "rgl" / f"{mat}.bsdf")
        for tol in args.tols:
            times = []
            for _ in range(args.repeat):
                fit = fit_brdf(b, tol=tol, intervals=args.intervals, value_transform=args.value,
                               theta_h_transform=args.theta_h)
                times.append(fit.time_s)
            model = fit.model
            row = {"material": mat, "tol": tol, "n_coef": [r.n_coefficients for r in fit.results],
                   "max_rel": max(e["max_rel_error"] for e in fit.errors),
                   "rms_rel": max(e["rms_rel_error"] for e in fit.errors),
                   "valid": fit.valid, "time_s": statistics.median(times)}
            rows.append(row)
            print(f"| {mat} | {tol:g} | {'/'.join(map(str, row['n_coef']))} | {100 * row['max_rel']:.1f} % | "
                  f"{100 * row['rms_rel']:.2f} % | {'yes' if row['valid'] else 'no'} | {row['time_s']:.1f} |",
                  flush=True)
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
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(5, 3.5), dpi=120)
        for mat in args.materials:
            r = [x for x in rows if x["material"] == mat]
            ax.plot([x["tol"] * 100 for x in r], [sum(x["n_coef"]) for x in r], "o-", label=mat)
        ax.set_xlabel("relative tolerance (%)")
        ax.set_ylabel("coefficients (R+G+B)")
        ax.set_xscale("log")
        ax.legend(fontsize=7)
        ax.set_title(f"Rational BRDF fit ({args.intervals}, {args.value} value, {args.theta_h} theta_h)", fontsize=8)
        fig.tight_layout()
        Path(args.chart).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(args.chart)
        print(f"wrote {args.chart}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
