"""The limb of the 2-D representations: how much of the error that ``projected`` and
``rational`` show along the sphere's silhouette under a sunny map is the median's, how much any
function of (theta_h, theta_d) alone must leave, and what a fit that keeps phi_d shows there.

Scene and renders as :mod:`studies.fidelity` (the reference scene of Mitsuba 3's ``measured``
plugin: unit sphere, camera at (0, 0, 4), 30 deg vertical fov, hidden map at scale 1, one
environment and one BSDF sample per camera sample, power heuristic; each image the mean of two
half-spp renders with the study's seeds). Every representation is rendered with the ``mis``
sampler and compared **paired** with the ``rgl`` material (the ``.bsdf`` file evaluated
exactly) rendered with the same sampler and seeds, so the difference is the representations'
alone:

* ``measured``: the 3-D MERL-grid table of the file (keeps phi_d);
* ``projected``: the (theta_h, theta_d) table of per-cluster **medians** over phi_d (the
  paper's projection, the table the 2-D fits approximate);
* ``projected-mean``: the table of per-cluster **means** over phi_d. Per cluster the mean is the
  least-squares best constant over the cluster's phi_d samples, so this table is the closest
  (in L2 over the MERL grid's samples) that any function of (theta_h, theta_d) alone comes to
  the measurement: what it leaves on the limb no 2-D representation removes;
* ``rational``: the 2-D fit at 5 % (:func:`studies.fidelity.rational_fit`: cached or shipped
  fits; new fits only with ``--fit``), flagged pieces shown as the projected table (the
  renderer's default);
* ``rational-3d``: a 3-D fit of (theta_h, theta_d, |phi_d|) (:mod:`fit.rational.fit3d`)
  read from ``--fits3d`` (``<stem>_3d.json``, as ``python -m benchmarks.bench_fit_accuracy``
  writes them), when the folder has one.

Regions (pixels fully covered by the sphere, as the fidelity study): the **inside** (the disc
without its rim band), the **grazing-sun rim** (the rim band's pixels where the map's brightest
texel, the sun, is within 17.5 deg of the local horizon: |n . s| < 0.3; there the view and the
sun are both grazing) and the **other rim** (the rest of the band). Per region and
representation: the luminance ratio (mean Rec.709 luminance over the ``rgl`` render's) and the
ΔE2000 mean at the fidelity study's exposure (99th-percentile luminance of the reference ->
L* = 100).

    python -m studies.limb --docs                          # 20 materials under rooitou
    python -m studies.limb --materials paper_white --resolution 64 --spp 16   # a quick look
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from studies import common as C
from studies import fidelity as FI
from studies import metrics as M
from studies import publish as P
from warp_rbrdf.lights.latlong import LUMINANCE as LUMA

REPS = ("measured", "projected", "projected-mean", "rational", "rational-3d")
REGIONS = ("inside", "grazing_sun_rim", "other_rim")
SUN_GRAZING = 0.3                # |n . s| below it: the sun within 17.5 deg of the local horizon
FIT_TIME_LIMIT_S = 300.0         # a new 2-D fit (``--fit``), as the fidelity study bounds it
DOCS = dict(name="limb", title="The limb of the 2-D representations (median, mean, 2-D and 3-D fits)",
            charts={"limb.png": "study_limb.png"},
            about=("What it measures: the error of the 2-D representations along the sphere's silhouette "
                   "under a sunny map (`rooitou`), where light and view both graze: the luminance ratio and "
                   "CIE ΔE2000 against the `rgl` material (same rays) on the grazing-sun rim, the rest of the "
                   "rim and the inside of the disc, for the 3-D table, the φd-median and φd-mean (θh, θd) "
                   "tables, the 2-D rational fit and the 3-D rational fit: how much of the error is the "
                   "median's, how much any function of (θh, θd) alone must leave, and what a fit that keeps "
                   "φd shows there."))
PRESETS = {
    "full": dict(resolution=256, spp=128, maps=["rooitou"], materials=None, tol=0.05,
                 fits3d="results/fit_accuracy", allow_fit=False),
    "smoke": dict(resolution=32, spp=8, maps=["rooitou"], materials=["paper_white"], tol=0.05,
                  fits3d="results/fit_accuracy", allow_fit=False),
}


def sun_direction(envmap) -> np.ndarray:
    """World direction (3,) of the brightest texel (Rec.709 luminance) of a lat-long map, by the
    conventions of :mod:`warp_rbrdf.lights.latlong` (identity rotation)."""
    from warp_rbrdf.lights.env_file import read_latlong
    from warp_rbrdf.lights.latlong import uv_to_direction

    img = read_latlong(envmap)
    H, W = img.shape[:2]
    j, i = np.unravel_index(np.argmax(img[..., :3] @ LUMA), (H, W))
    return uv_to_direction((i + 0.5) / W, (j + 0.5) / H)


def pixel_normals(scene) -> np.ndarray:
    """(H, W, 3) unit normals of the scene's unit sphere (centred at the origin) at the pixel
    centres' camera rays; NaN where a ray misses."""
    from warp_rbrdf.camera import camera_frame, camera_rays_numpy

    W, H = scene.camera.resolution
    px, py = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    d = camera_rays_numpy(scene.camera, px, py)
    o = np.asarray(camera_frame(scene.camera)[0], float)
    b = d @ o
    disc = b * b - (o @ o - 1.0)
    t = -b - np.sqrt(np.where(disc >= 0, disc, np.nan))
    return o + t[..., None] * d


def regions(scene, mask, band, envmap) -> dict:
    """Boolean (H, W) masks of :data:`REGIONS` (module docstring)."""
    grazing = np.abs(pixel_normals(scene) @ sun_direction(envmap)) < SUN_GRAZING    # NaN (a miss): False
    return {"inside": mask & ~band, "grazing_sun_rim": band & grazing, "other_rim": band & ~grazing}


def region_stats(img, ref, masks, exposure) -> dict:
    """Per region: ``y_ratio`` (mean luminance of ``img`` over ``ref``'s) and ``de_mean``."""
    de = M.delta_e2000(img, ref, exposure)
    out = {}
    for k, m in masks.items():
        if not m.any():
            continue
        y = float((img[m] @ LUMA).mean()) / max(float((ref[m] @ LUMA).mean()), 1e-30)
        out[k] = dict(y_ratio=y, de_mean=float(np.nanmean(de[m])), pixels=int(m.sum()))
    return out


def representations(path, tol: float, fits3d: Path | None, allow_fit: bool) -> tuple[dict, list]:
    """``({name: MaterialSpec}, notes)`` of the representations of one RGL file."""
    from fit.formats import load_measured
    from fit.projection.project import project
    from warp_rbrdf.scene import MaterialSpec

    meas = load_measured(path)
    specs, notes = {}, []

    def spec(kind, **kw):
        return MaterialSpec(name="obj", type=kind, sampler=FI.PAIRED_SAMPLER, **kw)

    specs["measured"] = spec("measured", data=meas)
    specs["projected"] = spec("projected", data=project(meas, statistic="median"))
    specs["projected-mean"] = spec("projected", data=project(meas, statistic="mean"))
    stem = Path(path).stem
    model, info = FI.rational_fit(path, tol, FIT_TIME_LIMIT_S, allow_fit)
    if model is not None:
        specs["rational"] = (spec("rational", file=Path(info["file"])) if info.get("file") else
                             spec("rational", data=model))
    else:
        notes.append(f"rational: no {100 * tol:g} % fit ({info.get('error')})")
    f3 = Path(fits3d) / f"{stem}_3d.json" if fits3d is not None else None
    if f3 is not None and f3.is_file():
        specs["rational-3d"] = spec("rational", file=f3)
    else:
        notes.append(f"rational-3d: no 3-D fit {f3} (python -m benchmarks.bench_fit_accuracy writes them)")
    return specs, notes


def run(preset="full", out="results/limb", materials=None, maps=None, resolution=None, spp=None,
        fits3d=None, allow_fit=None, charts=True, quiet=False) -> dict:
    from lab import mitsuba_reference as MR

    allm = FI.rgl_materials()
    cfg = FI.study_config(PRESETS[preset], allm, materials=materials, maps=maps, resolution=resolution, spp=spp,
                          fits3d=fits3d, allow_fit=allow_fit)
    res = int(cfg["resolution"])
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    f3dir = Path(cfg["fits3d"]) if cfg["fits3d"] else None
    if f3dir is not None and not f3dir.is_absolute():
        f3dir = C.ROOT / f3dir
    t0 = time.perf_counter()
    rows, images = [], {}
    bar = C.progress(total=len(cfg["materials"]) * len(cfg["maps"]), desc="limb", disable=quiet)
    for m in cfg["materials"]:
        specs, notes = representations(allm[m], cfg["tol"], f3dir, cfg["allow_fit"])
        for mapname in cfg["maps"]:
            env = C.data_path(FI.MAPS[mapname])
            base = MR.sphere_scene(allm[m], env, spp=cfg["spp"], resolution=res, pattern="stratified",
                                   tile_size=16)
            base.materials["obj"].sampler = FI.PAIRED_SAMPLER
            ref = FI.render_halves(base, cfg["spp"])
            mask = C.object_mask(base, ref["renderer"]) & MR.sphere_mask(res)
            masks = regions(base, mask, FI.rim_band(res, mask), env)
            expo = M.exposure_for(ref["img"], mask)
            row = dict(material=m, map=mapname, notes=list(notes), exposure=expo,
                       pixels={k: int(v.sum()) for k, v in masks.items()}, stats={})
            imgs = {"rgl": ref["img"]}
            for rep, spec in specs.items():
                try:
                    x = FI.render_halves(FI._with(base, spec), cfg["spp"])
                except Exception as e:  # noqa: BLE001 - a representation that cannot load: reported
                    row["notes"].append(f"{rep}: {type(e).__name__}: {e}")
                    continue
                row["stats"][rep] = region_stats(x["img"], ref["img"], masks, expo)
                imgs[rep] = x["img"]
            rows.append(row)
            images[(m, mapname)] = dict(imgs=imgs, exposure=expo, masks=masks)
            bar.update(1)
            if not quiet:
                print(one_line(row), flush=True)
    bar.close()
    meta = dict(preset=preset, config=cfg, seeds=FI.SEEDS, rim_px=FI.rim_width(res), machine=P.machine_info(),
                wall_seconds=time.perf_counter() - t0)
    summary = summarize(rows)
    P.write_json(out / "limb.json", dict(meta=meta, summary=summary, rows=rows))
    md = markdown(rows, meta, summary)
    (out / "limb.md").write_text(md)
    if charts and images:
        plot(images, out / "limb.png")
    return dict(rows=rows, meta=meta, summary=summary, markdown=md)


# --------------------------------------------------------------------------------------------
def _cell(s) -> str:
    return "–" if s is None else f"{s['y_ratio']:.3f} / {s['de_mean']:.2f}"


def one_line(row) -> str:
    st = row["stats"]
    return (f"{row['material']}/{row['map']}: grazing-sun / other rim Y ratio / ΔE " +
            "; ".join(f"{k} {_cell(v.get('grazing_sun_rim'))}, {_cell(v.get('other_rim'))}" for k, v in st.items()) +
            (f"  [{'; '.join(row['notes'])}]" if row["notes"] else ""))


def summarize(rows) -> dict:
    """Per representation and region: the range and median over the rows of the luminance ratio
    and ΔE mean."""
    out = {}
    for rep in REPS:
        for reg in REGIONS:
            xs = [r["stats"][rep][reg] for r in rows if reg in r["stats"].get(rep, {})]
            if not xs:
                continue
            y = np.array([x["y_ratio"] for x in xs])
            d = np.array([x["de_mean"] for x in xs])
            out.setdefault(rep, {})[reg] = dict(n=len(xs), y_min=float(y.min()), y_max=float(y.max()),
                                                y_median=float(np.median(y)), de_min=float(d.min()),
                                                de_max=float(d.max()), de_median=float(np.median(d)))
    return out


def summary_table(summary) -> str:
    body = []
    for rep, regs in summary.items():
        cells = []
        for reg in REGIONS:
            s = regs.get(reg)
            cells.append("–" if s is None else
                         f"{s['y_median']:.3f} ({s['y_min']:.2f}–{s['y_max']:.2f}) / "
                         f"{s['de_median']:.2f} ({s['de_min']:.2f}–{s['de_max']:.2f})")
        body.append([rep, max(s["n"] for s in regs.values())] + cells)
    return P.md_table(body, ["representation", "cases", "inside", "grazing-sun rim", "other rim"])


def markdown(rows, meta, summary) -> str:
    cfg = meta["config"]
    L = [f"{cfg['resolution']} px, {cfg['spp']} spp (two halves, seeds {meta['seeds']}), rim band "
         f"{meta['rim_px']:g} px, maps {', '.join(cfg['maps'])}; every representation rendered with `mis` and "
         f"paired with `rgl` on the same rays. Cells: luminance ratio over `rgl` / ΔE2000 mean; summary: median "
         f"(range) over the cases.", "", summary_table(summary), ""]
    for reg in REGIONS:
        L += [f"Per case, {reg.replace('_', ' ').replace('grazing sun', 'grazing-sun')}:", "",
              P.md_table([[r["material"], r["map"]] + [_cell(r["stats"].get(rep, {}).get(reg)) for rep in REPS]
                          for r in rows], ["material", "map"] + list(REPS)), ""]
    notes = [f"- {r['material']}/{r['map']}: {n}" for r in rows for n in r["notes"]]
    if notes:
        L += ["", "Notes:", ""] + notes
    return "\n".join(L) + "\n"


def block_table(res) -> str:
    return (summary_table(res["summary"]) +
            "\n(luminance ratio over `rgl` / ΔE2000 mean: median (range) over the cases; "
            "[study_limb.md](study_limb.md) has every case.)\n")


def plot(images, path, shown=REPS, lo=0.7, hi=1.3):
    """Luminance-ratio maps (representation over ``rgl``; grey 1, black <= ``lo``, white >= ``hi``),
    one row per case."""
    import matplotlib.pyplot as plt

    keys = list(images)
    height = 1.6 * len(keys) + 0.4
    fig, axes = plt.subplots(len(keys), len(shown) + 1, figsize=(1.6 * (len(shown) + 1), height), squeeze=False)
    for i, k in enumerate(keys):
        d = images[k]
        ref = d["imgs"]["rgl"]
        mask = d["masks"]["inside"] | d["masks"]["grazing_sun_rim"] | d["masks"]["other_rim"]
        axes[i, 0].imshow(FI._srgb(ref, d["exposure"]))
        axes[i, 0].set_ylabel(f"{k[0]}\n{k[1]}", fontsize=6)
        for j, rep in enumerate(shown, 1):
            ax = axes[i, j]
            if rep in d["imgs"]:
                ratio = (d["imgs"][rep] @ LUMA) / np.maximum(ref @ LUMA, 1e-30)
                ax.imshow(np.where(mask, ratio, np.nan), cmap="gray", vmin=lo, vmax=hi)
            if i == 0:
                ax.set_title(rep, fontsize=7)
        if i == 0:
            axes[i, 0].set_title("rgl (reference)", fontsize=7)
    for ax in axes.flat:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"luminance over rgl (black ≤ {lo}, white ≥ {hi})", fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.3 / height))     # the title above the column titles
    P.save_figure(fig, path)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.limb", description=__doc__.split("\n")[0])
    p.add_argument("--out", default="results/limb")
    p.add_argument("--quick", "--smoke", dest="quick", action="store_true",
                   help="smoke configuration: paper_white, rooitou, 32 px, 8 spp")
    p.add_argument("--materials", nargs="*", help="short names of shared RGL files (default: all)")
    p.add_argument("--maps", nargs="*", choices=sorted(FI.MAPS), help="default: rooitou")
    p.add_argument("--resolution", type=int)
    p.add_argument("--spp", type=int, help="samples per pixel (even)")
    p.add_argument("--fits3d", help="folder of 3-D fits <stem>_3d.json (default results/fit_accuracy)")
    p.add_argument("--fit", action="store_true", help="make 2-D fits that are neither cached nor shipped")
    P.add_docs_arguments(p)
    a = p.parse_args(argv)
    res = run("smoke" if a.quick else "full", a.out, a.materials, a.maps, a.resolution, a.spp, a.fits3d,
              True if a.fit else None)
    print(res["markdown"])
    print(f"wrote {a.out}/limb.json, .md, limb.png ({res['meta']['wall_seconds']:.0f} s)")
    P.publish_run(a, res, block_table, __file__, argv, DOCS)
    return res


if __name__ == "__main__":
    main()
