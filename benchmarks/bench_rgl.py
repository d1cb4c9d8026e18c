"""Benchmark of the RGL-EPFL reader (fit.formats.rgl) on one core, plus the per-material albedo table.

    python -m benchmarks.bench_rgl [FILE ...] [--n 1000000] [--repeats 5] [--thumbnails DIR]

Without files it uses every ``*.bsdf`` under $RBRDF_DATA/rgl (default ../shared/data/rgl).
For each material it prints the median (and min) over ``--repeats`` of

* the file read (parse + table construction),
* ``evaluate`` on ``--n`` random direction pairs in the upper hemisphere, as evaluations/s,
* ``to_measured`` (resampling at the bin centres of the full-circle MERL grid, 90 x 90 x 360
  = 2.916 M evaluations: RGL files are not reciprocal, so phi_d is not folded),

and the directional albedo (RGB) at theta_i = 0 and 60 deg. Targets: >= 1 M evaluations/s,
resample in a few seconds at most. With ``--thumbnails DIR`` it also writes
``DIR/rgl_<material>.png``: the median projection onto (theta_h, theta_d) as a tone-mapped RGB
image (x: theta_d 0 -> 90 deg, y: theta_h 0 (bottom) -> 90 deg (top) on the MERL sqrt-spaced
bins, 2 x 2 pixels per cluster; empty clusters dark grey).
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]

import numpy as np  # noqa: E402

from fit.formats.angles import spherical_to_direction  # noqa: E402
from fit.formats.rgl import read_rgl  # noqa: E402
from fit.projection.albedo import directional_albedo  # noqa: E402


def _timed(fn, repeats):
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), min(times), out


def _random_pairs(n, seed=0):
    rng = np.random.default_rng(seed)

    def dirs():
        return spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)

    return dirs(), dirs()


def write_thumbnail(measured, path, scale: int = 2) -> None:
    """Tone-mapped RGB image of the median projection (see the module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image as mpimg

    from fit.projection.project import project

    p = project(measured).value  # (theta_h, theta_d, 3), NaN where empty
    lum = p @ np.array([0.2126, 0.7152, 0.0722])
    ref = np.nanmedian(lum)
    # log tone curve relative to the median cluster; white = the 99th percentile (grazing
    # clusters, where rho = f cos / cos(theta_o) is ill-conditioned, saturate)
    top = np.nanpercentile(lum, 99.0)
    x = np.log1p(np.nan_to_num(p, nan=0.0) / (0.5 * ref)) / np.log1p(top / (0.5 * ref))
    x = np.clip(x, 0.0, 1.0)
    img = np.where(np.isnan(p), 0.15, x ** (1 / 2.2))
    img = img[::-1]  # theta_h = 0 at the bottom
    img = np.repeat(np.repeat(img, scale, axis=0), scale, axis=1)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    mpimg.imsave(str(path), img, metadata={"Description": f"{measured.name}: median projection "
                                           "over (theta_d -> x, theta_h -> y), log tone-mapped"})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_rgl", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="*")
    ap.add_argument("--n", type=int, default=1_000_000, help="direction pairs per evaluate() call")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--thumbnails", metavar="DIR", help="write rgl_<material>.png thumbnails here")
    args = ap.parse_args(argv)
    files = list(args.files)
    if not files:
        data = Path(os.environ.get("RBRDF_DATA", ROOT.parent / "shared" / "data")) / "rgl"
        files = sorted(str(p) for p in data.glob("*.bsdf"))
        if not files:
            print(f"no .bsdf files under {data} (set RBRDF_DATA)", file=sys.stderr)
            return 1
    wi, wo = _random_pairs(args.n)
    print(f"one core (OMP_NUM_THREADS={os.environ['OMP_NUM_THREADS']}), {args.n} random pairs, "
          f"median (min) of {args.repeats} repeats")
    print(f"{'material':24s} {'read s':>7s} {'eval s':>13s} {'Mevals/s':>9s} {'resample s':>13s}   "
          f"{'albedo 0 deg (R G B)':22s} {'albedo 60 deg (R G B)':22s} theta_i_max")
    rows = []
    for f in files:
        r_med, _, b = _timed(lambda: read_rgl(f), args.repeats)
        e_med, e_min, _ = _timed(lambda: b.evaluate(wi, wo), args.repeats)
        s_med, s_min, m = _timed(b.to_measured, args.repeats)
        a0 = directional_albedo(b.evaluate, 0.0)
        a60 = directional_albedo(b.evaluate, np.radians(60.0))
        rows.append((b, a0, a60))
        fmt = lambda a: " ".join(f"{v:.3f}" for v in a)  # noqa: E731
        print(f"{b.name[:24]:24s} {r_med:7.3f} {e_med:6.3f} ({e_min:5.3f}) {args.n / e_med / 1e6:9.2f} "
              f"{s_med:6.2f} ({s_min:5.2f})   {fmt(a0):22s} {fmt(a60):22s} "
              f"{np.degrees(b.theta_i_max):.1f} deg")
        if args.thumbnails:
            out = Path(args.thumbnails) / f"rgl_{b.name}.png"
            write_thumbnail(m, out)
            print(f"  wrote {out} ({out.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
