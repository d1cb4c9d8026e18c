"""Hostile command lines for ``rbrdf-fit`` (issue 22): every flag of every sub-command given an
out-of-range, non-finite or malformed value, every output path given a place it cannot be
written to, and runs that fail after they started, with existing outputs in place.

Each case asserts the project principle: exit status 2 (1 for a fit that misses its tolerance),
exactly one stderr line naming the flag or the path, no traceback or warning, nothing printed
on stdout, and every existing file unchanged with no partial or temporary file left behind.
Flags and output paths are checked before the input is read, so these cases take
milliseconds. ``CLASSES`` as in test_hostile_fit_files.py.
"""
from __future__ import annotations

import os

import pytest
from hostile import (
    CLASSES,
    assert_bad_input,
    assert_unchanged,
    glossy_merl,
    lambert_merl,
    run,
    small_cdf_dict,
    snapshot,
    write_json,
)


#: the parser built once for the module's in-process runs (conftest.fit_parser_once)
pytestmark = pytest.mark.usefixtures("fit_parser_once")


@pytest.fixture(scope="module")
def merl(tmp_path_factory):
    """A valid MERL file, outside the folders whose contents the cases check."""
    return lambert_merl(tmp_path_factory.mktemp("input") / "lambert.binary")


@pytest.fixture(scope="module")
def glossy(tmp_path_factory):
    return glossy_merl(tmp_path_factory.mktemp("input") / "glossy.binary")


@pytest.fixture(scope="module")
def cdf_json(tmp_path_factory):
    return write_json(tmp_path_factory.mktemp("input") / "small_cdf.json", small_cdf_dict())


@pytest.fixture
def work(tmp_path):
    """An output folder with an existing file of each kind the commands write."""
    (tmp_path / "old.json").write_text('{"keep": "me"}\n')
    (tmp_path / "old.npz").write_bytes(b"old npz bytes")
    (tmp_path / "plots").mkdir()
    (tmp_path / "plots" / "lambert_mean.png").write_bytes(b"old png")
    return tmp_path


# ----------------------------------------------------------------------------------------------
# Flags: refused by the parser (one line naming the flag), before anything is read or written
# ----------------------------------------------------------------------------------------------
BRDF = ["brdf", "{merl}", "--out", "{work}/old.json"]
PROJECT = ["project", "{merl}", "--out", "{work}/old.npz"]
PLOT = ["plot", "{merl}", "--out", "{work}/plots"]
CDF = ["cdf", "{merl}", "--out", "{work}/old.json"]
PLOT_CDF = ["plot-cdf", "{merl}", "--out", "{work}/plots"]

FLAG_CASES = [
    # (id, class, base command, extra arguments, text the error must hold)
    ("tol-0", "traceback", BRDF, ["--tol", "0"], "--tol"),
    ("tol-negative", "silent", BRDF, ["--tol", "-0.1"], "--tol"),
    ("tol-2", "silent", BRDF, ["--tol", "2"], "--tol"),
    ("tol-nan", "unclear", BRDF, ["--tol", "nan"], "--tol"),
    ("tol-inf", "unclear", BRDF, ["--tol", "inf"], "--tol"),
    ("tol-text", "traceback", BRDF, ["--tol", "five"], "--tol"),
    ("tol-tiny", "hang", BRDF, ["--tol", "1e-12"], "--tol"),
    ("tol-empty", "traceback", BRDF, ["--tol", ""], "--tol"),
    ("max-degree-negative", "lost", BRDF, ["--max-degree", "-1"], "--max-degree"),
    ("max-degree-1e5", "hang", BRDF, ["--max-degree", "100000"], "--max-degree"),
    ("max-degree-21", "hang", BRDF, ["--max-degree", "21"], "--max-degree"),
    ("max-degree-float", "traceback", BRDF, ["--max-degree", "2.5"], "--max-degree"),
    ("max-den-degree-negative", "traceback", BRDF, ["--max-den-degree", "-3"], "--max-den-degree"),
    ("max-den-degree-1e9", "memory", BRDF, ["--max-den-degree", "1000000000"], "--max-den-degree"),
    ("max-theta-h-pieces-99", "memory", BRDF, ["--max-theta-h-pieces", "99"], "--max-theta-h-pieces"),
    ("floor-frac-negative", "silent", BRDF, ["--floor-frac", "-1"], "--floor-frac"),
    ("floor-frac-nan", "unclear", BRDF, ["--floor-frac", "nan"], "--floor-frac"),
    ("floor-frac-huge", "silent", BRDF, ["--floor-frac", "1e9"], "--floor-frac"),
    ("core-negative", "silent", BRDF, ["--core-theta-d", "-5"], "--core-theta-d"),
    ("core-zero", "traceback", BRDF, ["--core-theta-d", "0"], "--core-theta-d"),
    ("core-90", "silent", BRDF, ["--core-theta-d", "90"], "--core-theta-d"),
    ("core-78.6", "silent", BRDF, ["--core-theta-d", "78.6"], "--core-theta-d"),
    ("core-nan", "unclear", BRDF, ["--core-theta-d", "nan"], "--core-theta-d"),
    ("core-text", "traceback", BRDF, ["--core-theta-d", "automatic"], "--core-theta-d"),
    ("intervals", "traceback", BRDF, ["--intervals", "loose"], "--intervals"),
    ("band-intervals", "traceback", BRDF, ["--band-intervals", ""], "--band-intervals"),
    ("theta-h", "traceback", BRDF, ["--theta-h", "cube"], "--theta-h"),
    ("value", "traceback", BRDF, ["--value", "exp"], "--value"),
    ("brdf-unknown-flag", "traceback", BRDF, ["--tolerance", "0.1"], "--tolerance"),
    ("brdf-no-out", "traceback", ["brdf", "{merl}"], [], "--out"),
    ("brdf-no-file", "traceback", ["brdf", "--out", "{work}/x.json"], [], "file"),
    ("statistic", "traceback", PROJECT, ["--statistic", "max"], "--statistic"),
    ("cutoff-negative", "silent", PROJECT, ["--grazing-cutoff", "-10"], "--grazing-cutoff"),
    ("cutoff-zero", "silent", PROJECT, ["--grazing-cutoff", "0"], "--grazing-cutoff"),
    ("cutoff-91", "silent", PROJECT, ["--grazing-cutoff", "91"], "--grazing-cutoff"),
    ("cutoff-nan", "silent", PROJECT, ["--grazing-cutoff", "nan"], "--grazing-cutoff"),
    ("grazing-angle", "traceback", PROJECT, ["--grazing-angle", "theta_x"], "--grazing-angle"),
    ("plot-cutoff-inf", "silent", PLOT, ["--grazing-cutoff", "inf"], "--grazing-cutoff"),
    ("plot-statistic", "traceback", PLOT, ["--statistic", ""], "--statistic"),
    ("n-v-0", "traceback", CDF, ["--n-v", "0"], "--n-v"),
    ("n-v-1", "traceback", CDF, ["--n-v", "1"], "--n-v"),
    ("n-v-negative", "traceback", CDF, ["--n-v", "-4"], "--n-v"),
    ("n-v-1e9", "memory", CDF, ["--n-v", "1000000000"], "--n-v"),
    ("n-v-text", "traceback", CDF, ["--n-v", "many"], "--n-v"),
    ("n-t-1", "traceback", CDF, ["--n-t", "1"], "--n-t"),
    ("n-t-1e5", "memory", CDF, ["--n-t", "100000"], "--n-t"),
    ("n-p-0", "traceback", CDF, ["--n-p", "0"], "--n-p"),
    ("n-p-huge", "memory", CDF, ["--n-p", "99999999"], "--n-p"),
    ("cells-product", "memory", CDF, ["--n-v", "128", "--n-t", "512", "--n-p", "512"], "--n-v/--n-t/--n-p"),
    ("table-memory", "memory", CDF, ["--n-v", "8", "--n-t", "512", "--n-p", "512", "--table-only"],
     "--n-v/--n-t/--n-p"),
    ("eps-0", "traceback", CDF, ["--eps", "0"], "--eps"),
    ("eps-negative", "silent", CDF, ["--eps", "-0.1"], "--eps"),
    ("eps-1.5", "silent", CDF, ["--eps", "1.5"], "--eps"),
    ("eps-nan", "unclear", CDF, ["--eps", "nan"], "--eps"),
    ("refinements-negative", "silent", CDF, ["--refinements", "-1"], "--refinements"),
    ("refinements-1e6", "hang", CDF, ["--refinements", "1000000"], "--refinements"),
    ("time-limit-negative", "silent", CDF, ["--time-limit", "-5"], "--time-limit"),
    ("time-limit-nan", "silent", CDF, ["--time-limit", "nan"], "--time-limit"),
    ("time-limit-inf", "hang", CDF, ["--time-limit", "inf"], "--time-limit"),
    ("layout", "traceback", CDF, ["--layout", "rows"], "--layout"),
    ("incident", "traceback", CDF, ["--incident", "both"], "--incident"),
    ("plot-cdf-n-t", "memory", PLOT_CDF, ["--n-t", "1000000"], "--n-t"),
    ("plot-cdf-eps", "silent", PLOT_CDF, ["--eps", "7"], "--eps"),
    ("prefix-empty", "traceback", PLOT_CDF, ["--prefix", ""], "--prefix"),
    ("prefix-slash", "silent", PLOT_CDF, ["--prefix", "../escape"], "--prefix"),
    ("prefix-dotdot", "silent", PLOT_CDF, ["--prefix", ".."], "--prefix"),
    ("prefix-control", "unclear", PLOT_CDF, ["--prefix", "a\nb"], "--prefix"),
    ("no-command", "traceback", [], [], "COMMAND"),
    ("unknown-command", "traceback", ["fit"], [], "fit"),
    ("info-no-file", "traceback", ["info"], [], "file"),
]


def _argv(base, extra, **kw):
    return [a.format(**kw) for a in base] + list(extra)


@pytest.mark.parametrize("name, klass, base, extra, flag", FLAG_CASES, ids=[c[0] for c in FLAG_CASES])
def test_bad_flag_values(capsys, merl, work, name, klass, base, extra, flag):
    before = snapshot(work)
    rc, _, err = run(capsys, _argv(base, extra, merl=merl, work=work))
    assert_bad_input(rc, err, flag, out="")
    assert_unchanged(before, work)


# ----------------------------------------------------------------------------------------------
# Output paths: checked before the input is read
# ----------------------------------------------------------------------------------------------
def _fifo(work):
    os.mkfifo(work / "pipe.json")
    return work / "pipe.json"


def _file(work, name="afile"):
    (work / name).write_text("x")
    return work / name


OUT_CASES = [
    # (id, class, command, path maker, text of the error)
    ("brdf-out-is-dir", "traceback", "brdf", lambda w: w / "plots", "is a folder"),
    ("brdf-parent-is-file", "traceback", "brdf", lambda w: _file(w) / "fit.json", "is a file, not a folder"),
    ("brdf-grandparent-is-file", "traceback", "brdf", lambda w: _file(w) / "a" / "b" / "fit.json", "not a folder"),
    ("brdf-wrong-suffix", "silent", "brdf", lambda w: w / "fit.bsdf", "ending with .json"),
    ("brdf-no-suffix", "silent", "brdf", lambda w: w / "fit", "ending with .json"),
    ("brdf-out-fifo", "hang", "brdf", _fifo, "named pipe"),
    ("brdf-out-empty", "traceback", "brdf", lambda w: "", "empty"),
    ("brdf-name-too-long", "traceback", "brdf", lambda w: w / ("n" * 300 + ".json"), "longer than 255"),
    ("brdf-out-dotdot", "traceback", "brdf", lambda w: w / "..", "names a folder"),
    ("brdf-out-dev", "lost", "brdf", lambda w: _devnull(w, "dev.json"), "is a device"),
    ("cdf-out-is-dir", "traceback", "cdf", lambda w: w / "plots", "is a folder"),
    ("cdf-parent-is-file", "traceback", "cdf", lambda w: _file(w) / "c.json", "not a folder"),
    ("cdf-wrong-suffix", "silent", "cdf", lambda w: w / "c.npz", "ending with .json"),
    ("project-out-is-dir", "traceback", "project", lambda w: w / "plots", "is a folder"),
    ("project-parent-is-file", "traceback", "project", lambda w: _file(w) / "p.npz", "not a folder"),
    ("project-wrong-suffix", "silent", "project", lambda w: w / "p.json", "ending with .npz"),
    ("project-no-suffix", "silent", "project", lambda w: w / "p", "ending with .npz"),
    ("plot-out-is-file", "traceback", "plot", lambda w: _file(w, "plots.png"), "is a file, not a folder"),
    ("plot-parent-is-file", "traceback", "plot", lambda w: _file(w) / "plots", "not a folder"),
    ("plot-out-fifo", "traceback", "plot", _fifo, "named pipe"),
    ("plot-cdf-out-is-file", "traceback", "plot-cdf", lambda w: _file(w, "cdfplots"), "is a file, not a folder"),
    ("plot-cdf-parent-is-file", "traceback", "plot-cdf", lambda w: _file(w) / "x" / "y", "not a folder"),
]


def _devnull(work, name):
    (work / name).symlink_to("/dev/null")
    return work / name


@pytest.mark.parametrize("name, klass, command, make, fragment", OUT_CASES, ids=[c[0] for c in OUT_CASES])
def test_bad_output_paths(capsys, merl, work, name, klass, command, make, fragment):
    out = make(work)
    before = snapshot(work)
    rc, _, err = run(capsys, [command, merl, "--out", out])
    assert_bad_input(rc, err, "--out", fragment, out="")
    assert_unchanged(before, work)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_folder(capsys, merl, work):
    ro = work / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        rc, _, err = run(capsys, ["project", merl, "--out", ro / "p.npz"])
        assert_bad_input(rc, err, "not writable", out="")
    finally:
        ro.chmod(0o700)


# ----------------------------------------------------------------------------------------------
# Runs that fail after they started: nothing lost, nothing half-written
# ----------------------------------------------------------------------------------------------
LOST_CASES = []


def lost(klass):
    def deco(fn):
        LOST_CASES.append((fn.__name__, klass))
        return fn
    return deco


@lost("lost")
def test_infeasible_fit_keeps_the_existing_file(capsys, glossy, work):
    """A fit that misses its tolerance exits 1 and writes nothing: the existing fit stays."""
    before = snapshot(work)
    rc, out, err = run(capsys, ["brdf", glossy, "--out", work / "old.json", "--tol", "0.01",
                                "--max-degree", "1", "--max-den-degree", "0", "--core-theta-d", "78.5"])
    assert rc == 1 and len(err.splitlines()) == 1       # the verdict on stderr, the table on stdout
    assert "nothing written" in err and "--allow-infeasible" in err and "nothing written" not in out
    assert_unchanged(before, work)
    # with --allow-infeasible the flagged fit replaces it, whole (no sampler: a flagged fit's is
    # written by tests/test_cli_fit.py::test_brdf_2d_flagged_fit_carries_what_the_renderer_shows)
    rc, _, err = run(capsys, ["brdf", glossy, "--out", work / "old.json", "--tol", "0.01",
                                "--max-degree", "1", "--max-den-degree", "0", "--core-theta-d", "78.5",
                                "--allow-infeasible", "--no-sampler"])
    assert rc == 0 and '"valid": false' in (work / "old.json").read_text()
    from fit.rational.coefficient_file import load

    load(work / "old.json")
    assert set(snapshot(work)) == set(before)


@lost("lost")
def test_bad_input_keeps_existing_outputs(capsys, work):
    bad = work.parent / f"{work.name}_bad.binary"
    bad.write_bytes(b"\x00" * 100)
    before = snapshot(work)
    for argv in (["project", bad, "--out", work / "old.npz"], ["brdf", bad, "--out", work / "old.json"],
                 ["cdf", bad, "--out", work / "old.json"], ["plot", bad, "--out", work / "plots"],
                 ["plot-cdf", bad, "--out", work / "plots"], ["plot", bad, "--out", work / "new" / "deep"]):
        rc, _, err = run(capsys, argv)
        assert_bad_input(rc, err, bad, out="")
        assert_unchanged(before, work)


@lost("silent")
def test_cutoff_that_keeps_nothing_is_refused(capsys, merl, work):
    """A cut-off that drops every sample used to write an all-NaN projection with exit 0."""
    before = snapshot(work)
    rc, _, err = run(capsys, ["project", merl, "--out", work / "old.npz", "--grazing-angle", "theta_d",
                                "--grazing-cutoff", "0.1"])
    assert_bad_input(rc, err, "--grazing-cutoff", "keeps no sample", out="")
    assert_unchanged(before, work)


@lost("lost")
def test_plot_failing_at_its_second_figure_leaves_nothing(capsys, merl, work, monkeypatch):
    import fit.outputs

    calls = []
    real = fit.outputs.OutputSet.stage

    def stage(self, final):
        calls.append(final)
        if len(calls) == 2:
            raise fit.outputs.OutputError(final, "simulated: disk full", "--out")
        return real(self, final)

    monkeypatch.setattr(fit.outputs.OutputSet, "stage", stage)
    before = snapshot(work)
    rc, _, err = run(capsys, ["plot", merl, "--out", work / "plots"])
    assert_bad_input(rc, err, "disk full", out="")
    assert_unchanged(before, work)
    # a new folder is removed again
    calls.clear()
    rc, _, err = run(capsys, ["plot", merl, "--out", work / "fresh" / "plots"])
    assert rc == 2
    assert_unchanged(before, work)


@lost("lost")
def test_disk_full_while_writing_keeps_the_old_file(capsys, merl, work, monkeypatch):
    import builtins

    import fit.atomic_files

    def full(path, mode="r", *a, **k):
        if "w" in mode:
            raise OSError(28, "No space left on device")
        return builtins.open(path, mode, *a, **k)

    monkeypatch.setattr(fit.atomic_files, "open", full, raising=False)
    before = snapshot(work)
    rc, _, err = run(capsys, ["cdf", merl, "--out", work / "old.json", "--table-only", "--n-v", "2",
                                "--n-t", "4", "--n-p", "4"])
    assert_bad_input(rc, err, "old.json", "No space left on device", out="")
    assert_unchanged(before, work)


@lost("lost")
def test_interrupt_leaves_nothing(capsys, merl, work, monkeypatch):
    import fit.cli.cdf

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(fit.cli.cdf, "plot_cdf", interrupted)
    before = snapshot(work)
    rc, _, err = run(capsys, ["plot-cdf", merl, "--out", work / "plots", "--n-v", "2", "--n-t", "4",
                                "--n-p", "4"])
    assert rc == 130 and len(err.splitlines()) == 1 and "no output written" in err
    assert_unchanged(before, work)


@lost("lost")
def test_successful_runs_replace_whole_files(capsys, merl, cdf_json, work):
    """The good paths still write: outputs are replaced whole, permissions as before, no
    temporary file left."""
    os.chmod(work / "old.npz", 0o640)
    rc, _, err = run(capsys, ["project", merl, "--out", work / "old.npz"])
    assert rc == 0 and err == ""
    from fit.projection.projected import ProjectedBRDF

    assert ProjectedBRDF.load(work / "old.npz").value.shape == (90, 90, 3)
    assert (os.stat(work / "old.npz").st_mode & 0o777) == 0o640
    rc, _, err = run(capsys, ["plot-cdf", cdf_json, "--out", work / "new" / "plots", "--prefix", "c"])
    assert rc == 0 and sorted(os.listdir(work / "new" / "plots")) == ["c_phi.png", "c_theta.png"]
    rc, _, err = run(capsys, ["cdf", cdf_json, "--out", work / "copy.json"])
    assert rc == 0
    assert not [f for f in os.listdir(work) if f.startswith(".")]


def test_help_is_not_an_error(capsys):
    rc, out, err = run(capsys, ["brdf", "--help"])
    assert rc == 0 and "--max-degree" in out and err == ""


def case_counts() -> dict:
    out = dict.fromkeys(CLASSES, 0)
    for cases in (FLAG_CASES, OUT_CASES, LOST_CASES):
        for c in cases:
            out[c[1]] += 1
    return out
