"""The benchmarks are modules of the ``benchmarks`` package (``python -m benchmarks.<name>`` from
the checkout root): each imports as such and its ``--help`` works. Their timings are never
tested."""
from __future__ import annotations

import importlib

import pytest

BENCHMARKS = ("bench_fit", "bench_projection", "bench_render", "bench_rgl", "bench_samplers", "bench_startup")


@pytest.mark.parametrize("name", BENCHMARKS)
def test_benchmark_help(name, capsys):
    module = importlib.import_module(f"benchmarks.{name}")
    with pytest.raises(SystemExit) as e:
        module.main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: ") and f"python -m benchmarks.{name}" in out
