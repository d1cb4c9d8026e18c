"""Shared test fixtures.

Data are found through ``RBRDF_DATA`` (default ``../shared/data`` from the project root).
Locally, tests that need data skip when it is missing; under CI (``CI=true``) a missing data
file is a failure, never a skip.
"""
from __future__ import annotations

import functools
import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("RBRDF_DATA", ROOT.parent / "shared" / "data")).absolute()
if "RBRDF_DATA" in os.environ:
    # a relative RBRDF_DATA means the folder where pytest started (warp_rbrdf.paths reads it
    # against the working directory, which tests that run in a temporary folder change)
    os.environ["RBRDF_DATA"] = str(DATA)
IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")
if "PYTEST_XDIST_WORKER" in os.environ:
    # The workers share the cores: one BLAS thread each (OpenBLAS reads this when NumPy is first
    # imported, which is after this file). With a BLAS thread per core in each process, the
    # fits of test_brdf_fit and test_fit3d_two_stage took 40 % more CPU time (22-23 s, 16 s).
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

RGL_MATERIALS = (
    "cc_ibiza_sunset_rgb",
    "cc_iris_purple_gem_rgb",
    "colodur_napoli_4f_rgb",
    "paper_white_rgb",
    "satin_rosaline_rgb",
    "vch_golden_yellow_rgb",
)
#: The two of them that the default run's per-material statistical tests take (a clear coat's
#: narrow peak and a matte paper); the other four carry the ``extended`` marker.
RGL_DEFAULT = ("cc_ibiza_sunset_rgb", "paper_white_rgb")


def rgl_params(materials=RGL_MATERIALS):
    """``materials`` as parameters, those outside :data:`RGL_DEFAULT` marked ``extended``."""
    return [m if m in RGL_DEFAULT else pytest.param(m, marks=pytest.mark.extended) for m in materials]


def missing(msg: str):
    """Something a test needs is not there: skip locally, fail under CI (``CI=true``), where the
    shared data, the ``test`` extra and the system tools are installed."""
    if IN_CI:
        pytest.fail(msg)
    pytest.skip(msg)


def data_file(relative: str) -> Path:
    """Path of a shared data file; skip (locally) or fail (CI) if it is missing."""
    p = DATA / relative
    if not p.exists():
        missing(f"shared data file missing: {p} (set RBRDF_DATA)")
    return p


@functools.lru_cache(maxsize=2)
def rgl_measured(name: str, incident: str = "view"):
    """The shared RGL file ``rgl/<name>.bsdf`` resampled on the MERL grid
    (:func:`fit.formats.load_measured`), made once per test process and shared by the tests
    that read it (about 6 s and 150 MB each; the last two kept): callers must not modify it."""
    from fit.formats import load_measured

    return load_measured(data_file(f"rgl/{name}.bsdf"), incident=incident)


def require_mitsuba():
    """:mod:`lab.mitsuba_reference` when Mitsuba 3 is usable; skip (locally) or fail (CI:
    the ``test`` extra installs it) when it is not."""
    from lab import mitsuba_reference as MR

    if not MR.available():
        missing(f"Mitsuba 3 is not installed ({MR.INSTALL_HINT})")
    return MR


def _usable_cpus() -> int:
    """CPUs this process may run on: its affinity, bounded by a cgroup v2 CPU quota."""
    n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    try:
        quota, period = Path("/sys/fs/cgroup/cpu.max").read_text().split()[:2]
        if quota != "max":
            n = min(n, max(1, int(quota) // int(period)))
    except (OSError, ValueError):
        pass
    return max(1, n)


def pytest_xdist_auto_num_workers(config):
    """``-n auto`` (``addopts``): one worker per usable CPU, at most 8, since each worker
    imports and collects the whole suite and holds its own copies of the shared data
    (pytest-xdist's own count takes psutil's physical cores, one where two hyper-threads are
    the machine's two CPUs, and a container's host CPUs beyond its quota);
    ``PYTEST_XDIST_AUTO_NUM_WORKERS`` decides when set."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS", "").isdigit():
        return int(os.environ["PYTEST_XDIST_AUTO_NUM_WORKERS"])
    return min(_usable_cpus(), 8)


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


@pytest.fixture(scope="session", autouse=True)
def _warp_cache(tmp_path_factory):
    """Keep Warp's kernel cache inside the checkout unless the caller chose one."""
    os.environ.setdefault("WARP_CACHE_PATH", str(ROOT / ".warp_cache"))
    yield
