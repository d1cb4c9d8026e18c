"""Conversions between the BRDF formats the project reads and writes:
:func:`convert` (``rbrdf-fit convert IN OUT``), chosen by the files' extensions.

Inputs (:mod:`fit.convert.sources`, each read as a :class:`fit.convert.source.Source`):
MERL-MIT ``.binary``, RGL-EPFL ``.bsdf``, a rational fit ``.json`` (:mod:`fit.convert.dense`).
Outputs:

* ``.binary``: the exact MERL layout (:mod:`fit.convert.merl_writer`: bin centres, invalid bins
  stored negative, the phi_d fold of a non-reciprocal source measured and reported);
* ``.bsdf``: an RGL-EPFL tensor file with the format's adaptive parameterization
  (:mod:`fit.convert.rgl_writer`), read by Mitsuba 3's ``measured`` plugin; with
  ``n_wavelengths`` a spectral one (:mod:`fit.convert.spectral`), read by pbrt-v4 too.

Every conversion writes its output atomically (:class:`fit.outputs.OutputSet`: the file is
complete or untouched), reads the staged file back and measures it against the source
(:mod:`fit.convert.summary`), and returns a :class:`ConversionSummary`. Bad input is one
:class:`fit.errors.RbrdfError` line.
"""
from __future__ import annotations

import math
import numbers
import os
import time
from pathlib import Path

from ..errors import FlagError, OutputError
from ..outputs import OutputSet, check_output_file
from .merl_writer import HORIZON_MARGIN_DEG
from .rgl_writer import (
    DEFAULT_N_NDF,
    DEFAULT_N_RGB,
    DEFAULT_N_THETA_I,
    DEFAULT_N_VNDF,
    DEFAULT_POWER_ITERATIONS,
)
from .source import Source
from .sources import SOURCE_SUFFIXES, load_source
from .summary import DEFAULT_MAX_THETA_DEG, DEFAULT_PAIRS, ConversionSummary, compare

#: Output extensions and their formats.
OUTPUT_SUFFIXES = {".binary": "MERL-MIT", ".bsdf": "RGL-EPFL"}

#: The options of :func:`convert`: (command-line flag, lowest, highest). The RGL sizes also
#: stay within the readers' limits together (:func:`fit.convert.rgl_writer.check_sizes`).
OPTIONS = {
    "n_theta_i": ("--theta-i", 2, 90),
    "n_vndf": ("--n-vndf", 8, 512),
    "n_rgb": ("--n-rgb", 4, 256),
    "n_ndf": ("--n-ndf", 8, 512),
    "power_iterations": ("--power-iterations", 0, 50),
    "n_wavelengths": ("--n-wavelengths", 16, 471),
    "horizon_margin_deg": ("--horizon-margin", 0.0, 45.0),
    "n_pairs": ("--pairs", 0, 1_000_000),
    "max_theta_deg": ("--max-theta", 1.0, 89.0),
    "seed": ("--seed", 0, 2**31 - 1),
}


def _check_options(values: dict) -> None:
    """One-line :class:`fit.errors.FlagError` (naming the command-line flag) for an option of
    the wrong type or outside :data:`OPTIONS`."""
    for key, v in values.items():
        flag, lo, hi = OPTIONS[key]
        is_int = isinstance(lo, int)
        ok_type = (isinstance(v, numbers.Integral) if is_int else isinstance(v, numbers.Real)) \
            and not isinstance(v, bool)
        if not ok_type or not (lo <= v <= hi) or (not is_int and not math.isfinite(v)):
            raise FlagError(flag, f"{key} = {v!r}: expected {'an integer' if is_int else 'a number'} in "
                                  f"[{lo}, {hi}]")

__all__ = ["OPTIONS", "OUTPUT_SUFFIXES", "SOURCE_SUFFIXES", "ConversionSummary", "Source", "convert", "load_source"]


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.realpath(a) == os.path.realpath(b)


def convert(src, out, *, n_theta_i: int = DEFAULT_N_THETA_I, n_vndf: int = DEFAULT_N_VNDF,
            n_rgb: int = DEFAULT_N_RGB, n_ndf: int = DEFAULT_N_NDF,
            power_iterations: int = DEFAULT_POWER_ITERATIONS,
            horizon_margin_deg: float = HORIZON_MARGIN_DEG, n_pairs: int = DEFAULT_PAIRS,
            max_theta_deg: float = DEFAULT_MAX_THETA_DEG, seed: int = 0,
            flag: str | None = None, n_wavelengths: int | None = None) -> ConversionSummary:
    """Convert the BRDF file ``src`` (``.binary``, ``.bsdf``, ``.json`` fit) into ``out``
    (``.binary`` or ``.bsdf``) and return what was lost.

    ``n_theta_i``, ``n_vndf``, ``n_rgb``, ``n_ndf``, ``power_iterations``: the RGL output's
    sizes (:mod:`fit.convert.rgl_writer`); ``horizon_margin_deg``: the MERL output's "no
    sample" band above the horizon (:mod:`fit.convert.merl_writer`); ``n_pairs`` (0: none),
    ``max_theta_deg``, ``seed``: the comparison of the written file against the source
    (:func:`fit.convert.summary.compare`). The output path is checked before anything is read
    (``flag`` names it in errors); the file is replaced only when the conversion succeeds.
    Options outside :data:`OPTIONS` are a one-line :class:`fit.errors.FlagError`.
    ``n_wavelengths`` (None: RGB): a spectral ``.bsdf`` with that many wavelengths (``--spectral``).
    """
    t0 = time.perf_counter()
    _check_options({"n_theta_i": n_theta_i, "n_vndf": n_vndf, "n_rgb": n_rgb, "n_ndf": n_ndf,
                    "power_iterations": power_iterations, "horizon_margin_deg": horizon_margin_deg,
                    "n_pairs": n_pairs, "max_theta_deg": max_theta_deg, "seed": seed,
                    **({} if n_wavelengths is None else {"n_wavelengths": n_wavelengths})})
    src, out = Path(src), Path(out)
    out = check_output_file(out, flag, tuple(OUTPUT_SUFFIXES))
    if _same_file(src, out):
        raise OutputError(out, "is the input file; write the conversion to another file", flag)
    suffix = out.suffix.lower()
    if n_wavelengths is not None and suffix != ".bsdf":
        raise FlagError("--spectral", f"a spectral output needs a .bsdf file, not {suffix}")
    if suffix == ".bsdf":
        from .rgl_writer import check_sizes

        check_sizes(n_theta_i, n_vndf, n_rgb, n_ndf, n_wavelengths)
    source = load_source(src)
    summary = ConversionSummary(str(src), str(out), SOURCE_SUFFIXES[src.suffix.lower()],
                                OUTPUT_SUFFIXES[suffix], source.name, notes=list(source.notes))
    with OutputSet(flag) as outputs:
        tmp = outputs.stage(out)
        if suffix == ".binary":
            from ..formats.merl import read_merl, write_merl
            from .merl_writer import tabulate_merl

            table, summary.fold = tabulate_merl(source, horizon_margin_deg)
            write_merl(table, tmp)
            back = read_merl(tmp).evaluate
        else:
            from ..formats.rgl import read_rgl
            from ..formats.tensor_file import write_tensor_file
            from .rgl_writer import build_rgl

            summary.build = build_rgl(source, n_theta_i, n_vndf, n_rgb, n_ndf, power_iterations,
                                      n_wavelengths=n_wavelengths)
            write_tensor_file(tmp, summary.build.fields)
            back = read_rgl(tmp, incident="view").evaluate
        summary.difference = compare(back, source.evaluate, n_pairs, seed, max_theta_deg)
        outputs.commit()
    summary.seconds = time.perf_counter() - t0
    return summary
