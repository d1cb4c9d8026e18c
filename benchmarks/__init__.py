"""Timing scripts (never run by the tests), run from the checkout root as modules:
``python -m benchmarks.bench_render --help`` (also bench_samplers, bench_fit, bench_rgl, bench_projection)."""
