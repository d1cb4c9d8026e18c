"""The coefficient count as a dial: a 3-D fit's accuracy against its coefficients.

For each material, every layout of a ladder (:data:`LADDER`: one theta_h piece of growing
degrees, then four and six pieces, including the three layouts the default selection tries,
:data:`fit.rational.fit3d.VARIANTS`) is fitted the way :func:`fit.rational.fit3d.fit_rgl_select`
fits its candidates (``fit_rgl`` with the command's settings, ``tol`` 0.01, no verification, no
albedo policy, no proved bound: the selection verifies and corrects the chosen one only), and
measured at held-out pairs: the benchmark's metric (:mod:`benchmarks.bench_fit_accuracy`:
``--pairs`` cosine-distributed direction pairs, seed ``--seed``, not the fit's data, objective or
validation points), i.e. the relative RMSE of ``rho cos cos`` (mean over R, G, B) and the median
and 95th percentile of the relative error of rho.

Marked per material:

* ``smallest``: the fewest coefficients whose relative RMSE meets ``--tol`` (the user's
  tolerance; also reported for each of ``--tols``);
* ``default``: the layout the default selection picks (its rule applied to the same fits: the
  layouts of ``VARIANTS`` in order, a later one only below its ``if_rmse_below`` validation RMSE
  and kept only when its validation score is :data:`fit.rational.fit3d.SELECT_MARGIN` lower;
  the fits are deterministic, so they are the selection's own).

CPU seconds of each fit (``time.process_time``; valid under load) are reported with it.

    OMP_NUM_THREADS=1 python -m benchmarks.bench_dial --materials paper_white satin_rosaline cc_ibiza_sunset --docs

``--docs`` writes the table into docs/fit_accuracy.md (between its ``bench:dial`` markers) and
the chart to docs/images/fit_dial.png; ``--out`` keeps ``results.json``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from datetime import date
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- BEGIN bench:dial -->", "<!-- END bench:dial -->"
#: The layouts of the dial, fewest coefficients first (``fit_rgl`` settings; ``name`` for the
#: table). ``select-0``, ``select-1`` and ``select-2`` are :data:`fit.rational.fit3d.VARIANTS` 0, 1
#: and 2.
LADDER = (
    {"name": "1 piece (3,1)", "theta_h_edges": [], "degrees": (3, 1)},
    {"name": "1 piece (4,2)", "theta_h_edges": [], "degrees": (4, 2)},
    {"name": "1 piece (5,2)", "theta_h_edges": [], "degrees": (5, 2)},
    {"name": "1 piece (6,3)", "theta_h_edges": [], "degrees": (6, 3)},
    {"name": "1 piece (7,3) [select-1]", "variant": 1},
    {"name": "4 pieces (3,1)", "theta_h_edges": [0.05, 0.1, 0.2], "piece_degrees": [(3, 1)] * 4},
    {"name": "6 pieces (4,2)/(5,2) [select-0]", "variant": 0},
    {"name": "6 pieces, relative [select-2]", "variant": 2},
)
TOLS = (0.02, 0.05, 0.1)


def layout_settings(entry: dict) -> dict:
    """The ``fit_rgl`` settings of a :data:`LADDER` entry (a selection variant: its own, without
    the selection's keys)."""
    from fit.rational.fit3d import VARIANTS

    if "variant" in entry:
        v = dict(VARIANTS[entry["variant"]])
        for k in ("if_rmse_below", "verify_rounds", "verify_above"):
            v.pop(k, None)
        return v
    return {k: v for k, v in entry.items() if k != "name"}


def default_pick(rows: list) -> int | None:
    """Index in ``rows`` of the layout :func:`fit.rational.fit3d.fit_rgl_select` keeps with its
    default ``VARIANTS`` and settings: its rule on the rows' ``validation_rmse`` (the
    ``if_rmse_below`` gates), ``valid`` and score: ``image_score`` under the default
    ``select_by="image"`` (rows without it: ``validation_score``), else ``validation_score`` (the
    selection's objective ``rho_cos_cos``: the validation RMSE)."""
    from fit.rational.fit3d import SELECT_MARGIN, VARIANTS
    from fit.rational.settings import Fit3DSettings

    key = "image_score" if Fit3DSettings().select_by == "image" and all("image_score" in r for r in rows) \
        else "validation_score"

    by_variant = {r["variant"]: i for i, r in enumerate(rows) if r.get("variant") is not None}
    best = None
    for k, v in enumerate(VARIANTS):
        i = by_variant.get(k)
        if i is None:
            continue
        below = v.get("if_rmse_below")
        if below is not None and best is not None and rows[best]["validation_rmse"] >= below:
            continue
        r = rows[i]
        if r["valid"] and (best is None or r[key] < (1.0 - SELECT_MARGIN) * rows[best][key]):
            best = i
    return best


def _default_index(rows: list, meta: dict, material: str) -> int | None:
    """The default's layout: ``meta["default"][material]`` (a layout name: the layout the
    command kept in a run of its own) when given, else :func:`default_pick` on the rows."""
    name = (meta.get("default") or {}).get(material)
    if name is not None:
        return next((i for i, r in enumerate(rows) if r["layout"] == name), None)
    return default_pick(rows)


def smallest_meeting(rows: list, tol: float, key: str = "rel_rmse") -> int | None:
    """Index of the row with the fewest coefficients whose ``key`` is at most ``tol`` (valid fits)."""
    ok = [i for i, r in enumerate(rows) if r.get("valid") is not False and r[key] <= tol]
    return min(ok, key=lambda i: (rows[i]["coefficients"], rows[i][key])) if ok else None


def run_material(name: str, data: Path, pairs: int, seed: int, tol: float) -> list:
    from benchmarks.bench_fit_accuracy import cosine_pairs, relative_error_stats, relative_rmse
    from fit.formats.rgl import read_rgl
    from fit.rational.fit3d import fit_rgl
    from fit.rational.image_check import image_check
    from fit.rational.select3d import image_score, validation_rmse, validation_score
    from fit.rational.settings import Fit3DSettings
    from fit.rational.variables3d import evaluate_directions

    brdf = read_rgl(data / "rgl" / f"{name}_rgb.bsdf")
    wi, wo = cosine_pairs(pairs, seed)
    truth = np.maximum(np.asarray(brdf.evaluate(wi, wo), np.float64), 0.0)
    base = Fit3DSettings(tol=tol)
    rows = []
    for entry in LADDER:
        s = base.clone(**layout_settings(entry), verify=0, albedo=False, prove_bound=False)
        c0 = time.process_time()
        res = fit_rgl(brdf, settings=s)
        cpu = time.process_time() - c0
        rho = np.asarray(evaluate_directions(res.model, wi, wo), np.float64)
        med, p95 = relative_error_stats(rho, truth)
        row = {"layout": entry["name"], "variant": entry.get("variant"), "coefficients": int(res.n_coefficients),
               "valid": bool(res.valid), "bound": float(res.tolerance), "rel_rmse": float(relative_rmse(rho, truth, wi, wo).mean()),
               "median_rel": med, "p95_rel": p95, "validation_rmse": validation_rmse(brdf, res.model),
               "validation_score": validation_score(brdf, res.model, base.objective),
               "image_score": image_score(image_check(brdf, res.model)), "cpu_s": cpu}
        rows.append(row)
        print(f"{name}: {row['layout']}: {row['coefficients']} coef, rel RMSE {row['rel_rmse']:.4f}, "
              f"median {row['median_rel']:.4f}, p95 {row['p95_rel']:.4f}, {cpu:.1f} CPU s, bound "
              f"{100 * row['bound']:.1f} %, valid {row['valid']}, validation RMSE {row['validation_rmse']:.4f}",
              flush=True)
    return sorted(rows, key=lambda r: (r["coefficients"], r["layout"]))


def _cpu(r: dict) -> str:
    c = r.get("cpu_s")
    return "–" if c is None or not np.isfinite(c) else f"{c:.1f}"


def markdown(results: dict, meta: dict) -> str:
    tol, tols = meta["tol_rmse"], meta["tols"]
    out = [f"`{meta['command']}` ({meta['date']}, {meta['machine']}, load average {meta['load']}; "
           f"{meta['pairs']:,} held-out pairs, seed {meta['seed']}; fits as the selection fits its "
           "candidates: `tol` 0.01, no verification, no albedo policy). **D**: "
           + meta.get("d_note", "the layout the default selection keeps")
           + f"; **S**: the fewest coefficients with a relative RMSE within {tol:g}.", ""]
    for m, rows in results.items():
        d, s = _default_index(rows, meta, m), smallest_meeting(rows, tol)
        out += [f"**{m}**", "", "| layout | coefficients | relative RMSE | median rel. error | p95 rel. error "
                "| stated bound | CPU s | |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
        for i, r in enumerate(rows):
            mark = " ".join(x for x, j in (("**D**", d), ("**S**", s)) if j == i)
            bound = f"{100 * r['bound']:.1f} %" if "bound" in r else "–"
            out.append(f"| {r['layout']} | {r['coefficients']} | {r['rel_rmse']:.4f} | {r['median_rel']:.4f} | "
                       f"{r['p95_rel']:.4f} | {bound} | {_cpu(r)} | {mark} |")
        picks = []
        for t in tols:
            k = smallest_meeting(rows, t)
            picks.append(f"{t:g}: " + ("none" if k is None else f"{rows[k]['coefficients']} ({rows[k]['layout']})"))
        out += ["", "Fewest coefficients within a relative RMSE of " + "; ".join(picks) + ".", ""]
        if d is not None and s is not None and rows[s]["coefficients"] < rows[d]["coefficients"]:
            out += [f"The default keeps {rows[d]['coefficients']} coefficients (relative RMSE "
                    f"{rows[d]['rel_rmse']:.4f}) where {rows[s]['coefficients']} meet {tol:g} "
                    f"({rows[s]['rel_rmse']:.4f}).", ""]
    return "\n".join(out).rstrip() + "\n"


def chart(results: dict, meta: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fit.atomic_files import save_figure

    fig, ax = plt.subplots(figsize=(7, 4.2))
    for m, rows in results.items():
        x = [r["coefficients"] for r in rows]
        y = [r["rel_rmse"] for r in rows]
        (line,) = ax.plot(x, y, "o-", label=m, ms=4)
        d, s = _default_index(rows, meta, m), smallest_meeting(rows, meta["tol_rmse"])
        if d is not None:
            ax.plot([x[d]], [y[d]], "*", ms=14, color=line.get_color(), mec="k")
        if s is not None:
            ax.plot([x[s]], [y[s]], "s", ms=10, mfc="none", mec=line.get_color(), mew=2)
    ax.axhline(meta["tol_rmse"], color="0.5", ls="--", lw=1)
    ax.set_yscale("log")
    ax.set_xlabel("coefficients (R, G, B, all pieces)")
    ax.set_ylabel("relative RMSE of rho cos cos (held out)")
    ax.set_title(f"3-D fits: error against coefficients (star: default; square: fewest within {meta['tol_rmse']:g})",
                 fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


def write_docs(text: str, path: Path) -> None:
    from fit.outputs import atomic_write

    old = path.read_text(encoding="utf-8")
    if BEGIN not in old or END not in old:
        raise SystemExit(f"bench_dial: {path} has no {BEGIN} ... {END} block")
    a, b = old.index(BEGIN) + len(BEGIN), old.index(END)
    with atomic_write(path) as f:
        f.write(old[:a] + "\n" + text + old[b:])


def _save(folder, d: dict) -> None:
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(d, indent=1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_dial", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=os.environ.get("RBRDF_DATA", str(ROOT.parent / "shared" / "data")))
    ap.add_argument("--materials", nargs="+", default=["paper_white", "satin_rosaline", "cc_ibiza_sunset"])
    ap.add_argument("--pairs", type=int, default=200_000, help="held-out direction pairs (default 200000)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the pairs (the fit-accuracy benchmark's)")
    ap.add_argument("--tol", type=float, default=0.05, help="the user's tolerance on the relative RMSE (default 0.05)")
    ap.add_argument("--tols", type=float, nargs="+", default=list(TOLS), help="tolerances reported per material")
    ap.add_argument("--out", default=str(ROOT / "results" / "dial"), help="folder of results.json")
    ap.add_argument("--from-json", default=None, help="only write the table and chart of an earlier results.json")
    ap.add_argument("--docs", action="store_true", help="write docs/fit_accuracy.md's block and docs/images/fit_dial.png")
    args = ap.parse_args(argv)
    if args.from_json:
        d = json.loads(Path(args.from_json).read_text())
        results, meta = d["results"], d["meta"]
    else:
        data = Path(args.data)
        load0 = os.getloadavg()
        results = {}
        for m in args.materials:
            if not (data / "rgl" / f"{m}_rgb.bsdf").is_file():
                print(f"bench_dial: no file {data / 'rgl' / (m + '_rgb.bsdf')} (set RBRDF_DATA)", file=sys.stderr)
                return 2
            results[m] = run_material(m, data, args.pairs, args.seed, 0.01)
            _save(args.out, {"results": results})           # each material as it is done
        meta = {"command": "python -m benchmarks.bench_dial " + " ".join(sys.argv[1:] if argv is None else argv),
                "date": date.today().isoformat(), "machine": f"{os.cpu_count()}-core shared machine",
                "load": f"{load0[0]:.1f} at the start, {os.getloadavg()[0]:.1f} at the end", "pairs": args.pairs, "seed": args.seed,
                "tol_rmse": args.tol, "tols": args.tols}
        _save(args.out, {"meta": meta, "results": results})
    text = markdown(results, meta)
    print(text)
    if args.docs:
        write_docs(text, ROOT / "docs" / "fit_accuracy.md")
        chart(results, meta, ROOT / "docs" / "images" / "fit_dial.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
