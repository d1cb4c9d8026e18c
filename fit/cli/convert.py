"""``rbrdf-fit convert IN OUT``: convert a BRDF between formats, chosen by the extensions
(:func:`fit.convert.convert`), and print what was lost.

``IN``: MERL ``.binary``, RGL ``.bsdf`` or a rational fit ``.json``; ``OUT``: ``.binary`` or
``.bsdf``. The output is checked before the input is read and replaced only when the
conversion succeeds; every error is one line, exit status 2 (docs/robustness.md).
"""
from __future__ import annotations

from ..convert import convert
from ..convert.merl_writer import HORIZON_MARGIN_DEG
from ..convert.rgl_writer import (
    DEFAULT_N_NDF,
    DEFAULT_N_RGB,
    DEFAULT_N_THETA_I,
    DEFAULT_N_VNDF,
    DEFAULT_POWER_ITERATIONS,
)
from ..convert.summary import DEFAULT_MAX_THETA_DEG, DEFAULT_PAIRS
from ..limits import MAX_RGL_TABLE_SIDE, MAX_RGL_THETA_I
from .flags import integer, number

#: Most random direction pairs the comparison may draw.
MAX_PAIRS = 1_000_000


def _cmd_convert(args) -> int:
    summary = convert(args.input, args.output, n_theta_i=args.theta_i, n_vndf=args.n_vndf,
                      n_rgb=args.n_rgb, n_ndf=args.n_ndf, power_iterations=args.power_iterations,
                      horizon_margin_deg=args.horizon_margin, n_pairs=args.pairs,
                      max_theta_deg=args.max_theta, seed=args.seed, flag=None)
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
    g = p.add_argument_group("RGL output (.bsdf)")
    side = min(MAX_RGL_TABLE_SIDE, 512)
    g.add_argument("--theta-i", type=integer(2, min(MAX_RGL_THETA_I, 90)), default=DEFAULT_N_THETA_I,
                   metavar="N", help=f"incidence slices, uniform in [0, 90] deg (default {DEFAULT_N_THETA_I})")
    g.add_argument("--n-vndf", type=integer(8, side), default=DEFAULT_N_VNDF, metavar="N",
                   help=f"VNDF table side (default {DEFAULT_N_VNDF})")
    g.add_argument("--n-rgb", type=integer(4, 256), default=DEFAULT_N_RGB, metavar="N",
                   help=f"rgb and luminance table side on the warped grid (default {DEFAULT_N_RGB})")
    g.add_argument("--n-ndf", type=integer(8, side), default=DEFAULT_N_NDF, metavar="N",
                   help=f"ndf and sigma columns (default {DEFAULT_N_NDF})")
    g.add_argument("--power-iterations", type=integer(0, 50), default=DEFAULT_POWER_ITERATIONS,
                   metavar="N", help=f"power iterations of the NDF estimate (default {DEFAULT_POWER_ITERATIONS})")
    g = p.add_argument_group("MERL output (.binary)")
    g.add_argument("--horizon-margin", type=number(0.0, 45.0), default=HORIZON_MARGIN_DEG, metavar="DEG",
                   help="bins with a direction within this angle of the horizon are marked 'no sample' "
                        f"(default {HORIZON_MARGIN_DEG:g})")
    g = p.add_argument_group("comparison against the source")
    g.add_argument("--pairs", type=integer(0, MAX_PAIRS), default=DEFAULT_PAIRS, metavar="N",
                   help=f"random direction pairs (0: no comparison; default {DEFAULT_PAIRS})")
    g.add_argument("--max-theta", type=number(1.0, 89.0), default=DEFAULT_MAX_THETA_DEG, metavar="DEG",
                   help=f"largest polar angle of the pairs (default {DEFAULT_MAX_THETA_DEG:g})")
    g.add_argument("--seed", type=integer(0, 2**31 - 1), default=0, help="seed of the pairs (default 0)")
    p.set_defaults(func=_cmd_convert)
