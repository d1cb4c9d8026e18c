"""``rbrdf-fit brdf FILE --out material.json``: rational fit of a measured BRDF, written as an
``rbrdf-rational`` coefficient file (:mod:`fit.rational.coefficient_file`), with a per-piece,
per-channel summary table. ``--model`` picks the fit:

* ``2d``: the (theta_h, theta_d) fit of the median projection within ``--tol``
  (:func:`fit.rational.brdf_fit.fit_brdf`, file version 1 or 2);
* ``3d``: the (theta_h, theta_d, |phi_d|) fit of an RGL ``.bsdf`` measurement
  (:mod:`fit.cli.brdf3d`, :func:`fit.rational.fit3d.fit_rgl_select`, file version 4: functions of
  rho cos theta_i; version 3 with ``--value-factor none``);
* ``auto`` (default): ``3d`` for an RGL ``.bsdf`` file, ``2d`` for a MERL ``.binary`` file.

Why ``3d`` where it exists (docs/fitting.md, "Which model"): the product renders measured
materials, so the default is the fit closest to the measurement where the time and the
coefficients stay moderate. On the 20 RGL materials of docs/fit_accuracy.md the 3-D fit's
relative RMSE (rho cos cos over cosine-distributed pairs) is 1.8-5.1x lower than the 2-D fit's
at 5 % (median 2.9x), below the phi_d-median table that bounds every 2-D fit on 19 of 20 (on
chm_mint the difference is within its bootstrap interval); its directional albedo is within 5 %
both ways at 0/30/60/75 deg on 11 of them; its renders reach ΔE2000 mean <= 1 against the
measurement on 36 of 40 cases and mean <= 1 with p99 <= 3 on 33 (docs/fit_accuracy.md); it has
1,323 coefficients (seven theta_h pieces; 420 where one piece looks better; 2-D: 160-835, median
358) and takes 19-51 s on one core (median 40 s; two fits at once on the two cores,
benchmarks/bench_fit_time.py;
2-D: 3-31 s, median 9 s). A MERL table is reciprocal and folded over phi_d; the 3-D fit is made from an
RGL file's own evaluation (with its light and view roles), so ``--model 3d`` refuses a
``.binary`` file in one line.

The flags of the other model are refused in one line (exit status 2). Registered by
:mod:`fit.cli` (it calls :func:`register` with its sub-parsers). The output is written only
when the run succeeds: a fit that misses its tolerance (2-D) or has a function outside its
bound (3-D) exits with status 1 and writes nothing (an existing file stays as it was; the
summary table on stdout, the verdict on stderr) unless ``--allow-infeasible`` is given (2-D
only). Progress (reading, projecting, each piece's channels; for 3-D each layout's sampling
and fit, the verification and the albedo policy) goes to stderr
(:class:`fit.progress.CLIProgress`).
"""
from __future__ import annotations

import sys
from pathlib import Path

from ..errors import BRDFFileError, FlagError, display_path, display_text
from ..formats import load_measured
from ..limits import (
    MAX_FIT_DEGREE,
    MAX_FIT_DEN_DEGREE,
    MAX_FLOOR_FRAC,
    MAX_TOLERANCE,
    MIN_CORE_THETA_D_DEG,
    MIN_TOLERANCE,
)
from ..outputs import OutputSet, check_output_file
from ..progress import Deadline, one_step
from ..rational.brdf_fit import fit_brdf
from ..rational.domain import THETA_D_MAX_DEG
from ..rational.coefficient_file import save
from ..rational.settings import INTERVALS, THETA_H_TRANSFORMS, VALUE_TRANSFORMS, BRDFFitSettings
from . import brdf3d
from .cdf import add_sampler_flags, attach_sampler
from .flags import add_run_flags, core_angle, integer, number

MODELS = ("auto", "2d", "3d")
#: The flags of the 2-D fit (argparse destinations), refused with ``--model 3d``.
FLAGS_2D = {"intervals": "--intervals", "core_theta_d": "--core-theta-d", "band_intervals": "--band-intervals",
            "theta_h": "--theta-h", "value": "--value", "floor_frac": "--floor-frac", "max_degree": "--max-degree",
            "max_den_degree": "--max-den-degree", "max_theta_h_pieces": "--max-theta-h-pieces"}


def chosen_model(args) -> str:
    """``"2d"`` or ``"3d"``: ``--model`` (``auto``: 3d for an RGL ``.bsdf`` file, 2d otherwise);
    a FlagError for ``3d`` of another file type or for a flag of the other model."""
    path = Path(args.file)
    rgl = path.suffix.lower() == ".bsdf"
    model = getattr(args, "model", "auto")
    if model == "auto":
        model = "3d" if rgl else "2d"
    elif model == "3d" and not rgl:
        raise FlagError("--model", f"3d needs an RGL .bsdf file, got {display_path(path.name)}: the 3-D fit is made "
                                   "from an RGL file's own evaluation with its light and view roles, and a MERL "
                                   ".binary table is reciprocal, folded over phi_d (fit it with --model 2d)")
    other = brdf3d.given(args) if model == "2d" else [f for d, f in FLAGS_2D.items() if getattr(args, d, None) is not None]
    if other:
        why = "--model 3d" if model == "2d" else "--model 2d"
        picked = "" if getattr(args, "model", "auto") != "auto" else f" (--model auto picks {model} for this file)"
        raise FlagError(other[0], f"a flag of the {why[8:]} fit ({why}); this run fits in {model}{picked}")
    return model


def _cmd_brdf(args) -> int:
    limit = getattr(args, "time_limit", None)
    deadline = Deadline(limit or None)      # only a --time-limit the user gave bounds the wall clock
    out = check_output_file(args.out, "--out", (".json",))
    if chosen_model(args) == "3d":
        return brdf3d.run(args, out, deadline)
    settings = settings_from_args(args)
    progress = getattr(args, "progress", None)
    with one_step(progress, "reading the file"):
        b = load_measured(args.file)
    try:
        fit = fit_brdf(b, settings, progress=progress, source_file=Path(args.file).name)
    except ValueError as e:
        raise BRDFFileError(args.file, str(e)) from None
    write = fit.valid or args.allow_infeasible
    sampler_line = attach_sampler(fit.model, args, progress) if write else ""
    if write:
        with OutputSet() as outputs:
            save(fit.model, outputs.stage(out))
            outputs.commit()
    print(f"{display_text(b.name)}: tol {settings.tol:g}, theta_h {settings.theta_h_transform}, "
          f"value {settings.value_transform}, "
          f"floor {fit.model.fit_info['abs_floor'][0]:.3g} 1/sr")
    print(f"{'theta_d deg':16s}{'intervals':>11s}{'ch':>3s}{'degrees':>9s}{'coefs':>7s}{'max rel':>9s}"
          f"{'rms rel':>9s}{'inside':>8s}{'Q>0':>5s}{'time s':>8s}")
    for pc in fit.pieces:
        rng = f"{pc.theta_d_range_deg[0]:g}-{pc.theta_d_range_deg[1]:g}"
        if tuple(pc.theta_h_range_deg) != (0.0, 90.0):
            rng += f" h{pc.theta_h_range_deg[0]:g}-{pc.theta_h_range_deg[1]:g}"
        for ch, r, e in zip("RGB", pc.results, pc.errors):
            print(f"{rng:16s}{pc.intervals:>11s}{ch:>3s}{f'({r.num_degree},{r.den_degree})':>9s}"
                  f"{r.n_coefficients:7d}{100 * e['max_rel_error']:8.2f}%{100 * e['rms_rel_error']:8.2f}%"
                  f"{100 * e['inside_fraction']:7.1f}%"
                  f"{'yes' if r.certificate and r.certificate.certified else 'NO':>5s}{r.time_s:8.2f}")
    if write:
        if sampler_line:
            print(sampler_line)
        print(f"{fit.summary()}; wrote {display_path(out)}")
        return 0
    sys.stdout.flush()      # the table first, then the verdict on stderr
    print(f"rbrdf-fit brdf: {fit.summary()}; the tolerance is not met: nothing written to "
          f"{display_path(out)} (--allow-infeasible writes the flagged fit)", file=sys.stderr)
    return 1


def settings_from_args(args) -> BRDFFitSettings:
    """The :class:`fit.rational.settings.BRDFFitSettings` of parsed ``rbrdf-fit brdf`` flags
    (a flag not given: the class default)."""
    given = {k: getattr(args, a) for k, a in (
        ("tol", "tol"), ("intervals", "intervals"), ("core_theta_d_deg", "core_theta_d"),
        ("band_intervals", "band_intervals"), ("theta_h_transform", "theta_h"), ("value_transform", "value"),
        ("max_degree", "max_degree"), ("max_den_degree", "max_den_degree"), ("floor_frac", "floor_frac"),
        ("max_theta_h_pieces", "max_theta_h_pieces"))
        if getattr(args, a, None) is not None}
    return BRDFFitSettings(**given)


def register(subparsers) -> None:
    """Add ``brdf`` to the sub-parsers ``subparsers`` (defaults: :class:`BRDFFitSettings`'s and,
    for 3-D, :mod:`fit.cli.brdf3d`'s; a model's flags default to None, so that a flag of the
    other model can be refused when it is given)."""
    d = BRDFFitSettings()
    p = subparsers.add_parser(
        "brdf", help="fit R, G, B with rational functions (3-D for an RGL file, else 2-D); write JSON coefficients",
        description="Fit R, G and B of a measured BRDF with rational functions P/Q, Q > 0 certified, and write "
                    "an rbrdf-rational JSON file (see fit.rational.coefficient_file). --model 3d (the default "
                    "for an RGL .bsdf file): rational functions of (theta_h, theta_d, |phi_d|) fitted to the "
                    "file's own evaluation, the tolerance the outcome (version 4: functions of rho cos theta_i; "
                    "1,323 coefficients, "
                    "19-51 s on one core): the most accurate form, its relative RMSE 1.8-5.1x (median 2.9x) "
                    "below the 2-D fit's at 5 % on the 20 RGL materials of docs/fit_accuracy.md. --model 2d "
                    "(the default for a "
                    "MERL .binary file, which is reciprocal and has no 3-D fit): project onto (theta_h, "
                    "theta_d) (median, grazing samples beyond 79 deg dropped), fit each channel with the "
                    "fewest coefficients inside the intervals (LP with constraint generation), proved at every cluster of the "
                    "core theta_d <= core and, separately, on the grazing band up to 78.5 deg (version 1 or "
                    "2; 3-31 s). Absolute floor of the 2-D fit: tol * A_Y / pi (A_Y = white-sky luminance "
                    "albedo). The flags of the other model are refused.")
    p.add_argument("file", help="MERL .binary or RGL .bsdf file")
    p.add_argument("--out", required=True, help="output .json coefficient file (replaced only if the run succeeds)")
    add_sampler_flags(p)
    p.add_argument("--model", choices=MODELS, default="auto",
                   help="auto (default): 3d for an RGL .bsdf file (its most accurate form), 2d for a MERL "
                        ".binary file; 2d: (theta_h, theta_d) within --tol; 3d: (theta_h, theta_d, |phi_d|), "
                        "RGL .bsdf files only")
    p.add_argument("--tol", type=number(MIN_TOLERANCE, MAX_TOLERANCE), default=None,
                   help=f"relative tolerance in [{MIN_TOLERANCE:g}, {MAX_TOLERANCE:g}]; 2-D: met at every cluster of the "
                        f"core (default {d.tol:g}); 3-D: the first tolerance of the ladder, the bound the file "
                        f"states is the one met (default {brdf3d.TOL_3D:g})")
    g = p.add_argument_group("2-D fit (--model 2d; auto for a MERL .binary)")
    g.add_argument("--intervals", choices=INTERVALS, default=None,
                   help="interval policy of the core (met at every cluster): 'tol' (default) = y +- max(tol y, floor); "
                        "'tol+spread' also widens to the cluster's phi_d standard deviation")
    g.add_argument("--core-theta-d", dest="core_theta_d", default=None, metavar="DEG|auto",
                   type=core_angle(MIN_CORE_THETA_D_DEG, THETA_D_MAX_DEG),
                   help="theta_d (deg) up to which the tolerance is met at every cluster; the grazing band above "
                        "it, up to 78.5 deg, gets its own functions; in [5, 78.5]. 'auto' (default): the "
                        "largest of 60, 50, 40 that every channel meets; 78.5: one function per channel")
    g.add_argument("--band-intervals", dest="band_intervals", choices=INTERVALS, default=None,
                   help="interval policy of the grazing band: 'tol' (default), the core's pure tolerance, "
                        "flagged where not met (the renderer then shows the projected table there, which "
                        "the file carries); 'tol+spread' also widens to the cluster's phi_d spread (met more "
                        "often, vouches for less)")
    g.add_argument("--theta-h", dest="theta_h", choices=THETA_H_TRANSFORMS, default=None,
                   help=f"input transform of theta_h (default {d.theta_h_transform})")
    g.add_argument("--value", choices=VALUE_TRANSFORMS, default=None,
                   help=f"value transform (default {d.value_transform})")
    g.add_argument("--floor-frac", dest="floor_frac", type=number(0.0, MAX_FLOOR_FRAC), default=None,
                   help="absolute floor = FLOOR_FRAC * tol * A_Y / pi (A_Y: white-sky luminance albedo; "
                        f"default {d.floor_frac:g}, at most {MAX_FLOOR_FRAC:g}). Smaller keeps dark off-specular "
                        "values relative (better colour on dark glossy materials) at the price of feasibility")
    g.add_argument("--max-degree", type=integer(0, MAX_FIT_DEGREE), default=None,
                   help=f"largest numerator total degree, 0-{MAX_FIT_DEGREE} (default {d.max_degree})")
    g.add_argument("--max-den-degree", type=integer(0, MAX_FIT_DEN_DEGREE), default=None,
                   help=f"largest denominator total degree, 0-{MAX_FIT_DEN_DEGREE} (default {d.max_den_degree})")
    g.add_argument("--max-theta-h-pieces", dest="max_theta_h_pieces", type=integer(2, 16), default=None,
                   help="when no core is met with the specular-peak split, the theta_h pieces that miss are "
                        "split at their midpoints (in the --theta-h variable), round after round, up to this "
                        f"many pieces, 2-16 (default {d.max_theta_h_pieces}; 2: no split beyond the peak's)")
    g.add_argument("--allow-infeasible", action="store_true",
                   help="write the file and exit 0 even when no fit meets the tolerance (the file is "
                        "flagged and carries the projected table the renderer shows there); without it such "
                        "a run writes nothing and exits 1")
    brdf3d.add_flags(p)
    add_run_flags(p)
    p.set_defaults(func=_cmd_brdf)
