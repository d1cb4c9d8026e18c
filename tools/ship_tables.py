"""Regenerate (or check) the inverse-CDF table that ``warp_rbrdf`` ships for the default scene.

Tabulates the embedded default scene's fit (the first shipped coefficient file,
``warp_rbrdf/data/*.json``, as a rational material with the default spec fields) into
``warp_rbrdf/data/tables/<key>.npz`` (:func:`warp_rbrdf.techniques.table_cache.key`: the
material file, its spec fields, the tabulation parameters and version), removing stale tables
(about 1 MB each: only the default's is shipped). One BLAS thread, as the fitter's batch
workers: the tabulation's last bit depends on the thread count, and the shipped table is
compared bit for bit (``tests/test_table_cache.py``)::

    python -m tools.ship_tables          # write the table under today's key
    python -m tools.ship_tables --check  # exit 1 if no table is shipped under today's key
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from warp_rbrdf.techniques import table_cache as tc

COMMAND = "python -m tools.ship_tables"


def default_spec_scene():
    """A one-sphere scene whose material ``m`` is the default fit with the default spec fields."""
    from warp_rbrdf.defaults import shipped_coefficient_files
    from warp_rbrdf.scene import parse_scene

    f = shipped_coefficient_files()[0]
    return parse_scene(f'[materials.m]\ntype = "rational"\nfile = "pkg:{f.name}"\n'
                       f'sampler = "mis-tabulated"\n[[shapes]]\ntype = "sphere"\nmaterial = "m"\n',
                       path="<ship>")


def shipped_path() -> Path:
    """Where the default fit's table ships under today's key."""
    return tc.SHIPPED / f"{tc.key(default_spec_scene().materials['m'])}.npz"


def ship_default_tables() -> list[Path]:
    """Tabulate the default fit's table into ``warp_rbrdf/data/tables/`` unless it is there,
    and remove every other table there; returns the tables kept."""
    from warp_rbrdf.materials.build import build_material_data

    out = shipped_path()
    if tc.read(out) is None:
        sc = default_spec_scene()
        md = build_material_data(sc, ["m"], log=lambda *a: None)
        tc.write(out, md.cdf[0])
    for p in tc.SHIPPED.glob("*.npz"):
        if p != out:
            p.unlink()
    return [out]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog=COMMAND, description="Regenerate (or --check) the shipped CDF table.")
    ap.add_argument("--check", action="store_true", help="exit 1 if no table ships under today's key")
    a = ap.parse_args(argv)
    if a.check:
        out = shipped_path()
        if tc.read(out) is None:
            print(f"shipped CDF table not current: no {out.name}; run {COMMAND}")
            return 1
        return 0
    for p in ship_default_tables():
        print(p)
    return 0


if __name__ == "__main__":
    from fit.batch.tasks import THREAD_ENV

    if any(os.environ.get(k) != v for k, v in THREAD_ENV.items()):   # one BLAS thread (see above)
        os.execve(sys.executable, [sys.executable, "-m", "tools.ship_tables", *sys.argv[1:]],
                  {**os.environ, **THREAD_ENV})
    sys.exit(main())
