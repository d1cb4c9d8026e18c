"""Proved bounds between the data points on every shared RGL material
(:mod:`fit.rational.proved_bound`; docs/fit_accuracy.md, "Proved bounds between the data points").

Per material, per piece and channel: the proved bound (``proved``), the part of the measured
domain where the proved cell bound is within the tolerance (``proved_fraction``), the largest
error observed (``verified``, at the cell centres) and the proof's wall seconds, for

* ``2d``: the 2-D fit at ``--tol`` (5 %): the shipped file (``warp_rbrdf/data/<stem>.json`` of that
  tolerance, checked against the RGL file's SHA-256 it records), else a cached
  ``<stem>_tol0p05_cli.json`` in ``--fits-2d`` (``results/fits``, what ``rbrdf-fit brdf FILE --tol
  0.05`` and :mod:`studies.fits` write), else a new :func:`fit.rational.brdf_fit.fit_brdf` with the
  command line's defaults (:class:`fit.rational.settings.BRDFFitSettings`), saved there. The
  projection it is proved against is rebuilt from the RGL file as the fitter builds it
  (:func:`fit.rational.brdf_data.project_for_fit`: median, 79 deg grazing cut-off), cached in
  ``--cache`` (``results/proved_bound/proj``);
* ``3d``: 3-D fits: the chart's 3-D fit in ``--fits-3d`` (``results/chart/fits``,
  :mod:`benchmarks.chart_fits`; :func:`chart_fit_3d`: the file of the chart's key of today's
  fitter defaults, else the newest made with today's layouts and settings as the fit records
  them; never a fit of earlier defaults such as the four-piece layout; the source column names
  the file), else, with ``--fit-3d``, a small-budget :func:`fit.rational.fit3d.fit_rgl`
  (:data:`SMALL_3D`), saved to ``--cache``.

``--enclosure`` picks the proof's enclosure (:data:`fit.rational.proved_bound.ENCLOSURES`;
``both``: each in turn on the same fits, for before/after). ``--docs`` writes the table into
docs/fit_accuracy.md between its markers.

    python -m benchmarks.bench_proved_bound --materials paper_white satin_rosaline
    python -m benchmarks.bench_proved_bound --enclosure both --fit-3d --docs
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "proved_bound"
DOCS = ROOT / "docs" / "fit_accuracy.md"
MARK = ("<!-- bench_proved_bound: begin -->", "<!-- bench_proved_bound: end -->")
#: The small-budget 3-D fit (fit.rational.fit3d.fit_rgl keyword arguments) made with --fit-3d.
SMALL_3D = dict(tol=0.05, verify=0, albedo=False, time_limit=60.0)
#: The accuracy targets per class of material (docs/fit_accuracy.md): matte and satin 10 %, the
#: glossy films (TeckWrap vinyl, metallic paint) 25 %.
MATTE_SATIN = ("acrylic_felt_green", "acrylic_felt_pink", "acrylic_felt_purple", "cardboard",
               "colodur_azure_4e", "colodur_connemara_4c", "colodur_napoli_4f", "ilm_l3_37_matte",
               "paper_blue", "paper_white", "satin_purple", "satin_rosaline")


def target(material: str) -> float:
    return 0.10 if material in MATTE_SATIN else 0.25


def data_dir() -> Path:
    return Path(os.environ.get("RBRDF_DATA", ROOT.parent / "shared" / "data")) / "rgl"


def all_materials() -> list:
    return sorted(p.name[:-len("_rgb.bsdf")] for p in data_dir().glob("*_rgb.bsdf"))


def _tag(tol: float) -> str:
    return f"{tol:g}".replace(".", "p")


def projection(stem: str, cache: Path):
    """The projection a 2-D fit of the RGL file ``stem`` is made from, cached as ``.npz``."""
    from fit.projection.projected import ProjectedBRDF
    p = cache / "proj" / f"{stem}.npz"
    if p.exists():
        return ProjectedBRDF.load(p)
    from fit.formats import load_measured
    from fit.rational.brdf_data import project_for_fit
    proj = project_for_fit(load_measured(data_dir() / f"{stem}.bsdf"))
    p.parent.mkdir(parents=True, exist_ok=True)
    proj.save(p)
    return proj


def model_2d(stem: str, tol: float, fits_dir: Path, fit_timeout: float):
    """``(model, source)``: the 2-D fit of ``stem`` at ``tol`` (module docstring), or
    ``(None, why)``."""
    from fit.formats.measured import file_sha256
    from fit.rational.coefficient_file import load
    from warp_rbrdf.paths import PACKAGE_DATA
    sha = file_sha256(data_dir() / f"{stem}.bsdf")
    for p in sorted(PACKAGE_DATA.glob(f"{stem}*.json")):
        m = load(p)
        if m.fit_info.get("kind") != "3d" and abs(float(m.fit_info.get("tolerance", -1)) - tol) < 1e-12:
            src = getattr(m, "source", None) or {}
            if isinstance(src, dict) and src.get("sha256") not in (None, sha):
                continue
            return m, f"shipped ({p.name})"
    p = fits_dir / f"{stem}_tol{_tag(tol)}_cli.json"
    if not p.exists():
        cmd = [sys.executable, "-m", "fit.cli", "brdf", str(data_dir() / f"{stem}.bsdf"), "--model", "2d",
               "--tol", str(tol), "--out", str(p), "--allow-infeasible", "--no-sampler", "--no-progress"]
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=fit_timeout, cwd=ROOT)
        except subprocess.TimeoutExpired:
            return None, f"no 2-D fit: rbrdf-fit brdf ran past {fit_timeout:g} s"
        if not p.exists():
            return None, f"no 2-D fit: {(r.stderr or r.stdout).strip().splitlines()[-1:]}"
        return load(p), f"fitted ({p.name})"
    return load(p), f"cached ({p.name})"


#: Settings a 3-D fit records in its ``fit_info`` (name there: name in
#: :class:`fit.rational.settings.Fit3DSettings`) that :func:`chart_fit_3d` checks against the defaults.
_RECORDED = {"grazing_cos": "grazing_cos", "channel_floor": "channel_floor", "objective": "objective",
             "relative_floor": "relative_floor", "noise_frac": "noise_frac", "theta_max_deg": "theta_fit_deg",
             "time_limit": "time_limit", "wall_limit": "wall_limit"}


def _plain(x):
    return json.loads(json.dumps(x))


def todays_layouts() -> list:
    """The layouts a 3-D fit with the fitter's defaults tries (:data:`fit.rational.select3d.VARIANTS`),
    as its ``fit_info["variants"][i]["options"]`` records them (without the selection's own
    settings)."""
    from fit.rational.select3d import _SELECT_SETTINGS, SELECTION_KEYS, VARIANTS
    return [_plain({k: v for k, v in d.items() if k not in SELECTION_KEYS and k not in _SELECT_SETTINGS})
            for d in VARIANTS]


def is_todays_fit(fit_info: dict) -> bool:
    """Whether a 3-D fit (its ``fit_info``) was made with the fitter's defaults of today as far as
    the fit records them: the layouts it tried (:func:`todays_layouts`) and :data:`_RECORDED`."""
    from fit.rational.settings import Fit3DSettings
    d = Fit3DSettings()
    today = todays_layouts()
    keys = {k for v in today for k in v}     # a skipped layout's log also holds the command's settings (--tol)
    tried = [{k: x for k, x in _plain(v.get("options") or {}).items() if k in keys}
             for v in fit_info.get("variants") or []]
    return (tried == today
            and all(k in fit_info and _plain(fit_info[k]) == _plain(getattr(d, a)) for k, a in _RECORDED.items()))


def chart_fit_3d(stem: str, fits_dir: Path):
    """``(path, how)``: the 3-D fit of ``stem`` in ``fits_dir`` that the chart renders, picked
    deterministically, or ``(None, why)``:

    1. the chart's own cache file (:func:`benchmarks.chart_fits.fit3d_path`: its key is the
       measured file's SHA-256, the command's flags and the fitter's defaults of today);
    2. else (the chart's key moved on with a setting that does not change the coefficients, e.g.
       ``image_check``, and the chart has not refitted yet) the files of ``stem`` whose fit was
       made with today's defaults as far as it records them (:func:`is_todays_fit`: the layouts
       tried and the recorded settings), the newest of them (modification time, then name).

    Other files (fits of earlier defaults: the four-piece layout) are never used."""
    from benchmarks.chart_fits import fit3d_path
    chart = fit3d_path(data_dir() / f"{stem}.bsdf", fit_dir=fits_dir)
    if chart.exists():
        return chart, "the chart's key of today's fitter defaults"
    files = sorted(fits_dir.glob(f"{stem}_3d_*.json")) if fits_dir.is_dir() else []
    today = []
    for p in files:
        fi = json.loads(p.read_text()).get("fit") or {}
        if is_todays_fit(fi):
            today.append(p)
    if not today:
        return None, (f"no 3-D fit of today's fitter defaults ({chart.name} not cached; "
                      f"{len(files)} fit(s) of other defaults left out)")
    p = max(today, key=lambda q: (q.stat().st_mtime, q.name))
    return p, (f"today's layouts and settings; the chart's key is now {chart.stem.rsplit('_', 1)[-1]} "
               f"(not cached); {len(files) - 1} other file(s) left out")


def model_3d(stem: str, fits_dir: Path, cache: Path, fit_small: bool):
    """``(result, brdf, source)``: a 3-D fit of ``stem`` as :func:`fit.rational.proved_bound.prove_fit3d`
    reads it, or ``(None, None, why)``."""
    from fit.formats.rgl import read_rgl
    from fit.rational.coefficient_file import load, save
    from fit.rational.proved_bound import leaves
    path, how = chart_fit_3d(stem, fits_dir)
    small = cache / "fits3d" / f"{stem}_3d_small.json"
    brdf = read_rgl(data_dir() / f"{stem}.bsdf")
    if path is not None:
        m, src = load(path), f"cached ({path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}; {how})"
    elif small.exists():
        m, src = load(small), f"small budget, cached ({small.name})"
    elif fit_small:
        from fit.rational.fit3d import fit_rgl
        res = fit_rgl(brdf, **SMALL_3D)
        small.parent.mkdir(parents=True, exist_ok=True)
        save(res.model, small)
        m, src = res.model, f"small budget, fitted ({small.name})"
    else:
        return None, None, "no 3-D fit (--fit-3d makes a small-budget one)"
    fi = m.fit_info
    recs = [{"piece": k, "channel": "RGB"[c], "tolerance": float(leaf.function_info[c]["tolerance"])}
            for k, leaf in enumerate(leaves(m)) for c in range(3)]
    from fit.rational.settings import Fit3DSettings
    grid = tuple(fi.get("grid") or Fit3DSettings().grid)      # a file without it: the default grid
    if "grid" not in fi:
        src += f", grid {grid} (the default; the file records none)"
    res = SimpleNamespace(model=m, data=None, settings=SimpleNamespace(grid=grid), noise=tuple(fi["noise"]),
                          records=recs)
    return res, brdf, src


def _rows(bounds, model) -> list:
    """The records of ``bounds`` with their status and whether the fit flags the function
    (:func:`fit.rational.model.flagged`: not within its intervals at its data points; the renderer
    shows the projected table there)."""
    from fit.rational.model import flagged
    from fit.rational.proved_bound import leaves
    lv = leaves(model)
    return [dict(b.record(), unit=None, status=b.status,
                 flagged=bool(flagged(lv[b.piece].function_info["RGB".index(b.channel)])
                              if lv[b.piece].function_info else False)) for b in bounds]


def _summary(bounds, model) -> dict:
    """:func:`fit.rational.proved_bound.summary` and the same over the functions the fit does
    not flag (``vouched``)."""
    from fit.rational import proved_bound as pb
    rows = _rows(bounds, model)
    keep = [b for b, r in zip(bounds, rows) if not r["flagged"]]
    v = pb.summary(keep) if keep else {"proved": None, "proved_fraction": None, "verified": None}
    return {**pb.summary(bounds), "vouched": {k: v[k] for k in ("proved", "proved_fraction", "verified")},
            "flagged": [f"piece {r['piece']} {r['channel']}" for r in rows if r["flagged"]], "bounds": rows}


def unit_2d(model, c: int):
    """The error unit of :data:`fit.rational.proved_bound.UNIT_2D` at interpolant values (N, C)."""
    floor = float(model.fit_info["abs_floor"][c]) / float(model.fit_info["tolerance"])
    return lambda m: np.maximum(m[:, c], floor)


def unit_3d(res, c: int):
    """The error unit of :data:`fit.rational.proved_bound.UNIT_3D` at interpolant values (N, C)."""
    from fit.rational.settings import DEFAULT_CHANNEL_FLOOR
    cf = float(res.model.fit_info.get("channel_floor", DEFAULT_CHANNEL_FLOOR))
    noise = float(res.noise[c])
    return lambda m: np.maximum(np.maximum(m[:, c], noise), cf * m.max(axis=1))


def gap(bound, leaf, unit, n: int = 33) -> dict:
    """Where ``bound`` (a :class:`fit.rational.proved_bound.ProvedBound`) comes from: on its
    worst cells (``worst_cells``), the largest error at ``n`` points per axis (a dense grid of
    each cell, the interpolant multilinear, ``unit`` the error unit at the points) against the
    cell's proved bound, and the range of P/Q there against its Bernstein enclosure.
    ``dense_max`` close to ``proved``: the error between the nodes is real (only another fit
    lowers it); far below it: the enclosure is loose."""
    from fit.rational.cell_enclosure import Enclosure
    from fit.rational.proved_bound import _leaf_output, _multilinear
    w = bound.worst_cells
    c = "RGB".index(bound.channel)
    fn = leaf.functions[c]
    k = w["lo"].shape[1]
    g = np.linspace(0.0, 1.0, n)
    loc = np.stack(np.meshgrid(*([g] * k), indexing="ij"), -1).reshape(-1, k)
    dom = fn.domain
    enc = Enclosure(fn)
    out = []
    for i in range(len(w["bound"])):
        x = w["lo"][i] + loc * (w["hi"][i] - w["lo"][i])
        m = _multilinear(np.repeat(w["corners"][i][None], len(loc), axis=0), loc)
        r = fn(x)
        err = np.abs(_leaf_output(leaf, c, r) - m[:, c]) / unit(m)
        t = lambda z: ((2.0 * z - (dom[:, 0] + dom[:, 1])) / (dom[:, 1] - dom[:, 0]))[None]  # noqa: E731
        rl, rh = enc.ratio(np.clip(t(w["lo"][i]), -1, 1), np.clip(t(w["hi"][i]), -1, 1))
        out.append({"cell_bound": float(w["bound"][i]), "dense_max": float(err.max()),
                    "pq_range": float(r.max() - r.min()), "pq_enclosure": float(rh[0] - rl[0])})
    best = max(out, key=lambda d: d["dense_max"]) if out else {}
    return {"piece": bound.piece, "channel": bound.channel, "proved": bound.proved,
            "dense_max_worst_cells": best.get("dense_max"), "cells": out}


def run(args) -> dict:
    from fit.rational import proved_bound as pb
    encl = list(pb.ENCLOSURES) if args.enclosure == "both" else [args.enclosure]
    fits_2d, fits_3d, cache = Path(args.fits_2d), Path(args.fits_3d), Path(args.cache)
    out = {"date": datetime.date.today().isoformat(), "load": os.getloadavg(), "tol": args.tol,
           "enclosures": encl, "materials": {}}
    if args.merge and Path(args.out).exists():      # an earlier run's rows for the materials not run now
        old = json.loads(Path(args.out).read_text())
        if old.get("enclosures") == encl and old.get("tol") == args.tol:
            out["materials"] = old["materials"]
            out["runs"] = old.get("runs") or [_run_record(old)]
    for mat in args.materials:
        stem = f"{mat}_rgb"
        prev = out["materials"].get(mat, {})
        row = out["materials"][mat] = {"target": target(mat)}
        for kind in ("2d", "3d"):
            if kind not in args.models and kind in prev:
                row[kind] = prev[kind]
        if "2d" in args.models:
            m, src = model_2d(stem, args.tol, fits_2d, args.fit_timeout)
            row["2d"] = {"source": src}
            if m is not None:
                proj = projection(stem, cache)
                row["2d"]["coefficients"] = int(sum(np.size(f.num_coef) + np.size(f.den_coef)
                                                    for leaf in pb.leaves(m) for f in leaf.functions))
                for e in encl:
                    t0 = time.perf_counter()
                    b = pb.prove_brdf(m, proj, enclosure=e)
                    row["2d"][e] = {"wall_s": time.perf_counter() - t0, **_summary(b, m)}
                    print(f"{mat} 2d {e}: {_line(row['2d'][e])}", flush=True)
                    if args.gap:
                        w = max(b, key=lambda x: np.inf if x.proved is None else x.proved)
                        row["2d"][e]["gap"] = gap(w, pb.leaves(m)[w.piece], unit_2d(m, "RGB".index(w.channel)))
                        print(f"  gap: {_gap_line(row['2d'][e]['gap'])}", flush=True)
            else:
                print(f"{mat} 2d: {src}", flush=True)
        if "3d" in args.models:
            res, brdf, src = model_3d(stem, fits_3d, cache, args.fit_3d)
            row["3d"] = {"source": src}
            if res is not None:
                row["3d"]["coefficients"] = int(sum(np.size(f.num_coef) + np.size(f.den_coef)
                                                    for leaf in pb.leaves(res.model) for f in leaf.functions))
                row["3d"]["stated"] = max(r["tolerance"] for r in res.records)
                for e in encl:
                    t0 = time.perf_counter()
                    b = pb.prove_fit3d(res, brdf, enclosure=e)
                    row["3d"][e] = {"wall_s": time.perf_counter() - t0, **_summary(b, res.model)}
                    print(f"{mat} 3d {e}: {_line(row['3d'][e])}", flush=True)
                    if args.gap:
                        w = max(b, key=lambda x: np.inf if x.proved is None else x.proved)
                        row["3d"][e]["gap"] = gap(w, pb.leaves(res.model)[w.piece],
                                                  unit_3d(res, "RGB".index(w.channel)), n=17)
                        print(f"  gap: {_gap_line(row['3d'][e]['gap'])}", flush=True)
                if args.grazing:
                    t0 = time.perf_counter()
                    b = pb.prove_fit3d(res, brdf, enclosure="joint", grazing=True)
                    row["3d"]["grazing"] = {"wall_s": time.perf_counter() - t0, **_summary(b, res.model)}
                    print(f"{mat} 3d joint, grazing weight: {_line(row['3d']['grazing'])}", flush=True)
            else:
                print(f"{mat} 3d: {src}", flush=True)
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(out, indent=1))
    out["load_end"] = os.getloadavg()
    if "runs" in out:       # merged: this run listed after the earlier ones, with its own materials
        out["runs"].append(dict(_run_record(out), materials={m: sorted(k for k in args.models if k in out["materials"][m])
                                                             for m in args.materials}))
    Path(args.out).write_text(json.dumps(out, indent=1))
    return out


def _run_record(r: dict) -> dict:
    """A run's entry of ``runs`` (what :func:`write_docs` lists): date, loads, and per material
    the models it holds."""
    return {"date": r["date"], "load": r["load"], "load_end": r.get("load_end", r["load"]),
            "materials": {m: sorted(k for k in row if k in ("2d", "3d")) for m, row in r["materials"].items()}}


def _pct(x) -> str:
    return "none" if x is None else f"{100 * x:.3g} %"


def _frac(x) -> str:
    """A part of the domain: one short of all of it is not printed as 100 %."""
    return "> 99.9 %" if x is not None and 0.999 < x < 1.0 else _pct(x)


def _gap_line(g) -> str:
    c = max(g["cells"], key=lambda d: d["cell_bound"]) if g["cells"] else {}
    return (f"piece {g['piece']} {g['channel']}: proved {_pct(g['proved'])}, dense max on its "
            f"{len(g['cells'])} worst cells {_pct(g['dense_max_worst_cells'])}; worst cell: bound "
            f"{_pct(c.get('cell_bound'))}, dense {_pct(c.get('dense_max'))}, P/Q range {c.get('pq_range', 0):.3g} "
            f"enclosed in {c.get('pq_enclosure', 0):.3g}")


def _line(r) -> str:
    return (f"proved {_pct(r['proved'])}, within tol on {_frac(r['proved_fraction'])}, verified "
            f"{_pct(r['verified'])}, {r['wall_s']:.1f} s")


def main(argv=None):
    from fit.rational.proved_bound import ENCLOSURES
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_proved_bound", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--materials", nargs="+", default=None, help="RGL material names (default: all shared)")
    ap.add_argument("--models", nargs="+", default=["2d", "3d"], choices=["2d", "3d"])
    ap.add_argument("--tol", type=float, default=0.05, help="the 2-D fits' tolerance (default 0.05)")
    ap.add_argument("--enclosure", default=ENCLOSURES[-1], choices=list(ENCLOSURES) + ["both"])
    ap.add_argument("--fits-2d", default=str(ROOT / "results" / "fits"))
    ap.add_argument("--fits-3d", default=str(ROOT / "results" / "chart" / "fits"))
    ap.add_argument("--cache", default=str(RESULTS))
    ap.add_argument("--fit-3d", action="store_true", help="make a small-budget 3-D fit where none is cached")
    ap.add_argument("--fit-timeout", type=float, default=900.0, help="seconds per new 2-D fit")
    ap.add_argument("--out", default=str(RESULTS / "results.json"))
    ap.add_argument("--gap", action="store_true",
                    help="on the worst piece and channel, the error at dense points of its worst cells")
    ap.add_argument("--grazing", action="store_true",
                    help="3-D: also the joint bound in the unit of the stated tolerance (grazing weight)")
    ap.add_argument("--merge", action="store_true",
                    help="keep the rows of --out for the materials (and models) not run now")
    ap.add_argument("--docs", action="store_true", help="write the table into docs/fit_accuracy.md")
    ap.add_argument("--from-json", nargs="+", default=None, metavar="FILE",
                    help="no run: merge the rows of these results files (later files win per material and "
                         "model) and print (with --docs: write) their tables")
    args = ap.parse_args(argv)
    args.materials = args.materials or all_materials()
    out = merged(args.from_json) if args.from_json else run(args)
    if args.from_json:
        print(table(out))
    if args.docs:
        write_docs(out)


def _verdict(r, tgt: float) -> str:
    """The bound against the material's target: met, met on the functions the fit vouches for,
    or missed and why (:attr:`fit.rational.proved_bound.ProvedBound.status`)."""
    allp, v = r["proved"], r["vouched"]
    if allp is not None and allp <= tgt:
        return "met"
    if v["proved"] is not None and v["proved"] <= tgt:
        return f"met where vouched ({', '.join(r['flagged'])} flagged)"
    worst = v if v["proved"] is not None else r
    if worst["verified"] is not None and worst["verified"] > tgt:
        return f"missed: the fit's error between the nodes (verified {_pct(worst['verified'])})"
    return "missed: the proof's budget"


def _verdict_3d(r3, tgt: float, last: str) -> str:
    """A 3-D bound against the material's target, in the unit of the fit's stated tolerance (the
    ``--grazing`` row; without it, the row of ``last``): met, met where vouched, or missed and why:
    the fit's stated tolerance (its bound at its own data points) above the target already, else
    the fit's error between the nodes, else the proof's budget."""
    g = r3.get("grazing") or r3[last]
    allp, v = g["proved"], g["vouched"]
    if allp is not None and allp <= tgt:
        return "met"
    if v["proved"] is not None and v["proved"] <= tgt:
        return f"met where vouched ({', '.join(g['flagged'])} flagged)"
    if r3.get("stated") is not None and r3["stated"] > tgt:
        return f"missed: the fit's stated tolerance {_pct(r3['stated'])} is above it"
    worst = v if v["proved"] is not None else g
    if worst["verified"] is not None and worst["verified"] > tgt:
        return f"missed: the fit's error between the nodes (verified {_pct(worst['verified'])})"
    return "missed: the proof's budget"


def _found(r) -> str:
    """The largest error found at dense points of the worst cells (``--gap``): observed, so a
    lower bound of the true largest error, like ``verified``."""
    g = r.get("gap")
    return _pct(g["dense_max_worst_cells"]) + f" ({g['piece']} {g['channel']})" if g else "n/a"


def _arrow(r, key, encl) -> str:
    fmt = _frac if key == "proved_fraction" else _pct
    return " → ".join(fmt(r[e][key]) for e in encl if e in r)


def merged(files) -> dict:
    """The runs of ``files`` in one (their dates and loads listed in ``runs``)."""
    runs = [json.loads(Path(f).read_text()) for f in files]
    out = dict(runs[0], materials={}, runs=[])
    for r in runs:
        assert r["enclosures"] == out["enclosures"], "runs with different enclosures"
        out["runs"].append(_run_record(r))
        for m, row in r["materials"].items():
            out["materials"].setdefault(m, {}).update(row)
    return out


def _source_3d(src: str) -> str:
    """A 3-D row's source in the table: the cached file's name (how it was picked and the grid it
    was proved on stay in the results' ``source``)."""
    m = re.match(r"cached \((?:[^;)]*/)?([^/;)]+\.json)", src)
    return f"`{m.group(1)}`" if m else src


def table(out) -> str:
    """The markdown tables of a run: 2-D fits, then 3-D fits."""
    encl = out["enclosures"]
    last = encl[-1]
    lines = ["| material | target | 2-D fit at 5 % | coefficients | proved, " + " → ".join(encl)
             + " | proved where vouched | within 5 %, " + " → ".join(encl) + " | verified (points) | found on the "
             "worst cells | proof s, " + " → ".join(encl) + " | against the target |",
             "| " + " | ".join(["---"] * 11) + " |"]
    rows3 = []
    for mat, row in out["materials"].items():
        r = row.get("2d")
        if r is not None and last in r:
            pts = sum(b["verified_points"] for b in r[last]["bounds"])
            lines.append(f"| {mat} | {_pct(row['target'])} | {r['source']} | {r.get('coefficients', '')} | "
                         f"{_arrow(r, 'proved', encl)} | {_pct(r[last]['vouched']['proved'])} | "
                         f"{_arrow(r, 'proved_fraction', encl)} | {_pct(r[last]['verified'])} ({pts:,}) | "
                         f"{_found(r[last])} | "
                         + " → ".join(f"{r[e]['wall_s']:.1f}" for e in encl if e in r)
                         + f" | {_verdict(r[last], row['target'])} |")
        elif r is not None:
            lines.append(f"| {mat} | {_pct(row['target'])} | {r['source']} |" + " |" * 8)
        r3 = row.get("3d")
        if r3 is not None and last in r3:
            g = r3.get("grazing")
            rows3.append(f"| {mat} | {_source_3d(r3['source'])} | {r3.get('coefficients', '')} | {_pct(r3.get('stated'))} | "
                         f"{_arrow(r3, 'proved', encl)} | {_pct(g['proved']) if g else 'n/a'} | "
                         f"{_arrow(r3, 'proved_fraction', encl)} | {_frac(g['proved_fraction']) if g else 'n/a'} | "
                         f"{_pct(r3[last]['verified'])} | {_found(r3[last])} | {_pct(g['verified']) if g else 'n/a'} | "
                         + " → ".join(f"{r3[e]['wall_s']:.0f}" for e in encl if e in r3)
                         + (f", {g['wall_s']:.0f}" if g else "") + f" | {_pct(row['target'])} | "
                         f"{_verdict_3d(r3, row['target'], last)} |")
    if rows3:
        lines += ["", "| material | 3-D fit | coefficients | stated tolerance | proved (no grazing weight), "
                  + " → ".join(encl) + " | proved in the stated unit | within the stated tolerance, "
                  + " → ".join(encl) + " | … in the stated unit | verified | found on the worst cells | verified in "
                  "the stated unit | proof s | target | against the target (stated unit) |",
                  "| " + " | ".join(["---"] * 14) + " |"] + rows3
    return "\n".join(lines)


def write_docs(out) -> None:
    text = DOCS.read_text()
    a, b = text.index(MARK[0]), text.index(MARK[1])
    runs = out.get("runs") or [_run_record(out)]
    lines = [f"- {r['date']}, load average {r['load'][0]:.1f} at the start and {r['load_end'][0]:.1f} at the end: "
             + ", ".join(f"{m} ({'/'.join(k.upper().replace('D', '-D') for k in ks)})" for m, ks in r["materials"].items())
             for r in runs]
    block = (f"{MARK[0]}\n\n`python -m benchmarks.bench_proved_bound --enclosure "
             f"{'both' if len(out['enclosures']) > 1 else out['enclosures'][0]} --gap` (`--models 3d --grazing` for "
             f"the 3-D rows), one process, on the shared 2-core machine (seconds are wall clock, under the "
             f"load given):\n\n" + "\n".join(lines) + f"\n\n{table(out)}\n\n")
    DOCS.write_text(text[:a] + block + text[b:])


if __name__ == "__main__":
    main()
