"""``rbrdf-fit brdf FILE --tol 0.05 --out material.json``: rational fit of a measured BRDF
(:func:`fit.rational.brdf_fit.fit_brdf`), written as an ``rbrdf-rational`` coefficient file
(:mod:`fit.rational.coefficient_file`), with a per-piece, per-channel summary table.

Registered by :mod:`fit.cli` (it calls :func:`register` with its sub-parsers). The output is
written only when the run succeeds: a fit that misses its tolerance exits with status 1 and
writes nothing (an existing file stays as it was; the summary table on stdout, the verdict on
stderr) unless ``--allow-infeasible`` is given. Progress (reading, projecting, each piece's
channels) goes to stderr (:class:`fit.progress.CLIProgress`).
"""
from __future__ import annotations

import sys
from pathlib import Path

from ..errors import BRDFFileError, display_path, display_text
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
from ..progress import one_step
from ..rational.brdf_fit import fit_brdf
from ..rational.domain import THETA_D_MAX_DEG
from ..rational.coefficient_file import save
from ..rational.settings import INTERVALS, THETA_H_TRANSFORMS, VALUE_TRANSFORMS, BRDFFitSettings
from .flags import add_run_flags, core_angle, integer, number


def _cmd_brdf(args) -> int:
    out = check_output_file(args.out, "--out", (".json",))
    progress = getattr(args, "progress", None)
    with one_step(progress, "reading the file"):
        b = load_measured(args.file)
    try:
        fit = fit_brdf(b, settings_from_args(args), progress=progress, source_file=Path(args.file).name)
    except ValueError as e:
        raise BRDFFileError(args.file, str(e)) from None
    write = fit.valid or args.allow_infeasible
    if write:
        with OutputSet() as outputs:
            save(fit.model, outputs.stage(out))
            outputs.commit()
    print(f"{display_text(b.name)}: tol {args.tol:g}, theta_h {args.theta_h}, value {args.value}, "
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
        print(f"{fit.summary()}; wrote {display_path(out)}")
        return 0
    sys.stdout.flush()      # the table first, then the verdict on stderr
    print(f"rbrdf-fit brdf: {fit.summary()}; the tolerance is not met: nothing written to "
          f"{display_path(out)} (--allow-infeasible writes the flagged fit)", file=sys.stderr)
    return 1


def settings_from_args(args) -> BRDFFitSettings:
    """The :class:`fit.rational.settings.BRDFFitSettings` of parsed ``rbrdf-fit brdf`` flags."""
    return BRDFFitSettings(tol=args.tol, intervals=args.intervals, core_theta_d_deg=args.core_theta_d,
                           band_intervals=args.band_intervals, theta_h_transform=args.theta_h,
                           value_transform=args.value, max_degree=args.max_degree,
                           max_den_degree=args.max_den_degree, floor_frac=args.floor_frac)


def register(subparsers) -> None:
    """Add ``brdf`` to the sub-parsers ``subparsers`` (defaults: :class:`BRDFFitSettings`'s)."""
    d = BRDFFitSettings()
    p = subparsers.add_parser(
        "brdf", help="fit R, G, B with rational functions inside a tolerance; write JSON coefficients",
        description="Project the BRDF onto (theta_h, theta_d) (median, grazing samples beyond 79 deg "
                    "dropped), fit each channel with the rational function with the fewest "
                    "coefficients inside the intervals (LP with constraint generation) on a "
                    "guaranteed core theta_d <= core and, separately, on the grazing band up to "
                    "78.5 deg; certify Q > 0 and write an rbrdf-rational JSON file (version 2 when "
                    "piecewise; see fit.rational.coefficient_file). Absolute floor: tol * A_Y / pi (A_Y = white-"
                    "sky luminance albedo).")
    p.add_argument("file", help="MERL .binary or RGL .bsdf file")
    p.add_argument("--tol", type=number(MIN_TOLERANCE, MAX_TOLERANCE), default=d.tol,
                   help=f"relative tolerance in [{MIN_TOLERANCE:g}, {MAX_TOLERANCE:g}] (default {d.tol:g})")
    p.add_argument("--out", required=True, help="output .json coefficient file (replaced only if the run succeeds)")
    p.add_argument("--intervals", choices=INTERVALS, default=d.intervals,
                   help="interval policy of the guaranteed core: 'tol' (default) = y +- max(tol y, floor); "
                        "'tol+spread' also widens to the cluster's phi_d standard deviation")
    p.add_argument("--core-theta-d", dest="core_theta_d", default=d.core_theta_d_deg, metavar="DEG|auto",
                   type=core_angle(MIN_CORE_THETA_D_DEG, THETA_D_MAX_DEG),
                   help="theta_d (deg) up to which the tolerance is guaranteed; the grazing band above "
                        "it, up to 78.5 deg, gets its own functions; in [5, 78.5]. 'auto' (default): the "
                        "largest of 60, 50, 40 that every channel meets; 78.5: one function per channel")
    p.add_argument("--band-intervals", dest="band_intervals", choices=INTERVALS, default=d.band_intervals,
                   help="interval policy of the grazing band: 'tol' (default), the core's pure tolerance, "
                        "flagged where not met (the renderer then shows the projected table there); "
                        "'tol+spread' also widens to the cluster's phi_d spread (met more often, vouches "
                        "for less)")
    p.add_argument("--theta-h", dest="theta_h", choices=THETA_H_TRANSFORMS, default=d.theta_h_transform,
                   help="input transform of theta_h (default sqrt)")
    p.add_argument("--value", choices=VALUE_TRANSFORMS, default=d.value_transform, help="value transform (default log)")
    p.add_argument("--floor-frac", dest="floor_frac", type=number(0.0, MAX_FLOOR_FRAC), default=d.floor_frac,
                   help="absolute floor = FLOOR_FRAC * tol * A_Y / pi (A_Y: white-sky luminance albedo; "
                        f"default 1, at most {MAX_FLOOR_FRAC:g}). Smaller keeps dark off-specular values relative "
                        "(better colour on "
                        "dark glossy materials) at the price of feasibility")
    p.add_argument("--max-degree", type=integer(0, MAX_FIT_DEGREE), default=d.max_degree,
                   help=f"largest numerator total degree, 0-{MAX_FIT_DEGREE} (default {d.max_degree})")
    p.add_argument("--max-den-degree", type=integer(0, MAX_FIT_DEN_DEGREE), default=d.max_den_degree,
                   help=f"largest denominator total degree, 0-{MAX_FIT_DEN_DEGREE} (default {d.max_den_degree})")
    p.add_argument("--allow-infeasible", action="store_true",
                   help="write the file and exit 0 even when no fit meets the tolerance (the file is "
                        "flagged); without it such a run writes nothing and exits 1")
    add_run_flags(p)
    p.set_defaults(func=_cmd_brdf)
