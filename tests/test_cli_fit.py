"""rbrdf-fit info / project / plot on exact-layout MERL files, and one-line errors."""
import subprocess
import sys

import numpy as np
import pytest

from lab.analytic import glossy_lobe, lambert
from fit.cli import main
from fit.formats.measured import MeasuredBRDF
from fit.projection.projected import ProjectedBRDF
from fit.formats.merl import write_merl


@pytest.fixture(scope="module")
def lambert_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("cli") / "lambert.binary"
    write_merl(MeasuredBRDF.from_function(lambert((0.8, 0.5, 0.2))), path)
    return path


def test_info_reports_albedo(lambert_file, capsys):
    assert main(["info", str(lambert_file)]) == 0
    out = capsys.readouterr().out
    assert "90 x 90 x 180" in out
    line = [l for l in out.splitlines() if l.startswith("albedo")][0]
    r, g, b = (float(line.split(ch)[1].split()[0]) for ch in (" R ", " G ", " B "))
    assert (r, g, b) == pytest.approx((0.8, 0.5, 0.2), abs=2e-3)


def test_project_writes_npz(lambert_file, tmp_path, capsys):
    out = tmp_path / "sub" / "p.npz"
    assert main(["project", str(lambert_file), "--out", str(out), "--statistic", "mean",
                 "--grazing-cutoff", "80"]) == 0
    p = ProjectedBRDF.load(out)
    assert p.statistic == "mean" and p.grazing_cutoff_deg == 80.0
    assert np.nanmax(np.abs(p.value[..., 1] - 0.5 / np.pi)) < 1e-12


def test_plot_writes_pngs(tmp_path):
    path = tmp_path / "glossy.binary"
    write_merl(MeasuredBRDF.from_function(glossy_lobe(), name="glossy"), path)
    assert main(["plot", str(path), "--out", str(tmp_path / "plots")]) == 0
    pngs = sorted(p.name for p in (tmp_path / "plots").glob("*.png"))
    assert pngs == ["glossy_isolines.png", "glossy_mean.png", "glossy_variance.png"]
    for p in (tmp_path / "plots").glob("*.png"):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000


@pytest.mark.parametrize("content, message", [
    (b"\x01\x00\x00\x00" * 3 + b"\0" * 64, "wrong MERL header"),
    (np.array([90, 90, 180], "<i4").tobytes() + b"\0" * 100, "truncated MERL file"),
])
def test_cli_errors_are_one_line(tmp_path, capsys, content, message):
    path = tmp_path / "bad.binary"
    path.write_bytes(content)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and str(path) in err
    assert "Traceback" not in err


def test_cli_unknown_type_and_missing(tmp_path, capsys):
    assert main(["info", str(tmp_path / "nope.binary")]) == 2
    assert "file not found" in capsys.readouterr().err
    (tmp_path / "x.txt").write_text("hi")
    assert main(["info", str(tmp_path / "x.txt")]) == 2
    assert "unknown BRDF file type" in capsys.readouterr().err


def test_console_script_help():
    r = subprocess.run([sys.executable, "-m", "fit.cli", "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "info" in r.stdout and "project" in r.stdout and "plot" in r.stdout


def test_fit_package_does_not_import_warp():
    """Every module of the fitter (sub-packages included) imports without pulling in Warp."""
    code = ("import sys, pkgutil, importlib, fit; "
            "[importlib.import_module(m.name) for m in pkgutil.walk_packages(fit.__path__, 'fit.')]; "
            "print('warp' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "False"


def test_cdf_table_only_writes_a_flagged_table(lambert_file, tmp_path, capsys):
    from fit.sampling.cdf_file import load

    out = tmp_path / "l_cdf.json"
    assert main(["cdf", str(lambert_file), "--table-only", "--n-v", "4", "--n-t", "16", "--n-p", "16",
                 "--out", str(out)]) == 0
    fit = load(out)
    assert fit.fallback and "--table-only" in fit.reason and fit.maps is None
    assert fit.table is not None and fit.table_params["n_t"] == 16


def test_cdf_of_an_rgl_file_records_its_roles_and_a_scene_checks_them(tmp_path, capsys):
    """A table built from an RGL file depends on which direction is the tensors' theta_i: the
    file records it and a scene whose material has the other roles refuses it in one line."""
    from conftest import data_file

    from fit.sampling.cdf_file import load
    from warp_rbrdf.errors import SceneError
    from warp_rbrdf.renderer import Renderer
    from warp_rbrdf.scene import parse_scene

    src = data_file("rgl/paper_white_rgb.bsdf")
    out = tmp_path / "paper_cdf.json"
    assert main(["cdf", str(src), "--table-only", "--incident", "light", "--n-v", "4", "--n-t", "8",
                 "--n-p", "8", "--out", str(out)]) == 0
    assert load(out).source["incident"] == "light"
    text = (f'[materials.m]\ntype = "measured"\nfile = "{src}"\nsampler = "tabulated"\n'
            f'cdf = "{out}"\nincident = "{{}}"\n[[shapes]]\ntype = "sphere"\nmaterial = "m"\n')
    with pytest.raises(SceneError, match="built with incident = 'light', the material has 'view'"):
        Renderer(parse_scene(text.format("view"), path=tmp_path / "s.toml"))
    Renderer(parse_scene(text.format("light"), path=tmp_path / "s.toml"))   # same roles: accepted
