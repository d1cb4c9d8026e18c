"""Long work reports progress and stays bounded; the command lines end quietly and point to the
right help: progress callbacks (:mod:`fit.progress`) of ``fit_cdf``, ``fit_brdf`` and the 3-D
fit, progress lines on a stderr that is not a terminal, HiGHS's banner kept off both streams
(``--verbose`` shows it), ``rbrdf-fit cdf --time-limit`` bounding the whole run, a stdout closed
by its reader (exit 141, no traceback), an unknown flag named with the closest one and the
sub-command's help, and the "nothing written" verdict of an infeasible fit on stderr."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lab.analytic import lambert
from tests.hostile import glossy_merl, lambert_merl, run

ROOT = Path(__file__).resolve().parents[1]
SMALL = ["--n-v", "8", "--n-t", "8", "--n-p", "8"]


@pytest.fixture(scope="module")
def merl(tmp_path_factory):
    return lambert_merl(tmp_path_factory.mktemp("input") / "lambert.binary")


@pytest.fixture(scope="module")
def glossy(tmp_path_factory):
    return glossy_merl(tmp_path_factory.mktemp("input") / "glossy.binary")


def _recorder():
    calls = []
    return calls, lambda stage, done, total: calls.append((stage, done, total))


def _check_counts(calls):
    """Every call is (str, int, int) with 0 <= done <= total, and within a stage the counts
    never go down."""
    assert calls
    last = {}
    for stage, done, total in calls:
        assert isinstance(stage, str) and isinstance(done, int) and isinstance(total, int)
        assert 0 <= done <= total, (stage, done, total)
        assert done >= last.get(stage, 0) or done == 0, (stage, done, last)
        last[stage] = done


# --- the callback of the Python API ------------------------------------------------------------
def test_fit_cdf_calls_progress_with_increasing_counts():
    from fit.sampling.cdf_file import fit_cdf

    calls, cb = _recorder()
    fit_cdf(lambert((0.5, 0.5, 0.5)), table_params=dict(n_v=8, n_t=8, n_p=8),
            pieces_kw=dict(gate_samples=256, gate_recheck=None), progress=cb)
    _check_counts(calls)
    stages = [s for s, _, _ in calls]
    assert stages[0] == "tabulating the CDFs" and ("tabulating the CDFs", 8, 8) in calls
    gate = [c for c in calls if c[0].startswith("variance gate")]
    assert gate[0][1] == 0 and gate[-1][1:] == (8, 8)


def test_fit_brdf_calls_progress_per_piece_and_channel(glossy):
    from fit.formats import load_measured
    from fit.rational.brdf_fit import fit_brdf

    calls, cb = _recorder()
    fit_brdf(load_measured(glossy), tol=0.5, core_theta_d_deg=78.5, max_degree=2, max_den_degree=1,
             progress=cb)
    _check_counts(calls)
    assert calls[:2] == [("projecting", 0, 1), ("projecting", 1, 1)]
    assert calls[2] == ("fitting theta_d 0-78.5", 0, 3)
    assert any(s.startswith("fitting theta_d 0-78.5") and d == t == 3 for s, d, t in calls), calls


def test_fit_samples_calls_progress_per_function():
    from fit.rational.fit3d import fit_samples

    rng = np.random.default_rng(1)
    X = rng.random((400, 3)) * [1.2, 1.2, np.pi]
    rho = np.repeat((0.3 + 0.1 * np.cos(X[:, :1])), 3, axis=1)
    calls, cb = _recorder()
    fit_samples(X, rho, degrees=(1, 0), theta_h_edges=[0.6], tol=0.2, ladder_steps=2, progress=cb)
    _check_counts(calls)
    assert calls[0] == ("3-D fit", 0, 6) and calls[-1] == ("3-D fit", 6, 6)
    assert [d for _, d, _ in calls] == list(range(7))


# --- the command line's progress on stderr -------------------------------------------------------
def test_progress_lines_on_stderr_when_not_a_terminal(capsys, merl, tmp_path, monkeypatch):
    """Not a terminal (pytest's capture): one line per stage on stderr, none on stdout;
    ``--no-progress`` silences them."""
    import fit.progress

    monkeypatch.setattr(fit.progress, "MIN_SECONDS", 0.0)   # report even the short stages
    rc, out, err = run(capsys, ["cdf", merl, "--out", tmp_path / "c.json", *SMALL, "--table-only"])
    assert rc == 0, err
    lines = err.splitlines()
    assert any(ln.startswith("rbrdf-fit cdf: tabulating the CDFs: ") for ln in lines), err
    assert len([ln for ln in lines if "tabulating the CDFs" in ln]) == 1       # one line per stage
    assert "tabulating" not in out and "wrote" in out
    rc, out, err = run(capsys, ["cdf", merl, "--out", tmp_path / "c.json", *SMALL, "--table-only",
                                "--no-progress"])
    assert rc == 0 and err == ""


def test_cli_progress_estimate_line():
    """The line of a stage states the steps done and an estimate of the time left."""
    import io

    from fit.progress import CLIProgress

    s = io.StringIO()
    p = CLIProgress("rbrdf-fit cdf", stream=s, min_seconds=0.0)
    p("gate", 0, 4)
    time.sleep(0.01)
    p("gate", 1, 4)
    p("gate", 2, 4)
    line, = s.getvalue().splitlines()
    assert line.startswith("rbrdf-fit cdf: gate: 1/4 after ") and line.endswith(" s left")


# --- HiGHS stays quiet ---------------------------------------------------------------------------
def test_highs_banner_absent_unless_verbose(capfd, glossy, tmp_path, monkeypatch):
    """A small fit prints no HiGHS banner on either stream (checked at the file descriptors,
    where HiGHS's C++ code writes); ``--verbose`` shows HiGHS's output."""
    from fit.cli import main
    from fit.rational import lp

    # (the fit's own inverse CDFs bounded to 1 s: their variance gate takes a minute otherwise)
    argv = ["brdf", str(glossy), "--out", str(tmp_path / "g.json"), "--tol", "0.5", "--max-degree", "2",
            "--max-den-degree", "1", "--core-theta-d", "78.5", "--sampler-time-limit", "1"]
    capfd.readouterr()
    main(argv)
    out, err = capfd.readouterr()
    assert "HiGHS" not in out and "HiGHS" not in err, (out, err)
    monkeypatch.setattr(lp, "_VERBOSE", False)      # restored after the test
    main(argv + ["--verbose", "--no-sampler"])        # the fit's LPs (no sampler to make again)
    out, _ = capfd.readouterr()
    assert "Running HiGHS" in out


# --- --time-limit bounds the whole command -------------------------------------------------------
def test_time_limit_bounds_the_pieces_layout():
    """A deadline reached during the variance gate sends the rows not yet checked to the table,
    says so, and ends the call near the limit (each row here costs >= 0.3 s, the table 0.3 s:
    unbounded, the call would take >= 2.7 s)."""
    from fit.sampling.cdf_file import fit_cdf

    base = lambert((0.5, 0.5, 0.5))

    def slow(wi, wo):
        time.sleep(0.15)
        return base(wi, wo)

    t0 = time.perf_counter()
    fit = fit_cdf(slow, table_params=dict(n_v=8, n_t=8, n_p=8), time_limit_s=1.2,
                  pieces_kw=dict(gate_samples=256, gate_recheck=None))
    dt = time.perf_counter() - t0
    rows = fit.fit_info["rows"]
    late = [r for r in rows if r.get("reason") == "time limit reached"]
    assert fit.fit_info["time_limit_reached"] and 0 < len(late) < 8
    assert "time limit reached" in fit.reason
    assert dt < 1.2 + 1.0, dt


def test_cdf_time_limit_cli_says_so(capsys, merl, tmp_path):
    """``rbrdf-fit cdf --time-limit`` counts from the start of the command: a limit shorter
    than reading and tabulating leaves every row to the table, and the run says so."""
    out_file = tmp_path / "c.json"
    rc, out, err = run(capsys, ["cdf", merl, "--out", out_file, *SMALL, "--time-limit", "0.001"])
    assert rc == 0, err
    assert "time limit 0.001 s reached" in out and "FALLBACK" in out
    d = json.loads(out_file.read_text())
    assert d["fallback"] is True and "time limit reached" in d["reason"]


# --- a stdout closed by its reader ---------------------------------------------------------------
def test_broken_pipe_ends_quietly(merl):
    """``rbrdf-fit info FILE | head -0``: the reader is gone before the first line; the command
    ends with status 141 (as killed by SIGPIPE) and nothing on stderr."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-m", "fit.cli", "info", str(merl)], cwd=ROOT, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()                               # before the command has printed anything
    err = p.stderr.read().decode()
    rc = p.wait(timeout=120)
    assert rc == 141 and err == "", (rc, err)


# --- unknown flags -------------------------------------------------------------------------------
def test_unknown_flag_names_the_subcommand_and_the_closest_flag(capsys):
    rc, out, err = run(capsys, ["brdf", "x.binary", "--out", "x.json", "--tolerance", "0.05"])
    assert rc == 2 and out == ""
    assert err == ("rbrdf-fit brdf: error: unrecognized argument --tolerance (did you mean --tol?); "
                   "see 'rbrdf-fit brdf --help'\n")
    rc, _, err = run(capsys, ["cdf", "x.binary", "--out", "x.json", "--time-limt=3"])
    assert rc == 2 and "(did you mean --time-limit?); see 'rbrdf-fit cdf --help'" in err
    assert len(err.splitlines()) == 1


def test_unknown_flag_named_before_the_error_it_causes(capsys):
    """A mistyped required flag is named, not the "required" error it leads to; abbreviations
    argparse accepts and negative numbers are not unknown flags."""
    rc, out, err = run(capsys, ["brdf", "x.binary", "--output", "x.json"])
    assert rc == 2 and out == ""
    assert err == ("rbrdf-fit brdf: error: unrecognized argument --output (did you mean --out?); "
                   "see 'rbrdf-fit brdf --help'\n")
    rc, _, err = run(capsys, ["brdf", "x.binary", "--to", "0.05"])
    assert rc == 2 and "the following arguments are required: --out" in err and "unrecognized" not in err
    rc, _, err = run(capsys, ["cdf", "x.binary", "--n-v", "-3"])
    assert rc == 2 and "unrecognized" not in err


def test_unknown_render_flag(capsys):
    from warp_rbrdf.cli import main as rbrdf

    capsys.readouterr()
    rc = rbrdf(["render", "--spp-count", "4"])
    out, err = capsys.readouterr()
    assert rc == 2 and out == ""
    assert err == ("rbrdf render: error: unrecognized argument --spp-count (did you mean --spp?); "
                   "see 'rbrdf render --help'\n")


# --- an infeasible fit: the verdict on stderr ----------------------------------------------------
def test_infeasible_brdf_verdict_on_stderr(capsys, glossy, tmp_path):
    rc, out, err = run(capsys, ["brdf", glossy, "--out", tmp_path / "g.json", "--tol", "0.01",
                                "--max-degree", "1", "--max-den-degree", "0", "--core-theta-d", "78.5"])
    assert rc == 1 and not (tmp_path / "g.json").exists()
    line, = err.splitlines()
    assert line.startswith("rbrdf-fit brdf: ") and "nothing written" in line
    assert "theta_d deg" in out and "nothing written" not in out


# --- rbrdf render's setup ------------------------------------------------------------------------
def test_render_setup_reports_its_stages():
    """A Renderer tells its progress callback each setup stage (materials counted up to their
    number, geometry, environment map) and the kernel load."""
    from warp_rbrdf.defaults import default_scene
    from warp_rbrdf.renderer import Renderer

    calls = []
    scene = default_scene()
    r = Renderer(scene, progress=lambda s, d, t: calls.append((s, d, t)))
    r.compile()
    stages = [c[0] for c in calls]
    for want in ("loading materials", "building the geometry", "environment map", "loading the render kernel"):
        assert want in stages, (want, stages)
    loads = [(d, t) for s, d, t in calls if s == "loading materials"]
    n = len({sh.material for sh in scene.shapes})
    assert loads[0] == (0, n) and loads[-1] == (n, n)
    assert [d for d, _ in loads] == sorted(d for d, _ in loads)
