"""Fit study: per material, rational coefficients vs tolerance vs render error (ΔE2000) vs
evaluation cost.

For each material and tolerance a rational fit is obtained through :mod:`studies.fits` (the
project's fitter, :func:`fit.rational.brdf_fit.fit_brdf` with ``rbrdf-fit brdf``'s defaults, in
this process and without a time limit; with ``--direct-fallback`` a labelled stand-in built on
:class:`fit.rational.fitter.IntervalRationalFitter`). Then:

* coefficients (total over R, G, B), fit seconds, whether every channel met its intervals;
* render error: a sphere under the environment map (sampler "light", same seed for every
  representation), CIE ΔE2000 (colour-science) of the rational render against the 3-D table
  render and against the 2-D projection render (the fit's own target), mean and 99th percentile
  on the object's fully covered pixels; exposure as in :mod:`studies.comparison`;
* evaluation cost: nanoseconds per BRDF evaluation in the renderer's Warp code (``eval_material``
  on ``n_eval`` random direction pairs, median of 5, one CPU thread) for the 3-D table, the
  2-D table and each fit; and the render seconds of the sphere.

    python -m studies.fit_study --out results/fit_study_full --docs      # full size, published to docs/
    python -m studies.fit_study --out results/fit_study --smoke
    python -m studies.fit_study --preset moderate --materials paper satin ibiza gold napoli iris \\
        --out results/fit_study                                             # 64 px, 20/10/5 %

``--docs`` also copies the chart to ``docs/images/study_fit.png``, writes ``docs/study_fit.md``
and its block in ``docs/results.md`` between ``<!-- BEGIN study:fit -->`` and
``<!-- END study:fit -->`` (:func:`studies.publish.publish_docs`).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from studies import common as C
from studies import metrics as M
from studies import publish as P
from studies import fits as F

PRESETS = {
    "smoke": dict(materials=["paper"], tols=[0.2], resolution=16, spp=8, n_eval=1 << 14, stride=9,
                  max_degree=3),
    "moderate": dict(materials=["paper", "ibiza", "satin"], tols=[0.2, 0.1, 0.05], resolution=64, spp=256,
                     n_eval=1 << 20, stride=3, max_degree=8),
    "full": dict(materials=list(C.MATERIALS), tols=[0.2, 0.1, 0.05, 0.02], resolution=128, spp=1024,
                 n_eval=1 << 21, stride=1, max_degree=10),
}
SEED = 5
#: ``--docs``: the study's key, title and chart ({file in --out: name under docs/images/}).
DOCS = dict(name="fit", title="Fit study: coefficients vs tolerance vs ΔE2000 vs evaluation cost",
            charts={"fit_study.png": "study_fit.png"},
            about=("What it measures: per material and tolerance (20, 10, 5 and 2 %), the rational fit's "
                   "coefficient count and whether it meets its intervals, the CIE ΔE2000 of its render "
                   "against the 3-D table's and the 2-D projection's (a sphere under the `studio` map, the "
                   "same seed for every representation), and the cost of one BRDF evaluation in the "
                   "renderer's Warp kernel against the 2-D and 3-D tables'."))


def random_pairs(n: int, seed: int = 0):
    """``n`` pairs of cosine-distributed local directions (upper hemisphere)."""
    from fit.formats.angles import cosine_directions

    rng = np.random.default_rng(seed)
    return (cosine_directions(rng, n).astype(np.float32), cosine_directions(rng, n).astype(np.float32))


def eval_ns(renderer, wi, wo, reps: int = 5) -> float:
    """Nanoseconds per evaluation of the scene's (first) material in the renderer's Warp code:
    one launch of its ``eval_bsdf`` kernel over preallocated arrays (median of ``reps``)."""
    wp = renderer.wp
    renderer.compile()
    dev = renderer.device
    a = wp.array(np.ascontiguousarray(wi, np.float32), dtype=wp.vec3, device=dev)
    b = wp.array(np.ascontiguousarray(wo, np.float32), dtype=wp.vec3, device=dev)
    o = wp.zeros(len(wi), dtype=wp.vec3, device=dev)
    k = renderer.kernels.eval_bsdf
    ts = []
    for i in range(reps + 1):
        t0 = time.perf_counter()
        wp.launch(k, dim=len(wi), inputs=[renderer.materials, 0, a, b], outputs=[o], device=dev)
        wp.synchronize_device(dev)
        if i:  # the first launch is a warm-up
            ts.append(time.perf_counter() - t0)
    return float(np.median(ts) / len(wi) * 1e9)


def run(preset="full", out="results/fit_study", materials=None, tols=None, env="studio", resolution=None,
        spp=None, allow_fit=True, allow_direct=False, charts=True, quiet=False) -> dict:
    cfg = dict(PRESETS[preset])
    for k, v in dict(materials=materials, tols=tols, resolution=resolution, spp=spp).items():
        if v is not None:
            cfg[k] = v
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fit_dir = out / "fits" if preset == "smoke" else None
    t_start = time.perf_counter()
    wi, wo = random_pairs(cfg["n_eval"])
    rows, base_rows = [], []
    avail = F.brdf_fit_available()
    bar = C.progress(total=len(cfg["materials"]) * (len(cfg["tols"]) + 1), desc="fit study", disable=quiet)
    for mname in cfg["materials"]:
        bar.set_postfix_str(f"{mname} tables")
        base = C.make_scene("sphere", env, C.material_spec("measured", C.measured(mname), "light"),
                            resolution=cfg["resolution"])
        imgs, cost = {}, {}
        for rep, spec in (("measured", C.material_spec("measured", C.measured(mname), "light")),
                          ("projected", C.material_spec("projected", C.projected(mname), "light"))):
            r, _ = C.renderer(C.with_material(base, spec))
            r.render(spp=1, seed=0)
            imgs[rep], sec = C.timed_render(r, cfg["spp"], SEED)
            cost[rep] = dict(eval_ns=eval_ns(r, wi, wo), render_seconds=sec)
            if rep == "measured":
                mask = C.object_mask(base, r)
                noise, _ = C.timed_render(r, cfg["spp"], SEED + 1)
        expo = M.exposure_for(imgs["measured"], mask)
        de_pm = M.de_stats(M.delta_e2000(imgs["projected"], imgs["measured"], expo), mask)
        de_noise = M.de_stats(M.delta_e2000(noise, imgs["measured"], expo), mask)
        base_rows.append(dict(material=mname, exposure=expo,
                              measured_bins=int(C.measured(mname).values[..., 0].size),
                              de_proj_vs_meas_mean=de_pm["mean"],
                              de_proj_vs_meas_p99=de_pm["p99"], noise_de_mean=de_noise["mean"],
                              **{f"{k}_{q}": v for k, d in cost.items() for q, v in d.items()}))
        bar.update(1)
        for tol in cfg["tols"]:
            bar.set_postfix_str(f"{mname} tol {tol:g}")
            model, info = _model(mname, tol, allow_fit, allow_direct, fit_dir, cfg)
            row = dict(material=mname, tol=tol, source=info.get("source"), fit_seconds=info.get("fit_seconds"),
                       error=info.get("error", ""))
            if model is not None:
                s = F.model_summary(model)
                row.update(n_coefficients=s["n_coefficients"], feasible=s["feasible_all"],
                           core_guaranteed=s["core_guaranteed"],
                           coefficients_rgb="/".join(map(str, s["per_channel"])))
                r, csec = C.renderer(C.with_material(base, C.material_spec("rational", model, "light")))
                r.render(spp=1, seed=0)
                img, sec = C.timed_render(r, cfg["spp"], SEED)
                row.update(compile_seconds=csec, render_seconds=sec, eval_ns=eval_ns(r, wi, wo))
                for ref in ("measured", "projected"):
                    d = M.de_stats(M.delta_e2000(img, imgs[ref], expo), mask)
                    row.update({f"de_vs_{ref}_{k}": v for k, v in d.items()})
                np.save(out / f"{mname}_tol{tol:g}.npy", img)
            rows.append(row)
            bar.update(1)
    bar.close()
    meta = dict(preset=preset, config=cfg, env=env, seed=SEED, fitter=avail,
                machine=P.machine_info(), wall_seconds=time.perf_counter() - t_start)
    P.write_csv(out / "fit_study.csv", rows)
    P.write_csv(out / "fit_study_tables.csv", base_rows)
    P.write_json(out / "fit_study.json", dict(meta=meta, rows=rows, tables=base_rows))
    md = summary_markdown(rows, base_rows, meta)
    (out / "fit_study.md").write_text(md)
    if charts and any("n_coefficients" in r for r in rows):
        plot(rows, base_rows, out / "fit_study.png")
    return dict(rows=rows, tables=base_rows, meta=meta, markdown=md)


def _model(mname, tol, allow_fit, allow_direct, fit_dir, cfg):
    # allow_infeasible: where no fit meets the tolerance the best one found is still rendered
    # and reported as "no" (the fitter flags it), so the study shows what a tolerance costs
    # where it cannot be met instead of a gap.
    return F.rational_model(mname, tol, allow_fit=allow_fit, allow_direct=allow_direct,
                            fit_dir=fit_dir, direct_stride=cfg["stride"], direct_max_degree=cfg["max_degree"],
                            allow_infeasible=True)


#: the "in tol." column: what the fit guarantees.
GUARANTEE_LEGEND = ("in tol.: yes = every piece inside its intervals, core = the guaranteed θd core is, "
                    "the grazing band is a flagged best effort, no = not guaranteed (best fit found, flagged)")


def guarantee(row) -> str:
    """``yes`` / ``core`` / ``no`` for a row of :func:`run` (see :data:`GUARANTEE_LEGEND`)."""
    if row["feasible"]:
        return "yes"
    return "core" if row.get("core_guaranteed") else "no"


def summary_markdown(rows, base_rows, meta) -> str:
    cfg = meta["config"]
    L = [f"Sphere under `{meta['env']}`, {cfg['resolution']}×{cfg['resolution']} px, sampler `light` at "
         f"{cfg['spp']} spp, same seed for all representations; ΔE2000 on fully covered object pixels. "
         f"Evaluation cost: ns per BRDF evaluation in the renderer's Warp kernel ({cfg['n_eval']} random "
         f"direction pairs, one thread, median of 5). Fitter: {meta['fitter'][1]}; fit s: the fitter's own "
         f"seconds as its coefficient file records them (cached fits report the run that made them); "
         f"{GUARANTEE_LEGEND}.\n"]
    hdr = ["material", "tol", "fit", "coefficients (R/G/B)", "in tol.", "fit s", "ΔE vs 3-D mean/p99",
           "ΔE vs 2-D mean/p99", "ns / eval", "render s"]
    body = []
    for b in base_rows:
        # 90 x 90 x 360 bins: RGL tables keep the full phi_d circle (rows of older runs, without
        # the key, were 90 x 90 x 180)
        n_bins = f"{b.get('measured_bins', 1_458_000):,}".replace(",", " ")
        body.append([b["material"], "3-D table", "–", f"{n_bins} × 3 values", "–", "–", "noise %.2f" % b["noise_de_mean"],
                     "%.2f / %.2f" % (b["de_proj_vs_meas_mean"], b["de_proj_vs_meas_p99"]) + " (2-D vs 3-D)",
                     b["measured_eval_ns"], b["measured_render_seconds"]])
        body.append([b["material"], "2-D table", "–", "8 100 × 3 values", "–", "–", "–", "–",
                     b["projected_eval_ns"], b["projected_render_seconds"]])
        for r in rows:
            if r["material"] != b["material"]:
                continue
            if "n_coefficients" not in r:
                body.append([r["material"], r["tol"], "none", r.get("error", "")[:120], "", "", "", "", "", ""])
                continue
            body.append([r["material"], r["tol"], r["source"], f"{r['n_coefficients']} ({r['coefficients_rgb']})",
                         guarantee(r), r["fit_seconds"] or float("nan"),
                         "%.2f / %.2f" % (r["de_vs_measured_mean"], r["de_vs_measured_p99"]),
                         "%.2f / %.2f" % (r["de_vs_projected_mean"], r["de_vs_projected_p99"]),
                         r["eval_ns"], r["render_seconds"]])
    L.append(P.md_table(body, hdr))
    return "\n".join(L)


def block_table(res) -> str:
    """The compact table of a run (``run``'s result) for its block in docs/results.md: per
    material, at each tolerance, coefficients, mean ΔE2000 vs the 3-D table and ns per evaluation;
    the tables' cost and the 2-D table's ΔE and the noise for scale."""
    rows, base_rows, meta = res["rows"], res["tables"], res["meta"]
    cfg = meta["config"]
    tols = list(cfg["tols"])
    tl = " / ".join(f"{100 * t:g}" for t in tols) + " %"

    def per_tol(m, f):
        d = {r["tol"]: r for r in rows if r["material"] == m}
        return " / ".join(f(d[t]) if t in d and "n_coefficients" in d[t] else "–" for t in tols)

    body = [[b["material"], per_tol(b["material"], lambda r: str(r["n_coefficients"])),
             per_tol(b["material"], lambda r: f"{r['de_vs_measured_mean']:.2f}"),
             per_tol(b["material"], lambda r: P._fmt(float(r["eval_ns"]))),
             per_tol(b["material"], guarantee),
             f"{b['projected_eval_ns']:.0f} / {b['measured_eval_ns']:.0f}",
             f"{b['de_proj_vs_meas_mean']:.2f} / {b['noise_de_mean']:.2f}"] for b in base_rows]
    hdr = ["material", f"coefficients at {tl}", "mean ΔE vs 3-D", "ns / eval", "in tol.",
           "ns / eval 2-D / 3-D table", "ΔE 2-D vs 3-D / noise"]
    return (P.md_table(body, hdr)
            + f"\n(sphere under `{meta['env']}`, {cfg['resolution']} px, sampler `light` at {cfg['spp']} spp, same "
              f"seed for every representation; mean ΔE2000 of the rational render against the 3-D table's on the "
              f"object's fully covered pixels; ns per RGB evaluation in the Warp kernel, one thread; "
              f"coefficients: R + G + B; {GUARANTEE_LEGEND}; –: no fit. Fitter: {meta['fitter'][1]}.)\n")


def plot(rows, base_rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mats = list(dict.fromkeys(r["material"] for r in rows if "n_coefficients" in r))
    fig, axes = plt.subplots(1, 3, figsize=(10, 3.0))
    for i, m in enumerate(mats):
        rs = sorted([r for r in rows if r["material"] == m and "n_coefficients" in r], key=lambda r: -r["tol"])
        c = plt.cm.tab10(i)
        tol = [r["tol"] for r in rs]
        axes[0].plot(tol, [r["n_coefficients"] for r in rs], "o-", color=c, label=m)
        axes[1].plot([r["n_coefficients"] for r in rs], [r["de_vs_measured_mean"] for r in rs], "o-", color=c, label=f"{m} vs 3-D")
        axes[1].plot([r["n_coefficients"] for r in rs], [r["de_vs_projected_mean"] for r in rs], "s--", color=c, alpha=0.6,
                     label=f"{m} vs 2-D")
        axes[2].plot([r["n_coefficients"] for r in rs], [r["eval_ns"] for r in rs], "o-", color=c, label=m)
        b = [x for x in base_rows if x["material"] == m][0]
        axes[1].axhline(b["de_proj_vs_meas_mean"], color=c, ls=":", lw=1)
    for b in base_rows[:1]:
        axes[2].axhline(b["measured_eval_ns"], color="k", ls=":", lw=1, label="3-D table")
        axes[2].axhline(b["projected_eval_ns"], color="0.5", ls="--", lw=1, label="2-D table")
    axes[0].set_xscale("log")
    axes[0].invert_xaxis()
    axes[0].set_xlabel("tolerance", fontsize=8)
    axes[0].set_ylabel("coefficients (R+G+B)", fontsize=8)
    axes[1].set_xlabel("coefficients", fontsize=8)
    axes[1].set_ylabel("mean ΔE2000 (dotted: 2-D vs 3-D)", fontsize=8)
    axes[2].set_xlabel("coefficients", fontsize=8)
    axes[2].set_ylabel("ns per evaluation", fontsize=8)
    for ax in axes:
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=72)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.fit_study", description=__doc__.split("\n")[0])
    p.add_argument("--out", default="results/fit_study")
    p.add_argument("--preset", choices=sorted(PRESETS), default="full")
    p.add_argument("--smoke", action="store_true")
    p.add_argument("--materials", nargs="*", choices=sorted(C.MATERIALS))
    p.add_argument("--tols", nargs="*", type=float)
    p.add_argument("--env", default="studio", choices=sorted(C.ENVMAPS))
    p.add_argument("--resolution", type=int)
    p.add_argument("--spp", type=int)
    p.add_argument("--no-fit", action="store_true", help="only cached/shipped fits")
    p.add_argument("--direct-fallback", action="store_true",
                   help="if the project's fitter is unavailable, use studies.fits.direct_fit (labelled)")
    P.add_docs_arguments(p)
    a = p.parse_args(argv)
    res = run("smoke" if a.smoke else a.preset, a.out, a.materials, a.tols, a.env, a.resolution, a.spp,
              not a.no_fit, a.direct_fallback)
    print(res["markdown"])
    print(f"wrote {a.out}/fit_study.csv, .json, .md, fit_study.png ({res['meta']['wall_seconds']:.0f} s)")
    P.publish_run(a, res, block_table, __file__, argv, DOCS)
    return res


if __name__ == "__main__":
    main()
