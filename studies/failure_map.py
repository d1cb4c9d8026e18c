"""Failure map: where each sampler or fit breaks down, with numbers.

Cases (each pinned by a test in tests/test_studies.py):

* ``mirror``: a near-mirror lobe written as an exact-layout MERL file (``fit.formats.merl.write_merl``)
  from an analytic normalized Blinn-Phong lobe (exponent 5000, ~1 deg wide, peak ~200 /sr, plus
  a 2 % Lambert term) on a sphere under the studio map and under the tiny sun (rooitou);
* ``grazing``: a plane seen at a grazing angle (view ~80 deg from the normal) against the same
  plane seen from above, glossy ibiza vinyl under the studio map (sampler noise, and the 2-D
  projection's error against the 3-D table, ΔE2000);
* ``sun``: diffuse paper_white on a sphere under the tiny bright sun (rooitou) against the studio
  map;
* ``low_albedo``: paper_white scaled by 0.02 (samplers: relative noise is unchanged, the
  estimators are linear in the BRDF; fit: with an absolute interval floor the relative guarantee
  is lost);
* ``fit_mirror``: a rational fit at 5 % of the mirror lobe's projection needs far more
  coefficients than a diffuse material, or is flagged infeasible;
* ``mirror_cdf``: the rational inverse CDFs of the mirror lobe (the fitter's default layout,
  "pieces"): per view row rational or sent to the table with the reason (variance gate), or an
  explicit fallback to the tabulated sampler (the same fit is what the inverse-CDF samplers of
  the mirror rows use).

Sampler metric (no reference image needed): the relative standard error of the pixel estimate,
``sqrt(mean over the mask of (per-pixel sample variance / spp)) / mean radiance``, with
independent samples (pattern "independent", so the sample variance is unbiased), median over
seeds. It is what an RMSE against the converged image would be without bias; heavy-tailed
estimators (rare fireflies) are *under*-estimated at low spp, so the numbers are lower bounds for
the failing samplers.

    python -m studies.failure_map --out results/failure_map_full --docs   # full size, published to docs/
    python -m studies.failure_map --out results/failure_map --smoke
    python -m studies.failure_map --preset moderate --out results/failure_map   # 48 px, ~1.5 min

``--docs`` also copies the chart to ``docs/images/study_failure_map.png``, writes
``docs/study_failure_map.md`` and its block in ``docs/results.md`` between
``<!-- BEGIN study:failure_map -->`` and ``<!-- END study:failure_map -->``
(:func:`studies.publish.publish_docs`).
"""
from __future__ import annotations

import argparse
import time
from functools import lru_cache
from pathlib import Path

import numpy as np

from studies import common as C
from studies import metrics as M
from studies import publish as P

#: cdf_time_limit: bound (s) on each material's rational inverse-CDF fit (global layout only; 0:
#: none, so that the larger presets' pages do not depend on the machine's load);
#: cdf_pieces: options of the pieces layout (absent: its defaults; the small presets use
#: :data:`studies.common.SMALL_CDF_PIECES`).
PRESETS = {
    "smoke": dict(resolution=16, spp=16, seeds=1, fit_stride=9, fit_max_degree=4, cdf_time_limit=5.0,
                  cdf_pieces=C.SMALL_CDF_PIECES),
    "test": dict(resolution=24, spp=32, seeds=2, fit_stride=9, fit_max_degree=4, cdf_time_limit=20.0,
                 cdf_pieces=C.SMALL_CDF_PIECES),
    "moderate": dict(resolution=48, spp=64, seeds=3, fit_stride=3, fit_max_degree=8, cdf_time_limit=0.0),
    "full": dict(resolution=96, spp=256, seeds=4, fit_stride=2, fit_max_degree=10, cdf_time_limit=0.0),
}
MIRROR_EXPONENT = 5000
#: ``--docs``: the study's key, title and chart ({file in --out: name under docs/images/}).
DOCS = dict(name="failure_map", title="Failure map", charts={"failure_map.png": "study_failure_map.png"},
            about=("What it measures: where each sampler and fit breaks down. The relative standard error "
                   "of the pixel estimate of every sampler on a near-mirror lobe under compact lights and "
                   "under a tiny sun, a glossy plane seen at a grazing and at a steep view, a matte sphere "
                   "under the tiny sun and the same material at 2 % of its albedo; the 2-D projection's "
                   "ΔE2000 against the 3-D table at the grazing view; and how a rational fit and the rational "
                   "inverse CDFs cope with the mirror lobe and the low albedo. `tests/test_studies.py` pins "
                   "these findings."))


# --------------------------------------------------------------------------------------------
def mirror_lobe_file(path, exponent: int = MIRROR_EXPONENT, kd: float = 0.02, ks: float = 1.0) -> Path:
    """Write the near-mirror lobe as an exact-layout MERL ``.binary`` and return its path.

    rho = kd / pi + ks (n + 8) / (8 pi) cos^n theta_h  (grey; normalized Blinn-Phong)."""
    from fit.formats.measured import MeasuredBRDF
    from fit.formats.merl import write_merl

    path = Path(path)
    if path.exists():
        return path

    def f(wi, wo):
        h = wi + wo
        h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        c = np.clip(h[..., 2], 0.0, 1.0)
        v = kd / np.pi + ks * (exponent + 8) / (8 * np.pi) * c ** exponent
        return np.repeat(v[..., None], 3, -1)

    path.parent.mkdir(parents=True, exist_ok=True)
    write_merl(MeasuredBRDF.from_function(f, name=f"mirror_n{exponent}"), path)
    return path


def load_mirror(out_dir) -> object:
    """The mirror lobe's table (one object per folder and process: its tables and fits are
    cached by object in :func:`studies.common.cdf_for`)."""
    return _load_mirror(str(Path(out_dir).resolve()))


@lru_cache(maxsize=4)
def _load_mirror(out_dir: str):
    from fit.formats import load_measured

    return load_measured(mirror_lobe_file(Path(out_dir) / f"mirror_n{MIRROR_EXPONENT}.binary"))


def sampler_noise(geometry, light, spec, samplers, resolution, spp, seeds) -> dict:
    """Relative standard error per sampler (see the module docstring); also the mean radiance."""
    base = C.make_scene(geometry, light, spec, resolution=resolution)
    base.integrator.pattern = "independent"
    out = {}
    mask = None
    for s in samplers:
        try:
            r, _ = C.renderer(C.with_sampler(base, s))
            if mask is None:
                mask = C.object_mask(base, r)
            errs, secs, bad = [], [], 0
            for k in range(seeds):
                img, sec, var = C.timed_render(r, spp, 101 + 31 * k, variance=True)
                fin = mask & np.all(np.isfinite(img), -1) & np.all(np.isfinite(var), -1)
                bad += int((mask & ~fin).sum())  # non-finite pixels: a sampler bug, reported
                mu = float(np.mean(img[fin]))
                errs.append(np.sqrt(np.mean(var[fin]) / spp) / mu if mu > 0 else float("nan"))
                secs.append(sec)
            out[s] = dict(rel_err=float(np.median(errs)), seconds=float(np.median(secs)), mean=mu,
                          nonfinite_pixels=bad)
        except Exception as e:  # noqa: BLE001 - a sampler the material does not support
            out[s] = dict(rel_err=float("nan"), seconds=float("nan"), error=str(e)[:160])
    return out


def projection_error(geometry, light, material_key, resolution, spp, data=None) -> dict:
    """ΔE2000 of the 2-D projection against the 3-D table (sampler light, same seed)."""
    from fit.projection.project import project

    m3 = data if data is not None else C.measured(material_key)
    m2 = project(m3) if data is not None else C.projected(material_key)
    base = C.make_scene(geometry, light, C.material_spec("measured", m3, "light"), resolution=resolution)
    r3, _ = C.renderer(base)
    mask = C.object_mask(base, r3)
    a = r3.render(spp=spp, seed=5)
    r2, _ = C.renderer(C.with_material(base, C.material_spec("projected", m2, "light")))
    b = r2.render(spp=spp, seed=5)
    n = r3.render(spp=spp, seed=6)
    expo = M.exposure_for(a, mask)
    d = M.de_stats(M.delta_e2000(b, a, expo), mask)
    dn = M.de_stats(M.delta_e2000(n, a, expo), mask)
    return dict(de_mean=d["mean"], de_p99=d["p99"], noise_de_mean=dn["mean"])


def fit_channel(proj, tol, abs_floor, stride, max_degree, channel=1, theta_d_max_deg=80.0, scale=1.0):
    """IntervalRationalFitter on one channel of a projection (sqrt theta_h, theta_d); returns
    coefficients, feasibility, seconds and the relative errors at the data points: over every
    point with a value > 0 (``max_rel_err``, ``p99_rel_err``), and over the points where the
    interval is relative, value >= abs_floor / tol (``max_rel_err_relative``; the share of such
    points is ``relative_share``). Below that value the floor sets the interval, so a fit inside
    its intervals may be off by many times the value there."""
    from fit.rational.fitter import IntervalRationalFitter

    th = proj.theta_h[::stride]
    td = proj.theta_d[::stride]
    keep = td <= np.radians(theta_d_max_deg)
    TH, TD = np.meshgrid(np.sqrt(th), td[keep], indexing="ij")
    y = scale * np.asarray(proj.value, float)[::stride, ::stride][:, keep, channel]
    X = np.stack([TH.ravel(), TD.ravel()], -1)
    y = y.ravel()
    ok = np.isfinite(y)
    t0 = time.perf_counter()
    res = IntervalRationalFitter(tol=tol, abs_floor=abs_floor, max_degree=max_degree).fit(X[ok], y[ok])
    dt = time.perf_counter() - t0
    pred = res.function(X[ok]) if res.function is not None else np.full(ok.sum(), np.nan)
    pos = y[ok] > 0
    rel = np.abs(pred[pos] - y[ok][pos]) / y[ok][pos]
    relative = y[ok][pos] >= abs_floor / tol
    return dict(n_coefficients=int(res.n_coefficients), feasible=bool(res.feasible), valid=bool(res.valid),
                degrees=[int(res.num_degree), int(res.den_degree)], max_rel_err=float(rel.max()),
                max_rel_err_relative=float(rel[relative].max()) if relative.any() else float("nan"),
                relative_share=float(relative.mean()),
                p99_rel_err=float(np.percentile(rel, 99)), seconds=dt, points=int(ok.sum()),
                max_value=float(y[ok].max()))


# --------------------------------------------------------------------------------------------
def mirror_cdf(mirror) -> dict:
    """Fit (tables + rational inverse CDFs, with ``C.CDF_TIME_LIMIT_S`` and ``C.CDF_PIECES_KW``) of
    the mirror lobe, cached for the samplers; returns its outcome."""
    t0 = time.perf_counter()
    fit = C.cdf_for(C.material_spec("measured", mirror, sampler="rational"), rational=True)
    fi = fit.fit_info
    return dict(fallback=bool(fit.fallback), reason=fit.reason, seconds=time.perf_counter() - t0,
                fit_seconds=fi.get("time_s"), time_limit_s=fi.get("time_limit_s"),
                time_limit_reached=bool(fi.get("time_limit_reached")),
                theta=fi.get("theta", {}).get("n_coefficients"), phi=fi.get("phi", {}).get("n_coefficients"),
                layout=fi.get("layout", fit.layout), n_u=fi.get("n_u"), n_u_tried=fi.get("n_u_tried"),
                verified_rows=fi.get("verified_rows"), n_rows=fi.get("n_rows"))


def run(preset="full", out="results/failure_map", samplers=None, charts=True, quiet=False,
        cases=("mirror", "grazing", "sun", "low_albedo", "fit", "mirror_cdf")) -> dict:
    cfg = dict(PRESETS[preset])
    C.CDF_TIME_LIMIT_S = cfg["cdf_time_limit"]
    C.CDF_PIECES_KW = cfg.get("cdf_pieces")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    samplers = list(samplers or C.all_samplers())
    res, spp, seeds = cfg["resolution"], cfg["spp"], cfg["seeds"]
    t_start = time.perf_counter()
    noise_rows, other = [], {}
    jobs = []
    if "mirror" in cases:
        mirror = load_mirror(out)   # one object per process (cached), so its CDFs are shared
        jobs += [("mirror lobe / studio", "sphere", "studio", C.material_spec("measured", mirror)),
                 ("mirror lobe / sun", "sphere", "rooitou", C.material_spec("measured", mirror))]
    if "grazing" in cases:
        jobs += [("ibiza plane / view 80°", "grazing_plane", "studio", C.material_spec("measured", C.measured("ibiza"))),
                 ("ibiza plane / view 10°", "normal_plane", "studio", C.material_spec("measured", C.measured("ibiza")))]
    if "sun" in cases:
        jobs += [("paper sphere / sun", "sphere", "rooitou", C.material_spec("measured", C.measured("paper"))),
                 ("paper sphere / studio", "sphere", "studio", C.material_spec("measured", C.measured("paper")))]
    if "low_albedo" in cases:
        jobs += [("paper×0.02 sphere / studio", "sphere", "studio",
                  C.material_spec("measured", C.measured("paper"), scale=0.02))]
    bar = C.progress(total=len(jobs) + (2 if "grazing" in cases else 0) + (4 if "fit" in cases else 0)
                     + ("mirror_cdf" in cases), desc="failure map", disable=quiet)
    if "mirror_cdf" in cases:
        # First, so the mirror rows' inverse-CDF samplers reuse it (studies.common.cdf_for).
        bar.set_postfix_str("mirror inverse CDFs")
        other["mirror_cdf"] = mirror_cdf(load_mirror(out))
        bar.update(1)
    for label, g, l, spec in jobs:
        bar.set_postfix_str(label)
        d = sampler_noise(g, l, spec, samplers, res, spp, seeds)
        noise_rows.append(dict(case=label, geometry=g, light=l, spp=spp,
                               **{f"{s}_rel_err": v["rel_err"] for s, v in d.items()},
                               **{f"{s}_seconds": v["seconds"] for s, v in d.items()},
                               **{f"{s}_nonfinite": v.get("nonfinite_pixels", 0) for s, v in d.items()},
                               **{f"{s}_error": v["error"] for s, v in d.items() if "error" in v}))
        bar.update(1)
    if "grazing" in cases:
        for label, g in (("view 80°", "grazing_plane"), ("view 10°", "normal_plane")):
            bar.set_postfix_str(f"projection {label}")
            other[f"projection_de_{g}"] = projection_error(g, "studio", "ibiza", res, spp)
            bar.update(1)
    if "fit" in cases:
        from fit.projection.projected import ProjectedBRDF  # noqa: F401
        from fit.projection.project import project

        mirror = load_mirror(out)
        pm = project(mirror)
        pp = C.projected("paper")
        st, md = cfg["fit_stride"], cfg["fit_max_degree"]
        for key, proj, tol, floor, scale in (
                ("fit_paper", pp, 0.05, 1e-3, 1.0),
                ("fit_mirror", pm, 0.05, 1e-3, 1.0),
                ("fit_mirror_floor_0.1%_of_peak", pm, 0.05, 1e-3 * float(np.nanmax(pm.value[..., 1])), 1.0),
                ("fit_paper_x0.02", pp, 0.05, 1e-3, 0.02)):
            bar.set_postfix_str(key)
            other[key] = dict(fit_channel(proj, tol, floor, st, md, scale=scale), tol=tol, abs_floor=floor,
                              scale=scale, stride=st, max_degree=md)
            bar.update(1)
    bar.close()
    meta = dict(preset=preset, config=cfg, samplers=samplers, mirror_exponent=MIRROR_EXPONENT,
                metric="relative standard error sqrt(mean(var)/spp)/mean over fully covered pixels, "
                       "pattern independent, median over seeds",
                machine=P.machine_info(), wall_seconds=time.perf_counter() - t_start)
    P.write_csv(out / "failure_map.csv", noise_rows)
    P.write_json(out / "failure_map.json", dict(meta=meta, samplers=noise_rows, other=other))
    md = summary_markdown(noise_rows, other, meta)
    (out / "failure_map.md").write_text(md)
    if charts and noise_rows:
        plot(noise_rows, samplers, out / "failure_map.png", spp)
    return dict(samplers=noise_rows, other=other, meta=meta, markdown=md)


def _sampler_findings(rows, other, meta) -> list[str]:
    """The sampler table and the projection / mirror-CDF lines (the summary's first part, and the
    results page's block)."""
    cfg = meta["config"]
    s = meta["samplers"]
    L = []

    def cell(r, x):
        v = r.get(f"{x}_rel_err", float("nan"))
        n = r.get(f"{x}_nonfinite", 0)
        return f"{P._fmt(v)} ({n} NaN px)" if n else v

    L.append(P.md_table([[r["case"]] + [cell(r, x) for x in s] for r in rows], ["case"] + list(s)))
    if any(r.get(f"{x}_nonfinite", 0) for r in rows for x in s):
        L.append("\n\"NaN px\": pixels of the object with a non-finite value or variance, summed over the "
                 "seeds (a sampler bug); the error is measured on the finite pixels.\n")
    if "projection_de_grazing_plane" in other:
        g, n = other["projection_de_grazing_plane"], other["projection_de_normal_plane"]
        L.append(f"\nProjection (2-D vs 3-D, ibiza, studio map, sampler light, {cfg['spp']} spp): mean ΔE2000 "
                 f"{g['de_mean']:.2f} (p99 {g['de_p99']:.2f}) at a view 80° from the normal vs "
                 f"{n['de_mean']:.2f} (p99 {n['de_p99']:.2f}) at 10°; same-representation noise "
                 f"{g['noise_de_mean']:.2f} / {n['noise_de_mean']:.2f}.\n")
    if "mirror_cdf" in other:
        m = other["mirror_cdf"]
        lim = "" if m.get("time_limit_s") is None else f", time limit {m['time_limit_s']:g} s"
        if m.get("n_u"):
            tried = m.get("n_u_tried") or {}
            lim += f", {m['n_u']} phi pieces" + (f" (of {'/'.join(map(str, tried))} tried)" if len(tried) > 1 else "")
        L.append(f"\nRational inverse CDFs of the mirror lobe ({m['layout']} layout{lim}): "
                 + (f"FALLBACK to the tabulated sampler ({m['reason']})" if m["fallback"] else m["reason"])
                 + f", {m['fit_seconds']:.1f} s.\n")
    return L


def block_table(res) -> str:
    """The compact block of a run (``run``'s result) for docs/results.md: the relative standard
    error per case and sampler, and the projection and mirror inverse-CDF findings (the fits:
    study_failure_map.md only)."""
    meta = res["meta"]
    cfg = meta["config"]
    return (f"Relative standard error of the pixel estimate at {cfg['spp']} spp ({cfg['resolution']} px, "
            f"independent samples, median of {cfg['seeds']} seeds; > 1: the noise exceeds the signal; mirror "
            f"lobe: Blinn-Phong n = {meta['mirror_exponent']} as a MERL file):\n\n"
            + "\n\n".join(x.strip("\n") for x in _sampler_findings(res["samplers"], res["other"], meta)) + "\n")


def summary_markdown(rows, other, meta) -> str:
    cfg = meta["config"]
    L = [f"Relative standard error of the pixel estimate at {cfg['spp']} spp ({cfg['resolution']}×"
         f"{cfg['resolution']} px, independent samples, median of {cfg['seeds']} seeds; lower is "
         f"better, > 1 means the noise exceeds the signal). Mirror lobe: normalized Blinn-Phong "
         f"n = {meta['mirror_exponent']} written as a MERL file.\n"]
    L += _sampler_findings(rows, other, meta)
    fits = [(k, v) for k, v in other.items() if k.startswith("fit_")]
    if fits:
        L.append(f"\nRational fits of one channel (G) of the 2-D projection, θd ≤ 80°, one "
                 f"cluster in {fits[0][1]['stride']} along each axis, degrees ≤ {fits[0][1]['max_degree']} "
                 f"(fit.rational.fitter.IntervalRationalFitter):\n")
        L.append(P.md_table([[k[4:], v["tol"], f"{v['abs_floor']:.3g}", v["n_coefficients"],
                              "yes" if v["feasible"] else "NO", f"{100 * v['relative_share']:.0f} %",
                              v["max_rel_err_relative"], v["max_rel_err"], v["max_value"]]
                             for k, v in fits],
                            ["case", "tol", "abs. floor (1/sr)", "coefficients", "feasible",
                             "points with a relative interval", "max rel. error there", "max rel. error, all points",
                             "max ρ (1/sr)"]))
        L.append("\n(relative interval: value ≥ floor / tol, where the interval is ±tol × value; below it "
                 "the floor sets the interval and the relative error is not bounded.)\n")
    return "\n".join(L)


def plot(rows, samplers, path, spp):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    M = np.array([[r.get(f"{s}_rel_err", np.nan) for s in samplers] for r in rows], float)
    fig, ax = plt.subplots(figsize=(1.2 * len(samplers) + 2.6, 0.42 * len(rows) + 1.0))
    im = ax.imshow(np.where(np.isfinite(M), M, np.nan), cmap="RdYlGn_r",
                   norm=LogNorm(vmin=0.01, vmax=max(10.0, np.nanmax(M) if np.isfinite(M).any() else 10)))
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            ax.text(j, i, "–" if not np.isfinite(M[i, j]) else f"{M[i, j]:.2g}", ha="center", va="center", fontsize=7)
    ax.set_xticks(range(len(samplers)))
    ax.set_xticklabels(samplers, fontsize=7)
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels([r["case"] for r in rows], fontsize=7)
    ax.set_title(f"relative standard error at {spp} spp (red: fails)", fontsize=8)
    fig.colorbar(im, ax=ax, shrink=0.8)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m studies.failure_map", description=__doc__.split("\n")[0])
    p.add_argument("--out", default="results/failure_map")
    p.add_argument("--preset", choices=sorted(PRESETS), default="full")
    p.add_argument("--smoke", action="store_true")
    p.add_argument("--samplers", nargs="*")
    P.add_docs_arguments(p)
    a = p.parse_args(argv)
    r = run("smoke" if a.smoke else a.preset, a.out, a.samplers)
    print(r["markdown"])
    print(f"wrote {a.out}/failure_map.csv, .json, .md, failure_map.png ({r['meta']['wall_seconds']:.0f} s)")
    P.publish_run(a, r, block_table, __file__, argv, DOCS)
    return r


if __name__ == "__main__":
    main()
