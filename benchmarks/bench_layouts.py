"""Layouts and objectives of the 3-D fits judged by what users see: per RGL material, one 3-D fit
per (layout, objective) and its render's ΔE2000 (mean and p99 over the sphere) against the
converged ``rgl`` render of :mod:`benchmarks.bench_chart`, under both of its maps.

Layouts (:data:`LAYOUTS`; each one :func:`fit.rational.fit3d.fit_rgl_select` layout, verified
and given the albedo policy like the command's fits, with ``tol`` 0.01 as the command):

* ``p4``: four θh pieces (edges 0.05, 0.1, 0.2 rad; (4, 2), (5, 2), (5, 2), (4, 2); 666
  coefficients), the default before the six pieces;
* ``p6``: six θh pieces (edges 0.05, 0.1, 0.2, 0.4, 0.8 rad; (4, 2) then (5, 2); 1,125
  coefficients), the default before the seven pieces;
* ``p7``: the seven pieces of today's default (``fit.rational.fit3d.VARIANTS[0]``: ``p6`` with the
  last piece split at 1.15 rad; 1,323);
* ``p7peak``, ``p7mid``, ``p8``: ``p6`` with one more edge at 0.025 rad (the peak split; (4, 2) for
  both halves; 1,260), at 0.6 rad (1,323), and at both 0.6 and 1.15 rad (1,521): the other splits
  screened against ``p7`` (docs/fit_accuracy.md, "Seven pieces");
* ``single``: one piece of degrees (7, 3) (420; ``VARIANTS[1]``);
* ``m9``: nine pieces with a geometric ladder of edges from 0.004 rad (for near-mirror lobes;
  1,530 coefficients).

Objectives: ``Fit3DSettings.objective`` (docs/fitting.md, "The second stage's objective").
``--fit-dir LABEL=DIR`` adds the fit files of a folder (``DIR/<stem>*.json``, the newest) as a
column ``LABEL`` (e.g. the chart's fits). ``--image-check`` also computes each fit's own image
check (:func:`fit.rational.image_check.image_check`: a sphere under generic lights, no map of
the chart) and reports how well it ranks the columns as their renders do (Spearman over every
material and column of the mean ΔE, the renders' mean over the maps; and per material whether
the column the check puts first is the renders' best).
Fits are cached under ``<out>/fits/<layout>_<objective>/`` by material (delete a directory to
refit); the renders use each material kind's default sampler (``mis-rational`` when the file
carries its inverse CDFs, else ``mis-tabulated``), ``--spp`` spp at the truth's resolution,
seed 11; the truth is the chart's cache (``--chart-out``, made there when missing: ``--res`` px,
``--truth-spp`` spp). The render error holds the noise of ``--spp`` spp too: the ``rgl`` row
(the exact material at the same spp) is that floor.

    python -m benchmarks.bench_layouts --layouts p6 p7 --objectives rho_cos_cos relative
    python -m benchmarks.bench_layouts --materials chm_mint --layouts m9 --spp 256
    python -m benchmarks.bench_layouts --layouts p7 --set grazing_cos=0.1
    python -m benchmarks.bench_layouts --layouts p7 --objectives rho_cos_cos relative --fit-dir chart=results/chart/fits --image-check

Outputs: ``<out>/layouts.json`` (every fit's record and every render's errors) and
``<out>/layouts.md`` (one table: ΔE2000 mean / p99 per case and column, and per column the
cases with mean <= 1 and p99 <= 3). Progress lines on stderr.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
import types
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LAYOUTS = {
    "p4": {"theta_h_edges": [0.05, 0.1, 0.2], "piece_degrees": [(4, 2), (5, 2), (5, 2), (4, 2)]},
    "p6": {"theta_h_edges": [0.05, 0.1, 0.2, 0.4, 0.8], "piece_degrees": [(4, 2)] + [(5, 2)] * 5},
    "p7": None,        # fit.rational.fit3d.VARIANTS[0]
    "p7peak": {"theta_h_edges": [0.025, 0.05, 0.1, 0.2, 0.4, 0.8], "piece_degrees": [(4, 2)] * 2 + [(5, 2)] * 5},
    "p7mid": {"theta_h_edges": [0.05, 0.1, 0.2, 0.4, 0.6, 0.8], "piece_degrees": [(4, 2)] + [(5, 2)] * 6},
    "p8": {"theta_h_edges": [0.05, 0.1, 0.2, 0.4, 0.6, 0.8, 1.15], "piece_degrees": [(4, 2)] + [(5, 2)] * 7},
    "single": None,    # fit.rational.fit3d.VARIANTS[1] without its gate
    "m9": {"theta_h_edges": [0.004, 0.008, 0.016, 0.032, 0.064, 0.128, 0.256, 0.512],
           "piece_degrees": [(4, 2)] * 4 + [(5, 2)] * 5},
}


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def layout(name: str) -> dict:
    """The :func:`fit_rgl_select` layout (one dict of settings) called ``name``."""
    from fit.rational.fit3d import VARIANTS

    if name == "p7":
        return dict(VARIANTS[0])
    if name == "single":
        return {k: v for k, v in VARIANTS[1].items() if k != "if_rmse_below"}
    return dict(LAYOUTS[name])


def fit_file(bsdf: Path, lay: str, objective: str, out: Path, extra: dict | None = None) -> tuple[Path, dict]:
    """The cached or new fit of ``bsdf`` with layout ``lay``, ``objective`` and the further
    :class:`Fit3DSettings` values ``extra`` (``--set``): ``(file, record)``."""
    from fit.formats.rgl import read_rgl
    from fit.rational.coefficient_writer import save
    from fit.rational.fit3d import Fit3DSettings, fit_rgl_select

    path = out / "fits" / column(lay, objective, extra).replace("/", "_") / f"{bsdf.stem}.json"
    rec_path = path.with_suffix(".record.json")
    if path.is_file() and rec_path.is_file():
        return path, json.loads(rec_path.read_text())
    path.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.process_time()
    res = fit_rgl_select(read_rgl(bsdf), (layout(lay),),
                         settings=Fit3DSettings(tol=0.01, objective=objective, **(extra or {})))
    rec = {"cpu_s": time.process_time() - t0, "coefficients": int(res.n_coefficients), "bound": float(res.tolerance),
           "valid": bool(res.valid), "validation_rmse": float(res.validation_rmse),
           "validation_score": float(res.validation_score)}
    save(res.model, path)
    rec_path.write_text(json.dumps(rec))
    return path, rec


def column(lay: str, objective: str, extra: dict | None) -> str:
    """The name of a fit's column: ``layout/objective`` and the ``--set`` values."""
    return "/".join([lay, objective] + [f"{k}={v:g}" for k, v in sorted((extra or {}).items())])


def settings_values(pairs) -> dict:
    """``--set NAME=VALUE`` pairs as numbers, each a field of :class:`Fit3DSettings`."""
    from fit.rational.fit3d import Fit3DSettings

    names = set(Fit3DSettings().get_params())
    out = {}
    for p in pairs or ():
        name, _, value = p.partition("=")
        if name not in names or name in ("objective", "theta_h_edges", "piece_degrees", "degrees"):
            raise SystemExit(f"bench_layouts: --set {p}: not a numeric Fit3DSettings field")
        try:
            v = float(value)
            out[name] = int(v) if v.is_integer() and "." not in value and "e" not in value.lower() else v
        except ValueError:
            raise SystemExit(f"bench_layouts: --set {p}: VALUE must be a number") from None
    return out


def parse(argv):
    from fit.rational.samples3d import OBJECTIVES

    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_layouts", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="+", default=None, help="RGL file stems without _rgb (default: every shared file)")
    ap.add_argument("--layouts", nargs="+", choices=tuple(LAYOUTS), default=["p6", "p7"])
    ap.add_argument("--objectives", nargs="+", choices=OBJECTIVES, default=["rho_cos_cos"])
    ap.add_argument("--set", nargs="+", default=None, metavar="NAME=VALUE",
                    help="further numeric Fit3DSettings values of every fit (e.g. grazing_cos=0.1), part of "
                         "the column's name and cache folder")
    ap.add_argument("--fit-dir", nargs="+", default=[], metavar="LABEL=DIR",
                    help="also render the fit files of DIR (DIR/<stem>*.json, the newest) as column LABEL")
    ap.add_argument("--image-check", action="store_true",
                    help="also each fit's image check (fit.rational.image_check) and its agreement with the renders")
    ap.add_argument("--maps", nargs="+", choices=("studio", "rooitou"), default=["studio", "rooitou"])
    ap.add_argument("--spp", type=int, default=1024, help="spp of each fit's render (default 1024)")
    ap.add_argument("--res", type=int, default=64, help="image side in px, the truth's (default 64)")
    ap.add_argument("--truth-spp", type=int, default=2048, help="spp of the chart's truth (default 2048)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--chart-out", type=Path, default=ROOT / "results" / "chart", help="the chart's output folder (its truth cache)")
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "layouts")
    a = ap.parse_args(argv)
    for fd in a.fit_dir:
        if "=" not in fd or not Path(fd.partition("=")[2]).is_dir():
            ap.error(f"--fit-dir {fd}: expected LABEL=DIR with DIR a folder")
    if not (8 <= a.res <= 512 and 2 <= a.spp <= 8192 and a.truth_spp >= 2 and a.truth_spp % 2 == 0):
        ap.error("--res 8..512, --spp 2..8192, --truth-spp an even number >= 2")
    return a


def main(argv=None) -> int:
    a = parse(argv)
    from benchmarks import bench_chart as BC
    from lab import mitsuba_reference as MR
    from studies import metrics as M
    from studies.fidelity import rim_band
    from warp_rbrdf.renderer import Renderer

    data = Path(os.environ.get("RBRDF_DATA", ROOT.parent / "shared" / "data"))
    mats = a.materials or sorted(p.name[:-len("_rgb.bsdf")] for p in (data / "rgl").glob("*_rgb.bsdf"))
    extra = settings_values(a.set)
    cols = [(lay, obj) for lay in a.layouts for obj in a.objectives]
    res_path = a.out / "layouts.json"
    res = json.loads(res_path.read_text()) if res_path.is_file() else {"fits": {}, "renders": {}}
    ta = types.SimpleNamespace(res=a.res, truth_spp=a.truth_spp, threads=a.threads)
    mask = MR.sphere_mask(a.res)
    band = rim_band(a.res, mask)
    for mat in mats:
        bsdf = data / "rgl" / f"{mat}_rgb.bsdf"
        if not bsdf.is_file():
            log(f"bench_layouts: {bsdf}: no such file")
            return 2
        files = {}                                  # column name -> fit file
        for lay, obj in cols:
            col = column(lay, obj, extra)
            files[col], rec = fit_file(bsdf, lay, obj, a.out, extra)
            res["fits"][f"{mat}/{col}"] = rec
            log(f"{mat} {col}: {rec['coefficients']} coefficients, validation RMSE {rec['validation_rmse']:.4f}, "
                f"{rec['cpu_s']:.0f} CPU s")
        for fd in a.fit_dir:
            label, _, d = fd.partition("=")
            found = sorted((p for p in Path(d).glob(f"{bsdf.stem}*.json") if not p.name.endswith(".record.json")),
                           key=lambda p: p.stat().st_mtime)
            if found:
                files[label] = found[-1]
        if a.image_check:
            from fit.formats.rgl import read_rgl
            from fit.rational.coefficient_reader import load
            from fit.rational.image_check import image_check

            brdf = read_rgl(bsdf)
            for col, f in files.items():
                res.setdefault("image_check", {})[f"{mat}/{col}"] = ic = image_check(brdf, load(f))
                log(f"  image check {col}: ΔE2000 mean {ic['mean']:.2f} p99 {ic['p99']:.1f}")
        for map_name in a.maps:
            env = data / BC.MAPS[map_name]
            base = MR.sphere_scene(bsdf, env, a.truth_spp, a.res, pattern=BC.OUR_PATTERN)
            ref = BC.truth(bsdf, env, base, ta, a.chart_out)["img"]
            expo = M.exposure_for(ref, mask)
            specs = [("rgl", BC.spec_for("rgl", bsdf, None)[0])]
            specs += [(col, BC.spec_for("rational-3d", bsdf, f)[0]) for col, f in files.items()]
            for col, spec in specs:
                r = Renderer(BC.scene_with(base, spec), device="cpu")
                r.compile()
                img = np.asarray(r.render(spp=a.spp, seed=11, threads=a.threads), np.float64)
                e = BC.errors(img, ref, mask, expo, band)
                res["renders"][f"{mat}/{map_name}/{col}"] = dict(e, spp=a.spp)
                log(f"  {map_name} {col}: ΔE2000 mean {e['de_mean']:.2f} p99 {e['de_p99']:.1f} "
                    f"(rim {e['de_rim']:.2f}, inner {e['de_inner']:.2f})")
        a.out.mkdir(parents=True, exist_ok=True)
        res_path.write_text(json.dumps(res, indent=1))
    names = [column(lay, obj, extra) for lay, obj in cols] + [fd.partition("=")[0] for fd in a.fit_dir]
    text = report(res, mats, a.maps, ["rgl"] + names)
    if a.image_check:
        text += "\n" + agreement(res, mats, a.maps, names)
    (a.out / "layouts.md").write_text(text)
    log(f"wrote {res_path} and {a.out / 'layouts.md'}")
    return 0


def report(res: dict, mats, maps, cols) -> str:
    """The markdown table of :func:`main`'s results."""
    R = res["renders"]
    L = ["| material | map | " + " | ".join(cols) + " |", "| --- | --- |" + " --- |" * len(cols)]
    for m in mats:
        for mp in maps:
            cells = [R.get(f"{m}/{mp}/{c}") for c in cols]
            L.append(f"| {m} | {mp} | " + " | ".join(f"{e['de_mean']:.2f} / {e['de_p99']:.1f}" if e else "–"
                                                    for e in cells) + " |")
    tot = []
    for c in cols:
        v = [R[f"{m}/{mp}/{c}"] for m in mats for mp in maps if f"{m}/{mp}/{c}" in R]
        tot.append(f"{sum(e['de_mean'] <= 1 for e in v)} / {sum(e['de_p99'] <= 3 for e in v)} of {len(v)}")
    L.append("| mean ≤ 1 / p99 ≤ 3 | | " + " | ".join(tot) + " |")
    return "\n".join(L) + "\n"


def agreement(res: dict, mats, maps, cols) -> str:
    """How the image check ranks the columns against their renders (module docstring)."""
    from scipy.stats import spearmanr

    R, C = res["renders"], res.get("image_check", {})
    xs, ys, best, n = [], [], 0, 0
    for m in mats:
        pairs = []
        for c in cols:
            r = [R.get(f"{m}/{mp}/{c}") for mp in maps]
            if f"{m}/{c}" in C and all(r):
                pairs.append((c, C[f"{m}/{c}"]["mean"], float(np.mean([e["de_mean"] for e in r]))))
        xs += [p[1] for p in pairs]
        ys += [p[2] for p in pairs]
        if len(pairs) > 1:
            n += 1
            best += min(pairs, key=lambda p: p[1])[0] == min(pairs, key=lambda p: p[2])[0]
    rho = spearmanr(xs, ys).statistic if len(xs) > 2 else float("nan")
    return (f"Image check against the renders: Spearman {rho:.2f} over {len(xs)} fits; the check's first "
            f"column is the renders' best on {best} of {n} materials.\n")


if __name__ == "__main__":
    sys.exit(main())
