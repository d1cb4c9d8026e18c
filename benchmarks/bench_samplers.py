"""Benchmark of the BRDF samplers.

1. Samples per second of each sampler alone in Warp (a kernel that only samples: tabulated
   binary search vs the rational inverse CDFs vs cosine), on the Warp CPU device unless
   --device says otherwise, for view directions in two orders: "coherent" (sorted by theta_v,
   as consecutive samples of a render tile see nearby view angles) and "random" (every
   sample another view row: worst case for the per-row coefficient reads and the branch
   predictor). Per launch the best of 3.
2. Variance per sample of the estimator of the luminance directional albedo
   integral rho cos dw at theta_v = 0, 45, 85 deg (NumPy), for cosine, tabulated, and the
   rational sampler where its fit is verified (else "fallback"), and the efficiency
   1 / (variance * time per sample) with the Warp sampling times.

Usage: python -m benchmarks.bench_samplers [--n 1000000] [--materials a,b] [--cdf-dir DIR]
       [--layout pieces|global] [--max-variance-ratio R | none] [--n-u 16,32,64]
(``--layout``: how the rational inverse CDFs are built here, default the fitter's default
"pieces" (fit.sampling.pieces, 2-21 s per material, mostly the variance gate).)
(``--max-variance-ratio none`` builds without the variance gate, so every verified row is
rational: the speed of the rational rows themselves.)
(``--cdf-dir``: rbrdf-cdf files named MATERIAL.json from `rbrdf-fit cdf`.)
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def warp_rate(renderer, name, sampler, n, reps=3, order="coherent"):
    rng = np.random.default_rng(0)
    from fit.formats.angles import spherical_to_direction

    tv = np.arccos(rng.random(n))
    wo = spherical_to_direction(np.sort(tv) if order == "coherent" else tv, rng.random(n) * 2 * np.pi)
    xi = rng.random((n, 2))
    renderer.sample_material(name, wo[:1000], xi[:1000], sampler)  # warm up
    wp = renderer.wp
    m = renderer.material_index(name)
    t = renderer.technique_code(name, sampler)
    kernel = renderer.kernels_for(t).sample_bsdf

    dwo = wp.array(wo.astype(np.float32), dtype=wp.vec3, device=renderer.device)
    dxi = wp.array(xi.astype(np.float32), dtype=wp.vec2, device=renderer.device)
    out = wp.zeros(n, dtype=wp.vec4, device=renderer.device)
    best = np.inf
    for _ in range(reps):
        wp.synchronize()
        t0 = time.perf_counter()
        wp.launch(kernel, dim=n, inputs=[renderer.materials, m, t, dwo, dxi], outputs=[out],
                  device=renderer.device)
        wp.synchronize()
        best = min(best, time.perf_counter() - t0)
    return n / best


def variances(evaluate, fit, n=200_000):
    from fit.formats.angles import spherical_to_direction
    from fit.formats.colour import LUMINANCE

    rng = np.random.default_rng(1)
    res = {}
    for tv_deg in (0, 45, 85):
        tv = np.radians(tv_deg)
        wo = spherical_to_direction(tv, 0.0)
        mu, tau = rng.random(n), rng.random(n)
        out = {}
        # cosine
        tl = np.arccos(np.sqrt(1 - mu))
        pl = 2 * np.pi * tau - np.pi
        e = (evaluate(spherical_to_direction(tl, pl), wo) @ LUMINANCE) * np.pi
        out["cosine"] = (e.mean(), e.var())
        tl, pl, pdf = fit.table.sample(tv, mu, tau)
        e = (evaluate(spherical_to_direction(tl, pl), wo) @ LUMINANCE) * np.cos(tl) / pdf
        out["tabulated"] = (e.mean(), e.var())
        if not fit.fallback:
            tl, pl, a = fit.sample(tv, mu, tau)
            e = (evaluate(spherical_to_direction(tl, pl), wo) @ LUMINANCE) * np.cos(tl) * a
            out["rational-derivative"] = (e.mean(), e.var())
        res[tv_deg] = out
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_samplers", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--materials", default="lambert,paper_white_rgb,satin_rosaline_rgb,vch_golden_yellow_rgb,"
                                           "cc_ibiza_sunset_rgb,cc_iris_purple_gem_rgb,colodur_napoli_4f_rgb")
    ap.add_argument("--cdf-dir", default=None)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--max-variance-ratio", default=None,
                    help="variance gate of the pieces layout (default: the layout's default; 'none': off)")
    ap.add_argument("--n-u", default=None,
                    help="pieces layout: phi pieces per map, one count or comma-separated candidates "
                         "(default: the layout's, 16,32,64: the fewest that pass the gate)")
    ap.add_argument("--layout", default="pieces", choices=("pieces", "global"),
                    help="layout of the rational inverse CDFs fitted here (default %(default)s; "
                         "fit.sampling.cdf_file)")
    args = ap.parse_args(argv)
    import warp as wp

    wp.config.quiet = True
    from lab.analytic import lambert
    from fit.formats import load_measured
    from fit.sampling.cdf_file import fit_cdf, load
    from lab import testing as T
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.paths import require_data_root
    from warp_rbrdf.scene import MaterialSpec

    print(f"warp {wp.__version__}, device {args.device}, n = {args.n} samples per launch")
    for name in args.materials.split(","):
        if name == "lambert":
            ev = lambert((0.8, 0.6, 0.4))
            fit = fit_cdf(ev, name="lambert", table_params=dict(n_v=8, n_t=32, n_p=32), layout=args.layout,
                          phi_kw=dict(degrees=(2, 1)), refinements=0)
            spec = T.lambert(albedo=(0.8, 0.6, 0.4), sampler="rational" if not fit.fallback else "tabulated")
        else:
            b = load_measured(require_data_root("bench_samplers") / "rgl" / f"{name}.bsdf")
            ev = b.evaluate
            cdf = Path(args.cdf_dir) / f"{name}.json" if args.cdf_dir else None
            t0 = time.perf_counter()
            gate = args.max_variance_ratio
            kw = {} if gate is None else {"max_variance_ratio": None if gate == "none" else float(gate)}
            pkw = dict(kw, **({} if args.n_u is None else {"n_u": [int(x) for x in args.n_u.split(",")]}))
            fit = load(cdf) if cdf and cdf.exists() else fit_cdf(ev, name=name, layout=args.layout,
                                                                 pieces_kw=pkw)
            print(f"{name}: fit {time.perf_counter() - t0:.1f} s, fallback {fit.fallback} ({fit.reason})")
            spec = MaterialSpec(name="m", type="measured", data=b,
                                sampler="rational" if not fit.fallback else "tabulated")
        spec.name = "m"
        spec.cdf = fit
        r = Renderer(T.plane_scene(spec, [T.constant_env(1.0)], resolution=2, spp=1), device=args.device)
        r.compile()
        if fit.layout == "pieces" and fit.maps is not None:
            g = [i["variance"]["ratio"] for i in fit.fit_info["rows"] if "variance" in i]
            n_ok = int(fit.maps.row_ok.sum())
            print(f"{name} ({fit.layout} layout, {fit.maps.n_u} phi pieces): rational on {n_ok}/{fit.table.n_v} view rows"
                  + (f"; variance gate, rational / tabulated per verified row: median {np.median(g):.2f}, "
                     f"range {min(g):.2f}-{max(g):.2f} ({len(g)} rows)" if g else ""))
        for order in ("random", "coherent"):   # the coherent rates (last) go into the efficiencies
            rates = {s: warp_rate(r, "m", s, args.n, order=order) for s in ("cosine", "tabulated")}
            if not fit.fallback:
                rates["rational"] = warp_rate(r, "m", "rational-derivative", args.n, order=order)
            print(f"{name}: Warp samples/s ({order} view angles) "
                  + ", ".join(f"{k} {v / 1e6:.2f} M" for k, v in rates.items())
                  + (f"; rational/tabulated {rates['rational'] / rates['tabulated']:.2f}x" if "rational" in rates else ""))
        for tv, out in variances(ev, fit).items():
            base = out["cosine"][1] / rates["cosine"]
            parts = []
            for k, (m, v) in out.items():
                rate = rates["rational" if k.startswith("rational") else k]
                eff = (1 / (v / rate)) / (1 / base) if v > 0 else float("inf")
                parts.append(f"{k} mean {m:.4f} var {v:.3g} eff x{eff:.1f}")
            print(f"  theta_v {tv:2d}: " + "; ".join(parts))


if __name__ == "__main__":
    main()
