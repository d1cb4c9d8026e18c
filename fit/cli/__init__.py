"""``rbrdf-fit``: command line of the fitter.

Sub-commands: ``info``, ``project``, ``plot`` (:mod:`fit.cli.measured`), ``brdf``
(:mod:`fit.cli.brdf`), ``cdf`` and ``plot-cdf`` (:mod:`fit.cli.cdf`), ``convert``
(:mod:`fit.cli.convert`: between MERL, RGL and rational fits), ``export`` (:mod:`fit.cli.export`:
a rational fit as GLSL, HLSL, C, a BRDF Explorer file or a Mitsuba 3 plugin) and ``batch``
(:mod:`fit.cli.batch`: a whole database on dask.distributed).

Bad input (docs/robustness.md): every error is one line on stderr naming the file (and key),
the flag or the output path -- ``rbrdf-fit: error: FILE: problem`` for the
:class:`fit.errors.RbrdfError` hierarchy, ``rbrdf-fit brdf: error: argument --tol: ...`` for
flags (:mod:`fit.cli.flags`) -- and the exit status is 2, without a traceback or warnings.
Outputs are staged and renamed into place only when the whole run succeeds
(:class:`fit.outputs.OutputSet`): a failing run leaves every existing file as it was.

Results go to stdout, progress to stderr (:class:`fit.progress.CLIProgress`, given to the
commands as ``args.progress``; ``--no-progress`` turns it off); HiGHS stays quiet unless
``--verbose``. A reader that closes stdout early (``rbrdf-fit info FILE | head -1``) ends the
command quietly with status 141, as a tool killed by SIGPIPE.
"""
from __future__ import annotations

import sys
import warnings

import numpy as np
from threadpoolctl import threadpool_limits

from ..errors import RbrdfError
from ..progress import CLIProgress
from . import batch, brdf, cdf, convert, export, measured
from .flags import OneLineParser, quiet_stdout

DESCRIPTION = """\
Fit measured isotropic BRDFs with rational functions (Rational BRDF, Pacanowski et al. 2012).

Input files: MERL-MIT '.binary' (90x90x180 theta_h/theta_d/phi_d, RGB; phi_d folded by
reciprocity) and RGL-EPFL isotropic '.bsdf' (resampled onto the MERL grid over the full phi_d
circle, 90x90x360: the files are not reciprocal). Angles are printed in degrees, BRDF values
in 1/sr.
"""


def build_parser() -> OneLineParser:
    import argparse

    parser = OneLineParser(prog="rbrdf-fit", description=DESCRIPTION,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    measured.register(sub)
    brdf.register(sub)
    cdf.register(sub)
    batch.register(sub)
    convert.register(sub)
    export.register(sub)
    return parser


def main(argv=None) -> int:
    """Run ``rbrdf-fit`` with ``argv`` (default ``sys.argv[1:]``); returns the exit status:
    0 success, 1 a fit that misses its tolerance (nothing written), 2 bad input (one line on
    stderr), 130 interrupted, 141 stdout closed by its reader."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:          # --help (0) or a one-line flag error (2)
        return e.code if isinstance(e.code, int) else 2
    np.set_printoptions(precision=4, suppress=True)
    if getattr(args, "verbose", False):
        from ..rational import lp

        lp.set_verbose(True)
    args.progress = CLIProgress(f"rbrdf-fit {args.command}", enabled=not getattr(args, "no_progress", False))
    try:
        # NumPy and matplotlib warnings are not messages to the user: what matters is checked
        # and reported in one line
        # one BLAS thread (fit/blas_threads.py: a fit's outcome must not depend on the thread count)
        with warnings.catch_warnings(), np.errstate(all="ignore"), threadpool_limits(limits=1, user_api="blas"):
            warnings.simplefilter("ignore")
            try:
                status = int(args.func(args) or 0)
                sys.stdout.flush()   # a reader that has gone is seen here, not at the exit
                return status
            finally:
                args.progress.close()
    except RbrdfError as e:
        print(f"rbrdf-fit: error: {e}", file=sys.stderr)
        return 2
    except MemoryError:
        print("rbrdf-fit: error: out of memory (no output written); an input asks for more than "
              "the limits of fit.limits foresee", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("rbrdf-fit: interrupted (no output written)", file=sys.stderr)
        return 130
    except BrokenPipeError:          # stdout closed early (rbrdf-fit info FILE | head -1)
        quiet_stdout()
        return 141                   # as a tool killed by SIGPIPE; outputs were committed first


