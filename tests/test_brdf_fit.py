"""BRDF fit: analytic glossy lobe in exact MERL layout, CLI, optional RGL material."""
import json
import os

import numpy as np
import pytest

from analytic import glossy_lobe
from conftest import RGL_MATERIALS, data_file
from fit.brdf_fit import THETA_D_MAX_DEG, channel_data, fit_brdf, project_for_fit
from fit.coefficients import load
from fit.measured import MeasuredBRDF
from fit.merl import write_merl


@pytest.fixture(scope="module")
def lobe_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("fit") / "lobe.binary"
    write_merl(MeasuredBRDF.from_function(glossy_lobe(exponent=30.0)), path)
    return path


@pytest.fixture(scope="module")
def lobe_fit(lobe_file):
    from fit.io import load_measured

    return fit_brdf(load_measured(lobe_file), tol=0.05, intervals="tol", max_degree=8, max_den_degree=4)


def test_glossy_lobe_fits_at_5_percent_with_guarantee(lobe_fit, lobe_file):
    from fit.io import load_measured

    assert lobe_fit.valid
    p = project_for_fit(load_measured(lobe_file))
    for c in range(3):
        d = channel_data(p, c, 0.05, "tol")
        fit = lobe_fit.model(d.X)[:, c]
        assert np.all((fit >= d.lower) & (fit <= d.upper))          # every cluster inside
        big = d.y * 0.05 >= d.abs_floor
        assert np.max(np.abs(fit[big] / d.y[big] - 1)) <= 0.05 + 1e-12
        assert lobe_fit.results[c].certificate.certified
    assert lobe_fit.model.n_coefficients < 3 * 60


def test_model_policy_and_file(lobe_fit, tmp_path):
    m = lobe_fit.model
    # clamped beyond the theta_d cut-off, never negative, 0 below the horizon
    cut = np.deg2rad(THETA_D_MAX_DEG)
    assert np.allclose(m.evaluate_brdf(0.2, cut + 0.1), m.evaluate_brdf(0.2, cut))
    assert np.all(m.evaluate_brdf(np.linspace(0, 1.57, 50), np.linspace(0, 1.57, 50)) >= 0)
    assert np.all(m.evaluate([0, 0, 1.0], [0.3, 0, -0.5]) == 0)
    path = tmp_path / "lobe.json"
    m.save(path)
    m2 = load(path)
    th = np.linspace(0, 1.5, 9)
    assert np.array_equal(m2.evaluate_brdf(th, th[::-1]), m.evaluate_brdf(th, th[::-1]))
    assert path.stat().st_size < 100_000
    d = json.loads(path.read_text())
    assert d["domain_policy"]["outside"] == "clamp" and d["fit"]["tolerance"] == 0.05


def test_cli_brdf(lobe_file, tmp_path, capsys):
    from fit.cli import main

    out = tmp_path / "lobe.json"
    rc = main(["brdf", str(lobe_file), "--tol", "0.1", "--intervals", "tol", "--max-degree", "6",
               "--max-den-degree", "3", "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0 and out.exists()
    assert "coefs" in text and "guaranteed" in text


def test_cli_brdf_bad_file(tmp_path, capsys):
    from fit.cli import main

    bad = tmp_path / "x.binary"
    bad.write_bytes(b"123")
    assert main(["brdf", str(bad), "--out", str(tmp_path / "o.json")]) == 2
    assert "x.binary" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize("material", ["paper_white_rgb"])
def test_rgl_material_fits_at_5_percent(material):
    from fit.io import load_measured

    b = load_measured(data_file(f"rgl/{material}.bsdf"))
    fit = fit_brdf(b, tol=0.05)
    assert fit.valid


def test_shipped_coefficient_files_load():
    from pathlib import Path

    folder = Path(__file__).resolve().parents[1] / "warp_rbrdf" / "data"
    files = sorted(folder.glob("*.json"))
    assert {f.name for f in files} >= {"paper_white_rgb.json", "satin_rosaline_rgb.json"}
    for f in files:
        m = load(f)
        assert m.kind == "brdf" and all(m.fit_info["valid"])
        assert f.stat().st_size < 100_000
        v = m.evaluate_brdf(np.linspace(0, 1.5, 20), np.linspace(0, 1.5, 20))
        assert np.all(np.isfinite(v)) and np.all(v >= 0)
