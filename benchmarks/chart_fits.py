"""The rational fits of :mod:`benchmarks.bench_chart`: found in a cache or made by the fitter's
own command line, in a child process.

* 2-D (``rational-2d``): :func:`studies.fits.rational_model` at 5 % (its cache
  ``results/fits/<stem>_tol0p05_cli.json`` or a shipped file), else made by
  ``rbrdf-fit brdf FILE --model 2d --tol 0.05 --out <that cache file>`` (the command's defaults:
  the fit :mod:`studies.fits` makes, with the fit's own inverse CDFs stored in the file).
* 3-D (``rational-3d``): ``rbrdf-fit brdf FILE --model 3d --out OUT`` with every default
  (``--layout select``, ``--tol 0.01``, no wall-clock limit, so a fit does not depend on the
  machine's load: docs/fitting.md, "The 3-D method"), cached as ``results/chart/fits/<stem>_3d_<key>.json`` where ``key`` is the first 12
  hex digits of the SHA-256 of the measured file's SHA-256, the command's flags and the fitter's
  defaults (:func:`fitter_defaults`: its layouts and settings): a new file, other flags or a
  fitter whose defaults changed make a new fit, the same ones reuse it.

A fit the command does not write (exit status 1: a function not valid) or that does not end
within ``time_limit_s`` is reported as missing (``None`` and the reason), never replaced by
another representation.
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIT3D_DIR = ROOT / "results" / "chart" / "fits"
#: The flags of the 3-D fit besides the file and ``--out``: the command's defaults.
FIT3D_FLAGS = ("--model", "3d", "--no-progress")
#: The 2-D fit's tolerance (the studies' and the shipped fits').
TOL_2D = 0.05
FIT2D_FLAGS = ("--model", "2d", "--tol", f"{TOL_2D:g}", "--no-progress")


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def fitter_defaults() -> str:
    """What a 3-D fit with the command's defaults depends on besides the file and the flags: the
    layouts :func:`fit.rational.fit3d.fit_rgl_select` tries, the default
    :class:`fit.rational.settings.Fit3DSettings` and the image check's scene, which chooses the
    layout (:mod:`fit.rational.image_check`), as text (part of the cache key)."""
    from fit.rational import image_check as IC
    from fit.rational.fit3d import TARGET_LADDER, VARIANTS, Fit3DSettings

    scene = (IC.DEFAULT_PIXELS, IC.DEFAULT_LIGHTS, IC.DEFAULT_SEEDS, IC.DEFAULT_SUN)
    return repr((VARIANTS, TARGET_LADDER, Fit3DSettings(), scene))


def fit3d_path(bsdf: Path, flags=FIT3D_FLAGS, fit_dir: Path = FIT3D_DIR) -> Path:
    """The cache file of the 3-D fit of ``bsdf`` made with ``flags`` by today's fitter."""
    key = hashlib.sha256(json.dumps([file_sha256(bsdf), list(flags), fitter_defaults()]).encode()).hexdigest()[:12]
    return Path(fit_dir) / f"{Path(bsdf).stem}_3d_{key}.json"


def run_fit_command(bsdf: Path, out: Path, flags, time_limit_s: float | None, log=None) -> tuple[bool, str, float]:
    """``rbrdf-fit brdf bsdf *flags --out out`` in a child process (one thread for BLAS):
    ``(written, message, seconds)``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "fit.cli", "brdf", str(bsdf), *flags, "--out", str(out)]
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    if log:
        log(f"fitting: {' '.join(cmd[2:])}")
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=time_limit_s)
    except subprocess.TimeoutExpired:
        return False, f"not fitted within {time_limit_s:g} s", time.perf_counter() - t0
    secs = time.perf_counter() - t0
    tail = (p.stderr.strip().splitlines() or p.stdout.strip().splitlines() or [""])[-1]
    if p.returncode != 0 or not out.is_file():
        return False, f"rbrdf-fit brdf exit {p.returncode}: {tail}", secs
    return True, "made", secs


def fit3d(bsdf: Path, time_limit_s: float | None = None, allow_fit: bool = True, log=None) -> tuple:
    """``(file or None, info)``: the cached or new 3-D fit of ``bsdf`` (module docstring)."""
    out = fit3d_path(bsdf)
    info = {"flags": list(FIT3D_FLAGS), "file": str(out.relative_to(ROOT)) if out.is_relative_to(ROOT) else str(out)}
    if out.is_file():
        return out, dict(info, source="cached")
    if not allow_fit:
        return None, dict(info, source=None, error="no cached 3-D fit (no fits made in this configuration)")
    ok, msg, secs = run_fit_command(bsdf, out, FIT3D_FLAGS, time_limit_s, log)
    return (out if ok else None), dict(info, source="made" if ok else None, wall_s=secs,
                                       **({} if ok else {"error": msg}))


def fit2d(bsdf: Path, time_limit_s: float | None = None, allow_fit: bool = True, log=None) -> tuple:
    """``(file or None, info)``: the 2-D 5 % fit of ``bsdf`` (module docstring)."""
    from studies import fits as F

    model, got = F.rational_model(str(bsdf), TOL_2D, allow_fit=False, allow_infeasible=True)
    if model is not None:
        return Path(got["file"]), {"source": got["source"], "file": got["file"]}
    out = F.FIT_DIR / f"{Path(bsdf).stem}_tol{F._tag(TOL_2D)}_cli.json"
    if not allow_fit:
        return None, {"source": None, "error": "no cached or shipped 2-D fit (no fits made in this configuration)"}
    ok, msg, secs = run_fit_command(Path(bsdf), out, FIT2D_FLAGS, time_limit_s, log)
    return (out if ok else None), {"source": "made" if ok else None, "file": str(out), "wall_s": secs,
                                   **({} if ok else {"error": msg})}


def main(argv=None) -> int:
    """Make the 2-D and 3-D fits of the given files ahead of a chart run (cached as above)."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m benchmarks.chart_fits",
                                 description="Make the chart's 2-D and 3-D fits of the given RGL files ahead of a run "
                                             "(cached: see benchmarks/chart_fits.py).")
    ap.add_argument("files", nargs="+", type=Path, metavar="FILE.bsdf")
    ap.add_argument("--model", choices=("2d", "3d", "both"), default="both")
    a = ap.parse_args(argv)
    for f in a.files:
        if not f.is_file():
            ap.error(f"{f}: no such file")
    for f in a.files:
        for kind, fn in (("2d", fit2d), ("3d", fit3d)):
            if a.model in (kind, "both"):
                print(kind, f, fn(f, log=lambda s: print(s, file=sys.stderr, flush=True)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
