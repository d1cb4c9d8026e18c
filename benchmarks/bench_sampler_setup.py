"""Benchmark: ``rbrdf render`` setup of a rational fit that carries its own sampler
(:mod:`fit.sampling.embedded`), for every strategy of a rational material, side by side.

Each run is one fresh ``python -m warp_rbrdf render`` process of the default scene
(:data:`warp_rbrdf.defaults.DEFAULT_TOML`: seed 0) with its sphere's fit replaced by FIT and the
sphere's ``sampler`` set, in a work folder of its own, ``RBRDF_DATA`` pointing to an empty
folder (no source measurement can be found) and the Warp kernel cache of the checkout
(``WARP_CACHE_PATH``; warm it first: ``--warm``); the renderer's own ``setup`` line is parsed
(files, tables, BVH: what a scene's load costs, compile and render excluded). Per round every
(fit, strategy, variant) runs once, in a shuffled order (fixed seed); medians over ``--repeats``
rounds. Variants:

* ``stored``: FIT as given (a record with ``pieces.knots`` reads its pieces from them);
* ``rebuilt`` (``--rebuilt``): a copy of FIT without ``pieces.knots`` (the record signed again),
  the load path of a record written before the knots were stored: pieces rebuilt from the table
  with SciPy and verified at points;
* ``TREE`` (``--tree NAME=DIR``, repeatable): FIT's copy without ``pieces.knots`` (as an
  older tree wrote it) rendered by the ``fit`` and ``warp_rbrdf``
  packages under DIR (``PYTHONPATH=DIR``), e.g. a copy of this checkout with older versions of
  a few modules (its kernels must be the checkout's, or it compiles).

Every run writes its image; the largest pixel difference of each variant to the first is
printed per (fit, strategy) (0: identical to the last bit). ``--resolution`` (default 64)
keeps the render short; the setup does not depend on it.

    python -m benchmarks.bench_sampler_setup FIT.json [FIT3D.json ...] [--repeats 5] [--rebuilt]
        [--tree NAME=DIR] [--strategies mis-tabulated,...] [--warm] [--work DIR] [--json FILE]

Prints a table (median and range of the setup per fit, strategy and variant, the machine's
load before and after) and a JSON line. The machine is shared: compare variants within one run.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STRATEGIES = ("mis-tabulated", "tabulated", "mis-rational", "rational", "rational-derivative")


def _scene(fit: Path, strategy: str) -> str:
    from warp_rbrdf.defaults import DEFAULT_TOML

    mat = f'type = "rational"\nfile = {json.dumps(str(fit))}\nsampler = "{strategy}"'
    return DEFAULT_TOML.format(sphere_material=mat)


def _strip_knots(src: Path, dst: Path) -> None:
    from fit.sampling.embedded import record_sha256

    d = json.loads(src.read_text())
    rec = d.get("sampler")
    if not rec or not (rec.get("pieces") or {}).get("knots"):
        raise SystemExit(f"{src}: its sampler record stores no pieces.knots (nothing to strip)")
    del rec["pieces"]["knots"]
    rec["sha256"] = record_sha256(rec)
    dst.write_text(json.dumps(d))


def _run(scene: Path, out: Path, pythonpath: str, data_dir: Path, resolution: int) -> dict:
    env = dict(os.environ, RBRDF_DATA=str(data_dir), PYTHONPATH=pythonpath)
    env.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp_cache"))
    cmd = [sys.executable, "-m", "warp_rbrdf", "render", str(scene), "--out", str(out), "--no-progress",
           "--resolution", str(resolution), str(resolution)]
    t = time.perf_counter()
    p = subprocess.run(cmd, cwd=scene.parent, env=env, capture_output=True, text=True, timeout=1800)
    wall = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({p.returncode}): {p.stderr.strip()[-2000:]}")
    setup = re.search(r"setup\s+([\d.]+) s", p.stdout)
    compiled = re.search(r"compile\s+([\d.]+) s \(([^)]*)\)", p.stdout)
    return {"setup_s": float(setup.group(1)), "wall_s": wall,
            "compile": compiled.group(2) if compiled else "", "image": str(out)}


def _max_diff(a: str, b: str) -> float:
    import numpy as np

    from warp_rbrdf.image_io import read_image

    return float(np.max(np.abs(read_image(a).astype(float) - read_image(b).astype(float))))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_sampler_setup", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("fits", nargs="+", type=Path, help="rational fits (.json) carrying their own sampler")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--strategies", default=",".join(STRATEGIES))
    ap.add_argument("--rebuilt", action="store_true", help="also the fit without pieces.knots (rebuild path)")
    ap.add_argument("--tree", action="append", default=[], metavar="NAME=DIR",
                    help="also render with the packages under DIR (PYTHONPATH=DIR)")
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--warm", action="store_true", help="one untimed run of every case first (compiles)")
    ap.add_argument("--work", type=Path, default=None)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    work = a.work or Path(tempfile.mkdtemp(prefix="bench_sampler_setup_"))
    work.mkdir(parents=True, exist_ok=True)
    data_dir = work / "no_data"
    data_dir.mkdir(exist_ok=True)
    strategies = [s for s in a.strategies.split(",") if s]
    here = os.pathsep.join([str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])
    cases = []                                   # (fit label, strategy, variant, fit path, pythonpath)
    for i, fit in enumerate(a.fits):
        label = fit.stem
        copy = work / f"fit{i}_{label}.json"
        copy.write_bytes(fit.read_bytes())
        variants = [("stored", copy, here)]
        old = copy
        if a.rebuilt or a.tree:
            old = work / f"fit{i}_{label}_rebuilt.json"
            _strip_knots(fit, old)
        if a.rebuilt:
            variants.append(("rebuilt", old, here))
        for spec in a.tree:
            name, _, d = spec.partition("=")
            variants.append((name, old, str(Path(d).resolve())))
        for s in strategies:
            for var, path, pp in variants:
                cases.append((label, s, var, path, pp))
    scenes = {}
    for label, s, var, path, pp in cases:
        sc = work / f"{label}_{s}_{var}.toml"
        sc.write_text(_scene(path, s))
        scenes[(label, s, var)] = sc
    load_before = os.getloadavg()
    if a.warm:
        for label, s, var, path, pp in cases:
            _run(scenes[(label, s, var)], work / "warm.exr", pp, data_dir, a.resolution)
    rng = random.Random(0)
    results = {(c[0], c[1], c[2]): [] for c in cases}
    for r in range(a.repeats):
        order = list(cases)
        rng.shuffle(order)
        for label, s, var, path, pp in order:
            out = work / "img" / f"{label}_{s}_{var}_{r}.exr"
            out.parent.mkdir(exist_ok=True)
            results[(label, s, var)].append(_run(scenes[(label, s, var)], out, pp, data_dir, a.resolution))
    load_after = os.getloadavg()
    rows = []
    print(f"load average before {load_before[0]:.2f} / after {load_after[0]:.2f} "
          f"({os.cpu_count()} CPUs); {a.repeats} rounds; {time.strftime('%Y-%m-%d %H:%M')}")
    print(f"{'fit':<28} {'strategy':<20} {'variant':<10} {'setup median s':>14} {'range':>13}  max |diff| to first")
    for label in dict.fromkeys(c[0] for c in cases):
        for s in strategies:
            first = None
            for (lb, st, var), runs in results.items():
                if lb != label or st != s:
                    continue
                xs = [x["setup_s"] for x in runs]
                ref = first or runs[0]["image"]
                first = ref
                diff = max(_max_diff(ref, x["image"]) for x in runs)
                med = statistics.median(xs)
                rows.append({"fit": label, "strategy": s, "variant": var, "setup_median_s": med,
                             "setup_s": xs, "max_abs_diff": diff})
                print(f"{label:<28} {s:<20} {var:<10} {med:>14.2f} {min(xs):>6.2f}-{max(xs):<6.2f}  {diff:g}")
    doc = {"load_before": load_before, "load_after": load_after, "repeats": a.repeats, "rows": rows,
           "date": time.strftime("%Y-%m-%d %H:%M")}
    print(json.dumps(doc))
    if a.json:
        a.json.write_text(json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
