"""Every fit entry point runs its BLAS calls on one thread (fit/blas_threads.py): a fit must not
depend on OMP_NUM_THREADS / OPENBLAS_NUM_THREADS. Each test sets two BLAS threads around the
call, records the BLAS libraries' thread counts from inside the fit (a spy on a function the
fit calls) and checks the caller's setting is back afterwards."""
from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from conftest import data_file
from lab.analytic import glossy_lobe
from fit.formats.measured import MeasuredBRDF


def _blas_threads() -> list:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


class _Stop(Exception):
    """Ends a fit at the spy (the limit is checked there; the rest of the fit is not needed)."""


def _spy(monkeypatch, module, name: str, seen: list, stop: bool = False) -> None:
    real = getattr(module, name)

    def spy(*args, **kwargs):
        seen.append(_blas_threads())
        if stop:
            raise _Stop
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, spy)


def _check(call, seen: list) -> None:
    with threadpool_limits(limits=2, user_api="blas"):
        assert _blas_threads() and set(_blas_threads()) == {2}
        call()
        assert set(_blas_threads()) == {2}                   # the caller's setting restored
    assert seen and all(counts and set(counts) == {1} for counts in seen)


def test_fit_brdf_runs_on_one_blas_thread(monkeypatch):
    from fit.rational import brdf_fit

    seen: list = []
    _spy(monkeypatch, brdf_fit, "project_for_fit", seen)
    b = MeasuredBRDF.from_function(glossy_lobe(exponent=30.0))
    _check(lambda: brdf_fit.fit_brdf(b, tol=0.2, intervals="tol", max_degree=4, max_den_degree=2), seen)


def test_fit_rgl_select_and_fit_rgl_run_on_one_blas_thread(monkeypatch):
    from fit.formats.rgl import read_rgl
    from fit.rational import rgl3d, select3d

    seen: list = []
    _spy(monkeypatch, select3d, "validation_rmse", seen)
    _spy(monkeypatch, rgl3d, "sample_rgl", seen)
    b = read_rgl(data_file("rgl/paper_white_rgb.bsdf"))
    small = [{"theta_h_edges": [], "degrees": (3, 1)}]
    _check(lambda: select3d.fit_rgl_select(b, variants=small, verify=0, albedo=False, proof_rounds=0), seen)
    assert len(seen) >= 2                                   # inside fit_rgl and inside the selection
    seen.clear()
    _check(lambda: rgl3d.fit_rgl(b, theta_h_edges=[], degrees=(3, 1), verify=0, albedo=False), seen)


def test_fit_cdf_runs_on_one_blas_thread(monkeypatch):
    from fit.sampling import cdf_file

    seen: list = []
    _spy(monkeypatch, cdf_file, "tabulate", seen, stop=True)
    b = MeasuredBRDF.from_function(glossy_lobe(exponent=30.0))

    def call():
        with pytest.raises(_Stop):                          # the limit is undone on a raise too
            cdf_file.fit_cdf(b.evaluate, name="lobe", table_params=dict(n_v=8))

    _check(call, seen)


def test_the_command_runs_on_one_blas_thread(monkeypatch, tmp_path):
    from fit import cli
    from fit.formats.merl import write_merl
    from fit.rational import brdf_fit

    seen: list = []
    _spy(monkeypatch, brdf_fit, "project_for_fit", seen)
    src = tmp_path / "lobe.binary"
    write_merl(MeasuredBRDF.from_function(glossy_lobe(exponent=30.0)), src)
    args = [str(src), "--out", str(tmp_path / "lobe.json"), "--tol", "0.2", "--max-degree", "4",
            "--max-den-degree", "2", "--no-sampler", "--no-progress"]
    _check(lambda: np.testing.assert_equal(cli.main(["brdf", *args]), 0), seen)
    assert (tmp_path / "lobe.json").is_file()


if __name__ == "__main__":
    raise SystemExit(pytest.main([__file__, "-q"]))
