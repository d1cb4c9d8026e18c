"""``rbrdf-fit batch INPUTS... --out DIR``: fit a whole database on dask.distributed
(:func:`fit.batch.runner.fit_database`), with the BRDF flags of ``rbrdf-fit brdf`` (the fit's
own inverse CDFs stored in each BRDF output unless ``--no-sampler``, bounded by
``--sampler-time-limit``, as there) and the table flags of ``rbrdf-fit cdf`` and their
defaults. Registered by :mod:`fit.cli`.

Progress: one line per stage and per material finished on stdout (``batch: [done/total] ...;
elapsed ..., about ... left``, :mod:`fit.batch.progress`), also without a terminal; on a
terminal a tqdm bar over the materials on stderr too. ``--quiet``: the summary only.

Exit status: 0 when every material's outputs are done (or were done before), 1 when at least
one material failed (listed in the summary and the report; the others are written), 2 for bad
arguments (one line, nothing fitted), 130 on Ctrl-C (tasks in flight cancelled, no file
half-written; a re-run resumes).
"""
from __future__ import annotations

import sys

from ..errors import FlagError, display_path, display_text
from ..limits import (
    MAX_CDF_PHI_CELLS,
    MAX_CDF_ROWS,
    MAX_CDF_THETA_CELLS,
    MAX_FIT_DEGREE,
    MAX_FIT_DEN_DEGREE,
    MAX_FLOOR_FRAC,
    MAX_REFINEMENTS,
    MAX_TIME_LIMIT_S,
    MAX_TOLERANCE,
    MIN_CORE_THETA_D_DEG,
    MIN_TOLERANCE,
)
from ..rational.brdf_fit import INTERVALS
from ..rational.domain import THETA_D_MAX_DEG
from .cdf import add_sampler_flags
from .flags import core_angle, integer, number

MAX_TOLERANCES = 16
MAX_WORKERS = 1024


def _cmd_batch(args) -> int:
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise FlagError("batch", "needs dask.distributed: pip install 'warp-rbrdf[batch]'") from None
    from ..batch.runner import fit_database

    if len(args.tol) > MAX_TOLERANCES:
        raise FlagError("--tol", f"{len(args.tol)} tolerances, at most {MAX_TOLERANCES}")
    brdf = {"intervals": args.intervals, "core_theta_d_deg": args.core_theta_d, "band_intervals": args.band_intervals,
                "theta_h_transform": args.theta_h, "value_transform": args.value, "floor_frac": args.floor_frac,
                "max_degree": args.max_degree, "max_den_degree": args.max_den_degree}
    cdf = {"n_v": args.n_v, "n_t": args.n_t, "n_p": args.n_p, "eps": args.eps, "incident": args.incident, "layout": args.layout,
               "refinements": args.refinements, "time_limit_s": None if args.time_limit <= 0 else args.time_limit}
    if not args.no_cdf:
        from ..sampling.table import check_table_size

        try:
            check_table_size(args.n_v, args.n_t, args.n_p)
        except ValueError as e:
            raise FlagError("--n-v/--n-t/--n-p", str(e)) from None
    try:
        tty = sys.stdout.isatty()
    except (AttributeError, ValueError):
        tty = False
    try:
        report = fit_database(args.inputs, args.out, tols=args.tol, cdf=not args.no_cdf, brdf_options=brdf,
                              cdf_options=cdf, sampler=not args.no_sampler,
                              sampler_time_limit_s=None if args.sampler_time_limit <= 0 else args.sampler_time_limit,
                              workers=args.workers, scheduler=args.scheduler,
                              report_only=args.report_only, progress=tty and not args.quiet,
                              on_progress=None if args.quiet else
                              (lambda e: print(display_text(e.line()), flush=True)))
    except KeyboardInterrupt:
        print("rbrdf-fit batch: interrupted: the materials finished are kept, the tasks in flight were "
              "cancelled (no file half-written); run the same command again to resume", file=sys.stderr)
        return 130
    c = report.counts
    failed = report.failed()
    print(f"{len(report)} rows; outputs done {c.get('done', 0)}, skipped (done before) {c.get('skipped', 0)}, "
          f"failed {c.get('failed', 0)}" + (f", missing {c['missing']}" if "missing" in c else "")
          + f"; {report.wall_s:.1f} s"
          + (f" on {report.workers} workers" if report.workers else ""))
    for r in failed:
        print(f"FAILED: {display_text(r['material'])} (tol {r['tol']}): {display_text(r['error'])}", file=sys.stderr)
    print(f"wrote {display_path(args.out)}/report.csv, report.md, report_coefficients.png")
    return 1 if failed else 0


def register(sub) -> None:
    """Add ``batch`` to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "batch", help="fit a whole database (BRDF + inverse CDFs per material) on dask; resumable; report",
        description="Fit every material of INPUTS (files, folders, glob patterns) -- the BRDF at each "
                    "tolerance (as rbrdf-fit brdf) and its inverse CDFs (as rbrdf-fit cdf) -- each material "
                    "an independent task on dask.distributed: a local cluster of single-threaded worker "
                    "processes (one per core) unless --scheduler names a running one. Outputs go to "
                    "OUT/MATERIAL/, keyed by the content hash of the input and the options, each with a "
                    "manifest: a re-run skips what is done, an interrupted run loses only the tasks in "
                    "flight. A material that fails is reported and does not stop the others. Writes "
                    "OUT/report.csv, OUT/report.md and OUT/report_coefficients.png. A fit that misses "
                    "its tolerance on the core is written flagged (as --allow-infeasible) and reported.")
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="MERL .binary / RGL .bsdf files, folders or globs")
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--tol", type=number(MIN_TOLERANCE, MAX_TOLERANCE), nargs="+", default=[0.05], metavar="TOL",
                   help=f"relative tolerance(s) in [{MIN_TOLERANCE:g}, {MAX_TOLERANCE:g}] (default 0.05); one "
                        "BRDF fit per material and tolerance")
    p.add_argument("--workers", type=integer(1, MAX_WORKERS), default=None,
                   help="local worker processes (default: one per core), one thread each")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of a running dask scheduler, [tcp|tls|ws|wss://]HOST:PORT (e.g. tcp://10.0.0.5:8786), "
                        "instead of a local cluster; reached within 5 s, its first worker within 30 s; its "
                        "workers must import this fit package and see INPUTS and --out")
    p.add_argument("--no-cdf", dest="no_cdf", action="store_true", help="BRDF fits only, no inverse CDFs")
    p.add_argument("--report-only", dest="report_only", action="store_true",
                   help="fit nothing: write the report of the outputs already in --out (not done: 'missing')")
    p.add_argument("--quiet", action="store_true", help="no progress lines or bar (the summary only)")
    g = p.add_argument_group("BRDF fit (as rbrdf-fit brdf)")
    g.add_argument("--intervals", choices=INTERVALS, default="tol")
    g.add_argument("--core-theta-d", dest="core_theta_d", default="auto", metavar="DEG|auto",
                   type=core_angle(MIN_CORE_THETA_D_DEG, THETA_D_MAX_DEG))
    g.add_argument("--band-intervals", dest="band_intervals", choices=INTERVALS, default="tol")
    g.add_argument("--theta-h", dest="theta_h", choices=("sqrt", "identity"), default="sqrt")
    g.add_argument("--value", choices=("log", "linear"), default="log")
    g.add_argument("--floor-frac", dest="floor_frac", type=number(0.0, MAX_FLOOR_FRAC), default=1.0)
    g.add_argument("--max-degree", type=integer(0, MAX_FIT_DEGREE), default=12)
    g.add_argument("--max-den-degree", type=integer(0, MAX_FIT_DEN_DEGREE), default=6)
    add_sampler_flags(g)
    g = p.add_argument_group("inverse CDFs (as rbrdf-fit cdf)")
    g.add_argument("--n-v", type=integer(2, MAX_CDF_ROWS), default=32)
    g.add_argument("--n-t", type=integer(2, MAX_CDF_THETA_CELLS), default=64)
    g.add_argument("--n-p", type=integer(2, MAX_CDF_PHI_CELLS), default=64)
    g.add_argument("--eps", type=number(0.0, 1.0, lo_open=True), default=0.02)
    g.add_argument("--incident", choices=("view", "light"), default="view")
    g.add_argument("--layout", choices=("pieces", "global"), default="pieces")
    g.add_argument("--refinements", type=integer(0, MAX_REFINEMENTS), default=1)
    g.add_argument("--time-limit", type=number(0.0, MAX_TIME_LIMIT_S), default=180.0, metavar="S")
    p.set_defaults(func=_cmd_batch)
