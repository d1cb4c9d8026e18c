"""Benchmark of environment-map importance sampling schemes.

The reference scene of :mod:`lab.mitsuba_reference` (unit sphere, camera at (0, 0, 4),
30 deg vertical fov, hidden map at scale 1, direct lighting) with a **Lambert** sphere and
**environment-map sampling only** (sampler ``light``: one environment sample and its shadow ray
per camera sample, no BSDF sample), under each map, rendered by

* ours, with each environment sampling scheme of :mod:`lab.env_schemes` (``hierarchical``: the
  renderer's; ``marginal``: the same density, exactly proportional to the bilinear lookup, by
  another warp; ``piecewise-constant``: one constant density per texel cell) and each sample
  pattern of :mod:`warp_rbrdf.sample_patterns` (``stratified``: padded correlated multi-jitter,
  the default; ``sobol``: Owen-scrambled Sobol; ``independent``), rendered by the light-only
  kernel of :mod:`lab.env_scheme_render` (the renderer's estimator for this scene, with the
  scheme's environment sample; with ``hierarchical`` it renders what the renderer renders);
* Mitsuba 3 (``scalar_rgb``, ``envmap`` emitter, ``direct`` integrator with
  ``emitter_samples = 1, bsdf_samples = 0``, box filter), samplers ``multijitter`` and
  ``independent``.

Error: relative RMSE of one render on the sphere's fully covered pixels
(:func:`lab.mitsuba_reference.sphere_mask`), from seed pairs: for two independent unbiased
renders X1, X2 of the same scene, E|X1 - X2|^2 = 2 sigma^2, so
RMSE = sqrt(mean((X1 - X2)^2) / 2), divided by the mean of (X1 + X2) / 2 over the same pixels;
the median over ``--pairs`` pairs (seeds 2k+1, 2k+2). No reference render is needed, and the
error is the noise only (every estimator here is unbiased).

Cost: the environment sample alone (a kernel that only samples, 10^6 uniforms, one thread, best
of 3) per scheme and map, and the light-only kernel's render wall time at the largest spp (all
cores, best of 5 renders, the schemes interleaved; the per-value seconds printed with the errors
are medians).

Usage: python -m benchmarks.bench_env_sampling [--quick] [--res 256] [--spp 1,16] [--pairs 3]
       [--maps studio,rooitou] [--schemes piecewise-constant,marginal,hierarchical]
       [--patterns stratified,sobol,independent] [--no-mitsuba] [--json PATH]
(``--quick``: 64 px, 1 pair, the default pattern only: a smoke run of a few seconds.)
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numpy as np

MAPS = {"studio": "envmaps/studio_small_03_1k.hdr", "rooitou": "envmaps/rooitou_park_1k.hdr"}
ALBEDO = 0.5


def rel_rmse_pair(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    """Relative RMSE of one render from two independent renders ``a``, ``b`` (H, W, 3) on
    ``mask`` (H, W): sqrt(mean((a - b)^2) / 2) / mean((a + b) / 2)."""
    a = np.asarray(a, np.float64)[mask]
    b = np.asarray(b, np.float64)[mask]
    return float(np.sqrt(np.mean((a - b) ** 2) / 2) / np.mean(0.5 * (a + b)))


def scheme_struct(image, name: str, device):
    """The Warp struct of scheme ``name`` (:data:`lab.env_schemes.SCHEME_NAMES`) for ``image``."""
    from lab import env_schemes as S

    return S.make_scheme_struct(S.build_scheme(image, S.SCHEME_NAMES[name]), device)


def light_only_renderer(path, res: int, pattern: str):
    """The reference sphere scene, Lambert, sampler ``light``, built, its light-only kernel loaded."""
    from lab import env_scheme_render as ER
    from warp_rbrdf.renderer import Renderer

    r = Renderer(ER.light_only_scene(path, res, pattern, ALBEDO))
    ER.compile_light_only(r.device)
    return r


def ours(path, image, res, spps, pairs, schemes, patterns):
    from lab import env_scheme_render as ER
    from lab import mitsuba_reference as MR

    mask = MR.sphere_mask(res)
    rows = []
    for pattern in patterns:
        r = light_only_renderer(path, res, pattern)
        for name in schemes:
            env = scheme_struct(image, name, r.device)
            for spp in spps:
                errs, secs = [], []
                for k in range(pairs):
                    a, sa = ER.render_light_only(r, env, spp, 2 * k + 1)
                    b, sb = ER.render_light_only(r, env, spp, 2 * k + 2)
                    secs += [sa, sb]
                    errs.append(rel_rmse_pair(a, b, mask))
                rows.append(dict(renderer="ours", scheme=name, pattern=pattern, spp=spp,
                                 rel_rmse=float(np.median(errs)), seconds=float(np.median(secs))))
                print(f"  ours  {name:18s} {pattern:11s} {spp:4d} spp  rel. RMSE {rows[-1]['rel_rmse']:.4f}"
                      f"  ({rows[-1]['seconds']:.2f} s)", flush=True)
    return rows


def mitsuba(path, res, spps, pairs, samplers):
    from lab import mitsuba_reference as MR

    mi = MR._mi()
    mask = MR.sphere_mask(res)
    rows = []
    for sampler in samplers:
        d = MR.mitsuba_scene_dict(("lambert", ALBEDO), path, 1, res)
        d["integrator"] = {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0,
                           "hide_emitters": True}
        d["sensor"]["sampler"] = {"type": sampler, "sample_count": 1}
        scene = mi.load_dict(d)
        for spp in spps:
            errs, secs = [], []
            for k in range(pairs):
                imgs = []
                for s in (2 * k + 1, 2 * k + 2):
                    t0 = time.perf_counter()
                    imgs.append(np.array(mi.render(scene, spp=spp, seed=s), np.float64)[..., :3])
                    secs.append(time.perf_counter() - t0)
                errs.append(rel_rmse_pair(imgs[0], imgs[1], mask))
            rows.append(dict(renderer="mitsuba", scheme="envmap (Hierarchical2D)", pattern=sampler, spp=spp,
                             rel_rmse=float(np.median(errs)), seconds=float(np.median(secs))))
            print(f"  mitsuba {sampler:28s} {spp:4d} spp  rel. RMSE {rows[-1]['rel_rmse']:.4f}"
                  f"  ({rows[-1]['seconds']:.2f} s)", flush=True)
    return rows


def sample_rate(image, name: str, n: int = 1_000_000, reps: int = 3) -> float:
    """Environment samples per second of scheme ``name`` (one Warp CPU launch = one thread),
    best of ``reps``."""
    import warp as wp

    from lab import env_schemes as S

    env = scheme_struct(image, name, "cpu")
    xi = wp.array(np.random.default_rng(0).random((n, 2)).astype(np.float32), dtype=wp.vec2, device="cpu")
    out = wp.zeros(n, dtype=wp.vec4, device="cpu")
    wp.launch(S.scheme_sample_kernel, dim=1000, inputs=[env, xi], outputs=[out], device="cpu")  # compile
    best = np.inf
    for _ in range(reps):
        wp.synchronize()
        t0 = time.perf_counter()
        wp.launch(S.scheme_sample_kernel, dim=n, inputs=[env, xi], outputs=[out], device="cpu")
        wp.synchronize()
        best = min(best, time.perf_counter() - t0)
    return n / best


def render_times(path, image, res, spp, schemes, rounds=5) -> dict:
    """Best-of-``rounds`` render seconds (all cores, default pattern) per scheme, the schemes
    interleaved round by round so that load changes hit them alike."""
    from lab import env_scheme_render as ER

    r = light_only_renderer(path, res, "stratified")
    envs = {name: scheme_struct(image, name, r.device) for name in schemes}
    best = {}
    for k in range(rounds):
        for name in schemes:
            _, sec = ER.render_light_only(r, envs[name], spp, k)
            best[name] = min(best.get(name, np.inf), sec)
    return best


def table(rows) -> str:
    spps = sorted({r["spp"] for r in rows})
    keys = []
    for r in rows:
        k = (r["map"], r["renderer"], r["scheme"], r["pattern"])
        if k not in keys:
            keys.append(k)
    head = "| map | renderer | env sampling | pattern | " + " | ".join(f"{s} spp" for s in spps) + " |"
    out = [head, "| " + " | ".join(["---"] * (4 + len(spps))) + " |"]
    for k in keys:
        vals = {r["spp"]: r["rel_rmse"] for r in rows if (r["map"], r["renderer"], r["scheme"], r["pattern"]) == k}
        out.append("| " + " | ".join(k) + " | " + " | ".join(f"{vals[s]:.3f}" if s in vals else "–" for s in spps) + " |")
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_env_sampling", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="64 px, 1 pair, default pattern only")
    ap.add_argument("--res", type=int, default=None, help="image size in pixels (default 256; quick 64)")
    ap.add_argument("--spp", default="1,16")
    ap.add_argument("--pairs", type=int, default=None, help="seed pairs per value, median (default 3; quick 1)")
    ap.add_argument("--maps", default="studio,rooitou")
    ap.add_argument("--schemes", default="piecewise-constant,marginal,hierarchical")
    ap.add_argument("--patterns", default=None,
                    help="our sample patterns (default stratified,sobol,independent; quick stratified)")
    ap.add_argument("--mitsuba-samplers", default=None,
                    help="Mitsuba samplers (default multijitter,independent; quick multijitter)")
    ap.add_argument("--no-mitsuba", action="store_true")
    ap.add_argument("--no-rate", action="store_true", help="skip the env_sample rate measurement")
    ap.add_argument("--json", default=None, help="write the results to this JSON file")
    args = ap.parse_args(argv)
    res = args.res or (64 if args.quick else 256)
    pairs = args.pairs or (1 if args.quick else 3)
    patterns = (args.patterns or ("stratified" if args.quick else "stratified,sobol,independent")).split(",")
    msamplers = (args.mitsuba_samplers or ("multijitter" if args.quick else "multijitter,independent")).split(",")
    spps = [int(s) for s in args.spp.split(",")]
    schemes = args.schemes.split(",")

    import warp as wp

    wp.config.quiet = True
    from lab import env_schemes as S
    from lab import mitsuba_reference as MR
    from warp_rbrdf.lights.env_file import read_latlong
    from warp_rbrdf.paths import require_data_root

    for s in schemes:
        if s not in S.SCHEME_NAMES:
            ap.error(f"unknown scheme {s!r} (one of {', '.join(S.SCHEME_NAMES)})")
    root = require_data_root()
    use_mitsuba = not args.no_mitsuba and MR.available()
    print(f"warp {wp.__version__}; {res}x{res} px, spp {spps}, {pairs} seed pair(s); Lambert sphere, sampler "
          f"'light'; {os.cpu_count()} cores, {platform.processor() or platform.machine()}; "
          f"Mitsuba: {MR.version() if use_mitsuba else 'not run'}")
    rows, rates = [], []
    for m in args.maps.split(","):
        path = root / MAPS[m]
        image = read_latlong(path)
        print(f"{m} ({image.shape[1]}x{image.shape[0]}):", flush=True)
        for r in ours(path, image, res, spps, pairs, schemes, patterns):
            rows.append(dict(r, map=m))
        if use_mitsuba:
            for r in mitsuba(path, res, spps, pairs, msamplers):
                rows.append(dict(r, map=m))
        if not args.no_rate:
            times = render_times(path, image, res, max(spps), schemes, rounds=2 if args.quick else 5)
            for s in schemes:
                rate = sample_rate(image, s, n=100_000 if args.quick else 1_000_000)
                rates.append(dict(map=m, scheme=s, samples_per_second=rate, render_seconds=times[s]))
                print(f"  env_sample {s:18s} {rate / 1e6:.2f} M samples/s (one thread); render "
                      f"{max(spps)} spp {times[s]:.2f} s (best of {2 if args.quick else 5})", flush=True)
    print()
    print(table(rows))
    if rates:
        print()
        print(f"| map | env sampling | env_sample, M samples/s (one thread) | render {max(spps)} spp, s "
              f"(best of {2 if args.quick else 5}, stratified) |\n| --- | --- | --- | --- |")
        for r in rates:
            print(f"| {r['map']} | {r['scheme']} | {r['samples_per_second'] / 1e6:.2f} | {r['render_seconds']:.2f} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(dict(config=dict(res=res, spp=spps, pairs=pairs, albedo=ALBEDO, cores=os.cpu_count()),
                           rows=rows, rates=rates), f, indent=1)
    return dict(rows=rows, rates=rates)


if __name__ == "__main__":
    main()
