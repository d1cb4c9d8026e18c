"""Convergence study: accuracy against speed for every sampler the renderer offers.

For each scene (geometry x light) x material x sampler, render at spp = 1, 2, 4, ... with several
seeds, time the render (wall clock, all cores, compile and a warm-up launch excluded) and measure
the RMSE against a reference image on the object's fully covered pixels.

Reference: the same scene rendered with the "mis" sampler (environment sample + cosine BSDF
sample, power heuristic) at ``ref_spp`` samples per pixel with a seed (1_000_003) that no test
render uses, so its noise is independent of every render it is compared with. Its own remaining
noise (the "floor": the mean over the mask of the per-pixel sample variance / ref_spp, an upper
bound for the stratified pattern) is reported; RMSE values near the floor mean "converged".

Samplers come from the registry (``warp_rbrdf.registry.STRATEGY_NAMES``): the four base ones
(uniform, cosine, light, mis) first, then the inverse-CDF ones; a sampler that a material type
does not support is recorded as skipped.

Presets: ``full`` (default; with ``--docs`` it makes the block in docs/results.md): 64×64 px,
spp = 1, 2, 4, ..., 1024, 3 seeds, reference 8192 spp, sphere and bunny under rooitou (tiny sun),
studio and a colinear light, ibiza and paper (12 scenes; about 30 minutes on 2 cores);
``moderate``: 48 px, spp ≤ 512, 2 seeds, reference 4096 spp, the same scenes; ``smoke``: 12 px,
spp ≤ 8, one seed, sphere under rooitou and colinear, ibiza, rational inverse CDFs with
:data:`studies.common.SMALL_CDF_PIECES` (CI).

    python -m studies.convergence --out results/convergence --docs     # full size, published to docs/
    python -m studies.convergence --out results/convergence --smoke    # tiny
    python -m studies.convergence --preset moderate --out results/convergence_moderate

``--docs`` also copies the charts to ``docs/images/study_convergence_*.png``, writes
``docs/study_convergence.md`` and its block in ``docs/results.md`` between
``<!-- BEGIN study:convergence -->`` and ``<!-- END study:convergence -->``
(:func:`studies.publish.publish_docs`).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from studies import common as C
from studies import metrics as M
from studies import publish as P

PRESETS = {
    # resolution, spp list max, seeds, reference spp
    # cdf_pieces: pieces layout options of the rational inverse CDFs (absent: the layout's defaults)
    "smoke": dict(resolution=12, max_spp=8, seeds=1, ref_spp=256, geometries=["sphere"],
                  lights=["rooitou", "colinear"], materials=["ibiza"], cdf_pieces=C.SMALL_CDF_PIECES),
    "moderate": dict(resolution=48, max_spp=512, seeds=2, ref_spp=4096,
                     geometries=["sphere", "bunny"], lights=["rooitou", "studio", "colinear"],
                     materials=["ibiza", "paper"]),
    # about 30 minutes on 2 cores (every sampler, 12 scenes)
    "full": dict(resolution=64, max_spp=1024, seeds=3, ref_spp=8192,
                 geometries=["sphere", "bunny"], lights=["rooitou", "studio", "colinear"],
                 materials=["ibiza", "paper"]),
}
REF_SEED = 1_000_003
#: ``--docs``: the study's key, title and charts ({file in --out: name under docs/images/}).
DOCS = dict(name="convergence", title="Convergence",
            charts={"convergence_rmse_time.png": "study_convergence_rmse_time.png",
                    "convergence_rmse_spp.png": "study_convergence_rmse_spp.png",
                    "convergence_efficiency.png": "study_convergence_efficiency.png"},
            block_charts=("study_convergence_rmse_time.png", "study_convergence_efficiency.png"),
            about=("What it measures: for every sampler the renderer offers, the relative RMSE of a render "
                   "against a reference image as the samples per pixel and the render seconds grow, and the "
                   "efficiency 1/(rel. MSE × seconds) relative to `mis`; a sphere and the bunny under a tiny "
                   "sun (`rooitou`), a few compact lights (`studio`) and a directional light colinear with the "
                   "view, with a glossy (cc_ibiza_sunset) and a matte (paper_white) RGL-EPFL material. The "
                   "reference is `mis` at many more samples per pixel with a seed no other render uses."))
#: Columns of the results page's compact table: relative RMSE of these samplers, efficiency vs MIS of
#: the last ones.
BLOCK_SAMPLERS = ("cosine", "light", "mis", "tabulated", "rational-derivative", "mis-tabulated", "mis-rational")
BLOCK_EFFICIENCY = ("light", "mis-tabulated", "mis-rational")
_SHORT = {"rational-derivative": "rational-deriv.", "mis-tabulated": "mis-tab.", "mis-rational": "mis-rat."}


def spp_list(max_spp: int) -> list[int]:
    out, s = [], 1
    while s <= max_spp:
        out.append(s)
        s *= 2
    return out


def run(preset="full", out="results/convergence", samplers=None, resolution=None, max_spp=None,
        seeds=None, ref_spp=None, geometries=None, lights=None, materials=None, threads=None,
        charts=True, quiet=False) -> dict:
    cfg = dict(PRESETS[preset])
    for k, v in dict(resolution=resolution, max_spp=max_spp, seeds=seeds, ref_spp=ref_spp,
                     geometries=geometries, lights=lights, materials=materials).items():
        if v is not None:
            cfg[k] = v
    C.CDF_TIME_LIMIT_S = None          # the inverse-CDF samplers' fits: fit_cdf's default limit
    C.CDF_PIECES_KW = cfg.get("cdf_pieces")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    all_s = C.all_samplers()
    samplers = list(samplers) if samplers else list(all_s)
    spps = spp_list(cfg["max_spp"])
    seed_list = [11 + 7919 * i for i in range(cfg["seeds"])]
    rows, refs, skipped = [], [], []
    configs = [(g, l, m) for g in cfg["geometries"] for l in cfg["lights"] for m in cfg["materials"]]
    bar = C.progress(total=len(configs) * len(samplers), desc="convergence", disable=quiet)
    t_start = time.perf_counter()
    for g, l, mname in configs:
        base = C.make_scene(g, l, C.material_spec("measured", C.measured(mname), "mis"),
                            resolution=cfg["resolution"])
        r, _ = C.renderer(base)
        mask = C.object_mask(base, r)
        ref, tref, var = C.timed_render(r, cfg["ref_spp"], REF_SEED, threads, variance=True)
        floor_mse = float(np.mean(var[mask]) / cfg["ref_spp"])
        mean_ref = float(np.mean(ref[mask]))
        refs.append(dict(geometry=g, light=l, material=mname, ref_sampler="mis", ref_spp=cfg["ref_spp"],
                         ref_seed=REF_SEED, ref_seconds=tref, mean_radiance=mean_ref,
                         floor_rmse=np.sqrt(floor_mse), floor_rel_rmse=np.sqrt(floor_mse) / mean_ref,
                         mask_pixels=int(mask.sum())))
        np.save(out / f"ref_{g}_{l}_{mname}.npy", ref)
        for s in samplers:
            bar.set_postfix_str(f"{g}/{l}/{mname}/{s}")
            try:
                rs, csec = C.renderer(C.with_sampler(base, s))
                rs.render(spp=1, seed=0, threads=threads)  # warm-up launch (not timed)
            except Exception as e:  # noqa: BLE001 - a sampler a material does not support
                skipped.append(dict(geometry=g, light=l, material=mname, sampler=s, reason=str(e)[:200]))
                bar.update(1)
                continue
            for spp in spps:
                for seed in seed_list:
                    img, sec = C.timed_render(rs, spp, seed, threads)
                    e = M.rmse(img, ref, mask)
                    rows.append(dict(geometry=g, light=l, material=mname, sampler=s, spp=spp, seed=seed,
                                     seconds=sec, rmse=e, rel_rmse=e / mean_ref,
                                     rel_mse=(e / mean_ref) ** 2, compile_seconds=csec,
                                     finite=bool(np.all(np.isfinite(img)))))
            bar.update(1)
    bar.close()
    summary = summarize(rows, refs)
    meta = dict(preset=preset, config=cfg, samplers=samplers, samplers_available=list(all_s), spp=spps,
                seeds=seed_list, reference=f"sampler 'mis' at {cfg['ref_spp']} spp, seed {REF_SEED}",
                metric="RMSE over fully covered object pixels (all 3 channels), relative = RMSE / mean "
                       "reference radiance on those pixels; time = render wall seconds, "
                       f"threads = {threads or 'all'} cores",
                machine=P.machine_info(), wall_seconds=time.perf_counter() - t_start, skipped=skipped)
    P.write_csv(out / "convergence.csv", rows)
    P.write_csv(out / "references.csv", refs)
    P.write_json(out / "convergence.json", dict(meta=meta, references=refs, rows=rows, summary=summary))
    md = summary_markdown(summary, refs, meta)
    (out / "convergence.md").write_text(md)
    if charts:
        plot(rows, refs, summary, out)
    return dict(rows=rows, references=refs, summary=summary, meta=meta, markdown=md)


def summarize(rows, refs) -> list[dict]:
    """Per config and sampler at the largest spp: medians over seeds, efficiency 1/(relMSE * s),
    and efficiency relative to "mis" (> 1: better than MIS)."""
    if not rows:
        return []
    top = max(r["spp"] for r in rows)
    groups: dict = {}
    for r in rows:
        if r["spp"] == top:
            groups.setdefault((r["geometry"], r["light"], r["material"], r["sampler"]), []).append(r)
    out = []
    for (g, l, m, s), rs in groups.items():
        rel = float(np.median([x["rel_rmse"] for x in rs]))
        sec = float(np.median([x["seconds"] for x in rs]))
        out.append(dict(geometry=g, light=l, material=m, sampler=s, spp=top, rel_rmse=rel, seconds=sec,
                        efficiency=1.0 / max(rel * rel * sec, 1e-300)))
    for o in out:
        mis = [x for x in out if (x["geometry"], x["light"], x["material"], x["sampler"])
               == (o["geometry"], o["light"], o["material"], "mis")]
        o["eff_vs_mis"] = o["efficiency"] / mis[0]["efficiency"] if mis else float("nan")
    # slope of log rel_rmse vs log spp (ideal Monte Carlo: -0.5)
    for o in out:
        rs = [x for x in rows if (x["geometry"], x["light"], x["material"], x["sampler"])
              == (o["geometry"], o["light"], o["material"], o["sampler"])]
        sp = np.array([x["spp"] for x in rs], float)
        e = np.array([x["rel_rmse"] for x in rs], float)
        ok = (e > 0) & np.isfinite(e)
        o["slope"] = float(np.polyfit(np.log(sp[ok]), np.log(e[ok]), 1)[0]) if ok.sum() > 2 and len(set(sp[ok])) > 1 \
            else float("nan")
    return out


def summary_markdown(summary, refs, meta) -> str:
    cfg = meta["config"]
    samplers = meta["samplers"]
    lines = [f"Convergence at {cfg['resolution']}×{cfg['resolution']} px, spp = 1…{cfg['max_spp']}, "
             f"{cfg['seeds']} seeds (medians); reference: {meta['reference']}. Relative RMSE on the "
             f"object's fully covered pixels at {cfg['max_spp']} spp; efficiency = 1/(rel. MSE × "
             f"render seconds), shown relative to MIS (> 1 is better than MIS). One sample: camera "
             f"ray, every directional light (one shadow ray), plus light: one environment sample; "
             f"cosine/uniform: one BSDF sample; mis: both, power heuristic. "
             f"{meta['machine']['cpus']} cores.\n"]
    header = ["scene", "material", "ref. floor"] + [f"{s} rel. RMSE" for s in samplers] \
        + [f"{s} eff./MIS" for s in samplers if s != "mis"]
    rows = []
    for ref in refs:
        key = (ref["geometry"], ref["light"], ref["material"])
        d = {s["sampler"]: s for s in summary if (s["geometry"], s["light"], s["material"]) == key}
        rows.append([f"{ref['geometry']} / {ref['light']}", ref["material"], ref["floor_rel_rmse"]]
                    + [d[s]["rel_rmse"] if s in d else float("nan") for s in samplers]
                    + [d[s]["eff_vs_mis"] if s in d else float("nan") for s in samplers if s != "mis"])
    lines.append(P.md_table(rows, header))
    # seconds per sample, medians over all configs
    sec = {}
    for s in summary:
        sec.setdefault(s["sampler"], []).append(s["seconds"])
    lines.append("\nRender seconds at the top spp (median over scenes): "
                 + ", ".join(f"{s} {np.median(v):.3g} s" for s, v in sec.items()) + ".\n")
    if meta.get("skipped"):
        sk = sorted({(x["sampler"], x["reason"][:80]) for x in meta["skipped"]})
        lines.append("\nSkipped: " + "; ".join(f"{s} ({r})" for s, r in sk) + "\n")
    return "\n".join(lines)


def block_table(res) -> str:
    """The compact table of a run (``run``'s result) for its block in docs/results.md: per scene,
    relative RMSE at the top spp of :data:`BLOCK_SAMPLERS` and efficiency vs MIS of
    :data:`BLOCK_EFFICIENCY`."""
    summary, refs, meta = res["summary"], res["references"], res["meta"]
    cfg = meta["config"]
    top = max((s["spp"] for s in summary), default=cfg["max_spp"])
    header = ["scene", "material", *(s.replace("derivative", "deriv.") for s in BLOCK_SAMPLERS),
              "eff./MIS: " + " / ".join(_SHORT.get(s, s) for s in BLOCK_EFFICIENCY)]
    body = []
    for ref in refs:
        key = (ref["geometry"], ref["light"], ref["material"])
        d = {s["sampler"]: s for s in summary if (s["geometry"], s["light"], s["material"]) == key}
        body.append([f"{ref['geometry']} / {ref['light']}", ref["material"]]
                    + [d[s]["rel_rmse"] if s in d else float("nan") for s in BLOCK_SAMPLERS]
                    + [" / ".join(P._fmt(d[s]["eff_vs_mis"] if s in d else float("nan"))
                                  for s in BLOCK_EFFICIENCY)])
    return (P.md_table(body, header)
            + f"\n(relative RMSE at {top} spp, median of {cfg['seeds']} seeds, on the object's fully covered "
              f"pixels at {cfg['resolution']}×{cfg['resolution']} px; reference: {meta['reference']}; "
              f"efficiency 1/(rel. MSE × render seconds) relative to MIS, > 1: better than MIS; "
              f"–: sampler not run.)\n")


def plot(rows, refs, summary, out: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    configs = [(r["geometry"], r["light"], r["material"]) for r in refs]
    samplers = list(dict.fromkeys(r["sampler"] for r in rows))
    colors = {s: plt.cm.tab10(i) for i, s in enumerate(samplers)}
    ncol = min(4, len(configs))
    nrow = int(np.ceil(len(configs) / ncol))
    for xkey, fname, xlabel in (("spp", "rmse_spp", "samples per pixel"),
                                ("seconds", "rmse_time", "render seconds")):
        fig, axes = plt.subplots(nrow, ncol, figsize=(3.0 * ncol, 2.4 * nrow), squeeze=False)
        for ax, (g, l, m) in zip(axes.flat, configs):
            ref = [r for r in refs if (r["geometry"], r["light"], r["material"]) == (g, l, m)][0]
            for s in samplers:
                rs = [r for r in rows if (r["geometry"], r["light"], r["material"], r["sampler"]) == (g, l, m, s)]
                if not rs:
                    continue
                spps = sorted({r["spp"] for r in rs})
                x = [np.median([r[xkey] for r in rs if r["spp"] == p]) for p in spps]
                y = [np.median([r["rel_rmse"] for r in rs if r["spp"] == p]) for p in spps]
                ax.loglog(x, y, "o-", ms=2.5, lw=1.2, color=colors[s], label=s)
            ax.axhline(ref["floor_rel_rmse"], color="0.5", ls=":", lw=1)
            ax.set_title(f"{g} / {l} / {m}", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(True, which="major", alpha=0.3)
        for ax in axes.flat[len(configs):]:
            ax.axis("off")
        for ax in axes[-1]:
            ax.set_xlabel(xlabel, fontsize=8)
        for ax in axes[:, 0]:
            ax.set_ylabel("relative RMSE", fontsize=8)
        axes.flat[0].legend(fontsize=7)
        fig.suptitle(f"relative RMSE vs {xlabel} (dotted: reference noise floor)", fontsize=9)
        fig.tight_layout()
        fig.savefig(out / f"convergence_{fname}.png", dpi=60)
        plt.close(fig)
    # efficiency bars
    fig, ax = plt.subplots(figsize=(max(6.0, 0.75 * len(configs)), 3.2))
    w = 0.8 / max(len(samplers), 1)
    for i, s in enumerate(samplers):
        y = []
        for c in configs:
            d = [x for x in summary if (x["geometry"], x["light"], x["material"], x["sampler"]) == (*c, s)]
            y.append(d[0]["efficiency"] if d else np.nan)
        ax.bar(np.arange(len(configs)) + (i - (len(samplers) - 1) / 2) * w, y, w, color=colors[s], label=s)
    ax.set_yscale("log")
    ax.set_xticks(np.arange(len(configs)))
    ax.set_xticklabels([f"{g}\n{l}\n{m}" for g, l, m in configs], fontsize=6)
    ax.set_ylabel("1 / (rel. MSE × seconds)", fontsize=8)
    ax.legend(fontsize=7, ncol=len(samplers))
    ax.set_title("efficiency at the largest spp (higher is better)", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "convergence_efficiency.png", dpi=72)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.convergence", description=__doc__.split("\n")[0])
    p.add_argument("--out", default="results/convergence")
    p.add_argument("--preset", choices=sorted(PRESETS), default="full")
    p.add_argument("--smoke", action="store_true", help="tiny size (same as --preset smoke)")
    p.add_argument("--samplers", nargs="*", help="default: every sampler the renderer offers")
    p.add_argument("--resolution", type=int)
    p.add_argument("--max-spp", type=int)
    p.add_argument("--seeds", type=int)
    p.add_argument("--ref-spp", type=int)
    p.add_argument("--geometries", nargs="*")
    p.add_argument("--lights", nargs="*")
    p.add_argument("--materials", nargs="*")
    p.add_argument("--threads", type=int)
    P.add_docs_arguments(p)
    a = p.parse_args(argv)
    res = run("smoke" if a.smoke else a.preset, a.out, a.samplers, a.resolution, a.max_spp, a.seeds,
              a.ref_spp, a.geometries, a.lights, a.materials, a.threads)
    print(res["markdown"])
    print(f"wrote {a.out}/convergence.csv, convergence.json, convergence.md, convergence_*.png "
          f"({res['meta']['wall_seconds']:.0f} s)")
    P.publish_run(a, res, block_table, __file__, argv, DOCS)
    return res


if __name__ == "__main__":
    main()
