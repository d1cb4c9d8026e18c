"""Hangs, memory bombs and file names that only a separate process can show (issue 22).

* Named pipes given as input to every reader and to ``rbrdf-fit``: a reader that opened one
  would block forever; they must be refused from ``stat`` at once (subprocess with a timeout).
* Memory bombs -- one integer or header changed in a small file, or one flag -- run in a
  process whose address space is limited to 2.5 GB (``RLIMIT_AS``): each must end with exit
  status 2 and one line, the process must survive, and its peak resident memory stay below
  2 GB.
* A file name that is not UTF-8, under a UTF-8 locale: the error line and the "wrote" line
  print it escaped instead of raising ``UnicodeEncodeError``.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import data_file
from hostile import CLASSES, lambert_merl, small_cdf_dict, small_rational_dict

ROOT = Path(__file__).resolve().parents[1]
# (id, class) of every case in this module, for docs/robustness.md
CASES = [("fifo-merl", "hang"), ("fifo-rgl", "hang"), ("fifo-rational", "hang"), ("fifo-cdf", "hang"),
         ("fifo-npz", "hang"), ("fifo-cli-info", "hang"), ("fifo-cli-plot-cdf", "hang"),
         ("bomb-cdf-n_mu", "memory"), ("bomb-cdf-rows", "memory"), ("bomb-rational-exponent", "memory"),
         ("bomb-rgl-f16", "memory"), ("bomb-npz-header", "memory"), ("bomb-merl-dims", "memory"),
         ("bomb-flag-cells", "memory"), ("bomb-flag-max-degree", "hang"), ("bomb-json-lists", "memory"),
         ("non-utf8-input", "traceback"), ("non-utf8-output", "traceback")]


def _env(**extra):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "tests")]),
               OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MPLBACKEND="Agg")
    env.update(extra)
    return env


def _python(code, timeout=60, **env):
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, check=False,
                          timeout=timeout, env=_env(**env), cwd=ROOT)


def test_named_pipes_are_refused_at_once(tmp_path):
    pipes = {}
    for suffix in (".binary", ".bsdf", ".json", ".npz"):
        pipes[suffix] = tmp_path / f"pipe{suffix}"
        os.mkfifo(pipes[suffix])
    code = f"""
        from fit.errors import BRDFFileError
        from fit.formats import load_measured
        from fit.projection.projected import ProjectedBRDF
        from fit.rational.coefficient_file import load as load_rational
        from fit.sampling.cdf_file import load as load_cdf
        for load, path in ((load_measured, {str(pipes['.binary'])!r}), (load_measured, {str(pipes['.bsdf'])!r}),
                           (load_rational, {str(pipes['.json'])!r}), (load_cdf, {str(pipes['.json'])!r}),
                           (ProjectedBRDF.load, {str(pipes['.npz'])!r})):
            try:
                load(path)
                print("LOADED", path)
            except BRDFFileError as e:
                print(e)
        """
    r = _python(code, timeout=60)
    lines = r.stdout.strip().splitlines()
    assert r.returncode == 0 and len(lines) == 5, r.stdout + r.stderr
    assert all("is a named pipe" in ln for ln in lines), lines
    for argv in (["info", pipes[".binary"]], ["plot-cdf", pipes[".json"], "--out", tmp_path / "plots"]):
        r = subprocess.run([sys.executable, "-m", "fit.cli", *map(str, argv)], capture_output=True, text=True, check=False,
                           timeout=60, env=_env(), cwd=ROOT)
        assert r.returncode == 2 and r.stdout == "", r.stdout + r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "is a named pipe" in r.stderr
    assert not (tmp_path / "plots").exists()


@pytest.fixture(scope="module")
def bombs(tmp_path_factory):
    """Small files that ask for far more than 2 GB (and a valid MERL file for the flag bombs)."""
    from fit.formats.merl import MERL_SHAPE
    from fit.formats.tensor_file import read_tensor_file, write_tensor_file

    d = tmp_path_factory.mktemp("bombs")
    cdf = small_cdf_dict()
    cdf["pieces"]["n_mu"] = 10**6                     # one integer of a CDF file
    (d / "n_mu.json").write_text(json.dumps(cdf))
    cdf = small_cdf_dict()
    cdf["table_data"]["theta_v"] = [0.1] * 100000     # rows claimed by the theta_v list
    (d / "rows.json").write_text(json.dumps(cdf))
    rat = small_rational_dict()
    rat["pieces"][0]["functions"][0]["denominator"]["exponents"][1] = [10**9, 0]
    (d / "exponent.json").write_text(json.dumps(rat))
    f = {k: np.array(v.data) for k, v in read_tensor_file(data_file("rgl/paper_white_rgb.bsdf")).items()}
    f["vndf"] = np.ones((1, 8, 1024, 1024), np.float16)    # 16 MB of float16 tables
    write_tensor_file(d / "f16.bsdf", f)
    import io
    import zipfile

    from lab.analytic import lambert
    from fit.formats.measured import MeasuredBRDF
    from fit.projection.project import project

    project(MeasuredBRDF.from_function(lambert((0.5, 0.5, 0.5)))).save(d / "ok.npz")
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z, zipfile.ZipFile(d / "ok.npz") as src:
        for n in src.namelist():
            if n != "value.npy":
                z.writestr(n, src.read(n))
        hdr = io.BytesIO()
        np.lib.format.write_array_header_1_0(hdr, {"descr": "<f8", "fortran_order": False,
                                                   "shape": (100000, 100000, 3)})
        z.writestr("value.npy", hdr.getvalue())
    (d / "header.npz").write_bytes(buf.getvalue())
    (d / "dims.binary").write_bytes(np.asarray([2**31 - 1] * 3, "<i4").tobytes() + b"\0" * 1024)
    (d / "lists.json").write_text("[" + "[]," * 3_000_000 + "[]]")
    lambert_merl(d / "ok.binary")
    assert int(np.prod(MERL_SHAPE)) > 0
    return d


def test_memory_bombs_under_a_2_5_gb_address_space(bombs, tmp_path):
    runs = [
        ["plot-cdf", bombs / "n_mu.json", "--out", tmp_path / "a"],
        ["plot-cdf", bombs / "rows.json", "--out", tmp_path / "b"],
        ["info", bombs / "f16.bsdf"],
        ["info", bombs / "dims.binary"],
        ["cdf", bombs / "ok.binary", "--out", tmp_path / "c.json", "--n-v", "128", "--n-t", "512", "--n-p", "512"],
        ["brdf", bombs / "ok.binary", "--out", tmp_path / "d.json", "--max-degree", "100000"],
        ["plot-cdf", bombs / "lists.json", "--out", tmp_path / "e"],
    ]
    code = f"""
        import json, resource, sys
        resource.setrlimit(resource.RLIMIT_AS, (2_500_000_000, 2_500_000_000))
        from fit.cli import main
        from fit.errors import BRDFFileError
        from fit.projection.projected import ProjectedBRDF
        from fit.rational.coefficient_file import load
        results = []
        for argv in {[[str(a) for a in r] for r in runs]!r}:
            results.append(main(argv))
        for loader, path in ((load, {str(bombs / "exponent.json")!r}),
                             (ProjectedBRDF.load, {str(bombs / "header.npz")!r})):
            try:
                loader(path)
                results.append("loaded")
            except BRDFFileError as e:
                print("rbrdf-fit: error:", e, file=sys.stderr)
                results.append(2)
        # this process's own peak: VmHWM belongs to the address space exec made (ru_maxrss
        # would keep the forking test process's peak, a test worker's gigabytes)
        peak_kb = int(next(ln.split()[1] for ln in open("/proc/self/status") if ln.startswith("VmHWM:")))
        print(json.dumps({{"results": results, "peak_kb": peak_kb}}))
        """
    r = _python(code, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads(r.stdout.strip().splitlines()[-1])
    assert res["results"] == [2] * (len(runs) + 2), r.stderr
    errors = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(errors) == len(runs) + 2 and all("error:" in ln for ln in errors), r.stderr
    assert "Traceback" not in r.stderr and "MemoryError" not in r.stderr
    print("memory bombs: peak resident", res["peak_kb"] // 1024, "MiB")
    assert res["peak_kb"] < 2_000_000, res
    for frag in ("MAX_CDF_PIECES", "MAX_CDF_ROWS", "MAX_RGL_ELEMENTS", "wrong MERL header", "--n-v/--n-t/--n-p",
                 "--max-degree", "MAX_JSON_CONTAINERS", "MAX_RATIONAL_EXPONENT", "array 'value'"):
        assert frag in r.stderr, (frag, r.stderr)
    assert not any((tmp_path / n).exists() for n in ("a", "b", "c.json", "d.json", "e"))


def test_non_utf8_file_names(tmp_path):
    """Under a UTF-8 locale, a name that is not UTF-8 prints escaped, in the error line and in
    the success line, with no UnicodeEncodeError."""
    bad = os.fsencode(tmp_path) + b"/bad\xff.binary"
    Path(os.fsdecode(bad)).write_bytes(b"\0" * 10)
    env = _env(LC_ALL="C.UTF-8", LANG="C.UTF-8", PYTHONIOENCODING="")
    env.pop("PYTHONIOENCODING")
    r = subprocess.run([sys.executable, "-m", "fit.cli", "info", bad], capture_output=True, timeout=60, check=False,
                       env=env, cwd=ROOT)
    err = r.stderr.decode("utf-8")
    assert r.returncode == 2 and len(err.strip().splitlines()) == 1, err
    assert "bad\\xff.binary" in err and "Traceback" not in err
    good = lambert_merl(tmp_path / "ok.binary")
    out = os.fsencode(tmp_path) + b"/out\xfe.npz"
    r = subprocess.run([sys.executable, "-m", "fit.cli", "project", str(good), "--out", out],
                       capture_output=True, timeout=120, env=env, cwd=ROOT, check=False)
    assert r.returncode == 0, r.stderr.decode()
    assert b"out\\xfe.npz" in r.stdout and r.stderr == b""
    assert os.path.exists(out)


def case_counts() -> dict:
    out = dict.fromkeys(CLASSES, 0)
    for _, k in CASES:
        out[k] += 1
    return out
