"""Lab code: what serves the tests, the studies and the benchmarks, not the users.

* :mod:`lab.mitsuba_reference`: Mitsuba 3 as the reference implementation (the ``measured``
  plugin's eval / pdf / sample, the reference sphere scene, Mitsuba's LLVM variant for timed
  renders); needs the optional extra ``reference``.
* :mod:`lab.testing`: small in-memory scenes for tests and examples.
* :mod:`lab.env_kernels`: per-direction / per-uniform kernels over the renderer's environment.
* :mod:`lab.env_schemes`, :mod:`lab.env_scheme_render`: environment sampling schemes kept for
  comparison (``benchmarks.bench_env_sampling``) and the light-only render that compares them.
* :mod:`lab.analytic`: analytic reference BRDFs (``lambert``, ``glossy_lobe``) for exact-layout
  MERL files in tests and benchmarks.

Reference harnesses, test helpers and variants kept for comparison live here. The package runs from a
checkout (``pythonpath = ["."]`` for pytest, ``python -m studies.<name>`` / ``python -m
benchmarks.<name>`` from the repository root) and is not in the wheel (``pyproject.toml`` packages
only ``fit*`` and ``warp_rbrdf*``). ``fit/`` and ``warp_rbrdf/`` never import it
(``tests/test_core_lab.py`` checks both).
"""
