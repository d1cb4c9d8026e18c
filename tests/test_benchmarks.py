"""The benchmarks are modules of the ``benchmarks`` package (``python -m benchmarks.<name>`` from
the checkout root): each imports as such and its ``--help`` works. Their timings are never
tested."""
from __future__ import annotations

import importlib

import pytest

BENCHMARKS = ("bench_env_sampling", "bench_fit", "bench_projection", "bench_render", "bench_rgl", "bench_samplers")


@pytest.mark.parametrize("name", BENCHMARKS)
def test_benchmark_help(name, capsys):
    module = importlib.import_module(f"benchmarks.{name}")
    with pytest.raises(SystemExit) as e:
        module.main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: ") and f"python -m benchmarks.{name}" in out


def test_bench_env_sampling_smoke(capsys):
    """A tiny run: every row is a finite relative RMSE, and the table lists them."""
    from benchmarks import bench_env_sampling as B
    from conftest import data_file

    data_file("envmaps/studio_small_03_1k.hdr")
    r = B.main(["--quick", "--res", "24", "--spp", "1,4", "--maps", "studio", "--no-mitsuba",
                "--schemes", "piecewise-constant,hierarchical", "--no-rate"])
    assert {(x["scheme"], x["spp"]) for x in r["rows"]} == {(s, n) for s in ("piecewise-constant", "hierarchical")
                                                           for n in (1, 4)}
    assert all(0 < x["rel_rmse"] < 10 for x in r["rows"])
    assert "| studio | ours | hierarchical | stratified |" in capsys.readouterr().out
