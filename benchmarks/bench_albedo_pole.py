"""The directional albedo at the normal incidence of an RGL measurement's tensors, and what an
isotropic fit can show there (docs/fit_accuracy.md, "Albedo at the normal view").

An RGL file tabulates, for each incidence ``theta_t`` of its tensors (our *view*, the default
roles of :class:`fit.formats.rgl.RGLBRDF`), the other direction relative to the incidence's
azimuth. At ``theta_t = 0`` that azimuth is undefined: the reference evaluation (ours, Mitsuba 3's
``measured``) reads the normal-incidence slice at the *absolute* azimuth of the other direction,
and just off the normal at its azimuth relative to the incidence's. Where the measured slice is
not rotationally symmetric, the measurement near the normal view depends on the light's azimuth
relative to the view's, which no isotropic BRDF does; a function of ``(theta_h, theta_d,
|phi_d|)`` (the 3-D fits, :mod:`fit.rational.variables3d`) maps all those azimuths at the normal
view to one point (``theta_h = theta_d``, ``phi_d = 0``) and has one value per light angle there.

Per material this measures, with the tensors' incidence fixed (``fixed`` = "view" for the
default roles, "light" for ``incident="light"``):

* **the slice's azimuthal spread**: at the normal, lights at 10, 20 and 30 deg and 24 azimuths:
  the largest ratio of the luminance's maximum to its minimum over the azimuth (1 for an
  isotropic slice);
* **the truth's albedo at the normal** over the whole azimuth (the directional albedo of
  :func:`fit.rational.albedo3d.albedo_quadrature` at 0 deg) and **in the plane of incidence**
  (the same quadrature with each varying direction rotated to azimuths 0 and pi, averaged: the
  values the data take where an isotropic function's pole is approached in that plane), and
  their relative difference (:func:`fit.rational.albedo3d.relative_errors`, 5 % channel floor,
  the largest over R, G, B);
* **the 3-D fit's albedo error** with that direction at 0, 2, 5, 15 deg (against the truth), and
  at 0 deg against the in-plane albedo.

    python -m benchmarks.bench_albedo_pole --fits results/fit_accuracy --docs
    python -m benchmarks.bench_albedo_pole --materials vch_ultra_pink --fits DIR
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs" / "fit_accuracy.md"
BEGIN, END = "<!-- BEGIN bench:albedo_pole -->", "<!-- END bench:albedo_pole -->"
#: Angles (deg) of the fixed direction at which the fit's albedo error is reported.
ANGLES_DEG = (0.0, 2.0, 5.0, 15.0)
#: Light angles (deg) and azimuths of the slice's azimuthal spread.
SPREAD_THETA_DEG = (10.0, 20.0, 30.0)
SPREAD_AZIMUTHS = 24
DEFAULT_POINTS = 256 ** 2


class BenchError(Exception):
    """Bad input: one line, exit status 2."""


def tensor_fixed(brdf) -> str:
    """``"view"`` or ``"light"``: the kind of directional albedo whose fixed direction is the
    tensors' incidence (:attr:`fit.formats.rgl.RGLBRDF.incident`)."""
    return "light" if getattr(brdf, "incident", "view") == "light" else "view"


def _pairs(fixed: str, w_fixed, w_var):
    """``(wi, wo)`` with ``w_fixed`` the fixed direction of ``fixed`` and ``w_var`` the other."""
    return (w_fixed, w_var) if fixed == "light" else (w_var, w_fixed)


def slice_spread(evaluate, fixed: str) -> float:
    """The largest over :data:`SPREAD_THETA_DEG` of max / min over :data:`SPREAD_AZIMUTHS`
    azimuths of the luminance of ``evaluate(wi, wo)`` (rho ``(n, 3)``), the ``fixed`` direction
    at the normal and the other at that angle (1 for a rotationally symmetric slice)."""
    from fit.formats.colour import LUMINANCE

    n = np.array([0.0, 0.0, 1.0])
    phi = 2.0 * np.pi * np.arange(SPREAD_AZIMUTHS) / SPREAD_AZIMUTHS
    out = 1.0
    for t in np.radians(SPREAD_THETA_DEG):
        d = np.stack([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.full_like(phi, np.cos(t))], axis=1)
        wi, wo = _pairs(fixed, np.broadcast_to(n, d.shape), d)
        y = np.maximum(np.asarray(evaluate(wi, wo), np.float64), 0.0) @ np.asarray(LUMINANCE)
        out = max(out, float(y.max() / max(y.min(), 1e-300)))
    return out


def normal_albedos(evaluate, fixed: str, n: int = DEFAULT_POINTS) -> tuple:
    """``(full (3,), in_plane (3,))``: the directional albedo with the ``fixed`` direction at the
    normal, over the whole azimuth and with each varying direction rotated into the plane of
    incidence (azimuth 0 and pi, averaged), on the quadrature of
    :func:`fit.rational.albedo3d.albedo_quadrature`."""
    from fit.rational.albedo3d import albedo_from_values, albedo_quadrature

    wi, wo, qw = albedo_quadrature([0.0], n, fixed)
    w_fixed, w_var = (wi, wo) if fixed == "light" else (wo, wi)
    full = albedo_from_values(np.maximum(np.asarray(evaluate(wi, wo), np.float64), 0.0), qw)[0]
    s = np.hypot(w_var[:, 0], w_var[:, 1])
    plane = 0.0
    for sign in (1.0, -1.0):
        d = np.stack([sign * s, np.zeros_like(s), w_var[:, 2]], axis=1)
        plane = plane + 0.5 * np.maximum(np.asarray(evaluate(*_pairs(fixed, w_fixed, d)), np.float64), 0.0)
    return full, albedo_from_values(plane, qw)[0]


def measure(brdf, model, n: int = DEFAULT_POINTS) -> dict:
    """Every number of one material (module docstring); ``model`` the 3-D fit or None."""
    from fit.rational.albedo3d import albedo_errors, relative_errors
    from fit.rational.variables3d import evaluate_directions

    fixed = tensor_fixed(brdf)
    full, plane = normal_albedos(brdf.evaluate, fixed, n)
    row = {"fixed": fixed, "slice_spread": slice_spread(brdf.evaluate, fixed),
           "truth_normal": full.tolist(), "truth_in_plane": plane.tolist(),
           "in_plane_vs_truth": float(relative_errors(plane[None], full[None]).max())}
    if model is not None:
        def ev(wi, wo):
            return evaluate_directions(model, wi, wo)
        e = albedo_errors(ev, brdf.evaluate, list(ANGLES_DEG), n, fixed=fixed)
        fit0 = np.asarray(e["fit"][0])
        row.update(fit_error=[float(x) for x in np.max(e["error"], axis=1)], fit_normal=fit0.tolist(),
                   fit_vs_in_plane=float(relative_errors(fit0[None], plane[None]).max()))
    return row


def _pct(x) -> str:
    return f"{100 * x:.1f} %"


def markdown(rows: dict, meta: dict) -> str:
    L = [f"`python -m benchmarks.bench_albedo_pole --fits {meta['fits']}` ({meta['date']}, {meta['points']:,} "
         "quadrature points per angle; errors: the largest over R, G, B, a channel darker than 5 % of the "
         "brightest held to 5 % of the brightest; the fixed direction: the tensors' incidence, the view).", "",
         "| material | slice spread (max / min) | truth: in-plane against whole azimuth at 0° | 3-D fit error at "
         + " / ".join(f"{a:g}°" for a in ANGLES_DEG) + " | 3-D fit against the in-plane albedo at 0° |",
         "| --- | --- | --- | --- | --- |"]
    for name in sorted(rows):
        r = rows[name]
        fe = " / ".join(_pct(x) for x in r["fit_error"]) if "fit_error" in r else "n/a"
        fp = _pct(r["fit_vs_in_plane"]) if "fit_vs_in_plane" in r else "n/a"
        L.append(f"| {name} | {r['slice_spread']:.2f} | {_pct(r['in_plane_vs_truth'])} | {fe} | {fp} |")
    miss = [m for m, r in rows.items() if r.get("fit_error", [0])[0] > 0.05]
    explained = [m for m in miss if rows[m]["in_plane_vs_truth"] > 0.05 and rows[m]["fit_error"][2] <= 0.05]
    L += ["", f"The 3-D fit is more than 5 % off at the normal view on {len(miss)} of {len(rows)} materials"
          + (f" ({', '.join(sorted(miss))})" if miss else "") + f"; on {len(explained)} of them"
          + (f" ({', '.join(sorted(explained))})" if explained else "")
          + " the measured slice is not rotationally symmetric (the truth's in-plane albedo more than 5 % from its "
            "whole-azimuth one) and the fit is within 5 % of the truth 5° from the normal: the miss is confined to "
            "the pole."]
    return "\n".join(L)


def write_docs(text: str, path: Path = DOCS) -> None:
    """Replace the block between :data:`BEGIN` and :data:`END` of ``path``
    (:func:`benchmarks.bench_fit_accuracy.write_docs`, which writes the page's other blocks)."""
    from benchmarks.bench_fit_accuracy import write_docs as write_block

    write_block(text + "\n", path, BEGIN, END)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_albedo_pole", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=os.environ.get("RBRDF_DATA", str(ROOT.parent / "shared" / "data")),
                    help="the data folder (its rgl/ files; default $RBRDF_DATA or ../shared/data)")
    ap.add_argument("--materials", nargs="+", default=["all"], help="RGL stems without _rgb (default all)")
    ap.add_argument("--fits", default=str(ROOT / "results" / "fit_accuracy"),
                    help="folder of the 3-D fits <stem>_rgb_3d.json (bench_fit_accuracy's --out); a material "
                         "without one is measured without its fit")
    ap.add_argument("--points", type=int, default=DEFAULT_POINTS,
                    help="quadrature points per angle (rounded to a square; default %(default)s)")
    ap.add_argument("--json", default=None, help="write the rows here")
    ap.add_argument("--docs", action="store_true", help="write the table into docs/fit_accuracy.md")
    args = ap.parse_args(argv)
    try:
        return _run(args)
    except BenchError as e:
        print(f"bench_albedo_pole: {e}", file=sys.stderr)
        return 2


def _run(args) -> int:
    from fit.errors import BRDFFileError
    from fit.formats.rgl import read_rgl
    from fit.rational.coefficient_file import load

    rgl = Path(args.data) / "rgl"
    if not rgl.is_dir():
        raise BenchError(f"--data {args.data}: no rgl/ folder (set RBRDF_DATA)")
    if not 100 <= args.points <= 4_000_000:
        raise BenchError(f"--points {args.points}: expected 100 to 4000000")
    names = (sorted(p.name[:-len("_rgb.bsdf")] for p in rgl.glob("*_rgb.bsdf")) if args.materials == ["all"]
             else list(args.materials))
    rows = {}
    for name in names:
        path = rgl / f"{name}_rgb.bsdf"
        if not path.is_file():
            raise BenchError(f"--materials {name}: no {path}")
        try:
            brdf = read_rgl(path)
            fit = Path(args.fits) / f"{name}_rgb_3d.json"
            model = load(fit) if fit.is_file() else None
        except BRDFFileError as e:
            raise BenchError(str(e)) from None
        rows[name] = measure(brdf, model, args.points)
        r = rows[name]
        print(f"{name:24s} spread {r['slice_spread']:.2f}  in-plane vs truth {_pct(r['in_plane_vs_truth'])}"
              + (f"  fit error {' / '.join(_pct(x) for x in r['fit_error'])}  fit vs in-plane "
                 f"{_pct(r['fit_vs_in_plane'])}" if model is not None else ""), flush=True)
    meta = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "points": int(args.points),
            "fits": os.path.relpath(args.fits, ROOT) if Path(args.fits).is_absolute() else args.fits}
    text = markdown(rows, meta)
    print(text)
    if args.json:
        from fit.outputs import atomic_write
        with atomic_write(Path(args.json)) as f:
            json.dump({"meta": meta, "rows": rows}, f, indent=1)
    if args.docs:
        write_docs(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
