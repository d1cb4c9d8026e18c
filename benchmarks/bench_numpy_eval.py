"""Benchmark: the fitter's NumPy evaluation of rational fits, the series without a basis matrix
(:func:`fit.rational.basis.chebyshev_series`, what ``RationalFunction.numerator`` /
``denominator`` use) against the basis matrix times the coefficients
(``chebyshev_basis(x, E, domain) @ coef``), side by side in one process.

Rows:

* ``P and Q, N points``: every function of each shipped 2-D fit (``warp_rbrdf/data/*.json``)
  evaluated at ``--points`` random points of its domain, numerator and denominator, both ways;
  the largest difference of R = P / Q between the two, relative to the function's largest
  value, is printed (rounding only);
* ``tabulate``: :func:`fit.sampling.table.tabulate` of each fit (the inverse-CDF table the
  renderer makes at load for a ``rational`` material without a sampler or ``cdf``; 32 x 64 x
  64 cells, 3 x 3 points each), ``RationalFunction.numerator`` / ``denominator`` switched
  between the two forms; the largest difference of the two tables' CDFs is printed.

One thread for BLAS (``OPENBLAS_NUM_THREADS`` etc. set to 1 before NumPy loads, unless set);
CPU seconds of the process, the two forms timed in turn, round by round (``--repeats``), each
row the median over rounds. The machine is shared: compare the two forms within one run.

    python -m benchmarks.bench_numpy_eval [--points 200000] [--repeats 3] [--no-tabulate] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
FITS = sorted((ROOT / "warp_rbrdf" / "data").glob("*_rgb.json"))


def _basis_form(f, x):
    from fit.rational.basis import chebyshev_basis

    return (chebyshev_basis(x, f.num_exponents, f.domain) @ f.num_coef,
            chebyshev_basis(x, f.den_exponents, f.domain) @ f.den_coef)


def _series_form(f, x):
    return f.numerator(x), f.denominator(x)


def _cpu(fn):
    t0 = time.process_time()
    out = fn()
    return time.process_time() - t0, out


class _BasisMatrixForm:
    """``RationalFunction.numerator`` / ``denominator`` through the basis matrix while active."""

    def __enter__(self):
        from fit.rational.function import RationalFunction

        self.saved = RationalFunction.numerator, RationalFunction.denominator
        RationalFunction.numerator = lambda f, x: _basis_form(f, x)[0]
        RationalFunction.denominator = lambda f, x: _basis_form(f, x)[1]

    def __exit__(self, *exc):
        from fit.rational.function import RationalFunction

        RationalFunction.numerator, RationalFunction.denominator = self.saved


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_numpy_eval", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=200_000, help="points per function (default 200000)")
    ap.add_argument("--repeats", type=int, default=3, help="rounds; each row is the median (default 3)")
    ap.add_argument("--no-tabulate", action="store_true", help="skip the tabulation rows")
    ap.add_argument("--json", type=Path, help="also write the rows to this JSON file")
    args = ap.parse_args(argv)
    if args.points < 1 or args.repeats < 1:
        ap.error("--points and --repeats must be at least 1")

    from fit.rational.coefficient_file import load
    from fit.sampling.table import tabulate
    from fit.sampling.model_sampler import vouched_evaluate

    rng = np.random.default_rng(0)
    rows = []
    for path in FITS:
        model = load(path)
        funcs = model.functions                 # every piece's, every channel
        terms = sum(len(f.num_coef) + len(f.den_coef) for f in funcs)
        xs = [f.domain[:, 0] + rng.random((args.points, f.n_vars)) * (f.domain[:, 1] - f.domain[:, 0])
              for f in funcs]
        times = {"basis matrix": [], "series": []}
        worst = 0.0
        for _ in range(args.repeats):
            for name, form in (("basis matrix", _basis_form), ("series", _series_form)):
                t, vals = _cpu(lambda form=form: [form(f, x) for f, x in zip(funcs, xs)])
                times[name].append(t)
                if name == "basis matrix":
                    ref = vals
                else:
                    for (p0, q0), (p1, q1) in zip(ref, vals):
                        r0, r1 = p0 / q0, p1 / q1
                        worst = max(worst, float(np.max(np.abs(r1 - r0)) / max(np.max(np.abs(r0)), 1e-300)))
        row = {"fit": path.name, "what": f"P and Q, {len(funcs)} functions, {terms} coefficients, "
                                         f"{args.points} points each",
               "basis_matrix_s": statistics.median(times["basis matrix"]),
               "series_s": statistics.median(times["series"]), "max_rel_diff": worst}
        rows.append(row)
        if not args.no_tabulate:
            evaluate = vouched_evaluate(model)
            times = {"basis matrix": [], "series": []}
            for _ in range(args.repeats):
                with _BasisMatrixForm():
                    t, a = _cpu(lambda: tabulate(evaluate))
                times["basis matrix"].append(t)
                t, b = _cpu(lambda: tabulate(evaluate))
                times["series"].append(t)
            diff = float(np.abs(np.asarray(a.cdf_phi) - np.asarray(b.cdf_phi)).max())
            rows.append({"fit": path.name, "what": "tabulate (32 x 64 x 64 cells)",
                         "basis_matrix_s": statistics.median(times["basis matrix"]),
                         "series_s": statistics.median(times["series"]), "max_rel_diff": diff})
    print(f"{'fit':28s} {'what':62s} {'basis matrix':>13s} {'series':>9s} {'speed-up':>9s} {'max diff':>9s}")
    for r in rows:
        print(f"{r['fit']:28s} {r['what']:62s} {r['basis_matrix_s']:11.3f} s {r['series_s']:7.3f} s "
              f"{r['basis_matrix_s'] / max(r['series_s'], 1e-9):8.1f}x {r['max_rel_diff']:9.1e}")
    print(json.dumps({"points": args.points, "repeats": args.repeats, "rows": rows}))
    if args.json:
        args.json.write_text(json.dumps({"points": args.points, "repeats": args.repeats, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
