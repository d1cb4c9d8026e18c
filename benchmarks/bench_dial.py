"""The coefficient count as a dial: a 3-D fit's accuracy, in the data and in the image, against
its coefficients.

For each material, every layout of a ladder (:data:`LADDER`: one theta_h piece of growing
degrees, fitted to the default and to the relative objective, then four and seven pieces,
including the three layouts the default selection tries, :data:`fit.rational.fit3d.VARIANTS`)
is fitted and measured at held-out pairs: the benchmark's metric
(:mod:`benchmarks.bench_fit_accuracy`: ``--pairs`` cosine-distributed direction pairs, seed
``--seed``, not the fit's data, objective or validation points), i.e. the relative RMSE of
``rho cos cos`` (mean over R, G, B) and the median and 95th percentile of the relative error of
rho. A layout is fitted as :func:`fit.rational.fit3d.fit_rgl_select` fits its candidates
(``fit_rgl`` with the command's settings, ``tol`` 0.01, no verification, no albedo policy, no
proved bound) or, with ``--complete``, as ``rbrdf-fit brdf`` fits that layout alone (verified,
the proof-guided refit, the albedo policy, the proved bound: what a user gets). Each fit is saved
under ``--out``/fits. A row for the command's own default fit (``rbrdf-fit brdf FILE --model
3d``: the chart's cached file, :func:`benchmarks.chart_fits.fit3d_path`) is measured beside them
where that file exists (``--no-default``: none).

``--render``: every fit is also rendered against the ``rgl`` material under each of
``--render-maps`` (:func:`benchmarks.bench_fit_accuracy.render_against_rgl`: the fidelity study's
sphere, paired ``mis`` renders, the same seeds), giving ΔE2000 mean and p99 per map: the curve
of ΔE against coefficients, and the fewest coefficients meeting the image target (mean ≤ 1 and
p99 ≤ 3 under every map).

Marked per material:

* ``S`` (smallest): the fewest coefficients whose relative RMSE meets ``--tol`` (the user's
  tolerance; also reported for each of ``--tols``);
* ``I`` (image): the fewest coefficients whose renders meet the image target;
* ``D`` (default): the command's default fit, or without its row the layout the default
  selection picks (its rule applied to the same fits: the layouts of ``VARIANTS`` in order, a
  later one only below its ``if_rmse_below`` validation RMSE and kept only when its score is
  :data:`fit.rational.fit3d.SELECT_MARGIN` lower).

CPU seconds of each fit (``time.process_time``; valid under load) are reported with it.

    OMP_NUM_THREADS=1 python -m benchmarks.bench_dial --materials paper_white satin_rosaline --complete --render --docs

``--rungs K ...`` fits some layouts of the ladder only; ``--from-json A B ...`` merges earlier
runs (a material's rows joined) and writes their table and chart. ``--docs`` writes
docs/fit_accuracy.md's ``bench:dial`` block and docs/images/fit_dial.png; with renders, the block
is the per-material summary and docs/fit_dial.md holds every layout's numbers.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
from datetime import date
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- BEGIN bench:dial -->", "<!-- END bench:dial -->"
#: The layouts of the dial (``fit_rgl`` settings; ``name`` for the table; ``flags``: those of
#: ``rbrdf-fit brdf --model 3d`` that fit the layout alone, where some do). ``select-0``,
#: ``select-1`` and ``select-2`` are :data:`fit.rational.fit3d.VARIANTS` 0, 1 and 2.
LADDER = (
    {"name": "1 piece (3,1)", "theta_h_edges": [], "degrees": (3, 1), "flags": "--layout single --degrees 3,1"},
    {"name": "1 piece (4,2)", "theta_h_edges": [], "degrees": (4, 2), "flags": "--layout single --degrees 4,2"},
    {"name": "1 piece (5,2)", "theta_h_edges": [], "degrees": (5, 2), "flags": "--layout single --degrees 5,2"},
    {"name": "1 piece (6,3)", "theta_h_edges": [], "degrees": (6, 3), "flags": "--layout single --degrees 6,3"},
    {"name": "1 piece (7,3) [select-1]", "variant": 1, "flags": "--layout single --objective relative"},
    {"name": "4 pieces (3,1)", "theta_h_edges": [0.05, 0.1, 0.2], "piece_degrees": [(3, 1)] * 4},
    {"name": "7 pieces (4,2)/(5,2) [select-0]", "variant": 0, "flags": "--layout pieces"},
    {"name": "7 pieces, relative [select-2]", "variant": 2, "flags": "--layout pieces --objective relative"},
    {"name": "1 piece (5,2), relative", "theta_h_edges": [], "degrees": (5, 2), "objective": "relative",
     "flags": "--layout single --degrees 5,2 --objective relative"},
    {"name": "1 piece (6,3), relative", "theta_h_edges": [], "degrees": (6, 3), "objective": "relative",
     "flags": "--layout single --degrees 6,3 --objective relative"},
    {"name": "4 pieces (4,2)/(5,2)", "theta_h_edges": [0.05, 0.1, 0.2],
     "piece_degrees": [(4, 2), (5, 2), (5, 2), (4, 2)]},
    {"name": "4 pieces (4,2)/(5,2), relative", "theta_h_edges": [0.05, 0.1, 0.2],
     "piece_degrees": [(4, 2), (5, 2), (5, 2), (4, 2)], "objective": "relative"},
)
TOLS = (0.02, 0.05, 0.1)


def layout_settings(entry: dict, keep_verify: bool = False) -> dict:
    """The ``fit_rgl`` settings of a :data:`LADDER` entry (a selection variant: its own, without
    the selection's keys; ``keep_verify``: with the variant's own verification rounds, for a
    layout fitted by the selection alone)."""
    from fit.rational.select3d import SELECTION_KEYS, VARIANTS

    if "variant" in entry:
        v = dict(VARIANTS[entry["variant"]])
        for k in SELECTION_KEYS + (() if keep_verify else ("verify_rounds", "verify_above")):
            v.pop(k, None)
        return v
    v = {k: v for k, v in entry.items() if k not in ("name", "flags")}
    if keep_verify and not v.get("theta_h_edges"):
        v.update(verify_rounds=1, verify_above=4.0)     # as `rbrdf-fit brdf --layout single` verifies
    return v


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
    if name is None and any(r["layout"] == DEFAULT_ROW for r in rows):
        name = DEFAULT_ROW
    if name is not None:
        return next((i for i, r in enumerate(rows) if r["layout"] == name), None)
    return default_pick(rows)


def smallest_meeting(rows: list, tol: float, key: str = "rel_rmse") -> int | None:
    """Index of the row with the fewest coefficients whose ``key`` is at most ``tol`` (valid fits of
    the ladder, not the default's row)."""
    ok = [i for i, r in enumerate(rows) if r.get("valid") is not False and r["layout"] != DEFAULT_ROW and r[key] <= tol]
    return min(ok, key=lambda i: (rows[i]["coefficients"], rows[i][key])) if ok else None


def _slug(layout: str) -> str:
    """A file name of a layout's name (``1 piece (3,1)`` -> ``1_piece_3_1``)."""
    return "_".join("".join(c if c.isalnum() else " " for c in layout).split())


def measure_model(model, brdf, wi, wo, truth, base) -> dict:
    """The benchmark's metrics of a 3-D ``model``: relative RMSE of ``rho cos cos``, median and
    p95 relative error of rho at the held-out pairs ``wi``, ``wo`` (``truth``: the reference's
    rho there), the selection's validation RMSE and score and its image check's score."""
    from benchmarks.bench_fit_accuracy import relative_error_stats, relative_rmse
    from fit.rational.image_check import image_check
    from fit.rational.select3d import image_score, validation_rmse, validation_score
    from fit.rational.variables3d import evaluate_directions

    rho = np.asarray(evaluate_directions(model, wi, wo), np.float64)
    med, p95 = relative_error_stats(rho, truth)
    return {"coefficients": int(model.n_coefficients), "rel_rmse": float(relative_rmse(rho, truth, wi, wo).mean()),
            "median_rel": med, "p95_rel": p95, "validation_rmse": validation_rmse(brdf, model),
            "validation_score": validation_score(brdf, model, base.objective),
            "image_score": image_score(image_check(brdf, model))}


def run_material(name: str, data: Path, pairs: int, seed: int, tol: float, complete: bool = False,
                 fits_dir: Path | None = None, default_file: Path | None = None, rungs=None) -> list:
    """The rows of one material: every layout of :data:`LADDER` fitted (``complete``: as
    ``rbrdf-fit brdf`` fits that layout alone, :func:`fit.rational.fit3d.fit_rgl_select` with it
    as the only layout: verified, refitted where the proof finds it outside its bound, the albedo
    policy, the proved bound; else as the selection fits its candidates) and measured; each fit
    saved to ``fits_dir/<name>/<layout>.json`` when given; plus a row :data:`DEFAULT_ROW` measured
    from ``default_file`` (the command's default fit of the file) when given. ``rungs``: the
    indices of the ladder's layouts to fit (None: all)."""
    from benchmarks.bench_fit_accuracy import cosine_pairs
    from fit.rational.coefficient_file import load, save
    from fit.formats.rgl import read_rgl
    from fit.rational.fit3d import fit_rgl, fit_rgl_select
    from fit.rational.settings import Fit3DSettings

    path = data / "rgl" / f"{name}_rgb.bsdf"
    brdf = read_rgl(path)
    brdf.source = path.name                  # as the command records it
    wi, wo = cosine_pairs(pairs, seed)
    truth = np.maximum(np.asarray(brdf.evaluate(wi, wo), np.float64), 0.0)
    base = Fit3DSettings(tol=tol)
    rows = []
    for k, entry in enumerate(LADDER):
        if rungs is not None and k not in rungs:
            continue
        c0 = time.process_time()
        if complete:
            res = fit_rgl_select(brdf, (layout_settings(entry, keep_verify=True),), settings=base)
        else:
            s = base.clone(**layout_settings(entry), verify=0, albedo=False, prove_bound=False)
            res = fit_rgl(brdf, settings=s)
        cpu = time.process_time() - c0
        row = {"layout": entry["name"], "variant": entry.get("variant"), "valid": bool(res.valid),
               "bound": float(res.tolerance), **measure_model(res.model, brdf, wi, wo, truth, base), "cpu_s": cpu}
        if complete:
            row["proved_over_stated"] = (res.model.fit_info.get("domain") or {}).get("proved_over_stated")
        if fits_dir is not None:
            f = Path(fits_dir) / name / f"{_slug(entry['name'])}.json"
            f.parent.mkdir(parents=True, exist_ok=True)
            save(res.model, f)
            row["file"] = str(f)
        rows.append(row)
        print(f"{name}: {row['layout']}: {row['coefficients']} coef, rel RMSE {row['rel_rmse']:.4f}, "
              f"median {row['median_rel']:.4f}, p95 {row['p95_rel']:.4f}, {cpu:.1f} CPU s, bound "
              f"{100 * row['bound']:.1f} %, valid {row['valid']}, validation RMSE {row['validation_rmse']:.4f}",
              flush=True)
    if default_file is not None and Path(default_file).is_file():
        model = load(default_file)
        rows.append({"layout": DEFAULT_ROW, "variant": None, "valid": True, "file": str(default_file),
                     **measure_model(model, brdf, wi, wo, truth, base), "cpu_s": None})
    return sorted(rows, key=lambda r: (r["coefficients"], r["layout"]))


#: The row of the command's own default fit (:func:`run_material`'s ``default_file``)
DEFAULT_ROW = "rbrdf-fit brdf default"
#: The image target of the fit-accuracy issue: render ΔE2000 mean and p99 at most these under every map
IMAGE_TARGET = (1.0, 3.0)


def render_rows(name: str, data: Path, rows: list, maps, resolution: int, spp: int) -> None:
    """Render every row's fit file against the ``rgl`` material of ``name`` under each of
    ``maps`` (:func:`benchmarks.bench_fit_accuracy.render_against_rgl`: paired ``mis`` renders,
    the fidelity study's sphere) and store ``row["render"] = {map: {de_mean, de_p99}}`` and, in
    ``row["render_floor"]``, the noise floor ``[mean, p99]`` per map (of the material's first
    comparison: one floor per material and map)."""
    from benchmarks.bench_fit_accuracy import render_against_rgl
    from warp_rbrdf.scene import MaterialSpec

    specs = {i: MaterialSpec(name="obj", type="rational", file=Path(r["file"]), sampler="mis")
             for i, r in enumerate(rows) if r.get("file")}
    recs = render_against_rgl(name, data / "rgl" / f"{name}_rgb.bsdf", specs, maps, resolution, spp)
    for i in specs:
        rows[i]["render"] = {x["map"]: x[i] for x in recs}
        rows[i]["render_floor"] = {x["map"]: [x["floor_mean"], x["floor_p99"]] for x in recs}


def image_met(row: dict, target=IMAGE_TARGET) -> bool | None:
    """Whether ``row``'s renders meet the image target under every map (None: not rendered)."""
    w = worst_map(row)
    return None if w is None else (w[0] <= target[0] and w[1] <= target[1])


def smallest_image(rows: list, target=IMAGE_TARGET) -> int | None:
    """Index of the row with the fewest coefficients (of the ladder, not the default's row) whose
    renders meet ``target`` under every map."""
    ok = [i for i, r in enumerate(rows) if r["layout"] != DEFAULT_ROW and image_met(r, target)]
    return min(ok, key=lambda i: rows[i]["coefficients"]) if ok else None


def _cpu(r: dict) -> str:
    c = r.get("cpu_s")
    return "–" if c is None or not np.isfinite(c) else f"{c:.1f}"


def _de(row: dict) -> str:
    """The row's render cells: ΔE2000 mean / p99 per map."""
    r = row.get("render") or {}
    return " | ".join(f"{v['de_mean']:.2f} / {v['de_p99']:.2f}" for v in r.values())


def markdown(results: dict, meta: dict) -> str:
    tol, tols = meta["tol_rmse"], meta["tols"]
    maps = meta.get("render_maps") or []
    how = ("each layout fitted as `rbrdf-fit brdf` fits it alone (verified, the proof-guided refit, the albedo "
           "policy, the proved bound)" if meta.get("complete") else
           "fits as the selection fits its candidates: `tol` 0.01, no verification, no albedo policy")
    rendered = (f"; rendered against the `rgl` material under {', '.join(maps)} (paired `mis` renders of the "
                f"fidelity study's sphere, {meta['render_res']} px, {meta['render_spp']} spp; ΔE2000 mean / p99)"
                if maps else "")
    out = [f"`{meta['command']}` ({meta['date']}, {meta['machine']}, load average {meta['load']}; "
           f"{meta['pairs']:,} held-out pairs, seed {meta['seed']}; {how}{rendered}). **D**: "
           + meta.get("d_note", "the layout the default selection keeps")
           + f"; **S**: the fewest coefficients with a relative RMSE within {tol:g}"
           + (f"; **I**: the fewest coefficients whose renders meet ΔE2000 mean ≤ {IMAGE_TARGET[0]:g} and p99 ≤ "
              f"{IMAGE_TARGET[1]:g} under every map" if maps else "") + ".", ""]
    for m, rows in results.items():
        d, s = _default_index(rows, meta, m), smallest_meeting(rows, tol)
        i_img = smallest_image(rows) if maps else None
        head = "| layout | coefficients | relative RMSE | median rel. error | p95 rel. error | stated bound | CPU s"
        head += "".join(f" | ΔE {x}" for x in maps) + " | |"
        out += [f"**{m}**", "", head, "| --- " * (8 + len(maps)) + "|"]
        for i, r in enumerate(rows):
            mark = " ".join(x for x, j in (("**D**", d), ("**S**", s), ("**I**", i_img)) if j == i)
            bound = f"{100 * r['bound']:.1f} %" if "bound" in r else "–"
            cells = (" | " + (_de(r) or " | ".join("–" for _ in maps))) if maps else ""
            out.append(f"| {r['layout']} | {r['coefficients']} | {r['rel_rmse']:.4f} | {r['median_rel']:.4f} | "
                       f"{r['p95_rel']:.4f} | {bound} | {_cpu(r)}{cells} | {mark} |")
        picks = []
        for t in tols:
            k = smallest_meeting(rows, t)
            picks.append(f"{t:g}: " + ("none" if k is None else f"{rows[k]['coefficients']} ({rows[k]['layout']})"))
        out += ["", "Fewest coefficients within a relative RMSE of " + "; ".join(picks) + ".", ""]
        if maps:
            dm = d is not None and image_met(rows[d])
            line = ("The image target is met by no layout of the ladder" if i_img is None else
                    f"The image target is met from {rows[i_img]['coefficients']} coefficients ({rows[i_img]['layout']})")
            if d is not None and rows[d].get("render"):
                line += (f"; the default ({rows[d]['coefficients']} coefficients) "
                         + ("meets it" if dm else "misses it"))
            out += [line + ".", ""]
        if d is not None and s is not None and rows[s]["coefficients"] < rows[d]["coefficients"]:
            out += [f"The default keeps {rows[d]['coefficients']} coefficients (relative RMSE "
                    f"{rows[d]['rel_rmse']:.4f}) where {rows[s]['coefficients']} meet {tol:g} "
                    f"({rows[s]['rel_rmse']:.4f}).", ""]
    if maps:
        n_i, n_d, _ = image_counts(results, meta)
        out += [f"Image target met by some layout of the ladder on {n_i} of {len(results)} materials; by the "
                f"default on {n_d}.", ""]
    return "\n".join(out).rstrip() + "\n"


def image_counts(results: dict, meta: dict) -> tuple:
    """``(ladder, default, default at the fewest)``: the materials whose ladder has a layout meeting
    the image target, those whose default fit meets it, and those whose default meets it with no
    more coefficients than the ladder's fewest that does."""
    n_i = n_d = n_fewest = 0
    for m, rows in results.items():
        i, d = smallest_image(rows), _default_index(rows, meta, m)
        dm = d is not None and bool(image_met(rows[d]))
        n_i += i is not None
        n_d += dm
        n_fewest += dm and i is not None and rows[d]["coefficients"] <= rows[i]["coefficients"]
    return n_i, n_d, n_fewest


def worst_map(row: dict) -> tuple | None:
    """``(mean, p99)`` of the row's renders, each the largest over the maps (None: not rendered)."""
    r = (row or {}).get("render")
    if not r:
        return None
    return max(v["de_mean"] for v in r.values()), max(v["de_p99"] for v in r.values())


def _worst(row: dict) -> str:
    """The row's worst render over the maps as a cell: ``mean / p99``."""
    w = worst_map(row)
    return "–" if w is None else f"{w[0]:.2f} / {w[1]:.2f}"


def summary_markdown(results: dict, meta: dict) -> str:
    """One row per material: the fewest coefficients of the ladder meeting the image target (and
    its worst render), the default's coefficients and worst render, the fewest within the
    relative-RMSE tolerance; a count line. Needs rendered rows."""
    tol = meta["tol_rmse"]
    out = [f"| material | fewest coefficients meeting the image target (layout) | its ΔE mean / p99 (worst map) | "
           f"default: coefficients | default: ΔE mean / p99 (worst map) | default meets it | fewest within RMSE {tol:g} |",
           "| --- | --- | --- | --- | --- | --- | --- |"]
    for m, rows in results.items():
        i, d, s = smallest_image(rows), _default_index(rows, meta, m), smallest_meeting(rows, tol)
        dm = d is not None and bool(image_met(rows[d]))
        out.append(f"| {m} | " + ("none" if i is None else f"{rows[i]['coefficients']} ({rows[i]['layout']})")
                   + f" | {_worst(rows[i]) if i is not None else '–'} | "
                   + ("–" if d is None else str(rows[d]["coefficients"])) + f" | {_worst(rows[d]) if d is not None else '–'} | "
                   + ("yes" if dm else "no") + " | "
                   + ("none" if s is None else f"{rows[s]['coefficients']} ({rows[s]['layout']})") + " |")
    n_i, n_d, n_fewest = image_counts(results, meta)
    out += ["", f"The image target (ΔE2000 mean ≤ {IMAGE_TARGET[0]:g} and p99 ≤ {IMAGE_TARGET[1]:g} under every map) is "
            f"met by some layout of the ladder on {n_i} of {len(results)} materials and by the default on {n_d}; "
            f"the default meets it with no more coefficients than the ladder's fewest on {n_fewest}."]
    return "\n".join(out) + "\n"


def envelope(rows: list, value) -> tuple:
    """``(coefficients, best)``: for each coefficient count of the ladder's rows (not the default's
    row), the lowest ``value(row)`` of the rows with at most that many coefficients: the best the
    ladder offers within a budget of coefficients."""
    pts = sorted((r["coefficients"], value(r)) for r in rows if r["layout"] != DEFAULT_ROW)
    xs, ys, best = [], [], np.inf
    for x, y in pts:
        best = min(best, y)
        if xs and xs[-1] == x:
            ys[-1] = best
        else:
            xs.append(x)
            ys.append(best)
    return xs, ys


def _worst_mean(r: dict) -> float:
    w = worst_map(r)
    return np.inf if w is None else w[0]


def chart(results: dict, meta: dict, path: Path) -> None:
    """The best of the ladder within a budget of coefficients (:func:`envelope`) per material:
    relative RMSE, and with renders the worst map's ΔE2000 mean; a star at the default's fit."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fit.atomic_files import save_figure

    maps = meta.get("render_maps") or []
    panels = [("rel_rmse", lambda r: r["rel_rmse"], meta["tol_rmse"], "relative RMSE of rho cos cos (held out)")]
    if maps:
        panels.append(("de", _worst_mean, IMAGE_TARGET[0], f"render ΔE2000 mean, worst of {', '.join(maps)}"))
    fig, axes = plt.subplots(1, len(panels), figsize=(6.2 * len(panels) + 2.2, 4.6), squeeze=False)
    cmap = plt.get_cmap("tab20")
    for k, (m, rows) in enumerate(results.items()):
        color = cmap(k % 20)
        d = _default_index(rows, meta, m)
        for ax, (_, value, _, _) in zip(axes[0], panels):
            xs, ys = envelope(rows, value)
            keep = [i for i, y in enumerate(ys) if np.isfinite(y)]
            ax.step([xs[i] for i in keep], [ys[i] for i in keep], where="post", color=color, lw=1.2,
                    label=m if ax is axes[0][0] else None)
            if d is not None and np.isfinite(value(rows[d])):
                ax.plot([rows[d]["coefficients"]], [value(rows[d])], "*", ms=11, color=color, mec="k", mew=0.6)
    for ax, (_, _, line, label) in zip(axes[0], panels):
        ax.axhline(line, color="0.4", ls="--", lw=1)
        ax.set_yscale("log")
        ax.set_xlabel("coefficients (R, G, B, all pieces)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_title(f"best of the ladder within N coefficients (dashed: {meta['tol_rmse']:g}; star: default)",
                         fontsize=9)
    if maps:
        axes[0][1].set_title(f"in the image ({meta['render_res']} px, {meta['render_spp']} spp; dashed: the target's "
                             f"mean {IMAGE_TARGET[0]:g})", fontsize=9)
    fig.legend(loc="center right", fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0, 1 - 2.0 / (6.2 * len(panels) + 2.2), 1))
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


#: The head of docs/fit_dial.md (the whole page is generated by ``--docs`` with ``--render``)
DIAL_PAGE_HEAD = """# The coefficient count as a dial, per material

What it measures: for every shared material, each 3-D layout of a ladder of growing coefficient
counts, fitted and measured at held-out pairs and rendered against the `rgl` material, beside the
default fit of `rbrdf-fit brdf FILE --model 3d`. Generated by `python -m benchmarks.bench_dial
--complete --render --docs` (the benchmark's module docstring has the method); the summary and
what it means are in [fit_accuracy.md](fit_accuracy.md#the-coefficient-count-as-a-dial). Do not
edit by hand.

"""


def ladder_markdown() -> str:
    """The ladder's layouts and the ``rbrdf-fit brdf FILE --model 3d`` flags that fit each alone."""
    out = ["| layout | `rbrdf-fit brdf FILE --model 3d` flags |", "| --- | --- |"]
    for e in LADDER:
        out.append(f"| {e['name']} | " + (f"`{e['flags']}`" if e.get("flags") else "no flag fits it alone") + " |")
    return "\n".join(out) + "\n"


def default_fit_file(name: str, data: Path) -> Path | None:
    """The chart's cached default fit of material ``name`` (``rbrdf-fit brdf FILE --model 3d`` with
    the chart's flags, :func:`benchmarks.chart_fits.fit3d_path`), or None where it is not made."""
    from benchmarks.chart_fits import fit3d_path

    f = fit3d_path(data / "rgl" / f"{name}_rgb.bsdf")
    return f if f.is_file() else None


def _load_results(files) -> tuple:
    """``(results, meta)`` merged from earlier results.json files (materials in order; a
    material's rows of several files joined, a later file's row of a layout replacing an
    earlier one's; rows of a layout no longer in :data:`LADDER`, e.g. one measured before the
    selection's layouts changed, dropped; the first file's meta, with the loads of all)."""
    known = {step["name"] for step in LADDER} | {DEFAULT_ROW}
    results, metas = {}, []
    for f in files:
        try:
            d = json.loads(Path(f).read_text())
            for m, rows in d["results"].items():        # a material's rows of several runs: merged
                have = {r["layout"]: r for r in results.get(m, [])}
                have.update({r["layout"]: r for r in rows if r["layout"] in known})
                results[m] = sorted(have.values(), key=lambda r: (r["coefficients"], r["layout"]))
            metas.append(d["meta"])
        except (OSError, ValueError, KeyError) as e:
            raise SystemExit(f"bench_dial: {f}: not a results.json of this benchmark ({e})") from None
    results = dict(sorted(results.items()))
    meta = dict(metas[0])
    if len(metas) > 1:
        meta["load"] = "; ".join(m["load"] for m in metas) + f" ({len(metas)} runs merged)"
        cmds = sorted({re.sub(r"--materials( [a-z0-9_]+)+", "--materials M", m["command"]).replace(" --out", "\0").split("\0")[0]
                       for m in metas})
        meta["command"] = " and ".join(f"`{c}`" for c in cmds)[1:-1]
    return results, meta


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_dial", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=os.environ.get("RBRDF_DATA", str(ROOT.parent / "shared" / "data")))
    ap.add_argument("--materials", nargs="+", default=["paper_white", "satin_rosaline", "cc_ibiza_sunset"])
    ap.add_argument("--pairs", type=int, default=200_000, help="held-out direction pairs (default 200000)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the pairs (the fit-accuracy benchmark's)")
    ap.add_argument("--tol", type=float, default=0.05, help="the user's tolerance on the relative RMSE (default 0.05)")
    ap.add_argument("--tols", type=float, nargs="+", default=list(TOLS), help="tolerances reported per material")
    ap.add_argument("--complete", action="store_true",
                    help="fit each layout as `rbrdf-fit brdf` fits it alone (verified, proof-guided refit, albedo "
                         "policy, proved bound) instead of as the selection fits its candidates")
    ap.add_argument("--render", action="store_true",
                    help="render every fit (and the default's) against the rgl material under --render-maps: "
                         "ΔE2000 against coefficients, and the fewest coefficients meeting the image target")
    ap.add_argument("--rungs", type=int, nargs="+", default=None,
                    help="fit only these layouts of the ladder (0-based indices of LADDER; default all)")
    ap.add_argument("--render-maps", nargs="+", default=["studio", "rooitou"])
    ap.add_argument("--render-res", type=int, default=64)
    ap.add_argument("--render-spp", type=int, default=1024)
    ap.add_argument("--no-default", action="store_true",
                    help="no row for the command's default fit (the chart's cached fit, results/chart/fits)")
    ap.add_argument("--out", default=str(ROOT / "results" / "dial"), help="folder of results.json (and fits/)")
    ap.add_argument("--from-json", nargs="+", default=None,
                    help="only write the table and chart of earlier results.json files (merged)")
    ap.add_argument("--docs", action="store_true", help="write docs/fit_accuracy.md's block and docs/images/fit_dial.png")
    args = ap.parse_args(argv)
    if args.rungs is not None and not all(0 <= k < len(LADDER) for k in args.rungs):
        print(f"bench_dial: --rungs: indices 0..{len(LADDER) - 1} of the ladder", file=sys.stderr)
        return 2
    if args.render and not (8 <= args.render_res <= 1024 and 2 <= args.render_spp <= 4096 and args.render_spp % 2 == 0):
        print("bench_dial: --render-res 8..1024 and --render-spp an even number 2..4096", file=sys.stderr)
        return 2
    if args.from_json:
        results, meta = _load_results(args.from_json)
    else:
        data = Path(args.data)
        for m in args.materials:
            if not (data / "rgl" / f"{m}_rgb.bsdf").is_file():
                print(f"bench_dial: no file {data / 'rgl' / (m + '_rgb.bsdf')} (set RBRDF_DATA)", file=sys.stderr)
                return 2
        load0 = os.getloadavg()
        results = {}
        for m in args.materials:
            dflt = None if args.no_default else default_fit_file(m, data)
            results[m] = run_material(m, data, args.pairs, args.seed, 0.01, args.complete,
                                      Path(args.out) / "fits", dflt, args.rungs)
            if args.render:
                render_rows(m, data, results[m], args.render_maps, args.render_res, args.render_spp)
            _save(args.out, {"results": results})           # each material as it is done
        meta = {"command": "python -m benchmarks.bench_dial " + " ".join(sys.argv[1:] if argv is None else argv),
                "date": date.today().isoformat(), "machine": f"{os.cpu_count()}-core shared machine",
                "load": f"{load0[0]:.1f} at the start, {os.getloadavg()[0]:.1f} at the end", "pairs": args.pairs, "seed": args.seed,
                "tol_rmse": args.tol, "tols": args.tols, "complete": args.complete}
        if any(r["layout"] == DEFAULT_ROW for rows in results.values() for r in rows):
            meta["d_note"] = ("the fit `rbrdf-fit brdf FILE --model 3d` writes (the chart's cached file: the layout its "
                              "selection keeps, verified, albedo policy, proved bound)")
        if args.render:
            meta.update(render_maps=list(args.render_maps), render_res=args.render_res, render_spp=args.render_spp)
        _save(args.out, {"meta": meta, "results": results})
    text = markdown(results, meta)
    print(text)
    if args.docs:
        if meta.get("render_maps"):
            summary = summary_markdown(results, meta)
            print(summary)
            write_docs(text.split("\n\n", 1)[0] + "\n\n" + summary + "\nEvery layout's numbers per material: "
                       "[fit_dial.md](fit_dial.md).\n", ROOT / "docs" / "fit_accuracy.md")
            from fit.outputs import atomic_write

            with atomic_write(ROOT / "docs" / "fit_dial.md") as f:
                f.write(DIAL_PAGE_HEAD + ladder_markdown() + "\n" + text)
        else:
            write_docs(text, ROOT / "docs" / "fit_accuracy.md")
        chart(results, meta, ROOT / "docs" / "images" / "fit_dial.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
