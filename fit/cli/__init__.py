"""``rbrdf-fit``: command line of the fitter.

Sub-commands: ``info``, ``project``, ``plot`` (:mod:`fit.cli.measured`), ``brdf``
(:mod:`fit.cli.brdf`), ``cdf`` and ``plot-cdf`` (:mod:`fit.cli.cdf`). Every sub-command prints
errors about files as one line (``rbrdf-fit: error: FILE: problem``) and exits with status 2,
without a traceback.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from ..errors import RbrdfError
from . import brdf, cdf, measured

DESCRIPTION = """\
Fit measured isotropic BRDFs with rational functions (Rational BRDF, Pacanowski et al. 2012).

Input files: MERL-MIT '.binary' (90x90x180 theta_h/theta_d/phi_d, RGB; phi_d folded by
reciprocity) and RGL-EPFL isotropic '.bsdf' (resampled onto the MERL grid over the full phi_d
circle, 90x90x360: the files are not reciprocal). Angles are printed in degrees, BRDF values
in 1/sr.
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="rbrdf-fit", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    measured.register(sub)
    brdf.register(sub)
    cdf.register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    np.set_printoptions(precision=4, suppress=True)
    try:
        return int(args.func(args) or 0)
    except RbrdfError as e:
        print(f"rbrdf-fit: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("rbrdf-fit: interrupted", file=sys.stderr)
        return 130
