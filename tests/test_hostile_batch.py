"""Hostile input of ``rbrdf-fit batch`` (fit.batch): inputs checked with ``stat`` before any
byte is read or hashed (sparse 20 GB files, named pipes, devices, link loops, walks without
end, oversized outputs of an earlier run), ``--scheduler`` checked and reached within its
timeout with the cause named (only 127.0.0.1 is ever contacted), progress lines without a
terminal and a bar on one, and the renderer's search for a fit's source measurement.

Every case runs without a cluster except one (the progress lines of a finished task: one local
worker process). Helpers: tests/hostile.py."""
from __future__ import annotations

import os
import socket
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from hostile import CLASSES, assert_bad_input, run

SPARSE = 20 * 2**30          # 20 GB, sparse: costs no disk

#: (case, class of the issue); see docs/robustness.md
CASES = [
    ("sparse-merl-explicit", "hang"), ("sparse-rgl-in-folder", "hang"), ("sparse-in-pattern", "hang"),
    ("sparse-link-in-folder", "hang"), ("pattern-link-loops", "hang"), ("walk-too-large", "hang"),
    ("sparse-output-of-earlier-run", "hang"),
    ("pipe-in-folder", "unclear"), ("device-link-in-folder", "silent"),
    ("scheduler-garbage", "traceback"), ("scheduler-http", "traceback"), ("scheduler-https", "traceback"),
    ("scheduler-inproc", "traceback"), ("scheduler-no-port", "traceback"), ("scheduler-port-0", "traceback"),
    ("scheduler-port-99999", "traceback"), ("scheduler-bad-ipv6", "traceback"), ("scheduler-empty", "traceback"),
    ("scheduler-newline", "traceback"), ("scheduler-ucx", "traceback"),
    ("scheduler-refused", "hang"), ("scheduler-no-answer", "unclear"), ("scheduler-silent-port", "hang"),
    ("progress-without-terminal", "unclear"), ("progress-bar-on-terminal", "unclear"),
    ("progress-callback", "unclear"), ("render-source-sparse", "hang"),
]


def case_counts() -> dict:
    out = dict.fromkeys(CLASSES, 0)
    for _, k in CASES:
        out[k] += 1
    return out


def _sparse(path: Path, size: int = SPARSE) -> Path:
    with open(path, "wb") as f:
        f.truncate(size)
    return path


def _one_failed_row(rc, out, err, *names):
    """Exit 1 (a material failed, the batch went on), its one FAILED line naming ``names``."""
    assert rc == 1, (rc, out, err)
    failed = [ln for ln in err.splitlines() if ln.strip()]
    assert failed and all(ln.startswith("FAILED: ") for ln in failed), err
    assert "Traceback" not in err
    for n in names:
        assert any(str(n) in ln for ln in failed), (n, err)
    return failed


# --- inputs: stat before any read or hash ---------------------------------------------------------
def test_sparse_merl_given_explicitly_is_refused_at_once(tmp_path, capsys):
    big = _sparse(tmp_path / "huge.binary")
    t = time.perf_counter()
    rc, out, err = run(capsys, ["batch", big, "--out", tmp_path / "out", "--no-cdf"])
    dt = time.perf_counter() - t
    failed = _one_failed_row(rc, out, err, "huge.binary", "21474836480 bytes", "above the limit")
    assert len(failed) == 1
    assert dt < 10, dt          # the report (matplotlib) included; the hash of 20 GB took > 120 s
    from fit.batch.inputs import collect_inputs

    t = time.perf_counter()
    (item,) = collect_inputs([big])
    assert time.perf_counter() - t < 0.5 and item.error and "huge.binary" in item.error


def test_sparse_files_in_folder_pattern_and_link(tmp_path, capsys):
    db = tmp_path / "db"
    (db / "sub").mkdir(parents=True)
    _sparse(db / "sub" / "big.bsdf")
    _sparse(tmp_path / "outside.binary")
    (db / "link.binary").symlink_to(tmp_path / "outside.binary")
    t = time.perf_counter()
    rc, out, err = run(capsys, ["batch", db, "--out", tmp_path / "o1", "--no-cdf"])
    assert len(_one_failed_row(rc, out, err, "big.bsdf", "link.binary", "RGL tensor file is 21474836480")) == 2
    rc, out, err = run(capsys, ["batch", f"{db}/**/*.bsdf", "--out", tmp_path / "o2", "--no-cdf"])
    assert len(_one_failed_row(rc, out, err, "big.bsdf")) == 1
    assert time.perf_counter() - t < 20


def test_pattern_with_link_loops_is_walked_once(tmp_path, capsys):
    """glob's ``**`` follows links to folders: two links back up made it walk without end."""
    db = tmp_path / "db" / "a" / "b"
    db.mkdir(parents=True)
    (db / "up").symlink_to("..")
    (db / "up2").symlink_to("../..")
    _sparse(tmp_path / "db" / "a" / "x.binary")
    t = time.perf_counter()
    rc, out, err = run(capsys, ["batch", f"{tmp_path}/db/**/*.binary", "--out", tmp_path / "o", "--no-cdf"])
    assert len(_one_failed_row(rc, out, err, "x.binary")) == 1
    assert time.perf_counter() - t < 10


def test_walk_too_large_is_one_line(tmp_path, capsys, monkeypatch):
    import fit.batch.inputs as bi

    monkeypatch.setattr(bi, "MAX_WALK_ENTRIES", 50)
    db = tmp_path / "db"
    db.mkdir()
    for i in range(60):
        (db / f"f{i}.txt").write_bytes(b"")
    rc, out, err = run(capsys, ["batch", db, "--out", tmp_path / "out"])
    assert_bad_input(rc, err, str(db), "more than 50 entries", "MAX_WALK_ENTRIES")
    rc, out, err = run(capsys, ["batch", f"{db}/**/*.binary", "--out", tmp_path / "out"])
    assert_bad_input(rc, err, str(db), "more than 50 entries")
    assert not (tmp_path / "out").exists()


def test_special_files_in_folder_are_failures_not_skipped(tmp_path, capsys):
    db = tmp_path / "db"
    db.mkdir()
    os.mkfifo(db / "pipe.binary")
    rc, out, err = run(capsys, ["batch", db, "--out", tmp_path / "o1", "--no-cdf"])
    _one_failed_row(rc, out, err, "pipe.binary", "named pipe")       # was: "folder without measured-BRDF files"
    os.unlink(db / "pipe.binary")
    (db / "zero.bsdf").symlink_to("/dev/zero")
    rc, out, err = run(capsys, ["batch", db, "--out", tmp_path / "o2", "--no-cdf"])
    _one_failed_row(rc, out, err, "zero.bsdf", "device")
    # named explicitly, a pipe is a bad argument (as it was: a regression check, not a case)
    os.mkfifo(tmp_path / "p.binary")
    rc, out, err = run(capsys, ["batch", tmp_path / "p.binary", "--out", tmp_path / "o3"])
    assert_bad_input(rc, err, "p.binary", "not a regular file")
    assert not (tmp_path / "o3").exists()


def test_sparse_output_of_an_earlier_run_is_not_hashed(tmp_path):
    """A 20 GB file where an earlier run's output was (its manifest next to it): not done, never hashed."""
    from fit.batch import fit_database
    from fit.batch.keys import BrdfOptions, brdf_key
    from fit.batch.tasks import brdf_name, manifest_path
    from fit.inputs import sha256_regular

    inp = tmp_path / "m.bsdf"
    inp.write_bytes(b"not really a tensor file")
    key = brdf_key(sha256_regular(inp, 1 << 20), BrdfOptions(tol=0.2))
    out = tmp_path / "out"
    (out / "m").mkdir(parents=True)
    target = _sparse(out / "m" / brdf_name(BrdfOptions(tol=0.2), key))
    manifest_path(target).write_text('{"format": "rbrdf-batch-manifest", "key": "%s", "output_sha256": "0"}' % key)
    t = time.perf_counter()
    report = fit_database([inp], out, tols=(0.2,), cdf=False, report_only=True, progress=False)
    assert time.perf_counter() - t < 10
    assert report["status"] == ["missing"]


# --- --scheduler ----------------------------------------------------------------------------------
@pytest.mark.parametrize("address, words", [
    ("not an address!!", "no port"),
    ("http://127.0.0.1:8787", "http:// is a web address"),
    ("https://127.0.0.1:8787", "https:// is a web address"),
    ("inproc://192.168.1.2/123/1", "inproc:// reaches a scheduler inside the same process only"),
    ("tcp://127.0.0.1", "no port"),
    ("tcp://127.0.0.1:0", "port '0' is not an integer in 1-65535"),
    ("tcp://127.0.0.1:99999", "port '99999'"),
    ("tcp://[zz::1]:8786", "not an IPv6 address"),
    ("", "empty address"),
    ("tcp://a\nb:1", "is not a host name"),
    ("ucx://127.0.0.1:8786", "unknown scheme 'ucx'"),
])
def test_bad_scheduler_address_is_one_line(tmp_path, capsys, address, words):
    (tmp_path / "m.bsdf").write_bytes(b"x")
    rc, out, err = run(capsys, ["batch", tmp_path / "m.bsdf", "--out", tmp_path / "out", "--scheduler", address])
    assert_bad_input(rc, err, "--scheduler", words)
    assert not (tmp_path / "out").exists()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_refused_port_answers_at_once(tmp_path, capsys):
    (tmp_path / "m.bsdf").write_bytes(b"x")
    addr = f"tcp://127.0.0.1:{_free_port()}"
    t = time.perf_counter()
    rc, out, err = run(capsys, ["batch", tmp_path / "m.bsdf", "--out", tmp_path / "out", "--scheduler", addr])
    dt = time.perf_counter() - t
    assert_bad_input(rc, err, "--scheduler", addr, "connection refused")
    assert dt < 5.0 + 3.0, dt          # the connect timeout (5 s) and a margin; it took 30 s
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("backlog", [0, 8], ids=["no-answer", "silent-port"])
def test_unresponsive_scheduler_within_timeout(tmp_path, backlog):
    """backlog 0 with one connection queued: the kernel drops further SYNs (a host that does
    not answer); backlog 8: the port accepts and never speaks (dask's Client waited forever)."""
    from fit.batch import fit_database
    from fit.errors import FlagError

    (tmp_path / "m.bsdf").write_bytes(b"x")
    with socket.socket() as srv:
        srv.bind(("127.0.0.1", 0))
        srv.listen(backlog)
        addr = f"tcp://127.0.0.1:{srv.getsockname()[1]}"
        held = socket.create_connection(srv.getsockname()) if backlog == 0 else None
        try:
            t = time.perf_counter()
            with pytest.raises(FlagError) as e:
                fit_database([tmp_path / "m.bsdf"], tmp_path / "out", scheduler=addr, connect_timeout_s=1.0,
                             progress=False)
            dt = time.perf_counter() - t
        finally:
            if held is not None:
                held.close()
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"--scheduler: cannot connect to {addr}: ")
    assert ("timed out" if backlog == 0 else "no dask scheduler answered") in msg, msg
    assert "memory" not in msg
    assert dt < 1.0 * 2 + 1.0 + 3.0, dt      # socket + handshake timeouts, thread join, imports
    assert not (tmp_path / "out").exists()


# --- progress ---------------------------------------------------------------------------------------
def test_progress_lines_without_terminal(tmp_path):
    """A fresh process with stdout a pipe: a line per stage and per material, with n/N, elapsed
    and an estimate, before the summary (it printed nothing until a material finished)."""
    import subprocess

    root = Path(__file__).resolve().parents[1]
    (tmp_path / "a_broken.bsdf").write_bytes(b"not a tensor file")
    _sparse(tmp_path / "b_huge.binary")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]),
               MPLBACKEND="Agg")
    p = subprocess.run([sys.executable, "-m", "fit.cli", "batch", str(tmp_path), "--out", str(tmp_path / "out"),
                        "--no-cdf", "--workers", "1"], capture_output=True, text=True, env=env, timeout=180)
    assert p.returncode == 1, (p.stdout, p.stderr)
    lines = p.stdout.splitlines()
    prog = [ln for ln in lines if ln.startswith("batch: [")]
    assert prog[0].startswith("batch: [0/2] 2 measured files") and "1 refused before reading" in prog[0]
    assert prog[1].startswith("batch: [1/2] 0 done before, 1 failed (not readable), 1 to fit; elapsed ")
    assert any(ln.startswith("batch: [1/2] starting a local cluster of 1 worker") for ln in prog)
    assert any(ln.startswith("batch: [1/2] 1 worker ready") for ln in prog)
    (mat,) = [ln for ln in prog if "a_broken: FAILED" in ln]
    assert mat.startswith("batch: [2/2] a_broken: FAILED: ") and "; elapsed " in mat and "about 0.0 s left" in mat
    assert prog[-1].startswith("batch: [2/2] writing report.csv")
    assert lines.index(prog[-1]) < next(i for i, ln in enumerate(lines) if ln.startswith("2 rows;"))
    assert "Traceback" not in p.stderr


def test_bar_on_terminal_and_quiet(tmp_path, capsys, monkeypatch):
    _sparse(tmp_path / "huge.binary")
    monkeypatch.setattr(sys.stdout, "isatty", lambda: True)
    rc, out, err = run(capsys, ["batch", tmp_path / "huge.binary", "--out", tmp_path / "o1", "--no-cdf"])
    assert rc == 1 and "materials: 100%" in err and "batch: [1/1]" in out
    rc, out, err = run(capsys, ["batch", tmp_path / "huge.binary", "--out", tmp_path / "o2", "--no-cdf", "--quiet"])
    assert rc == 1 and "materials" not in err and "batch: [" not in out


def test_progress_callback_of_the_api(tmp_path):
    from fit.batch import fit_database
    from fit.batch.progress import BatchProgress

    _sparse(tmp_path / "huge.binary")
    events = []
    fit_database([tmp_path], tmp_path / "out", cdf=False, progress=False, on_progress=events.append)
    assert all(isinstance(e, BatchProgress) for e in events)
    assert [e.stage for e in events] == ["inputs", "hashed", "report"]
    assert [(e.done, e.total) for e in events] == [(0, 1), (1, 1), (1, 1)]
    assert all(e.elapsed_s >= 0 for e in events) and events[-1].elapsed_s >= events[0].elapsed_s


# --- the renderer's search for a fit's source measurement --------------------------------------------
def test_render_source_candidate_is_not_hashed(tmp_path, monkeypatch):
    from warp_rbrdf.materials.rational import find_source
    from warp_rbrdf.errors import SceneError

    data = tmp_path / "data"
    (data / "merl").mkdir(parents=True)
    _sparse(data / "merl" / "src.binary")
    monkeypatch.setenv("RBRDF_DATA", str(data))
    model = SimpleNamespace(source={"file": "src.binary", "sha256": "ab" * 32})
    spec = SimpleNamespace(file=None)
    t = time.perf_counter()
    with pytest.raises(SceneError) as e:
        find_source(model, spec, tmp_path / "scene.toml", "materials.m", "flagged fit")
    assert time.perf_counter() - t < 2.0
    assert "src.binary" in str(e.value) and "\n" not in str(e.value)
