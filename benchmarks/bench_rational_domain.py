"""Rational fits at grazing views against the RGL reference: the file's recipe (extrapolated
beyond the measured domain) and the renderer's evaluation (on the measured domain).

    python -m benchmarks.bench_rational_domain [FIT.json ...] [--n 60000] [--bands 62,80 80,89.5]

Without files it uses every fit cached by the studies (``results/fits/*_tol0p05_cli.json``) and
the shipped ones (``warp_rbrdf/data/*.json``); each fit's source ``.bsdf`` is looked up in
``$RBRDF_DATA/rgl``. For each fit and band of view angles it prints, per channel R/G/B, the
radiance reflected towards views with theta_o uniform in the band from a uniform white sky of
radiance 1 (the mean directional albedo; lights cosine-distributed, ``--n`` pairs, seed 0),
as a ratio to the reference's (``rgl``: the file evaluated with the format's own interpolation),
for

* ``recipe``: the fit evaluated at the pairs' own angles (what the renderer did before, what the
  exports do): the clusters the grazing cut-off left empty, cos theta_h cos theta_d < cos 79 deg,
  are extrapolated;
* ``domain``: what the renderer evaluates (:func:`warp_rbrdf.materials.rational.load`, the pairs
  moved onto the measured domain, :func:`~warp_rbrdf.materials.rational.onto_measured_domain`).

The study's rim band (the outer 15 px of the sphere at 256 px) sees views from 62 to 80 deg.
Both columns use the same pairs; the ratios of glossy materials carry Monte Carlo noise (the
reference's and the fit's peaks are sampled by a few pairs: 62-80 deg on satin_rosaline reads
0.91-0.99 in red with other seeds or ``--n``).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

import numpy as np

from fit.formats import load_measured
from fit.formats.angles import spherical_to_direction


def white_sky(evaluate, band_deg, n: int, seed: int = 0) -> np.ndarray:
    """(3,): radiance towards views with theta_o uniform in ``band_deg`` (degrees, phi_o = 0) from
    a uniform white sky of radiance 1: pi times the mean of ``evaluate(wi, wo)`` over ``n``
    cosine-distributed lights ``wi``."""
    rng = np.random.default_rng(seed)
    wo = spherical_to_direction(np.radians(rng.uniform(*band_deg, n)), np.zeros(n))
    wi = spherical_to_direction(np.arcsin(np.sqrt(rng.random(n))), rng.random(n) * 2 * np.pi)
    return np.pi * np.asarray(evaluate(wi, wo), float).mean(axis=0)


def default_fits() -> list[Path]:
    return (sorted((ROOT / "results" / "fits").glob("*_tol0p05_cli.json"))
            + sorted((ROOT / "warp_rbrdf" / "data").glob("*.json")))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_rational_domain",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("fits", nargs="*", type=Path, help="rbrdf-rational files (default: the studies' and the shipped fits)")
    ap.add_argument("--n", type=int, default=60000, help="direction pairs per band (default 60000)")
    ap.add_argument("--bands", nargs="*", default=["62,80", "80,89.5"], help="view-angle bands in degrees, lo,hi")
    a = ap.parse_args(argv)
    from warp_rbrdf.materials import rational
    from warp_rbrdf.paths import data_root
    from warp_rbrdf.scene import MaterialSpec

    bands = [tuple(float(v) for v in b.split(",")) for b in a.bands]
    root = data_root()
    if root is None:
        print("set RBRDF_DATA (the RGL files are the reference)", file=sys.stderr)
        return 2
    os.environ.setdefault("RBRDF_DATA", str(root))
    print("| fit | views (deg) | recipe / rgl R/G/B | domain / rgl R/G/B |")
    print("| --- | --- | --- | --- |")
    for f in a.fits or default_fits():
        lm = rational.load(MaterialSpec(name="m", type="rational", file=f))
        src = Path(root) / "rgl" / str((lm.data.source or {}).get("file", ""))
        if not src.is_file():
            print(f"| {f.name} | – | source {src.name} not found | |")
            continue
        ref = load_measured(src)
        recipe = rational.evaluate_at_angles(lm.data, lm.fallback_table, None)
        for b in bands:
            r = white_sky(ref.evaluate, b, a.n)
            old, new = (white_sky(e, b, a.n) / r for e in (recipe, lm.evaluate))
            print(f"| {f.name} | {b[0]:g}-{b[1]:g} | {'/'.join(f'{v:.3g}' for v in old)} | "
                  f"{'/'.join(f'{v:.3g}' for v in new)} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
