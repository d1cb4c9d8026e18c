"""``rbrdf-fit export FIT.json OUT``: a rational fit (``rbrdf-rational`` file) as code other
tools use without this project (:mod:`fit.export`); the format is chosen by OUT's extension:

* ``.glsl``: GLSL functions (:func:`fit.export.to_glsl`);
* ``.hlsl``: HLSL functions (:func:`fit.export.to_hlsl`);
* ``.h`` / ``.c``: C99 / C++ header (``static inline``) or translation unit (:func:`fit.export.to_c`);
* ``.brdf``: Disney BRDF Explorer ``analytic`` file (:func:`fit.export.to_brdf_explorer`);
* ``.py``: standalone Mitsuba 3 BSDF plugin (:func:`fit.export.to_mitsuba_plugin`), sampled
  with the tables of ``--cdf CDF.json`` when given (else cosine).

2-D fits (versions 1 and 2, (theta_h, theta_d)) and 3-D fits (versions 3 and 4, (theta_h,
theta_d, |phi_d|), not reciprocal: the exported functions take the light first; version 4's
functions give rho cos theta_i and the exported code divides by cos theta_i) are exported alike.
Registered by :mod:`fit.cli`. Bad input: one line, exit status 2, nothing written (the output
is checked first and renamed into place only when complete, :class:`fit.outputs.OutputSet`).
Flagged pieces (the fit not within its tolerance there) are exported as the fitted function
clamped to its measured range, and the command says so on stdout.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import BRDFFileError, FlagError
from ..outputs import OutputSet, check_output_file

EXPORTERS = {".glsl": "glsl", ".hlsl": "hlsl", ".h": "c_header", ".c": "c_source", ".brdf": "brdf_explorer",
             ".py": "mitsuba"}


def render(model, suffix: str, name=None, precision: str = "float", cdf=None) -> str:
    """The exported text of ``model`` for an output suffix (a key of :data:`EXPORTERS`);
    ``precision``: the GLSL's scalar type (``.glsl`` only); ``cdf``: the ``rbrdf-cdf`` fit
    whose tables the Mitsuba plugin samples with (``.py`` only)."""
    from .. import export as X

    kind = EXPORTERS[suffix]
    if kind == "glsl":
        return X.to_glsl(model, name, precision=precision)
    if kind == "hlsl":
        return X.to_hlsl(model, name)
    if kind == "c_header":
        return X.to_c(model, name, header=True)
    if kind == "c_source":
        return X.to_c(model, name, header=False)
    if kind == "brdf_explorer":
        return X.to_brdf_explorer(model, name)
    return X.to_mitsuba_plugin(model, name, cdf=cdf)


def run(args, log=print) -> int:
    from ..export.emitter import ExportError, flagged_summary
    from ..export.escape import MAX_IDENTIFIER, is_identifier, literal
    from ..rational.coefficient_file import load

    out = check_output_file(args.out, flag="OUT", suffixes=tuple(EXPORTERS))
    if args.name is not None and not is_identifier(args.name):
        raise FlagError("--name", f"expected letters and digits joined by single '_' (not starting with a digit, "
                                  f"at most {MAX_IDENTIFIER} characters), got {literal(args.name, 80)}")
    if args.precision != "float" and out.suffix.lower() != ".glsl":
        raise FlagError("--precision", "only a .glsl output has a double variant (C: -DRBRDF_REAL_DOUBLE)")
    if args.cdf is not None and out.suffix.lower() != ".py":
        raise FlagError("--cdf", "only the Mitsuba plugin (.py output) samples with inverse CDFs")
    path = Path(args.fit)
    model = load(path)
    cdf = None
    if args.cdf is not None:
        from ..sampling.cdf_file import load as load_cdf

        cdf = load_cdf(Path(args.cdf))
    try:
        text = render(model, out.suffix.lower(), args.name, args.precision, cdf)
    except ExportError as e:
        raise BRDFFileError(path, f"cannot export this fit: {e}") from None
    with OutputSet(flag="OUT") as outputs:
        outputs.write_text(out, text)       # every byte checked on disk before the rename
        outputs.commit()
    from ..rational.variables3d import is_3d

    what = "3-D: theta_h, theta_d, |phi_d|; wi the light, wo the viewer, " if is_3d(model) else ""
    log(f"wrote {out} ({EXPORTERS[out.suffix.lower()]}, {what}{model.n_coefficients} coefficients)")
    for k, chans in flagged_summary(model):
        names = ", ".join(n for n, _ in chans)
        log(f"note: piece {k} channel(s) {names} flagged (not within tolerance): exported as the fitted "
            f"function clamped to its measured range (the renderer reads the measured table there)")
    return 0


def register(subparsers) -> None:
    """Add ``export`` to the sub-parsers ``subparsers``."""
    p = subparsers.add_parser(
        "export", help="write a rational fit as GLSL, C/C++, a BRDF Explorer .brdf or a Mitsuba 3 plugin",
        description="Export an rbrdf-rational coefficient file as code: OUT's extension picks the "
                    "format (.glsl GLSL; .hlsl HLSL; .h C/C++ header; .c C translation unit; .brdf BRDF Explorer "
                    "analytic file; .py Mitsuba 3 BSDF plugin). 2-D fits (theta_h, theta_d) and 3-D fits "
                    "(versions 3 and 4: theta_h, theta_d, |phi_d|; not reciprocal, wi is the light) alike. See "
                    "docs/exports.md for the domain and clamp policy and the measured agreement.")
    p.add_argument("fit", help="rbrdf-rational .json coefficient file (version 1, 2, 3 or 4)")
    p.add_argument("out", help="output file: .glsl, .hlsl, .h, .c, .brdf or .py (replaced only if the run succeeds)")
    p.add_argument("--name", default=None,
                   help="identifier used in the function / plugin names (default: the fit's name)")
    p.add_argument("--precision", choices=("float", "double"), default="float",
                   help="scalar type of the .glsl output (default float; double needs GLSL 4.00, "
                        "see docs/exports.md for the agreement of each)")
    p.add_argument("--cdf", default=None, metavar="CDF.json",
                   help="rbrdf-cdf file (rbrdf-fit cdf) whose tabulated inverse CDFs the Mitsuba plugin "
                        "(.py) samples with; default: cosine sampling")
    p.set_defaults(func=run)
