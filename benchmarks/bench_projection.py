"""Benchmark: projection of one measured BRDF onto (theta_h, theta_d), on one core.

    python -m benchmarks.bench_projection [FILE ...] [--repeats 7]

Without files it uses an exact-layout MERL file written from an analytic glossy lobe, plus
every RGL material found under $RBRDF_DATA/rgl (resampled once; resampling is not timed here).
Prints the median and min of the projection time per statistic. Target: <= 1 s per material.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]

from fit.formats import load_measured  # noqa: E402
from fit.formats.measured import MeasuredBRDF  # noqa: E402
from fit.formats.merl import write_merl  # noqa: E402
from fit.projection.project import project  # noqa: E402
from fit.projection.projected import STATISTICS  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_projection", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="*")
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args(argv)
    files = list(args.files)
    if not files:
        from lab.analytic import glossy_lobe

        tmp = Path(tempfile.mkdtemp()) / "analytic_glossy.binary"
        write_merl(MeasuredBRDF.from_function(glossy_lobe(phi_mod=0.3), name="analytic_glossy"), tmp)
        files.append(str(tmp))
        data = Path(os.environ.get("RBRDF_DATA", ROOT.parent / "shared" / "data")) / "rgl"
        files += sorted(str(p) for p in data.glob("*.bsdf"))
    print(f"{'material':28s} {'statistic':10s} {'median s':>9s} {'min s':>8s}")
    for f in files:
        try:
            b = load_measured(f)
        except Exception as e:  # a reader not available yet, or a bad file
            print(f"{Path(f).name:28s} skipped: {e}")
            continue
        for stat in STATISTICS:
            times = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                project(b, statistic=stat)
                times.append(time.perf_counter() - t)
            print(f"{b.name[:28]:28s} {stat:10s} {statistics.median(times):9.3f} {min(times):8.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
