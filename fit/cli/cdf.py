"""``rbrdf-fit cdf`` and ``rbrdf-fit plot-cdf``: importance-sampling tables and rational inverse
CDFs (issue 6, :mod:`fit.sampling`). Registered by :mod:`fit.cli`."""
from __future__ import annotations

from pathlib import Path

from ..formats import load_measured
from ..sampling.cdf_file import LAYOUTS, TIME_LIMIT_S, file_source, fit_cdf, load, table_only
from ..sampling.plots import plot_cdf


def _load_or_fit(args, log=print):
    path = Path(args.file)
    if path.suffix.lower() == ".json":
        return load(path)
    incident = getattr(args, "incident", "view")
    b = load_measured(path, incident=incident)
    params = dict(n_v=args.n_v, n_t=args.n_t, n_p=args.n_p, eps=args.eps)
    source = file_source(path)
    if path.suffix.lower() == ".bsdf":   # the tables depend on the roles of an RGL file
        source["incident"] = incident
    if getattr(args, "table_only", False):
        return table_only(b.evaluate, params, reason="table only (--table-only)", name=b.name,
                          source=source)
    return fit_cdf(b.evaluate, name=b.name, table_params=params, log=log, layout=args.layout,
                   refinements=args.refinements, source=source,
                   time_limit_s=None if args.time_limit <= 0 else args.time_limit)


def _add_table_args(p):
    p.add_argument("--n-v", type=int, default=32, help="theta_v rows (default 32)")
    p.add_argument("--n-t", type=int, default=64, help="theta_l cells (default 64)")
    p.add_argument("--n-p", type=int, default=64, help="|phi_l| cells (default 64)")
    p.add_argument("--eps", type=float, default=0.02, help="cosine mixture weight (default 0.02)")
    p.add_argument("--incident", choices=("view", "light"), default="view",
                   help="RGL .bsdf files: which direction is the tensors' theta_i (default: view, "
                        "as Mitsuba 3 and pbrt-v4 read them; must match the scene's `incident`)")
    p.add_argument("--layout", choices=LAYOUTS, default="pieces",
                   help="pieces (default): monotone rational-quadratic pieces uniform in mu and u, "
                        "constant-time lookup, the fastest sampler; global: the paper's "
                        "bivariate/trivariate rational functions")
    p.add_argument("--refinements", type=int, default=1, help="refit rounds when verification fails "
                                                               "(global layout)")
    p.add_argument("--table-only", action="store_true", help="tabulate only, no rational fit")
    p.add_argument("--time-limit", type=float, default=TIME_LIMIT_S, metavar="S",
                   help=f"bound on the rational fitting time in seconds (default {TIME_LIMIT_S:g}; 0: none); "
                        "what is not verified by then falls back to the tabulated sampler, with the reason")


def _cmd_cdf(args) -> int:
    fit = _load_or_fit(args)
    fit.save(args.out)
    if fit.fallback:
        print(f"FALLBACK: {fit.name}: rational inverse CDFs not usable ({fit.reason}); "
              f"renderers use the tabulated sampler")
    else:
        print(f"{fit.name}: rational inverse CDFs verified ({fit.reason})")
    print(f"wrote {args.out}")
    return 0


def _cmd_plot(args) -> int:
    args.table_only = args.table_only or Path(args.file).suffix.lower() != ".json"
    fit = _load_or_fit(args)
    for f in plot_cdf(fit, args.out, prefix=args.prefix):
        print(f"wrote {f}")
    return 0


def register(sub) -> None:
    """Add ``cdf`` and ``plot-cdf`` to the sub-parsers ``sub``."""
    p = sub.add_parser("cdf", help="tabulate the sampling CDFs and fit rational inverse CDFs",
                       description="Tabulate CDF^-1 of rho cos (luminance) per theta_v row, build the "
                                   "rational inverse CDFs (default layout 'pieces': per view row, monotone "
                                   "rational-quadratic pieces of equal mass, found in constant time; "
                                   "'global': fitted with the interval rational fitter), verify "
                                   "them (monotone, covering, no poles), send rows that fail or whose "
                                   "derivative estimator exceeds 1.2x the table's variance to the table, "
                                   "and write a versioned rbrdf-cdf JSON (fallback flag and per-row "
                                   "reasons included).")
    p.add_argument("file", help="MERL .binary or RGL .bsdf file")
    p.add_argument("--out", required=True, help="output .json")
    _add_table_args(p)
    p.set_defaults(func=_cmd_cdf)
    p = sub.add_parser("plot-cdf", help="plot PDF_v / CDF^-1_v (tabulated, and rational if verified)",
                       description="PNG plots of PDF_v(theta_l), CDF^-1_v(mu) at theta_v = 0/45/85 deg "
                                   "and slices of PDF_v(phi_l | theta_l), CDF^-1_v(tau | theta_l). FILE "
                                   "is a BRDF file (table only) or an rbrdf-cdf .json (with the fit).")
    p.add_argument("file")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--prefix", default="cdf")
    _add_table_args(p)
    p.set_defaults(func=_cmd_plot)
