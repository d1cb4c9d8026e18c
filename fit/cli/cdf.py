"""``rbrdf-fit cdf`` and ``rbrdf-fit plot-cdf``: importance-sampling tables and rational inverse
CDFs (:mod:`fit.sampling`). Registered by :mod:`fit.cli`.

The table flags are bounded (:mod:`fit.limits`: rows, cells and the estimated memory are
checked before anything is tabulated); outputs are written only when the run succeeds
(:class:`fit.outputs.OutputSet`). ``--time-limit S`` bounds the whole command: one
:class:`fit.progress.Deadline`, started with the command, is shared by reading, tabulating and
fitting; the table is always completed, and what is not verified when it runs out is sampled
with the table (the printed reason says so). Progress goes to stderr.

A rational fit (``rbrdf-rational`` .json) as the input makes the fit's own inverse CDFs from the
fit and writes the fit with them stored in it (:mod:`fit.sampling.embedded`); ``rbrdf-fit
brdf`` does the same at the end of every fit (:func:`attach_sampler`; ``--no-sampler``,
``--sampler-time-limit``: :func:`add_sampler_flags`)."""
from __future__ import annotations

from pathlib import Path

from ..errors import BRDFFileError, FlagError, display_path, display_text
from ..formats import load_measured
from ..limits import (
    MAX_CDF_PHI_CELLS,
    MAX_CDF_ROWS,
    MAX_CDF_THETA_CELLS,
    MAX_REFINEMENTS,
    MAX_TIME_LIMIT_S,
)
from ..outputs import OutputSet, check_output_dir, check_output_file
from ..progress import Deadline, one_step
from ..sampling.cdf_file import (
    LAYOUTS,
    TIME_LIMIT_S,
    check_pieces_size,
    file_source,
    fit_cdf,
    load,
    table_only,
)
from ..sampling.plots import plot_cdf
from ..sampling.table import check_table_size
from ..sampling.variance_gate import PIECES_DEFAULTS
from .flags import add_run_flags, file_prefix, integer, number


def _check_sizes(args) -> None:
    """The table (and pieces) the flags ask for fit the limits: checked before the input is read."""
    try:
        check_table_size(args.n_v, args.n_t, args.n_p)
        if args.layout == "pieces" and not getattr(args, "table_only", False):
            check_pieces_size(args.n_v, args.n_t, args.n_p, int(PIECES_DEFAULTS["n_mu"]),
                              int(max(PIECES_DEFAULTS["n_u"])))
    except ValueError as e:
        raise FlagError("--n-v/--n-t/--n-p", str(e)) from None


#: Default bound (s) on making the sampler a fit carries at the end of ``rbrdf-fit brdf``: 0,
#: none, so that the file written does not depend on the machine's load (a wall-clock bound
#: decides which view rows are verified rational and which are sampled with the table).
SAMPLER_TIME_LIMIT_S = 0.0


def add_sampler_flags(p) -> None:
    """``--no-sampler`` and ``--sampler-time-limit S`` on a fit command's parser ``p``."""
    p.add_argument("--no-sampler", dest="no_sampler", action="store_true",
                   help="do not store the fit's own inverse CDFs in the file (a renderer then "
                        "tabulates them at load; `rbrdf-fit cdf FIT.json --out FIT.json` adds them later)")
    p.add_argument("--sampler-time-limit", dest="sampler_time_limit", type=number(0.0, MAX_TIME_LIMIT_S),
                   default=SAMPLER_TIME_LIMIT_S, metavar="S",
                   help="a wall-clock bound on making the fit's inverse CDFs in seconds, your choice "
                        "(default: none; 0: none): the table is always completed; view rows not verified "
                        "by then are sampled with the table, so the file then depends on the machine's load")


def attach_sampler(model, args, progress=None) -> str:
    """Make the inverse CDFs of ``model`` from the fit itself and store them in it
    (:func:`fit.sampling.model_sampler.embed_sampler`) unless ``args.no_sampler``; returns the line
    the command prints ("" when skipped). A fit with nothing vouched to sample (a flagged fit
    without a fallback table) is written without one, and the line says so."""
    if getattr(args, "no_sampler", False):
        return ""
    from ..sampling.model_sampler import embed_sampler

    limit = getattr(args, "sampler_time_limit", SAMPLER_TIME_LIMIT_S)
    try:
        cdf = embed_sampler(model, time_limit_s=None if limit <= 0 else limit, progress=progress)
    except ValueError as e:
        return f"no sampler stored ({display_text(e)})"
    what = "table only" if cdf.fallback else "verified rational inverse CDFs"
    return f"sampler: {what} ({display_text(cdf.reason)}), stored in the fit"


def _is_fit_file(path: Path) -> bool:
    """True when ``path`` is an ``rbrdf-rational`` coefficient file (not an ``rbrdf-cdf`` file)."""
    from ..inputs import read_json
    from ..rational.coefficient_format import FORMAT as FIT_FORMAT

    d = read_json(path, "JSON file")
    return isinstance(d, dict) and d.get("format") == FIT_FORMAT


def _load_or_fit(args, log=print, deadline: Deadline | None = None):
    path = Path(args.file)
    if path.suffix.lower() == ".json":
        return load(path)
    progress = getattr(args, "progress", None)
    incident = getattr(args, "incident", "view")
    with one_step(progress, "reading the file"):
        b = load_measured(path, incident=incident)
    params = dict(n_v=args.n_v, n_t=args.n_t, n_p=args.n_p, eps=args.eps)
    source = file_source(path)
    if path.suffix.lower() == ".bsdf":   # the tables depend on the roles of an RGL file
        source["incident"] = incident
    if getattr(args, "table_only", False):
        return table_only(b.evaluate, params, reason="table only (--table-only)", name=b.name,
                          source=source, progress=progress)
    if deadline is None:
        deadline = Deadline(None if args.time_limit <= 0 else args.time_limit)
    return fit_cdf(b.evaluate, name=b.name, table_params=params, log=log, layout=args.layout,
                   refinements=args.refinements, source=source, deadline=deadline, progress=progress)


def _add_table_args(p):
    p.add_argument("--n-v", type=integer(2, MAX_CDF_ROWS), default=32,
                   help=f"theta_v rows, 2-{MAX_CDF_ROWS} (default 32)")
    p.add_argument("--n-t", type=integer(2, MAX_CDF_THETA_CELLS), default=64,
                   help=f"theta_l cells, 2-{MAX_CDF_THETA_CELLS} (default 64)")
    p.add_argument("--n-p", type=integer(2, MAX_CDF_PHI_CELLS), default=64,
                   help=f"|phi_l| cells, 2-{MAX_CDF_PHI_CELLS} (default 64; n_v x n_t x n_p is bounded too)")
    p.add_argument("--eps", type=number(0.0, 1.0, lo_open=True), default=0.02,
                   help="cosine mixture weight in (0, 1] (default 0.02)")
    p.add_argument("--incident", choices=("view", "light"), default="view",
                   help="RGL .bsdf files: which direction is the tensors' theta_i (default: view, "
                        "as Mitsuba 3 and pbrt-v4 read them; must match the scene's `incident`)")
    p.add_argument("--layout", choices=LAYOUTS, default="pieces",
                   help="pieces (default): monotone rational-quadratic pieces uniform in mu and u, "
                        "constant-time lookup, the fastest sampler; global: the paper's "
                        "bivariate/trivariate rational functions")
    p.add_argument("--refinements", type=integer(0, MAX_REFINEMENTS), default=1,
                   help=f"refit rounds when verification fails (global layout; 0-{MAX_REFINEMENTS})")
    p.add_argument("--table-only", action="store_true", help="tabulate only, no rational fit")
    p.add_argument("--time-limit", type=number(0.0, MAX_TIME_LIMIT_S), default=TIME_LIMIT_S, metavar="S",
                   help=f"bound on the whole command in seconds (default {TIME_LIMIT_S:g}; 0: none): the "
                        "table is always completed; what is not verified by then is sampled with the "
                        "table, with the reason")
    add_run_flags(p)


def _cmd_fit_sampler(args, out: Path, deadline: Deadline) -> int:
    """``rbrdf-fit cdf FIT.json --out OUT.json``: the fit with its own inverse CDFs stored in it
    (:mod:`fit.sampling.embedded`), made from the fit's vouched values with the default table
    and ``--layout``; ``--out`` may name the fit itself (replaced only on success)."""
    from ..rational.coefficient_file import load as load_fit
    from ..rational.coefficient_file import save as save_fit
    from ..sampling.model_sampler import embed_sampler

    if (args.n_v, args.n_t, args.n_p, args.eps) != (32, 64, 64, 0.02) or args.table_only:
        raise FlagError("--n-v/--n-t/--n-p/--eps/--table-only", "a fit's own sampler has the default table "
                                                                 "(the table a renderer would tabulate)")
    progress = getattr(args, "progress", None)
    with one_step(progress, "reading the file"):
        model = load_fit(args.file)
    try:
        cdf = embed_sampler(model, layout=args.layout, deadline=deadline, progress=progress, log=print)
    except ValueError as e:
        raise BRDFFileError(args.file, f"no sampler can be made from this fit ({e})") from None
    with OutputSet() as outputs:
        save_fit(model, outputs.stage(out))
        outputs.commit()
    name = display_text(model.name)
    what = "table only" if cdf.fallback else "rational inverse CDFs verified"
    print(f"{name}: {what} ({display_text(cdf.reason)}); stored in the fit")
    print(f"wrote {display_path(out)}")
    return 0


def _cmd_cdf(args) -> int:
    deadline = Deadline(None if args.time_limit <= 0 else args.time_limit)
    out = check_output_file(args.out, "--out", (".json",))
    _check_sizes(args)
    if Path(args.file).suffix.lower() == ".json" and _is_fit_file(Path(args.file)):
        return _cmd_fit_sampler(args, out, deadline)
    fit = _load_or_fit(args, deadline=deadline)
    with OutputSet() as outputs:
        fit.save(outputs.stage(out))
        outputs.commit()
    name = display_text(fit.name)
    if fit.fallback:
        print(f"FALLBACK: {name}: rational inverse CDFs not usable ({display_text(fit.reason)}); "
              f"renderers use the tabulated sampler")
    else:
        print(f"{name}: rational inverse CDFs verified ({display_text(fit.reason)})")
    if (fit.fit_info or {}).get("time_limit_reached"):
        print(f"time limit {args.time_limit:g} s reached (--time-limit): what was not verified by then "
              "is sampled with the table")
    print(f"wrote {display_path(out)}")
    return 0


def _cmd_plot(args) -> int:
    out = check_output_dir(args.out, "--out")
    args.table_only = args.table_only or Path(args.file).suffix.lower() != ".json"
    _check_sizes(args)
    if Path(args.file).suffix.lower() == ".json" and _is_fit_file(Path(args.file)):
        from ..sampling.embedded import load_file   # the sampler the fit carries

        fit = load_file(args.file)
    else:
        fit = _load_or_fit(args)
    with OutputSet() as outputs:
        plot_cdf(fit, out, prefix=args.prefix, outputs=outputs)
        files = outputs.commit()
    for f in files:
        print(f"wrote {display_path(f)}")
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
    p.add_argument("file", help="MERL .binary or RGL .bsdf file, or a rational fit .json (rbrdf-rational): "
                                "then --out is the fit with its own inverse CDFs stored in it (it may be the "
                                "fit itself)")
    p.add_argument("--out", required=True, help="output .json (replaced only if the run succeeds)")
    _add_table_args(p)
    p.set_defaults(func=_cmd_cdf)
    p = sub.add_parser("plot-cdf", help="plot PDF_v / CDF^-1_v (tabulated, and rational if verified)",
                       description="PNG plots of PDF_v(theta_l), CDF^-1_v(mu) at theta_v = 0/45/85 deg "
                                   "and slices of PDF_v(phi_l | theta_l), CDF^-1_v(tau | theta_l). FILE "
                                   "is a BRDF file (table only), an rbrdf-cdf .json (with the fit) or a "
                                   "rational fit .json carrying its own sampler (rbrdf-fit brdf, rbrdf-fit "
                                   "cdf FIT.json).")
    p.add_argument("file")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--prefix", default="cdf", type=file_prefix,
                   help="file-name prefix of the PNG files (default cdf)")
    _add_table_args(p)
    p.set_defaults(func=_cmd_plot)
