"""Where a 3-D fit's image error comes from: the chart's sphere rendered exactly (direct light,
NumPy quadrature over the environment map, no sampling noise) with the fit and with the
measurement, the CIEDE2000 per pixel, and for the worst 1 % of the pixels (what the p99 target
sees) the share of their luminance error that comes from light beyond 80 and 85 degrees of their
normal, and from the map's sun.

The scene is the chart's (``lab.mitsuba_reference``): camera at (0, 0, 4) looking at the origin,
+y up, 30 deg vertical field of view, a unit sphere, ``--res`` pixels a side (default 64, the
chart's), the pixels of the chart's mask (``lab.mitsuba_reference.sphere_mask``), a pixel's colour
taken at its centre; the hidden environment map (conventions.md:
``u = atan2(x, -z) / 2 pi``, ``v = acos(y) / pi``) averaged over blocks of ``--block`` x
``--block`` texels (default 16: 64 x 32 directions for the 1k maps), each block's radiance
weighted by its texels' ``sin(theta)`` so its power is kept; the sun is the block holding more
than a fifth of the brightest block's luminance. Pixel value: ``sum_k rho(wi_k, wo) cos(theta_i,k)
L_k dA_k`` over the blocks above the pixel's horizon (a convex object: no shadows), ``rho`` the
fit (:func:`fit.rational.variables3d.evaluate_directions`) or the measurement
(:meth:`fit.formats.rgl.RGLBRDF.evaluate`, light = ``wi``). Exposure as the chart's: the truth's
99th-percentile luminance over the pixels is Y = 1. The ΔE2000 is
:func:`fit.rational.image_check.delta_e2000`.

The quadrature is not the renderer (pixel centres, a coarse map): its ΔE is a proxy for the
chart's 1,024-spp renders, checked against them in docs/fit_accuracy.md ("Where the p99 misses
come from"). Per case it reports the ΔE mean and p99, the mean by view angle, and for the worst
1 % of pixels their median view angle, the fit's luminance over the truth's, and the shares of
their (signed) luminance error from lights at theta_i > 80 and > 85 deg and from the sun
(medians over those pixels).

    python -m benchmarks.bench_error_sources --fit-dir results/chart/fits --out results/error_sources.json
    python -m benchmarks.bench_error_sources --fit-dir DIR --materials acrylic_felt_green --maps rooitou
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
MAPS = {"studio": "envmaps/studio_small_03_1k.hdr", "rooitou": "envmaps/rooitou_park_1k.hdr"}
CAMERA_Z = 4.0
FOV_Y_DEG = 30.0
VIEW_BANDS = ((0, 45), (45, 60), (60, 70), (70, 80), (80, 90))


def data_dir() -> Path:
    return Path(os.environ.get("RBRDF_DATA", str(ROOT.parent / "shared" / "data")))


def block_map(img: np.ndarray, block: int):
    """``(dirs (K, 3), power (K, 3))`` of a lat-long map ``(H, W, 3)`` averaged over ``block`` x
    ``block`` texels: each block's centre direction and its radiance times its solid angle (sr),
    the texels weighted by ``sin(theta)`` of their rows (centres at ``(r + 0.5) / H``)."""
    img = np.asarray(img, np.float64)
    H, W = img.shape[:2]
    if H % block or W % block:
        raise ValueError(f"--block {block} does not divide the map's {W} x {H} texels")
    h, w = H // block, W // block
    s = np.sin(np.pi * (np.arange(H) + 0.5) / H)
    E = (img * s[:, None, None]).reshape(h, block, w, block, 3).sum((1, 3)) / (block * block)
    u, v = np.meshgrid((np.arange(w) + 0.5) / w, (np.arange(h) + 0.5) / h)
    d = np.stack([np.sin(2 * np.pi * u) * np.sin(np.pi * v), np.cos(np.pi * v),
                  -np.cos(2 * np.pi * u) * np.sin(np.pi * v)], -1).reshape(-1, 3)
    return d, E.reshape(-1, 3) * (2 * np.pi / w) * (np.pi / h)


def sphere_pixels(res: int):
    """``(normals (P, 3), wo (P, 3))`` (world) of the pixels the chart measures
    (:func:`lab.mitsuba_reference.sphere_mask`: whole footprint on the sphere, a pixel inside
    its silhouette), at their centre rays."""
    from lab.mitsuba_reference import sphere_mask

    t = np.tan(np.radians(FOV_Y_DEG) / 2)
    c = (2 * (np.arange(res) + 0.5) / res - 1) * t
    X, Y = np.meshgrid(c, -c)
    d = np.stack([X, Y, -np.ones_like(X)], -1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.array([0.0, 0.0, CAMERA_Z])
    b = d @ o
    disc = b * b - (o @ o - 1.0)
    hit = sphere_mask(res) & (disc > 0)
    tt = -b[hit] - np.sqrt(disc[hit])
    n = o + tt[:, None] * d[hit]
    return n / np.linalg.norm(n, axis=1, keepdims=True), -d[hit]


def _chunked(evaluate, wi, wo, n: int = 200_000) -> np.ndarray:
    """``max(evaluate(wi, wo), 0)`` (M, 3) in chunks of ``n`` pairs (bounded memory)."""
    return np.concatenate([np.maximum(np.asarray(evaluate(wi[i:i + n], wo[i:i + n]), np.float64), 0.0)
                           for i in range(0, len(wi), n)] or [np.zeros((0, 3))])


def error_sources(brdf, fit_eval, dirs, power, res: int = 64, truth_cache: dict | None = None) -> dict:
    """The module docstring's numbers for one material and map: ``brdf.evaluate`` and
    ``fit_eval(wi, wo) -> rho (M, 3)`` under the blocks ``dirs``, ``power`` (:func:`block_map`).
    ``truth_cache``: a dict the measurement's values are kept in (key ``"rho"``) and taken from,
    for several fits of one material under one map (the same pairs)."""
    from fit.formats.colour import LUMINANCE
    from fit.rational.image_check import delta_e2000, rgb_to_lab, tangent_frames

    nrm, wo_w = sphere_pixels(res)
    F = tangent_frames(nrm)                                    # (3, P, 3)
    wo = np.einsum("fpj,pj->pf", F, wo_w)
    wi = np.einsum("fpj,kj->pkf", F, dirs)                     # (P, K, 3) every block in every frame
    P = wi.shape[0]
    pp, kk = np.nonzero(wi[..., 2] > 1e-4)
    w_i, w_o = wi[pp, kk], wo[pp]
    if truth_cache is not None and "rho" in truth_cache:
        rho_t = truth_cache["rho"]
    else:
        rho_t = _chunked(brdf.evaluate, w_i, w_o)
        if truth_cache is not None:
            truth_cache["rho"] = rho_t
    contrib_t = rho_t * w_i[:, 2:3] * power[kk]
    contrib_f = _chunked(fit_eval, w_i, w_o) * w_i[:, 2:3] * power[kk]
    img_t = np.stack([np.bincount(pp, contrib_t[:, c], minlength=P) for c in range(3)], axis=1)
    img_f = np.stack([np.bincount(pp, contrib_f[:, c], minlength=P) for c in range(3)], axis=1)
    Y = np.percentile(img_t @ LUMINANCE, 99.0)
    expo = 1.0 / Y if Y > 0 else 1.0
    de = delta_e2000(rgb_to_lab(img_f, expo), rgb_to_lab(img_t, expo))
    theta_o = np.degrees(np.arccos(np.clip(wo[:, 2], -1, 1)))
    lum = power @ LUMINANCE
    sun = lum > 0.2 * lum.max()
    worst = np.argsort(de)[-max(1, P // 100):]
    rank = np.full(P, -1)
    rank[worst] = np.arange(len(worst))
    sel = rank[pp] >= 0                                        # the pairs of the worst pixels
    rows, err = rank[pp[sel]], (contrib_f[sel] - contrib_t[sel]) @ LUMINANCE
    theta_i = np.degrees(np.arccos(np.clip(w_i[sel, 2], -1, 1)))
    total = np.bincount(rows, err, minlength=len(worst))

    def share(mask):
        part = np.bincount(rows[mask], err[mask], minlength=len(worst))
        return float(np.median(part / np.where(total == 0, 1.0, total)))

    on_sun = sun[kk[sel]]
    return {"pixels": int(P), "de_mean": float(de.mean()), "de_p99": float(np.percentile(de, 99)),
            "de_by_view": {f"{a}-{b}": float(de[(theta_o >= a) & (theta_o < b)].mean())
                           for a, b in VIEW_BANDS if np.any((theta_o >= a) & (theta_o < b))},
            "worst": {"theta_o_median": float(np.median(theta_o[worst])),
                      "fit_over_truth": float(np.median((img_f[worst] @ LUMINANCE)
                                                        / np.maximum(img_t[worst] @ LUMINANCE, 1e-300))),
                      "error_share_theta_i_gt_80": share(theta_i > 80), "error_share_theta_i_gt_85": share(theta_i > 85),
                      "error_share_sun": share(on_sun),
                      "sun_theta_i_median": float(np.median(theta_i[on_sun])) if np.any(on_sun) else None}}


def newest_fit(fit_dir: Path, stem: str) -> Path | None:
    files = sorted(fit_dir.glob(f"{stem}_rgb*.json"), key=lambda p: (p.stat().st_mtime, p.name))
    return files[-1] if files else None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_error_sources", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--fit-dir", action="append", default=[], metavar="[LABEL=]DIR",
                    help="folder of 3-D fit files <material>_rgb*.json (the newest per material); repeatable")
    ap.add_argument("--materials", nargs="+", default=None, help="RGL material names (default: all shared)")
    ap.add_argument("--maps", nargs="+", default=list(MAPS), choices=list(MAPS))
    ap.add_argument("--res", type=int, default=64, help="pixels a side (default 64, the chart's)")
    ap.add_argument("--block", type=int, default=16, help="texels a side averaged into one light (default 16)")
    ap.add_argument("--out", type=Path, default=None, help="write the results as JSON (merged with an existing file)")
    a = ap.parse_args(argv)
    if not a.fit_dir:
        ap.error("--fit-dir is required")
    from fit.formats.rgl import read_rgl
    from fit.rational.coefficient_reader import load
    from fit.rational.variables3d import evaluate_directions
    from warp_rbrdf.lights.env_file import read_latlong

    data = data_dir()
    mats = a.materials or sorted(p.name[:-len("_rgb.bsdf")] for p in (data / "rgl").glob("*_rgb.bsdf"))
    dirs = [d.split("=", 1) if "=" in d else (Path(d).name, d) for d in a.fit_dir]
    maps = {m: block_map(read_latlong(data / MAPS[m]), a.block) for m in a.maps}
    res = json.loads(a.out.read_text()) if a.out and a.out.is_file() else {}
    print(f"{'material':22s} {'map':8s} {'fit':12s} {'ΔE mean':>8s} {'p99':>6s}  worst 1 %: theta_o, fit/truth, "
          "error share from theta_i > 80 / > 85 deg / the sun (sun's theta_i)")
    for mat in mats:
        brdf = read_rgl(data / "rgl" / f"{mat}_rgb.bsdf")
        truth = {m: {} for m in a.maps}              # the measurement's values, once per map
        for label, d in dirs:
            f = newest_fit(Path(d), mat)
            if f is None:
                continue
            model = load(f)
            for m in a.maps:
                t0 = time.perf_counter()
                r = error_sources(brdf, lambda wi, wo: evaluate_directions(model, wi, wo), *maps[m], res=a.res,
                                  truth_cache=truth[m])
                r.update(file=str(f), seconds=time.perf_counter() - t0, res=a.res, block=a.block)
                res[f"{mat}/{m}/{label}"] = r
                w = r["worst"]
                sun = "-" if w["sun_theta_i_median"] is None else f"{w['sun_theta_i_median']:.0f}"
                print(f"{mat:22s} {m:8s} {label:12s} {r['de_mean']:8.2f} {r['de_p99']:6.2f}  {w['theta_o_median']:4.0f}  "
                      f"{w['fit_over_truth']:.2f}  {w['error_share_theta_i_gt_80']:+.2f} / {w['error_share_theta_i_gt_85']:+.2f} / "
                      f"{w['error_share_sun']:+.2f} ({sun})", flush=True)
                if a.out:
                    a.out.parent.mkdir(parents=True, exist_ok=True)
                    a.out.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
