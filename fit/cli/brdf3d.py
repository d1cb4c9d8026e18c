"""``rbrdf-fit brdf FILE.bsdf --model 3d --out material.json``: the 3-D rational fit of an RGL
``.bsdf`` measurement in (theta_h, theta_d, |phi_d|) (:func:`fit.rational.fit3d.fit_rgl_select`),
written as an ``rbrdf-rational`` version-4 coefficient file (version 3 with ``--value-factor
none``), with a per-piece, per-channel
summary table. :mod:`fit.cli.brdf` registers the flags (:func:`add_flags`) and calls :func:`run`
when the model is ``3d`` (``--model auto`` picks it for an RGL file).

What the flags set (:class:`fit.rational.settings.Fit3DSettings`; docs/fitting.md, "The 3-D
method"):

* ``--tol``: the first tolerance of the ladder (default :data:`TOL_3D`, the benchmark's); the
  bound the file states is the one met;
* ``--layout``: ``select`` (default: the three layouts of :data:`fit.rational.fit3d.VARIANTS`
  fitted, the seven pieces with ``--objective``, then one piece and the seven pieces with the relative
  objective, the two relative ones only below a validation RMSE of 0.065; the best by
  ``--select-by`` kept), ``pieces`` (seven theta_h pieces, 1,323 coefficients) or ``single`` (one
  piece of ``--degrees``, default (7, 3): 420 coefficients, with ``--objective``);
* ``--target-rmse R``: the coefficient count as the dial: the layouts of
  :data:`fit.rational.select3d.TARGET_LADDER` (one piece of 72 to 420 coefficients, then the seven
  pieces' 1,323) fitted cheapest first, the first whose validation RMSE is within ``R`` kept (none:
  the lowest); only with ``--layout select``;
* ``--time-limit S`` (default: none; 0: none): a wall-clock limit the user chooses, one
  :class:`fit.progress.Deadline` from the start of the command (reading the file included);
  what is left of it after reading is the fit's ``wall_limit`` (checked between steps: a step
  under way finishes): once passed, no further layout, refit or albedo round starts and the
  ladder squares its steps, and the file records ``fit_info["stopped"] = "time"``
  (``stopped_by`` ``"wall"``). A fit it stops depends on the machine's load. Without it, only
  the fit's safety net applies (``time_limit``, :data:`DEFAULT_TIME_LIMIT` CPU seconds of the
  process, about 10x the largest fit: the same file and flags give the same coefficients on
  any load);
* ``--value-factor``: what the functions give: ``1/cos_theta_i`` (default: rho cos theta_i,
  which the evaluation divides by cos theta_i, finite where the RGL data grow as 1 / cos theta_i
  towards the light's horizon; a version-4 file) or ``none`` (rho itself; a version-3 file);
* ``--grid``, ``--random``, ``--verify``, ``--no-albedo``: the data grid, the random points of
  each kind, the fresh points of the verification and the directional-albedo policy;
* ``--proof-rounds``: the refits of the proof-guided refit (default 4; 0: none). Every fit's
  file records the proof of its error between the grid nodes per piece and channel, in the unit
  of its stated bound (the table's ``proved`` column).

There is no seed: every random draw of a 3-D fit has a fixed seed, so the same file and flags
give the same coefficients, bit for bit (docs/fitting.md, "Budgets").

A fit is written only when every function is valid (within its stated bound at every data
point, Q > 0 certified): what the renderer shows of it is then the file alone, each function
clamped to its vouched range, with no table to stand in anywhere (a 2-D fit's flagged pieces
carry their projected table instead, :mod:`fit.rational.fallback`). Otherwise the command
writes nothing and exits with status 1 (``--allow-infeasible`` is a 2-D flag).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..errors import BRDFFileError, FlagError, display_path, display_text
from ..limits import MAX_FIT_DEGREE, MAX_TIME_LIMIT_S
from ..outputs import OutputSet
from ..progress import one_step
from ..rational.coefficient_file import save
from ..rational.fit3d import (
    DEFAULT_GRID,
    DEFAULT_RANDOM,
    DEFAULT_TIME_LIMIT,
    DEFAULT_VERIFY,
    OBJECTIVES,
    SELECTION_KEYS,
    TARGET_LADDER,
    VARIANTS,
    Fit3DSettings,
    fit_rgl_select,
)
from ..rational.model import VALUE_FACTORS
from ..rational.settings import SELECT_BY
from .cdf import attach_sampler
from .flags import integer, number

#: The first tolerance of the 3-D ladder when ``--tol`` is not given: the benchmark's
#: (docs/fit_accuracy.md), whose fits the accuracy table measures.
TOL_3D = 0.01
#: ``--layout``: the layouts fitted (:data:`fit.rational.fit3d.VARIANTS`; ``single`` with ``--degrees``).
LAYOUTS = ("select", "pieces", "single")
#: The flags of the 3-D fit (argparse destinations), refused with ``--model 2d``.
FLAGS = {"layout": "--layout", "degrees": "--degrees", "target_rmse": "--target-rmse", "time_limit": "--time-limit",
         "grid": "--grid",
         "n_random": "--random", "verify": "--verify", "no_albedo": "--no-albedo", "objective": "--objective",
         "select_by": "--select-by", "value_factor": "--value-factor", "proof_rounds": "--proof-rounds"}
MAX_GRID = 200            # per dimension of --grid (8 million points at most)
MAX_POINTS = 1_000_000    # --random (each kind) and --verify


def integers(n: int, lo: int, hi: int, what: str):
    """Converter of ``n`` comma-separated integers in ``[lo, hi]`` (a tuple)."""
    one = integer(lo, hi)

    def convert(text: str) -> tuple:
        parts = text.split(",")
        if len(parts) != n:
            raise argparse.ArgumentTypeError(f"expected {what}, got {display_text(text)[:40]!r}")
        return tuple(one(p.strip()) for p in parts)

    convert.__name__ = what
    return convert


def add_flags(p) -> None:
    """The 3-D fit's flags on the ``brdf`` sub-parser ``p`` (defaults None: given or not)."""
    d = Fit3DSettings()
    g = p.add_argument_group("3-D fit (--model 3d; auto for an RGL .bsdf)")
    g.add_argument("--layout", choices=LAYOUTS, default=None,
                   help="select (default): seven theta_h pieces (1,323 coefficients) and, below a validation "
                        "RMSE of 0.065, one piece of degrees (7, 3) (420) and the seven pieces again, both fitted "
                        "to the relative objective, the best by --select-by kept; pieces: the seven pieces only; "
                        "single: one piece of --degrees only (both with --objective)")
    g.add_argument("--degrees", type=integers(2, 0, MAX_FIT_DEGREE, "NUM,DEN"), default=None, metavar="NUM,DEN",
                   help="total degrees of numerator and denominator of --layout single (default "
                        f"{','.join(map(str, VARIANTS[1]['degrees']))}; fewer coefficients, larger error)")
    g.add_argument("--target-rmse", dest="target_rmse", type=number(1e-6, 10.0), default=None, metavar="R",
                   help="the coefficient count as the dial: one piece of degrees (3,1), (4,2), (5,2), (6,3), "
                        "(7,3) (72 to 420 coefficients), then the seven pieces (1,323), fitted cheapest first; the "
                        "first whose validation RMSE (relative RMSE of rho cos cos at 20,000 held-out pairs) is "
                        "within R is kept, else the lowest. Fits up to six layouts where the default fits three")
    g.add_argument("--time-limit", dest="time_limit", type=number(0.0, MAX_TIME_LIMIT_S), default=None, metavar="S",
                   help="a wall-clock bound on the whole command in seconds, your choice (default: none; 0: "
                        "none): checked between the fit's steps (a step under way finishes); once passed, no "
                        "further layout, refit or albedo round starts, the tolerance ladder squares its steps, "
                        "and the file records it. A fit it stops depends on the machine's load. Without it "
                        f"the same file and flags give the same coefficients on any load: only a safety net of "
                        f"{DEFAULT_TIME_LIMIT:g} CPU seconds (about 10x the largest fit) ends a runaway")
    g.add_argument("--grid", type=integers(3, 2, MAX_GRID, "NH,ND,NP"), default=None, metavar="NH,ND,NP",
                   help=f"theta_h, theta_d, phi_d sizes of the data grid (default {','.join(map(str, DEFAULT_GRID))})")
    g.add_argument("--random", dest="n_random", type=integer(0, MAX_POINTS), default=None, metavar="N",
                   help=f"random data points of each kind: uniform in the variables and cosine-distributed "
                        f"pairs (default {DEFAULT_RANDOM})")
    g.add_argument("--verify", type=integer(0, MAX_POINTS), default=None, metavar="N",
                   help=f"fresh points the fit is checked at, the worst refitted (default {DEFAULT_VERIFY}; "
                        "0: none)")
    g.add_argument("--proof-rounds", dest="proof_rounds", type=integer(0, 10), default=None, metavar="N",
                   help=f"refits guided by the proof of the error between the grid nodes (default "
                        f"{d.proof_rounds}; 0: none): the cells where the proof finds the fit more than twice "
                        "outside its stated bound (spikes the fresh points miss) give data points, and the "
                        "functions outside their bound there are fitted again; the fit of the lowest proved "
                        "bound is kept. The file records the proof of the fit it holds per piece and channel. "
                        "docs/fit_accuracy.md, \"The proof-guided refit\"")
    g.add_argument("--objective", choices=OBJECTIVES, default=None,
                   help=f"what the second stage minimises and the layout selection compares (default "
                        f"{d.objective}): relative, the squared relative error of rho over cosine-distributed "
                        "pairs (dark regions count by their share of the value, as a colour difference sees "
                        "them); rho_cos_cos, the squared error of rho cos cos there (dominated by the "
                        "specular peak); blend, half each. docs/fitting.md, \"The second stage's objective\"")
    g.add_argument("--select-by", dest="select_by", choices=SELECT_BY, default=None,
                   help=f"what the layout selection compares (default {d.select_by}): validation, the held-out "
                        "error of --objective; image, the fitter's image check of each layout's fit (the ΔE2000 "
                        "of a sphere under generic lights against the measurement, mean + p99 / 3). "
                        "docs/fitting.md, \"The image check\"")
    g.add_argument("--value-factor", dest="value_factor", choices=VALUE_FACTORS, default=None,
                   help=f"what the functions give (default {d.value_factor}): 1/cos_theta_i, rho cos theta_i, "
                        "which the evaluation divides by cos theta_i (it stays finite where the RGL data grow as "
                        "1 / cos theta_i towards the light's horizon: the terminator under a small sun); a "
                        "version-4 file. none: rho itself, a version-3 file. docs/fitting.md, \"The light's cosine\"")
    g.add_argument("--no-albedo", dest="no_albedo", action="store_true", default=None,
                   help=f"no directional-albedo policy (default: channels outside {100 * d.albedo_tol:g} %% "
                        "refitted)")


def given(args) -> list:
    """The 3-D flags given on the command line (their names)."""
    return [flag for dest, flag in FLAGS.items() if getattr(args, dest, None) is not None]


def settings_from_args(args, wall_limit=None) -> tuple:
    """``(Fit3DSettings, layouts)`` of parsed flags; ``wall_limit``: the fit's wall-clock limit in
    seconds (None: none; :func:`run` gives it what is left of the command's ``--time-limit``); the
    CPU-time safety net is the settings' default."""
    layout = args.layout or "select"
    if args.degrees is not None and layout != "single":
        raise FlagError("--degrees", "sets the degrees of --layout single only")
    target = getattr(args, "target_rmse", None)
    if target is not None and layout != "select":
        raise FlagError("--target-rmse", f"chooses among the layouts of --layout select, not with --layout {layout}")
    d = Fit3DSettings()
    s = Fit3DSettings(tol=TOL_3D if args.tol is None else args.tol, wall_limit=wall_limit,
                      grid=d.grid if args.grid is None else tuple(args.grid),
                      n_random=d.n_random if args.n_random is None else args.n_random,
                      verify=d.verify if args.verify is None else args.verify,
                      proof_rounds=d.proof_rounds if getattr(args, "proof_rounds", None) is None else args.proof_rounds,
                      albedo=not args.no_albedo, target_rmse=target,
                      objective=d.objective if args.objective is None else args.objective,
                      select_by=d.select_by if args.select_by is None else args.select_by,
                      value_factor=d.value_factor if getattr(args, "value_factor", None) is None else args.value_factor)
    if layout == "select":
        return s, (VARIANTS if target is None else TARGET_LADDER)
    if layout == "pieces":
        return s, (VARIANTS[0],)
    single = {k: v for k, v in VARIANTS[1].items() if k not in SELECTION_KEYS}   # the only layout: always fitted
    single.pop("objective", None)             # the command's --objective
    if args.degrees is not None:
        single["degrees"] = tuple(args.degrees)
    return s, (single,)


def _layout_progress(progress, n: int):
    """``progress`` with the layout named in the stages of each layout's fit (``layout k/n:``)."""
    if progress is None:
        return None
    k = [0]

    def report(stage, done, total):
        if stage == "sampling the file" and done == 0:
            k[0] += 1
        if stage in ("sampling the file", "3-D fit") and n > 1:
            stage = f"layout {k[0]}/{n}: {stage}"
        progress(stage, done, total)

    return report


def run(args, out: Path, deadline) -> int:
    """The 3-D fit of ``args.file`` written to ``out`` (checked); ``deadline``: the command's
    :class:`fit.progress.Deadline`. Returns the exit status (0 written, 1 not valid)."""
    from ..formats.rgl import read_rgl

    if getattr(args, "allow_infeasible", False):
        raise FlagError("--allow-infeasible", "applies to --model 2d: a 3-D fit is written only when every "
                                              "function is within its bound (no table stands in for one that is not)")
    settings, layouts = settings_from_args(args, None)       # every flag checked before the file is read
    progress = getattr(args, "progress", None)
    with one_step(progress, "reading the file"):
        b = read_rgl(args.file)
    b.source = Path(args.file).name          # the source record names the file, as a 2-D fit's does
    left = deadline.left()                   # the rest of a --time-limit is the fit's wall-clock limit
    settings = settings.clone(wall_limit=None if left is None else max(left, 1e-3))
    try:
        res = fit_rgl_select(b, layouts, settings=settings, progress=_layout_progress(progress, len(layouts)))
    except RuntimeError as e:                # no layout valid
        print(f"rbrdf-fit brdf: {display_text(e)}; nothing written to {display_path(out)}", file=sys.stderr)
        return 1
    except ValueError as e:
        raise BRDFFileError(args.file, str(e)) from None
    sampler_line = attach_sampler(res.model, args, progress) if res.valid else ""
    if res.valid:
        with OutputSet() as outputs:
            save(res.model, outputs.stage(out))
            outputs.commit()
    _print_table(b.name, res, settings)
    if res.valid:
        if sampler_line:
            print(sampler_line)
        print(f"{res.summary()}; wrote {display_path(out)}")
        return 0
    sys.stdout.flush()
    print(f"rbrdf-fit brdf: {res.summary()}; a function is not within its bound: nothing written to "
          f"{display_path(out)}", file=sys.stderr)
    return 1


def _proved_line(dom: dict) -> str | None:
    """The proof's part of the summary line, from ``fit_info["domain"]``."""
    if dom.get("proved_at") != "grid cells":
        return None
    if dom.get("proved_bound") is None:
        return "between the grid nodes not proved (Q inconclusive on a cell)"
    return (f"between the grid nodes proved within {dom['proved_over_stated']:.3g} x the stated bound"
            + (" (within it)" if dom.get("proved") else ""))


def _print_table(name: str, res, settings) -> None:
    """The summary of a 3-D fit on stdout: the layout, then per piece and channel its degrees,
    coefficients, stated bound and RMS error (fractions of the error unit s), stage, Q > 0 and
    the error proved between the grid nodes (same unit; ``none``: Q inconclusive), then the
    verification, the proof and the albedo on one line."""
    info = res.model.fit_info
    layouts = info.get("variants") or []
    tried = ", ".join(f"{v['variant']}: {v.get('coefficients', '-')} coef, validation RMSE "
                      f"{v['validation_rmse']:.4g}" if "validation_rmse" in v else f"{v['variant']}: {v['skipped']}"
                      for v in layouts)
    print(f"{display_text(name)}: 3-D (theta_h, theta_d, |phi_d|), ladder from {settings.tol:g}, "
          f"{res.n_points} data points up to {info.get('theta_max_deg', 0):.4g} deg; layouts {tried}")
    proved = {(int(b["piece"]), b["channel"]): b["proved"] for b in info.get("bound") or []}
    print(f"{'theta_h deg':14s}{'ch':>3s}{'degrees':>9s}{'coefs':>7s}{'bound':>9s}{'rms':>8s}"
          f"{'stage':>11s}{'Q>0':>5s}" + (f"{'proved':>10s}" if proved else ""))
    pieces = getattr(res.model, "pieces", None) or [res.model]
    for k, leaf in enumerate(pieces):
        lo, hi = np.degrees(leaf.variables[0].domain)
        for ch, f, r in zip(leaf.outputs, leaf.functions, leaf.function_info):
            deg = r.get("degrees", ["?", "?"])
            pb = proved.get((k, ch), "-")
            print(f"{f'{lo:.3g}-{hi:.3g}':14s}{display_text(ch):>3s}{f'({deg[0]},{deg[1]})':>9s}"
                  f"{f.n_coefficients:7d}{100 * r['tolerance']:8.2f}%{100 * r['rms_rel_error']:7.2f}%"
                  f"{r['stage']['kind']:>11s}{'yes' if r['q_certificate']['certified'] else 'NO':>5s}"
                  + ((f"{'none':>10s}" if pb is None else f"{'-':>10s}" if pb == "-" else f"{100 * pb:9.3g}%")
                     if proved else ""))
    ratio = info.get("verify_max_ratio")
    alb = info.get("albedo") or {}
    parts = [f"validation RMSE {res.validation_rmse:.4g}" if res.validation_rmse is not None else None,
             (f"largest error at {info.get('verify_points')} fresh points {ratio:.3g} x the bound"
              if ratio is not None else "no verification"),
             _proved_line(info.get("domain") or {}),
             (f"directional albedo within {100 * alb['tol']:g} %" if alb.get("within") else
              f"directional albedo off by up to {100 * alb['max_error']:.3g} %") if alb else "no albedo policy",
             "time limit reached" if info.get("stopped") == "time" else None]
    img = info.get("image_check")
    if img:
        parts.insert(1, f"image ΔE2000 mean {img['mean']:.2f}, p99 {img['p99']:.2f} (a sphere under generic lights, "
                        "against the measurement)")
    tgt = info.get("target")
    if tgt:
        parts.insert(1, f"target validation RMSE {tgt['rmse']:g} " + ("met" if tgt["met"] else "not met (the lowest kept)")
                     + f" with {tgt['coefficients']} coefficients")
    print("; ".join(p for p in parts if p))
