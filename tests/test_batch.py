"""rbrdf-fit batch / fit.batch.fit_database (issue 24): output keys, the report, a 3-material
batch on a local dask cluster interrupted with Ctrl-C and resumed, the external-scheduler path
(``dask scheduler`` + ``dask worker`` processes on 127.0.0.1) with one corrupt input, and the
one-line argument errors. Tiny fits (tolerance 0.2, 4 x 8 x 8 CDF tables) on exact-layout MERL
files keep the whole module at a few tens of seconds."""
from __future__ import annotations

import csv
import io
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lab.analytic import glossy_lobe, lambert
from fit.batch.keys import BrdfOptions, CdfOptions, brdf_key, cdf_key, output_key
from fit.batch.report import COLUMNS, BatchReport, plot_coefficients, rows_from_results
from fit.cli import main
from fit.formats.measured import MeasuredBRDF
from fit.formats.merl import write_merl

ROOT = Path(__file__).resolve().parents[1]
# one function per channel over the whole theta_d range (no grazing band: half the LPs)
# no sampler stored in the BRDF outputs (test_batch_stores_the_fits_own_sampler tests it)
FAST = ["--tol", "0.2", "--core-theta-d", "78.5", "--n-v", "4", "--n-t", "8", "--n-p", "8", "--no-sampler"]
FAST_KW = {"tols": (0.2,), "brdf_options": {"core_theta_d_deg": 78.5}, "cdf_options": {"n_v": 4, "n_t": 8, "n_p": 8},
           "sampler": False}


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env.setdefault("MPLBACKEND", "Agg")
    return env


@pytest.fixture(scope="module")
def materials(tmp_path_factory):
    """Three small exact-layout MERL files in one folder."""
    d = tmp_path_factory.mktemp("db")
    write_merl(MeasuredBRDF.from_function(lambert((0.8, 0.5, 0.2)), name="a_lambert"), d / "a_lambert.binary")
    write_merl(MeasuredBRDF.from_function(lambert((0.3, 0.6, 0.4)), name="b_lambert"), d / "b_lambert.binary")
    write_merl(MeasuredBRDF.from_function(glossy_lobe(exponent=10.0), name="c_glossy"), d / "c_glossy.binary")
    return d


def _parts(folder: Path) -> list:
    return sorted(str(p) for p in folder.rglob("*") if ".part" in p.name)


def _manifests(folder: Path) -> list:
    return sorted(folder.rglob("*.manifest.json"))


# --- keys and report (no cluster) ---------------------------------------------------------------
def test_keys_follow_content_and_options():
    sha = "ab" * 32
    k = brdf_key(sha, BrdfOptions(tol=0.05))
    assert k == brdf_key(sha, BrdfOptions(tol=5e-2)) and len(k) == 16
    assert k != brdf_key("cd" * 32, BrdfOptions(tol=0.05))          # other bytes
    assert k != brdf_key(sha, BrdfOptions(tol=0.1))                  # other tolerance
    assert k != brdf_key(sha, BrdfOptions(tol=0.05, max_degree=8))   # other option
    # the key covers every setting of the fit (BRDFFitSettings.get_params()), not a hand-kept subset
    assert k != brdf_key(sha, BrdfOptions(tol=0.05, spread_k=2.0)) != brdf_key(sha, BrdfOptions(peak_split_deg=None))
    assert k == output_key("brdf", sha, BrdfOptions(tol=0.05).get_params())
    assert cdf_key(sha, CdfOptions()) != cdf_key(sha, CdfOptions(n_v=16))
    assert cdf_key(sha, CdfOptions()) != k


def test_report_rows_csv_markdown_chart(tmp_path):
    brdf = {"status": "done", "tol": 0.05, "coefficients": 30, "coefficients_rgb": [12, 10, 8],
            "core_theta_d_deg": 60.0, "guaranteed": True, "band": "met", "core_max_rel_error": 0.0499,
            "core_rms_rel_error": 0.02, "fit_s": 1.234}
    results = [
        {"name": "m2", "brdf": [brdf, dict(brdf, tol=0.1, coefficients=20, coefficients_rgb=[8, 6, 6],
                                          guaranteed=False, band="best effort", status="skipped")],
         "cdf": {"status": "done", "rows_rational": 31, "rows": 32, "fallback": False,
                 "variance_ratio_median": 0.91, "variance_ratio_max": 1.19, "cdf_s": 3.0}},
        {"name": "m1", "brdf": [], "cdf": None, "error": "m1.binary: truncated MERL file"},
    ]
    rep = BatchReport(rows_from_results(results))
    assert rep["material"] == ["m1", "m2", "m2"] and rep["coefs"] == [None, 30, 20]
    row = rep[1]
    assert (row["coefs_r"], row["coefs_g"], row["coefs_b"]) == (12, 10, 8)
    assert row["core_max_err_pct"] == 4.99 and row["cdf_rows_rational"] == "31/32" and row["fit_s"] == 1.23
    assert rep[2]["guaranteed"] is False and rep[2]["band"] == "best effort" and rep[2]["status"] == "skipped"
    assert [r["material"] for r in rep.failed()] == ["m1"]
    parsed = list(csv.DictReader(io.StringIO(rep.to_csv(tmp_path / "r.csv"))))
    assert tuple(parsed[0]) == COLUMNS and parsed[1]["coefs"] == "30" and parsed[0]["coefs"] == ""
    assert "truncated MERL file" in parsed[0]["error"]
    assert (tmp_path / "r.csv").read_text() == rep.to_csv()
    md = rep.to_markdown().splitlines()
    assert md[0].startswith("| material | tol | status | coefs | R | G | B |") and len(md) == 2 + 3 + 2
    assert "| m2 | 0.1 | skipped | 20 | 8 | 6 | 6 | 60.0 | no | best effort |" in md[4]
    assert md[-1] == "- m1 (tol None): m1.binary: truncated MERL file"
    assert plot_coefficients(rep.rows, tmp_path / "c.png")
    assert (tmp_path / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not plot_coefficients(rep.rows[:1], tmp_path / "none.png") and not (tmp_path / "none.png").exists()


# --- bad arguments: one line, exit 2, nothing written ---------------------------------------------
@pytest.mark.parametrize("args, message", [
    (["nope_dir/missing.binary"], "file not found"),
    (["x.txt"], "unknown BRDF file type"),
    (["*.nomatch"], "pattern matches no measured-BRDF file"),
    (["x.binary", "--tol", "nan"], "argument --tol"),
    (["x.binary", "--workers", "0"], "argument --workers"),
])
def test_bad_arguments_are_one_line(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "x.txt").write_text("hi")
    (tmp_path / "x.binary").write_bytes(b"")
    assert main(["batch", *args, "--out", "out"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


# --- local cluster: Ctrl-C half-way, then resume ----------------------------------------------------
@pytest.mark.heavy
def test_interrupt_and_resume_on_local_cluster(materials, tmp_path, capsys):
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "fit.cli", "batch", str(materials), "--out", str(out), "--workers", "1", *FAST]
    # Ctrl-C as in a terminal: SIGINT at its default in the batch, even when this test runs where
    # it is ignored (a background job of a shell without job control), which exec would pass on
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 120
        while not _manifests(out) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, "the batch ended before its first output: nothing to interrupt"
        assert _manifests(out), "no output within 120 s"
        os.killpg(proc.pid, signal.SIGINT)       # Ctrl-C in a terminal: the whole process group
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, (proc.returncode, stdout, stderr)
    assert "interrupted" in stderr and "Traceback" not in stderr
    assert _parts(out) == []                     # no half-written file
    assert not (out / "report.csv").exists()     # the report is written only by a run that ends
    first = {p.name for p in _manifests(out)}
    assert 1 <= len(first) < 6                   # 3 materials x (BRDF + CDF): interrupted half-way

    from fit.batch import fit_database

    # --report-only: the report of what is done, nothing fitted, no cluster
    partial = fit_database([materials], out, report_only=True, progress=False, **FAST_KW)
    assert {p.name for p in _manifests(out)} == first and partial.workers == 0
    assert partial.counts == {"done": 0, "skipped": len(first), "failed": 0, "missing": 6 - len(first)}
    n_brdf = sum(1 for name in first if name.startswith("brdf-"))
    assert partial["status"].count("skipped") == n_brdf and partial["status"].count("missing") == 3 - n_brdf
    assert [c is None for c in partial["coefs"]] == [s == "missing" for s in partial["status"]]

    report = fit_database([materials / "*.binary"], out, workers=1, progress=False, **FAST_KW)
    assert _parts(out) == []
    assert report.counts == {"done": 6 - len(first), "skipped": len(first), "failed": 0}
    assert report["material"] == ["a_lambert", "b_lambert", "c_glossy"]
    assert all(g is True for g in report["guaranteed"]) and report["cdf_rows_rational"] == ["4/4"] * 3
    assert report["coefs"][0] == report["coefs_r"][0] * 3        # grey-free lambert: same count per channel
    assert report["sampler"] == [None] * 3                       # --no-sampler: no sampler record
    for m in _manifests(out):                    # every output whole, readable, as its manifest says
        d = json.loads(m.read_text())
        target = m.with_name(d["output"])
        from fit import load_cdf, load_coefficients
        loaded = (load_coefficients if d["kind"] == "brdf" else load_cdf)(target)
        if d["kind"] == "brdf":                  # under the key of a BRDF output without a sampler
            assert loaded.sampler is None and "sampler" not in d["options"]
            assert target.name.endswith(brdf_key(d["input"]["sha256"], BrdfOptions(tol=0.2, core_theta_d_deg=78.5))
                                        + ".json")
    assert {p.name for p in _manifests(out)} >= first and len(_manifests(out)) == 6
    assert (out / "report.md").read_text().count("\n| ") == 4 and (out / "report_coefficients.png").exists()

    # a third run does nothing but report (exit 0): everything skipped, without starting a cluster
    capsys.readouterr()
    assert main(["batch", str(materials), "--out", str(out), "--quiet", *FAST]) == 0
    summary = capsys.readouterr().out.splitlines()[0]
    assert summary.startswith("3 rows; outputs done 0, skipped (done before) 6, failed 0;")
    assert "workers" not in summary
    again = list(csv.DictReader((out / "report.csv").open()))
    assert [r["status"] for r in again] == ["skipped"] * 3
    assert [r["coefs"] for r in again] == [str(c) for c in report["coefs"]]


# --- an external scheduler and worker (``dask scheduler`` + ``dask worker`` on 127.0.0.1) ---------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(procs):
    """Ctrl-C to each process, the last started first, each waited for in turn: a worker whose
    scheduler went first retries it for seconds before it ends (8 s of the module's time
    stopping both at once, 0.7 s in this order)."""
    for p in reversed(procs):
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
        try:
            p.wait(timeout=15)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory):
    """The address of a ``dask scheduler`` with one single-threaded ``dask worker``, processes
    started once for the tests that fit on an external cluster (the batch's own local cluster is
    started by the interrupted and resumed runs above), stopped after them."""
    cwd = tmp_path_factory.mktemp("cluster")
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    common = {"cwd": cwd, "env": _env(), "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port",
                               str(port), "--no-dashboard"], **common)]
    try:
        deadline = time.monotonic() + 60      # the batch says "connection refused" at once: wait for the port
        while time.monotonic() < deadline and procs[0].poll() is None:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                time.sleep(0.2)
        procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", addr, "--nthreads", "1",
                                       "--nworkers", "1", "--no-dashboard", "--death-timeout", "60"], **common))
        yield addr
    finally:
        _stop(procs)
    assert all(p.returncode is not None for p in procs)


# --- the fit's own sampler in each BRDF output, as rbrdf-fit brdf stores it --------------------------
@pytest.mark.heavy
def test_batch_stores_the_fits_own_sampler(materials, tmp_path, scheduler):
    """A BRDF output of the batch carries the fit's own inverse CDFs (the sampler record of
    rbrdf-fit brdf: made from the fit, its table the renderer's tabulation of the fit), reported
    in the 'sampler' column, under a key of its own (--no-sampler's outputs, without one and
    under the key without sampler options: test_interrupt_and_resume_on_local_cluster)."""
    from fit import load_coefficients
    from fit.batch import fit_database
    from fit.batch.keys import SamplerOptions
    from fit.sampling import embedded
    from fit.sampling.model_sampler import vouched_evaluate
    from fit.sampling.table import tabulate

    out = tmp_path / "out"
    one = [materials / "a_lambert.binary"]
    kw = dict(FAST_KW, cdf=False, sampler=True, sampler_time_limit_s=1.0)
    report = fit_database(one, out, scheduler=scheduler, connect_timeout_s=60, progress=False, **kw)
    assert report.counts == {"done": 1, "skipped": 0, "failed": 0}, report.rows
    (path,) = (out / "a_lambert").glob("brdf-*[0-9a-f].json")
    model = load_coefficients(path)
    cdf = embedded.read(model, path)
    assert cdf is not None                       # rows past the time limit are sampled with the table
    model.sampler = None
    np.testing.assert_array_equal(cdf.table.cdf_phi, tabulate(vouched_evaluate(model)).cdf_phi)
    cell = report["sampler"][0]
    rows = int((cdf.fit_info or {}).get("verified_rows", 0))
    assert cell == (f"rational {rows}/32" if not cdf.fallback else "table"), cell
    manifest = json.loads(path.with_name(path.name[:-5] + ".manifest.json").read_text())
    assert manifest["options"]["sampler"] == {"time_limit_s": 1.0}
    assert manifest["record"]["sampler"] in ("rational", "table")
    sha = manifest["input"]["sha256"]
    bo = BrdfOptions(tol=0.2, core_theta_d_deg=78.5)
    assert path.name.endswith(brdf_key(sha, bo, SamplerOptions(1.0)) + ".json")
    assert brdf_key(sha, bo, SamplerOptions(1.0)) != brdf_key(sha, bo) != brdf_key(sha, bo, SamplerOptions())


@pytest.mark.heavy
def test_external_scheduler_and_failure_isolation(materials, tmp_path, scheduler):
    from fit.batch import fit_database

    db = tmp_path / "db"
    db.mkdir()
    for name in ("a_lambert.binary", "c_glossy.binary"):
        (db / name).symlink_to(materials / name)
    (db / "broken.binary").write_bytes(b"\x01\x00\x00\x00" * 3 + b"\0" * 64)
    report = fit_database([db], tmp_path / "out", scheduler=scheduler, progress=False, connect_timeout_s=60,
                          **FAST_KW)
    assert report["material"] == ["a_lambert", "broken", "c_glossy"]
    assert report["status"] == ["done", "failed", "done"] and report.workers == 1
    err = report[1]["error"]
    assert "broken.binary" in err and "wrong MERL header" in err and "\n" not in err
    assert report.counts == {"done": 4, "skipped": 0, "failed": 2}
    assert not (tmp_path / "out" / "broken").exists()       # nothing written for the failed material
    manifests = _manifests(tmp_path / "out")
    assert len(manifests) == 4
    pids = {json.loads(m.read_text())["worker"].rsplit(":", 1)[1] for m in manifests}
    assert str(os.getpid()) not in pids                     # fitted by the external worker


def test_unreachable_scheduler_is_one_line(materials, tmp_path):
    from fit.batch import fit_database
    from fit.errors import FlagError

    with pytest.raises(FlagError, match="--scheduler: cannot connect to tcp://127.0.0.1:"):
        fit_database([materials / "a_lambert.binary"], tmp_path / "out", scheduler=f"tcp://127.0.0.1:{_free_port()}",
                     connect_timeout_s=2, progress=False, **FAST_KW)
