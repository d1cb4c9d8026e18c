"""Release tools of a source checkout: regenerate and check what ``warp_rbrdf`` ships.

Not part of the wheel (``pyproject.toml`` packages only ``fit`` and ``warp_rbrdf``), and never
imported by either package: the runtime keeps only the loaders
(:mod:`warp_rbrdf.shipped_kernels`, :mod:`warp_rbrdf.techniques.table_cache`).

- ``python -m tools.ship_kernels [--check]``: the AOT render kernels of the README main job
  (``warp_rbrdf/data/kernels/<warp version>/<platform>/``);
- ``python -m tools.ship_tables [--check]``: the inverse-CDF table of the default scene's fit
  (``warp_rbrdf/data/tables/<key>.npz``).
"""
