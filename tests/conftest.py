"""Shared test fixtures.

Data are found through ``RBRDF_DATA`` (default ``../shared/data`` from the project root).
Locally, tests that need data skip when it is missing; under CI (``CI=true``) a missing data
file is a failure, never a skip.
"""
from __future__ import annotations

import functools
import hashlib
import itertools
import os
import pickle
import re
import shutil
import sys
import tempfile
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


#: Environment variable naming this test session's folder of resampled RGL files (made by the
#: controlling process, passed to the pytest-xdist workers, removed at the session's end).
SESSION_CACHE_ENV = "RBRDF_TEST_SESSION_CACHE"


@functools.lru_cache(maxsize=2)
def rgl_measured(name: str, incident: str = "view", horizon_margin_deg: float | None = None):
    """The shared RGL file ``rgl/<name>.bsdf`` resampled on the MERL grid
    (``read_rgl(path, incident=incident).to_measured()``, what :func:`fit.formats.load_measured`
    does; ``horizon_margin_deg`` passed on when given), made once per test session and shared
    by the tests that read it, in every worker (:func:`session_cached`: about 6-12 s and 150 MB
    each, the last two kept in memory): callers must not modify it."""
    from fit.formats.rgl import read_rgl

    path = data_file(f"rgl/{name}.bsdf")

    def resample():
        b = read_rgl(path, incident=incident)
        # the method itself, also where rgl_resampled_once has it take its result from here
        to_measured = getattr(type(b).to_measured, "__wrapped__", type(b).to_measured)
        return to_measured(b) if horizon_margin_deg is None else to_measured(b, horizon_margin_deg)

    return session_cached(path, f"{name}-{incident}-{horizon_margin_deg}", resample)


@pytest.fixture
def rgl_resampled_once(monkeypatch):
    """``RGLBRDF.to_measured`` of a shared ``rgl/*.bsdf`` file made once per test session for the
    code under test (``load_measured``, a command, a material's source), under the key of
    :func:`rgl_measured` (:func:`session_cached`): the same result, computed once however many
    tests and workers ask. For tests of a command or loader, not of the resampling itself
    (tests/test_rgl.py); other files are resampled as they are."""
    from fit.formats.rgl import RGLBRDF

    real = RGLBRDF.to_measured

    def to_measured(self, horizon_margin_deg: float = 1.0):
        path = Path(self.source)
        if not self.source or path.resolve() != (DATA / "rgl" / path.name).resolve() or path.stem != self.name:
            return real(self, horizon_margin_deg)
        margin = None if horizon_margin_deg == 1.0 else horizon_margin_deg
        return session_cached(path, f"{self.name}-{self.incident}-{margin}", lambda: real(self, horizon_margin_deg))

    to_measured.__wrapped__ = real          # what rgl_measured calls (no second lock on its key)
    monkeypatch.setattr(RGLBRDF, "to_measured", to_measured)


@functools.lru_cache(maxsize=1)
def _fit_parser():
    import fit.cli

    return fit.cli.build_parser()


@pytest.fixture
def fit_parser_once(monkeypatch):
    """``rbrdf-fit``'s argument parser built once per process for a module's many in-process
    runs (each build registers every command's flags: 14 ms); each run still parses its own
    arguments with it. Use as ``pytestmark = pytest.mark.usefixtures("fit_parser_once")``."""
    import fit.cli

    parser = _fit_parser()
    monkeypatch.setattr(fit.cli, "build_parser", lambda: parser)


def session_cached(path: Path, what: str, make):
    """``make()`` computed once per test session for all workers: pickled into this session's
    folder (:data:`SESSION_CACHE_ENV`) under the SHA-256 of the file ``path`` and ``what``,
    written to a temporary file and renamed into place, under a lock file, so a second worker
    asking for the same key waits for the first one's result and loads it. Outside a test
    session (no folder) or without ``fcntl``: ``make()``."""
    folder = os.environ.get(SESSION_CACHE_ENV)
    try:
        import fcntl
    except ImportError:
        fcntl = None
    if not folder or fcntl is None or not Path(folder).is_dir():
        return make()
    key = hashlib.sha256(Path(path).read_bytes() + b"\0" + what.encode()).hexdigest()[:32]
    target = Path(folder) / f"{key}.pickle"
    with open(Path(folder) / f"{key}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)          # released when the file closes
        if target.exists():
            with open(target, "rb") as f:
                return pickle.load(f)
        value = make()
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f"{key}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                pickle.dump(value, f, protocol=pickle.HIGHEST_PROTOCOL)
            os.replace(tmp, target)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return value


def pytest_configure(config):
    """The session's folder of :func:`session_cached`: made by the controlling process (or the
    only one, ``-n 0``), handed to each pytest-xdist worker in its ``workerinput``."""
    global _SESSION_CACHE
    workerinput = getattr(config, "workerinput", None)
    if workerinput is not None:
        if workerinput.get("rbrdf_session_cache"):
            os.environ[SESSION_CACHE_ENV] = workerinput["rbrdf_session_cache"]
        return
    _SESSION_CACHE = tempfile.mkdtemp(prefix="rbrdf-test-session-")
    os.environ[SESSION_CACHE_ENV] = _SESSION_CACHE
    if config.getoption("numprocesses", None):
        # one BLAS thread per pytest-xdist worker (the workers inherit it; a value the caller set
        # stands): the workers already fill the cores, and a BLAS thread pool per worker only
        # competes with them (the 3-D fitting files: 149 -> 100 CPU s in one process, same wall)
        for var in BLAS_THREAD_VARIABLES:
            os.environ.setdefault(var, "1")


#: the thread counts of the BLAS and OpenMP libraries NumPy and SciPy may load
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


_SESSION_CACHE = None


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node):
    """pytest-xdist: the worker gets the session's folder (:func:`pytest_configure`)."""
    node.workerinput["rbrdf_session_cache"] = _SESSION_CACHE


def pytest_unconfigure(config):
    """The controlling process removes the session's folder after the workers are done."""
    global _SESSION_CACHE
    if _SESSION_CACHE is not None and getattr(config, "workerinput", None) is None:
        shutil.rmtree(_SESSION_CACHE, ignore_errors=True)
        if os.environ.get(SESSION_CACHE_ENV) == _SESSION_CACHE:
            del os.environ[SESSION_CACHE_ENV]
        _SESSION_CACHE = None


#: the line that marks a whole test module ``lab`` (tests of lab code only)
LAB_MODULE_LINE = re.compile(r"^pytestmark = pytest\.mark\.lab\b", re.M)


@functools.lru_cache(maxsize=None)
def deselects_every_lab_test(markexpr: str) -> bool:
    """Whether the ``-m`` expression ``markexpr`` is false for every test marked ``lab``,
    whatever other marks it has (every truth value of the expression's other names, ``lab``
    true). False for no expression or one pytest cannot parse (pytest then reports it)."""
    if not markexpr or "=" in markexpr:      # a mark's keyword arguments: not decided here
        return False
    try:
        from _pytest.mark.expression import Expression   # pytest's own -m grammar (no public API)

        expr = Expression.compile(markexpr)
    except Exception:  # noqa: BLE001 - an old or changed pytest, a bad expression: collect as usual
        return False
    names = sorted(set(re.findall(r"[A-Za-z_][\w.\-]*", markexpr)) - {"and", "or", "not", "lab"})
    if len(names) > 10:
        return False
    for values in itertools.product((False, True), repeat=len(names)):
        marks = dict(zip(names, values), lab=True)
        if expr.evaluate(lambda name, /, **kw: marks.get(name, False) and not kw):
            return False
    return True


def pytest_ignore_collect(collection_path, config):
    """A test module marked ``lab`` as a whole (its line ``pytestmark = pytest.mark.lab``) is
    not imported when the run's ``-m`` expression deselects all its tests (the default run's):
    each pytest-xdist worker imports every module it collects, and the lab modules' imports
    (colour-science, the studies, the benchmarks) cost each worker about 3 s of the default run.
    Such a module then counts neither as collected nor as deselected."""
    if collection_path.suffix != ".py" or not collection_path.name.startswith("test_"):
        return None
    if not deselects_every_lab_test(config.getoption("markexpr", "") or ""):
        return None
    try:
        text = collection_path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    return True if LAB_MODULE_LINE.search(text) else None


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


@pytest.fixture(autouse=True)
def _warp_default_device_is_the_cpu():
    """Arrays a test makes without naming a device live on the CPU, where the tests' own kernels
    run (Warp's default device is the first GPU wherever one exists). The renderer names its
    device itself: ``Renderer(scene)`` follows ``$RBRDF_DEVICE``, so ``RBRDF_DEVICE=cuda python
    -m pytest`` runs the renders of the suite on the GPU (docs/cuda.md). Acts once per process,
    and only where a test module imported Warp (initialised as the package does)."""
    global _DEFAULT_DEVICE_SET
    if not _DEFAULT_DEVICE_SET and "warp" in sys.modules:
        from warp_rbrdf.runtime import init_warp

        wp = init_warp()
        if wp.is_cuda_available():
            wp.set_device("cpu")
        _DEFAULT_DEVICE_SET = True
    yield


_DEFAULT_DEVICE_SET = False
