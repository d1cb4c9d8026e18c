"""The method's comparison renders (supplemental Figs. 4-5 of Pacanowski et al. 2012).

Each material is rendered with the measured 3-D table ("measured"), the projected 2-D table
("projected", median of each (theta_h, theta_d) cluster) and the rational fit ("rational", when a
fit is available, see :mod:`studies.fits`), on a sphere under

(a) ``colinear``: one directional light travelling along the camera axis (theta_d ≤ 6.2° at
    every visible point of the sphere: half the angle between the axis and a pixel's ray, which
    is at most 12.5° here), ``colinear_spp`` camera samples per pixel (anti-aliasing only);
(b) ``envmap``: the environment map with ``env_spp`` importance-sampled light directions per
    pixel (sampler "light": each camera sample draws one direction from the map's luminance
    distribution and traces one shadow ray; 1024 spp = 1024 lights per pixel).

All representations use the same seed (common random numbers: the same light directions per
pixel), so their differences are the representations', not the noise's. The remaining noise is
measured by rendering the 3-D table a second time with another seed ("noise floor").

Differences: CIE ΔE2000 per pixel (colour-science: linear Rec.709 -> XYZ with
``colour.RGB_to_XYZ``, -> Lab with ``colour.XYZ_to_Lab`` (D65), ``colour.delta_E(...,
method="CIE 2000")``) at one exposure per scene and material: the 99th percentile of the 3-D
render's luminance on the object is mapped to Y = 1 (L* = 100). Statistics on the object's fully
covered pixels: mean, 99th percentile; also by the view angle theta_o (where the error is).

    python -m studies.comparison --out results/comparison_full --docs  # full size, published to docs/
    python -m studies.comparison --out results/comparison --smoke
    python -m studies.comparison --preset moderate --out results/comparison     # 96 px, ~1 min

``--docs`` also copies the charts to ``docs/images/study_comparison_{colinear,envmap}.png``,
writes ``docs/study_comparison.md`` and its block in ``docs/results.md`` between
``<!-- BEGIN study:comparison -->`` and ``<!-- END study:comparison -->``
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
from studies import fits as F

PRESETS = {
    "smoke": dict(resolution=20, env_spp=16, colinear_spp=4, materials=["paper"], env="studio"),
    "moderate": dict(resolution=96, env_spp=1024, colinear_spp=16,
                     materials=list(C.MATERIALS), env="studio"),
    "full": dict(resolution=256, env_spp=1024, colinear_spp=64, materials=list(C.MATERIALS), env="studio"),
}
THETA_BINS = (0.0, 30.0, 60.0, 75.0, 90.0)
SEED, NOISE_SEED = 5, 900_001
PAIRS = (("measured", "projected"), ("measured", "rational"), ("projected", "rational"))
#: ``--docs``: the study's key, title and charts ({file in --out: name under docs/images/}).
DOCS = dict(name="comparison", title="The method's comparison (3-D table, 2-D projection, rational fit)",
            charts={"comparison_colinear.png": "study_comparison_colinear.png",
                    "comparison_envmap.png": "study_comparison_envmap.png"},
            about=("What it measures: how far the 2-D (θh, θd) projection and the 5 % rational fit render "
                   "from the 3-D measured table, as CIE ΔE2000 on the object's fully covered pixels (mean, "
                   "99th percentile, by view angle) against the noise floor of the 3-D table rendered with a "
                   "second seed; six RGL-EPFL materials on a sphere under a directional light colinear with "
                   "the view and under the `studio` map (the method's comparison of Pacanowski et al. 2012, "
                   "supplemental Figs. 4–5)."))


def view_angles(scene, renderer=None) -> np.ndarray:
    """Per-pixel view angle theta_o in degrees: the angle between the shading normal and each
    pixel's own ray back to the camera, from the mean cosine over 4x4 sub-pixel rays
    (:func:`studies.coverage.view_angle`). Not the angle to the light: the colinear light
    travels along the camera axis, so on the study's sphere (radius 0.8 seen from 3.7 away:
    half-angle 12.5°) the light's incidence angle reaches only ~77.5° at the silhouette where
    theta_o reaches 90°."""
    from studies.coverage import view_angle
    from warp_rbrdf import Renderer

    return view_angle(renderer if renderer is not None else Renderer(scene), 4)


def laplacian_energy(img, mask) -> float:
    """Mean |discrete Laplacian| of log luminance over the mask eroded by one pixel: how much
    pixel-scale structure (detail, noise or table artefacts) an image has."""
    Y = np.log(np.maximum(np.asarray(img, float) @ np.array([0.2126, 0.7152, 0.0722]), 1e-6))
    lap = -4 * Y[1:-1, 1:-1] + Y[:-2, 1:-1] + Y[2:, 1:-1] + Y[1:-1, :-2] + Y[1:-1, 2:]
    m = mask[1:-1, 1:-1] & mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:]
    return float(np.mean(np.abs(lap[m]))) if m.any() else float("nan")


def run(preset="full", out="results/comparison", materials=None, resolution=None, env=None,
        env_spp=None, colinear_spp=None, tol=0.05, allow_fit=True, allow_direct=False,
        geometry="sphere", charts=True, quiet=False) -> dict:
    cfg = dict(PRESETS[preset])
    for k, v in dict(materials=materials, resolution=resolution, env=env, env_spp=env_spp,
                     colinear_spp=colinear_spp).items():
        if v is not None:
            cfg[k] = v
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    rows, images, fit_info = [], {}, {}
    lights = [("colinear", "colinear", cfg["colinear_spp"]), ("envmap", cfg["env"], cfg["env_spp"])]
    bar = C.progress(total=len(cfg["materials"]) * 2, desc="comparison", disable=quiet)
    for mname in cfg["materials"]:
        reps = {"measured": C.material_spec("measured", C.measured(mname), "light"),
                "projected": C.material_spec("projected", C.projected(mname), "light")}
        model, info = F.rational_model(mname, tol, allow_fit=allow_fit, allow_direct=allow_direct)
        fit_info[mname] = dict(info, **(F.model_summary(model) if model is not None else {}))
        if model is not None:
            reps["rational"] = C.material_spec("rational", model, "light")
        for lname, light, spp in lights:
            bar.set_postfix_str(f"{mname}/{lname}")
            base = C.make_scene(geometry, light, reps["measured"], resolution=cfg["resolution"])
            imgs, secs = {}, {}
            for rep, spec in reps.items():
                r, _ = C.renderer(C.with_material(base, spec))
                r.render(spp=1, seed=0)
                imgs[rep], secs[rep] = C.timed_render(r, spp, SEED)
                if rep == "measured":
                    mask = C.object_mask(base, r)
                    noise, _ = C.timed_render(r, spp, NOISE_SEED)
            theta = view_angles(base, r)     # every representation: same geometry and camera
            expo = M.exposure_for(imgs["measured"], mask)
            images[(mname, lname)] = dict(imgs=imgs, exposure=expo, mask=mask, de={})
            row = dict(material=mname, light=lname, env=light, spp=spp, exposure=expo,
                       **{f"seconds_{k}": v for k, v in secs.items()})
            de_noise = M.delta_e2000(noise, imgs["measured"], expo)
            row.update({f"noise_de_{k}": v for k, v in M.de_stats(de_noise, mask).items()})
            for a, b in PAIRS:
                if a not in imgs or b not in imgs:
                    continue
                de = M.delta_e2000(imgs[b], imgs[a], expo)
                images[(mname, lname)]["de"][(a, b)] = de
                tag = f"{a[:4]}_{b[:4]}"
                row.update({f"de_{tag}_{k}": v for k, v in M.de_stats(de, mask).items()})
                for lo, hi in zip(THETA_BINS[:-1], THETA_BINS[1:]):
                    sel = mask & (theta >= lo) & (theta < hi)
                    row[f"de_{tag}_theta{int(lo)}_{int(hi)}"] = float(de[sel].mean()) if sel.any() else float("nan")
            for rep, im in imgs.items():
                row[f"lap_{rep}"] = laplacian_energy(im, mask)
            row["lap_noise"] = laplacian_energy(noise, mask)
            rows.append(row)
            np.savez_compressed(out / f"{mname}_{lname}.npz", mask=mask, theta_o=theta,
                                **{k: v for k, v in imgs.items()})
            bar.update(1)
    bar.close()
    meta = dict(preset=preset, config=cfg, tol=tol, geometry=geometry, seed=SEED, noise_seed=NOISE_SEED,
                fits=fit_info, machine=P.machine_info(), wall_seconds=time.perf_counter() - t_start)
    P.write_csv(out / "comparison.csv", rows)
    P.write_json(out / "comparison.json", dict(meta=meta, rows=rows))
    md = summary_markdown(rows, meta)
    (out / "comparison.md").write_text(md)
    if charts:
        for lname, _, _ in lights:
            plot(images, cfg["materials"], lname, out / f"comparison_{lname}.png")
    return dict(rows=rows, meta=meta, markdown=md)


def summary_markdown(rows, meta) -> str:
    cfg = meta["config"]
    L = [f"Sphere, {cfg['resolution']}×{cfg['resolution']} px; (a) one directional light colinear with the "
         f"view, {cfg['colinear_spp']} spp; (b) `{cfg['env']}` map, {cfg['env_spp']} importance-sampled "
         f"lights per pixel (sampler `light`, {cfg['env_spp']} spp); same seed for every representation. "
         f"ΔE2000 (colour-science) on the object's fully covered pixels, exposure: 99th-percentile "
         f"luminance of the 3-D render → L* = 100. Rational fits at tolerance {meta['tol']:g}.\n"]
    has_rat = any("de_meas_rati_mean" in r for r in rows)
    hdr = ["material", "light", "3-D↔2-D mean", "3-D↔2-D p99"]
    if has_rat:
        hdr += ["3-D↔rational mean", "3-D↔rational p99", "2-D↔rational mean"]
    hdr += ["noise floor mean", "3-D↔2-D mean by θo " + "/".join(f"{int(a)}–{int(b)}°" for a, b in
                                                               zip(THETA_BINS[:-1], THETA_BINS[1:])),
            "detail 3-D / 2-D"]
    body = []
    for r in rows:
        line = [r["material"], r["light"], r["de_meas_proj_mean"], r["de_meas_proj_p99"]]
        if has_rat:
            line += [r.get("de_meas_rati_mean", float("nan")), r.get("de_meas_rati_p99", float("nan")),
                     r.get("de_proj_rati_mean", float("nan"))]
        bins = "/".join(P._fmt(r[f"de_meas_proj_theta{int(a)}_{int(b)}"])
                        for a, b in zip(THETA_BINS[:-1], THETA_BINS[1:]))
        line += [r["noise_de_mean"], bins, r["lap_measured"] / r["lap_projected"]]
        body.append(line)
    L.append(P.md_table(body, hdr))
    L.append("\n\"detail 3-D / 2-D\": mean |Laplacian| of log luminance of the 3-D render over that of the "
             "2-D render (> 1: the 3-D table shows more pixel-scale structure: φd detail, noise or "
             "acquisition artefacts that the projection removes).\n")
    fits = meta.get("fits", {})
    if fits:
        L.append("\nRational fits: " + "; ".join(
            f"{m}: {f['n_coefficients']} coefficients ({f['source']})" if f.get("source")
            else f"{m}: none ({f.get('error', '')[:120]})" for m, f in fits.items()) + "\n")
    return "\n".join(L)


def block_table(res) -> str:
    """The compact table of a run (``run``'s result) for its block in docs/results.md: per
    material and light, mean / p99 ΔE2000 of 3-D ↔ 2-D and 3-D ↔ rational, the noise floor, and
    3-D ↔ 2-D by view angle."""
    rows, meta = res["rows"], res["meta"]
    cfg = meta["config"]
    bins = list(zip(THETA_BINS[:-1], THETA_BINS[1:]))

    def pair(r, tag):
        m, q = r.get(f"de_{tag}_mean"), r.get(f"de_{tag}_p99")
        return "–" if m is None else f"{P._fmt(m)} / {P._fmt(q)}"

    body = [[r["material"], r["light"], pair(r, "meas_proj"), pair(r, "meas_rati"), r["noise_de_mean"],
             "/".join(P._fmt(r[f"de_meas_proj_theta{int(a)}_{int(b)}"]) for a, b in bins)] for r in rows]
    hdr = ["material", "light", "3-D ↔ 2-D", "3-D ↔ rational", "noise floor",
           "3-D ↔ 2-D by θo " + "/".join(f"{int(a)}–{int(b)}°" for a, b in bins)]
    fits = meta.get("fits", {})
    coef = "; ".join(f"{m} {f['n_coefficients']}" if f.get("n_coefficients") else f"{m} none"
                     for m, f in fits.items())
    return (P.md_table(body, hdr)
            + f"\n(mean / 99th percentile ΔE2000 on the object's fully covered pixels; sphere "
              f"{cfg['resolution']} px; colinear light {cfg['colinear_spp']} spp; `{cfg['env']}` map with "
              f"{cfg['env_spp']} importance-sampled lights per pixel; rational: fits at tolerance "
              f"{meta['tol']:g}" + (f", coefficients: {coef}" if coef else "") + ".)\n")


def plot(images, materials, lname, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mats = [m for m in materials if (m, lname) in images]
    if not mats:
        return
    reps = ["measured", "projected", "rational"]
    cols = reps + [f"ΔE {a[:4]}↔{b[:4]}" for a, b in PAIRS[:2]]
    fig, axes = plt.subplots(len(mats), len(cols), figsize=(1.6 * len(cols), 1.6 * len(mats) + 0.4),
                             squeeze=False)
    for i, m in enumerate(mats):
        d = images[(m, lname)]
        for j, rep in enumerate(reps):
            ax = axes[i, j]
            if rep in d["imgs"]:
                x = np.clip(d["imgs"][rep] * d["exposure"], 0, None)
                srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
                ax.imshow(np.clip(srgb, 0, 1), interpolation="nearest")
            else:
                ax.text(0.5, 0.5, "no fit", ha="center", va="center", fontsize=7)
        for j, pair in enumerate(PAIRS[:2]):
            ax = axes[i, 3 + j]
            if pair in d["de"]:
                im = ax.imshow(np.where(d["mask"], d["de"][pair], np.nan), cmap="magma", vmin=0, vmax=10,
                               interpolation="nearest")
            else:
                ax.text(0.5, 0.5, "–", ha="center", va="center", fontsize=7)
        axes[i, 0].set_ylabel(m, fontsize=7)
    for j, c in enumerate(cols):
        axes[0, j].set_title(c, fontsize=7)
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{lname}: 3-D table, 2-D projection, rational fit; ΔE2000 (0–10)", fontsize=8)
    fig.tight_layout()
    if "im" in locals():
        fig.colorbar(im, ax=axes[:, 3:].ravel().tolist(), shrink=0.5)
    fig.savefig(path, dpi=72)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.comparison", description=__doc__.split("\n")[0])
    p.add_argument("--out", default="results/comparison")
    p.add_argument("--preset", choices=sorted(PRESETS), default="full")
    p.add_argument("--smoke", action="store_true")
    p.add_argument("--materials", nargs="*", choices=sorted(C.MATERIALS))
    p.add_argument("--resolution", type=int)
    p.add_argument("--env", choices=sorted(C.ENVMAPS))
    p.add_argument("--env-spp", type=int)
    p.add_argument("--colinear-spp", type=int)
    p.add_argument("--tol", type=float, default=0.05)
    p.add_argument("--no-fit", action="store_true", help="use only cached/shipped fits, never run the fitter")
    p.add_argument("--direct-fallback", action="store_true",
                   help="if the project's fitter is unavailable, fit with studies.fits.direct_fit (labelled)")
    P.add_docs_arguments(p)
    a = p.parse_args(argv)
    res = run("smoke" if a.smoke else a.preset, a.out, a.materials, a.resolution, a.env, a.env_spp,
              a.colinear_spp, a.tol, not a.no_fit, a.direct_fallback)
    print(res["markdown"])
    print(f"wrote {a.out}/comparison.csv, .json, .md, comparison_*.png ({res['meta']['wall_seconds']:.0f} s)")
    P.publish_run(a, res, block_table, __file__, argv, DOCS)
    return res


if __name__ == "__main__":
    main()
