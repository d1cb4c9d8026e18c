"""What the renderer's environment sample costs, stage by stage, and the same descent in float32.

    python -m benchmarks.bench_env_sample_cost [--maps studio rooitou] [--samples 1048576]
                                               [--repeats 9] [--compensation 0.25] [--json FILE]

The sample of :mod:`warp_rbrdf.lights.env_sampling` (the map as the renderer builds it, with the
MIS compensation of ``--compensation``, 0.25 by default) on one thread, one kernel launch of
``--samples`` uniform pairs per measurement, CPU seconds of the launching thread, the kernels
in turn round by round, median of ``--repeats``; uniforms independent (``random``) or sorted by
their first coordinate (``sorted``: neighbouring threads draw neighbouring rows, as a pixel's
stratified samples do):

* ``descent``: the hierarchical warp to a level-1 block (:func:`~.env_sampling.descend`:
  :func:`~.env_sampling.descend_level` per level, float64 uniforms, the pyramid's float32 masses);
* ``+ select``: and the last level's choice among four patches (:func:`~.env_sampling.patch_select`);
* ``+ invert``: the whole sample point (:func:`~.env_sampling.sample_patch_point`: the inversion
  inside the patch, float64);
* ``descent, float32``: ``descent`` with float32 uniforms and arithmetic (a variant measured here
  only: the renderer's is float64); the share of samples that reach the same block is printed.

Every kernel has the render kernels' module options
(:func:`warp_rbrdf.shipped_kernels.render_module_options`: the CPU's ISA level).

The render kernel takes the descent and the choice for 16 lanes together
(:mod:`warp_rbrdf.lights.env_lanes`), so its cost per sample is lower than here; these numbers
compare the stages and the two precisions, not the renderer's samples per second.

No ``from __future__ import annotations``: Warp reads the kernels' argument types from
annotations that name types imported inside :func:`make_kernels`.
"""
import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

MAPS = {"studio": "studio_small_03_1k.hdr", "rooitou": "rooitou_park_1k.hdr"}


def make_kernels():
    """``{name: kernel}``: the stages and the float32 descent, each writing one vec3d per
    sample (so nothing is optimized away)."""
    import warp as wp

    from warp_rbrdf.lights import env_sampling as E
    from warp_rbrdf.lights.env_map import EnvMap
    from warp_rbrdf.shipped_kernels import render_module_options

    opts = render_module_options()

    @wp.func
    def split32(s: float, m0: float, m1: float) -> wp.vec2:
        """:func:`~.env_sampling._split` in float32."""
        s = wp.clamp(s, 0.0, 1.0) * (m0 + m1)
        if (s > m0 or m0 <= 0.0) and m1 > 0.0:
            return wp.vec2(1.0, (s - m0) / m1)
        if m0 > 0.0:
            return wp.vec2(0.0, s / m0)
        return wp.vec2(0.0, 0.0)

    @wp.func
    def descend32(env: EnvMap, level: int, x: int, y: int, sx: float, sy: float):
        """:func:`~.env_sampling.descend_level` in float32."""
        k = env.mip_offset[level - 1] + 4 * (y * env.mip_blocks_x[level - 1] + x)
        v00 = env.mip[k]
        v10 = env.mip[k + 1]
        v01 = env.mip[k + 2]
        v11 = env.mip[k + 3]
        ry = split32(sy, v00 + v10, v01 + v11)
        ca = v00
        cb = v10
        y = 2 * y
        if ry[0] > 0.5:
            y = y + 1
            ca = v01
            cb = v11
        rx = split32(sx, ca, cb)
        x = 2 * x
        if rx[0] > 0.5:
            x = x + 1
        return x, y, rx[1], ry[1]

    @wp.kernel(module="unique", enable_backward=False, module_options=opts)
    def descent(env: EnvMap, xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec3d)):
        i = wp.tid()
        x, y, sx, sy = E.descend(env, xi[i])
        out[i] = wp.vec3d(wp.float64(x), wp.float64(y), sx + sy)

    @wp.kernel(module="unique", enable_backward=False, module_options=opts)
    def select(env: EnvMap, xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec3d)):
        i = wp.tid()
        x, y, sx, sy = E.descend(env, xi[i])
        j, c, px, py = E.patch_select(env, x, y, sx, sy)
        out[i] = wp.vec3d(wp.float64(j), wp.float64(c), px + py)

    @wp.kernel(module="unique", enable_backward=False, module_options=opts)
    def invert(env: EnvMap, xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec3d)):
        i = wp.tid()
        out[i] = E.sample_patch_point(env, xi[i])

    @wp.kernel(module="unique", enable_backward=False, module_options=opts)
    def descent32(env: EnvMap, xi: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec3d)):
        i = wp.tid()
        sy = wp.min(xi[i][0], 0.99999994)
        sx = wp.min(xi[i][1], 0.99999994)
        x = int(0)
        y = int(0)
        level = env.levels - 2
        while level >= 1:
            x, y, sx, sy = descend32(env, level, x, y, sx, sy)
            level = level - 1
        out[i] = wp.vec3d(wp.float64(x), wp.float64(y), wp.float64(sx + sy))

    return {"descent": descent, "+ select": select, "+ invert": invert, "descent, float32": descent32}


def measure(env, kernels: dict, xi: np.ndarray, repeats: int) -> dict:
    """``{name: ns per sample}`` (median over ``repeats`` rounds) and the share of samples whose
    float32 descent ends in the float64 one's block."""
    import warp as wp

    n = len(xi)
    xa = wp.array(xi.astype(np.float32), dtype=wp.vec2, device="cpu")
    outs = {k: wp.zeros(n, dtype=wp.vec3d, device="cpu") for k in kernels}
    for k, kern in kernels.items():       # compile and warm up
        wp.launch(kern, n, inputs=[env, xa, outs[k]], device="cpu")
    secs = {k: [] for k in kernels}
    for _ in range(repeats):
        for k, kern in kernels.items():
            c0 = time.thread_time()
            wp.launch(kern, n, inputs=[env, xa, outs[k]], device="cpu")
            secs[k].append(time.thread_time() - c0)
    a, b = outs["descent"].numpy(), outs["descent, float32"].numpy()
    same = float(np.mean((a[:, 0] == b[:, 0]) & (a[:, 1] == b[:, 1])))
    return {"ns_per_sample": {k: statistics.median(v) / n * 1e9 for k, v in secs.items()},
            "float32_same_block": same}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_env_sample_cost",
                                 description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--maps", nargs="+", default=list(MAPS), choices=list(MAPS))
    ap.add_argument("--samples", type=int, default=1 << 20)
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--compensation", type=float, default=0.25,
                    help="the MIS compensation of the sampled map (the renderer's default 0.25; 0: the full luminance)")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    if a.samples < 1 or a.repeats < 1 or not 0.0 <= a.compensation < 1.0:
        ap.error("--samples and --repeats must be >= 1, --compensation in [0, 1)")
    from warp_rbrdf.lights.env_distribution import build_env_distribution, compensated_distribution
    from warp_rbrdf.lights.env_file import read_latlong
    from warp_rbrdf.lights.env_map import make_env_struct
    from warp_rbrdf.paths import require_data_root
    from warp_rbrdf.runtime import init_warp

    init_warp()
    root = require_data_root("bench_env_sample_cost")
    kernels = make_kernels()
    rng = np.random.default_rng(1)
    res = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "load_start": os.getloadavg(),
           "samples": a.samples, "repeats": a.repeats, "compensation": a.compensation, "cases": {}}
    for m in a.maps:
        d = build_env_distribution(read_latlong(root / "envmaps" / MAPS[m]), None)
        if a.compensation > 0:
            d = compensated_distribution(d, a.compensation)
        env = make_env_struct(d, "cpu")
        xi = rng.random((a.samples, 2))
        for order in ("random", "sorted"):
            x = xi[np.argsort(xi[:, 0], kind="stable")] if order == "sorted" else xi
            r = measure(env, kernels, x, a.repeats)
            res["cases"][f"{m}/{order}"] = r
            ns = r["ns_per_sample"]
            print(f"{m:8s} {order:7s} " + "  ".join(f"{k} {v:6.1f}" for k, v in ns.items())
                  + f"  ns/sample; float32 descent in the same block: {100 * r['float32_same_block']:.3f} %",
                  flush=True)
    res["load_end"] = os.getloadavg()
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
