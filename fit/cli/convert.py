"""``rbrdf-fit convert IN OUT``: convert a BRDF between formats, chosen by the extensions
(:func:`fit.convert.convert`), and print what was lost.

``IN``: MERL ``.binary``, RGL ``.bsdf`` or a rational fit ``.json``; ``OUT``: ``.binary`` or
``.bsdf`` (``--spectral [--n-wavelengths N]``: a spectral ``.bsdf``, ``spectra`` and
``wavelengths`` fields, the only kind pbrt-v4 reads; :mod:`fit.convert.spectral`). The output is checked before the input is read and replaced only when the
conversion succeeds; every error is one line, exit status 2 (docs/robustness.md).
"""
from __future__ import annotations

from ..convert import OPTIONS, convert
from ..convert.merl_writer import HORIZON_MARGIN_DEG
from ..convert.rgl_writer import (
    DEFAULT_N_NDF,
    DEFAULT_N_RGB,
    DEFAULT_N_THETA_I,
    DEFAULT_N_VNDF,
    DEFAULT_POWER_ITERATIONS,
)
from ..convert.spectral import DEFAULT_N_WAVELENGTHS
from ..convert.summary import DEFAULT_MAX_THETA_DEG, DEFAULT_PAIRS
from ..errors import FlagError
from ..progress import one_step
from .flags import add_run_flags, integer, number


def _cmd_convert(args) -> int:
    options = {k: getattr(args, k) for k in OPTIONS}
    if options["n_wavelengths"] is not None and not args.spectral:
        raise FlagError("--n-wavelengths", "only applies to a spectral output: add --spectral")
    if args.spectral and options["n_wavelengths"] is None:
        options["n_wavelengths"] = DEFAULT_N_WAVELENGTHS
    with one_step(getattr(args, "progress", None), "converting"):
        summary = convert(args.input, args.output, flag=None, **options)
    print(summary)
    return 0


def register(sub) -> None:
    """Add ``convert`` to the sub-parsers ``sub``."""
    p = sub.add_parser(
        "convert", help="convert a BRDF between MERL .binary, RGL .bsdf and rational fits",
        description="Convert IN (MERL .binary, RGL .bsdf, rational fit .json) into OUT (.binary: exact "
                    "MERL layout; .bsdf: RGL-EPFL tensor file with the adaptive parameterization, "
                    "readable by Mitsuba 3's 'measured' plugin), chosen by the extensions, and print "
                    "what was lost: the phi_d fold of a non-reciprocal source (MERL output) and the "
                    "written file against the source at random direction pairs. See docs/interop.md.")
    p.add_argument("input", help="input BRDF: .binary, .bsdf or a rational fit .json")
    p.add_argument("output", help="output file: .binary or .bsdf (replaced only if the run succeeds)")
    def arg(group, key, default, help_, metavar="N"):
        flag, lo, hi = OPTIONS[key]
        conv = integer(lo, hi) if isinstance(lo, int) else number(lo, hi)
        group.add_argument(flag, dest=key, type=conv, default=default, metavar=metavar,
                           help=f"{help_} (default {default:g})" if default is not None else help_)

    g = p.add_argument_group("RGL output (.bsdf)")
    arg(g, "n_theta_i", DEFAULT_N_THETA_I, "incidence slices, uniform in [0, 90] deg")
    arg(g, "n_vndf", DEFAULT_N_VNDF, "VNDF table side")
    arg(g, "n_rgb", DEFAULT_N_RGB, "rgb and luminance table side on the warped grid")
    arg(g, "n_ndf", DEFAULT_N_NDF, "ndf and sigma columns")
    arg(g, "power_iterations", DEFAULT_POWER_ITERATIONS, "power iterations of the NDF estimate")
    g.add_argument("--spectral", action="store_true",
                   help="write a spectral .bsdf ('spectra' on the warped grid and 'wavelengths' in nm; "
                        "read by pbrt-v4 and Mitsuba 3's spectral variants, not its RGB ones): each rgb "
                        "node upsampled to a smooth non-negative spectrum that keeps its sRGB colour")
    _, lo, hi = OPTIONS["n_wavelengths"]
    arg(g, "n_wavelengths", None, f"wavelengths of --spectral, uniform over [360, 830] nm (default "
                                  f"{DEFAULT_N_WAVELENGTHS}: 10 nm steps; {lo} to {hi})")
    g = p.add_argument_group("MERL output (.binary)")
    arg(g, "horizon_margin_deg", HORIZON_MARGIN_DEG,
        "bins with a direction within this angle of the horizon are marked 'no sample'", "DEG")
    g = p.add_argument_group("comparison against the source")
    arg(g, "n_pairs", DEFAULT_PAIRS, "random direction pairs (0: no comparison)")
    arg(g, "max_theta_deg", DEFAULT_MAX_THETA_DEG, "largest polar angle of the pairs", "DEG")
    arg(g, "seed", 0, "seed of the pairs", "SEED")
    add_run_flags(p)
    p.set_defaults(func=_cmd_convert)
