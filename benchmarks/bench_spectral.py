"""What the spectral ``.bsdf`` output (``rbrdf-fit convert IN OUT.bsdf --spectral``) does to the
colours, measured (the numbers of docs/interop.md, section "Spectral .bsdf files").

    python -m benchmarks.bench_spectral [--n-wavelengths 16 48] [--materials NAME ...]
                                        [--convert paper_white_rgb] [--json FILE]

* For every RGL-EPFL file in $RBRDF_DATA/rgl (or ``--materials``): the ``rgb`` nodes of the
  file (negatives clamped, as the reader does) upsampled to spectra at N wavelengths
  (:func:`fit.convert.spectral.upsample`, stored as float32) and projected back to linear sRGB
  (:func:`fit.convert.spectral.to_rgb`): the difference relative to the node's largest
  channel (nodes above 1e-3 of the file's largest), and CIE ΔE2000 of the two colours each
  scaled by the node's largest channel (colour-science, the ``studies`` extra).
* ``--convert``: one file converted at the default sizes, RGB and spectral (48 wavelengths):
  wall time (2 cores shared; not a target) and file size.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("RBRDF_DATA", ROOT.parent / "shared" / "data"))


def _delta_e2000(a, b):
    import colour
    import numpy as np

    def lab(c):
        return colour.XYZ_to_Lab(colour.sRGB_to_XYZ(np.clip(c, 0, None), apply_cctf_decoding=False))

    return colour.delta_E(lab(a), lab(b), method="CIE 2000")


def round_trips(paths, n_wavelengths):
    """{N: {"nodes", "rel_max", "de_max"}} over all the files' nodes."""
    import numpy as np

    from fit.convert import spectral as sp
    from fit.formats.rgl import read_rgl

    out = {}
    for n in n_wavelengths:
        wl = sp.default_wavelengths(n)
        nodes, rel_max, de_max = 0, 0.0, 0.0
        for p in paths:
            rgb = np.moveaxis(read_rgl(p).rgb, 1, -1).reshape(-1, 3)
            s = sp.upsample(rgb, wl).astype(np.float32)
            m = rgb.max(axis=1)
            keep = m > 1e-3 * m.max()
            back = sp.to_rgb(s[keep], wl)
            rel_max = max(rel_max, float((np.abs(back - rgb[keep]).max(axis=1) / m[keep]).max()))
            de_max = max(de_max, float(_delta_e2000(rgb[keep] / m[keep, None], back / m[keep, None]).max()))
            nodes += int(keep.sum())
        out[n] = {"nodes": nodes, "rel_max": rel_max, "de_max": de_max}
        print(f"N = {n:3d}: {nodes} nodes of {len(paths)} files: sRGB round trip max {rel_max:.3g} of the "
              f"node's largest channel, ΔE2000 max {de_max:.3g}", flush=True)
    return out


def conversion_cost(path):
    from fit.convert import convert

    res = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, extra in (("rgb", {}), ("spectral", {"n_wavelengths": 48})):
            out = Path(tmp) / f"{label}.bsdf"
            t0 = time.perf_counter()
            convert(path, out, n_pairs=0, **extra)
            res[label] = {"seconds": time.perf_counter() - t0, "mib": out.stat().st_size / 2 ** 20}
            print(f"{path.name} -> {label} .bsdf (default sizes): {res[label]['seconds']:.1f} s, "
                  f"{res[label]['mib']:.1f} MiB", flush=True)
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_spectral", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n-wavelengths", type=int, nargs="*", default=[16, 48])
    ap.add_argument("--materials", nargs="*", help="names in $RBRDF_DATA/rgl (default: all)")
    ap.add_argument("--convert", default="paper_white_rgb", help="file of the cost measurement ('' : none)")
    ap.add_argument("--json", metavar="FILE", help="write the numbers as JSON")
    args = ap.parse_args(argv)
    rgl = DATA / "rgl"
    paths = [rgl / f"{m}.bsdf" for m in args.materials] if args.materials else sorted(rgl.glob("*.bsdf"))
    missing = [str(p) for p in paths if not p.exists()]
    if missing or not paths:
        print(f"bench_spectral: missing data: {missing or rgl} (set RBRDF_DATA)", file=sys.stderr)
        return 2
    result = {"round_trip": round_trips(paths, args.n_wavelengths)}
    if args.convert:
        result["cost"] = conversion_cost(rgl / f"{args.convert}.bsdf")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
