"""BRDF fit: analytic glossy lobe in exact MERL layout, CLI, optional RGL material."""
import json

import numpy as np
import pytest

from conftest import data_file
from lab.analytic import glossy_lobe
from fit.formats.measured import MeasuredBRDF
from fit.formats.merl import write_merl
from fit.rational.brdf_fit import THETA_D_MAX_DEG, channel_data, fit_brdf, project_for_fit, white_sky_albedo
from fit.rational.coefficient_file import load, save, to_dict


@pytest.fixture(scope="module")
def lobe_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("fit") / "lobe.binary"
    write_merl(MeasuredBRDF.from_function(glossy_lobe(exponent=30.0)), path)
    return path


@pytest.fixture(scope="module")
def lobe_fit(lobe_file):
    from fit.formats import load_measured

    return fit_brdf(load_measured(lobe_file), tol=0.05, intervals="tol", max_degree=8, max_den_degree=4)


def test_glossy_lobe_fits_at_5_percent_with_guarantee(lobe_fit, lobe_file):
    from fit.formats import load_measured

    assert lobe_fit.valid and lobe_fit.all_valid
    core = lobe_fit.pieces[0].theta_d_range_deg[1]
    assert core == 60.0                          # the largest automatic core is met
    p = project_for_fit(load_measured(lobe_file))
    for c in range(3):
        d = channel_data(p, c, 0.05, "tol", theta_d_range_deg=(0.0, core))
        fit = lobe_fit.model(d.X)[:, c]
        assert np.all((fit >= d.lower) & (fit <= d.upper))          # every cluster inside
        big = d.y * 0.05 >= d.abs_floor
        assert np.max(np.abs(fit[big] / d.y[big] - 1)) <= 0.05 + 1e-12
        assert lobe_fit.results[c].certificate.certified
    assert lobe_fit.model.n_coefficients < 2 * 3 * 60


def test_model_policy_and_file(lobe_fit, tmp_path):
    m = lobe_fit.model
    # clamped beyond the theta_d cut-off, never negative, 0 below the horizon
    cut = np.deg2rad(THETA_D_MAX_DEG)
    assert np.allclose(m.evaluate_brdf(0.2, cut + 0.1), m.evaluate_brdf(0.2, cut))
    assert np.all(m.evaluate_brdf(np.linspace(0, 1.57, 50), np.linspace(0, 1.57, 50)) >= 0)
    assert np.all(m.evaluate([0, 0, 1.0], [0.3, 0, -0.5]) == 0)
    path = tmp_path / "lobe.json"
    save(m, path)
    m2 = load(path)
    th = np.linspace(0, 1.5, 9)
    assert np.array_equal(m2.evaluate_brdf(th, th[::-1]), m.evaluate_brdf(th, th[::-1]))
    assert path.stat().st_size < 100_000
    d = json.loads(path.read_text())
    assert d["domain_policy"]["outside"] == "clamp" and d["fit"]["tolerance"] == 0.05
    assert d["version"] == 2 and d["split"]["edges"][1] == pytest.approx(np.deg2rad(60.0))
    assert d["domain_policy"]["guaranteed_theta_d_max_deg"] == 60.0
    assert [p["info"]["intervals"] for p in d["pieces"]] == ["tol", "tol"]       # the band: pure tolerance too
    assert all(p["info"]["guaranteed"] for p in d["pieces"])


def test_absolute_floor_is_the_luminance_lambertian(lobe_file, tmp_path):
    """A = albedo exactly for a Lambertian file; floor = tol * A_Y / pi in every channel."""
    from lab.analytic import lambert
    from fit.formats import load_measured

    path = tmp_path / "lambert.binary"
    write_merl(MeasuredBRDF.from_function(lambert((0.8, 0.5, 0.2))), path)
    a = white_sky_albedo(project_for_fit(load_measured(path)))
    np.testing.assert_allclose(a, [0.8, 0.5, 0.2], rtol=0.01)
    p = project_for_fit(load_measured(lobe_file))
    ay = float(np.array([0.2126, 0.7152, 0.0722]) @ white_sky_albedo(p))
    for c in range(3):
        assert channel_data(p, c, 0.05, "tol").abs_floor == pytest.approx(0.05 * ay / np.pi)


def test_single_function_over_the_whole_box(lobe_file):
    from fit.formats import load_measured

    fit = fit_brdf(load_measured(lobe_file), tol=0.05, core_theta_d_deg=THETA_D_MAX_DEG,
                   max_degree=8, max_den_degree=4)
    assert len(fit.pieces) == 1 and fit.valid
    assert to_dict(fit.model)["version"] == 1


def test_rough_grazing_band_is_flagged_not_hidden(tmp_path):
    """Clusters beyond theta_d = 60 deg alternate by +-30 % from bin to bin: no smooth function
    meets 5 % there. The core stays guaranteed; the band is a flagged best effort."""
    from fit.formats import load_measured
    from fit.formats.angles import directions_to_half_diff

    lobe = glossy_lobe(exponent=30.0)

    def rough(wi, wo):
        _, _, td, _ = directions_to_half_diff(wi, wo)
        jb = np.floor(np.rad2deg(td)).astype(int)
        bump = np.where(td > np.deg2rad(61.0), 1.0 + 0.3 * (-1.0) ** jb, 1.0)
        return lobe(wi, wo) * bump[..., None]

    path = tmp_path / "rough.binary"
    write_merl(MeasuredBRDF.from_function(rough), path)
    fit = fit_brdf(load_measured(path), tol=0.05, core_theta_d_deg=60.0, band_intervals="tol",
                   max_degree=6, max_den_degree=3)
    assert fit.valid and not fit.all_valid and not fit.pieces[1].valid
    d = to_dict(fit.model)
    assert d["pieces"][0]["info"]["guaranteed"] and not d["pieces"][1]["info"]["guaranteed"]
    assert d["pieces"][1]["info"]["max_interval_ratio"] > 1.0
    assert "NOT met" in d["domain_policy"]["guarantee"]


def test_cli_brdf(lobe_file, tmp_path, capsys):
    """The command's summary of a fit (no sampler: the command's own sampler is made by
    tests/test_progress.py::test_highs_banner_absent_unless_verbose and
    tests/test_cli_fit.py::test_brdf_2d_flagged_fit_carries_what_the_renderer_shows)."""
    from fit.cli import main

    out = tmp_path / "lobe.json"
    rc = main(["brdf", str(lobe_file), "--tol", "0.1", "--intervals", "tol", "--max-degree", "6",
               "--max-den-degree", "3", "--out", str(out), "--no-sampler"])
    text = capsys.readouterr().out
    assert rc == 0 and out.exists()
    assert "coefs" in text and "proved within its intervals at every cluster of theta_d <= 60 deg" in text
    assert "between the clusters proved" in text and "60-78.5" in text


def test_cli_brdf_bad_file(tmp_path, capsys):
    from fit.cli import main

    bad = tmp_path / "x.binary"
    bad.write_bytes(b"123")
    assert main(["brdf", str(bad), "--out", str(tmp_path / "o.json")]) == 2
    assert "x.binary" in capsys.readouterr().err


@pytest.mark.parametrize("material", [
    pytest.param("paper_white_rgb", marks=pytest.mark.extended),
    pytest.param("satin_rosaline_rgb", marks=pytest.mark.slow),
    pytest.param("colodur_napoli_4f_rgb", marks=pytest.mark.slow),
    pytest.param("vch_golden_yellow_rgb", marks=pytest.mark.slow),
    pytest.param("cc_ibiza_sunset_rgb", marks=pytest.mark.slow)])
def test_rgl_material_fits_at_5_percent(material):
    """Pure 5 % on the automatic core, verified cluster by cluster against the projection, on a
    real material at the default settings (the ``extended`` tier: paper_white; the others
    ``slow``). The default run checks the same on the analytic lobe
    (:func:`test_glossy_lobe_fits_at_5_percent_with_guarantee`)."""
    from fit.formats import load_measured

    b = load_measured(data_file(f"rgl/{material}.bsdf"))
    fit = fit_brdf(b, tol=0.05)
    assert fit.valid
    core = fit.pieces[0].theta_d_range_deg[1]
    assert core >= 40.0
    p = project_for_fit(b)
    for c in range(3):
        d = channel_data(p, c, 0.05, "tol", theta_d_range_deg=(0.0, core))
        f = fit.model(d.X)[:, c]
        assert np.all((f >= d.lower) & (f <= d.upper))
        assert fit.results[c].certificate.certified


@pytest.mark.slow
def test_sharp_clipped_peak_needs_the_theta_h_split():
    """cc_iris_purple_gem's red peak falls from 0.95 to exactly 0 within 3.5 deg of theta_h
    (clipped by the RGB conversion): without the theta_h split no core meets 5 % up to degrees
    (12, 6) and the fit says so; with the split at 5 deg the 40 deg core is guaranteed."""
    from fit.formats import load_measured

    b = load_measured(data_file("rgl/cc_iris_purple_gem_rgb.bsdf"))
    no_split = fit_brdf(b, tol=0.05, peak_split_deg=None)
    assert not no_split.valid and no_split.model.domain_policy["guaranteed_theta_d_max_deg"] is None
    fit = fit_brdf(b, tol=0.05)
    assert fit.valid and fit.core_theta_d_deg == 40.0
    assert [pc.theta_h_range_deg for pc in fit.core_pieces] == [(0.0, 5.0), (5.0, 90.0)]
    p = project_for_fit(b)
    for c in range(3):
        d = channel_data(p, c, 0.05, "tol", theta_d_range_deg=(0.0, 40.0))
        f = fit.model(d.X)[:, c]
        assert np.all((f >= d.lower) & (f <= d.upper))


@pytest.mark.slow
def test_glossy_felt_needs_the_rest_split():
    """acrylic_felt_pink: no core meets 5 % with the peak split alone (blue's (12, 6) function of
    theta_h 5-90 holds 95.7 % of its clusters); with that piece split at the midpoint of sqrt
    theta_h (34.4 deg) the 60 deg core is guaranteed with three theta_h pieces, fewer
    coefficients than the flagged best effort, and the renderer reads it from a flat record
    (four boxes)."""
    from fit.formats import load_measured
    from warp_rbrdf.materials import rational, rational_records

    b = load_measured(data_file("rgl/acrylic_felt_pink_rgb.bsdf"))
    without = fit_brdf(b, tol=0.05, max_theta_h_pieces=2, prove_bound=False)
    assert not without.valid
    fit = fit_brdf(b, tol=0.05, prove_bound=False)
    assert fit.valid and fit.core_theta_d_deg == 60.0 and fit.n_coefficients < without.n_coefficients
    assert [pc.theta_h_range_deg for pc in fit.core_pieces] == [(0.0, 5.0), (5.0, pytest.approx(34.3566, abs=1e-3)),
                                                                (pytest.approx(34.3566, abs=1e-3), 90.0)]
    assert fit.model.fit_info["theta_h_splits_deg"] == [5.0, pytest.approx(34.3566, abs=1e-3)]
    assert "split at theta_h = 5, 34.4 deg" in fit.summary()
    p = project_for_fit(b)
    for c in range(3):
        d = channel_data(p, c, 0.05, "tol", theta_d_range_deg=(0.0, 60.0))
        f = fit.model(d.X)[:, c]
        assert np.all((f >= d.lower) & (f <= d.upper))
    ints = rational.pack_model(fit.model)[0]
    assert ints[0] == rational_records.NODE_FLAT2D and ints[rational_records.FLAT_K] == 4


def test_refinement_splits_the_missing_pieces(tmp_path):
    """fit_brdf itself on a synthetic glossy MERL lobe at 1 % with degrees at most (2, 1) over the
    whole box: the peak split alone misses; the refinement splits the rest until the core is
    guaranteed, every cluster inside its interval, the pieces even in sqrt theta_h."""
    from hostile import glossy_merl

    from fit.formats import load_measured
    from fit.rational.brdf_fit import theta_h_midpoint

    b = load_measured(glossy_merl(tmp_path / "glossy.binary"))
    kw = dict(tol=0.01, max_degree=2, max_den_degree=1, core_theta_d_deg=78.5, prove_bound=False)
    assert not fit_brdf(b, max_theta_h_pieces=2, **kw).valid
    fit = fit_brdf(b, **kw)
    edges = [pc.theta_h_range_deg[0] for pc in fit.core_pieces] + [90.0]
    assert fit.valid and edges[:2] == [0.0, 5.0] and 3 < len(edges) - 1 <= 6
    assert edges[-2] == pytest.approx(theta_h_midpoint(5.0, 90.0, "sqrt"))
    p = project_for_fit(b)
    for c in range(3):
        d = channel_data(p, c, 0.01, "tol", theta_d_range_deg=(0.0, 78.5))
        f = fit.model(d.X)[:, c]
        assert np.all((f >= d.lower) & (f <= d.upper))


def test_theta_h_layouts_tried_in_turn():
    """One piece, the peak and the rest, then the pieces that miss split at their midpoints in
    the fit's own variable (sqrt: the square roots' midpoint; identity: the angles'), in order
    while there is room, and nothing to split when every piece is met or the layout is full."""
    from types import SimpleNamespace as NS

    from fit.rational.brdf_fit import bisect_failing, theta_h_midpoint, theta_h_splits

    assert theta_h_splits(None) == [(0.0, 90.0)]
    assert theta_h_splits(5.0) == [(0.0, 90.0), (0.0, 5.0, 90.0)]
    assert np.sqrt(theta_h_midpoint(5.0, 90.0, "sqrt")) == pytest.approx(0.5 * (np.sqrt(5.0) + np.sqrt(90.0)))
    assert theta_h_midpoint(10.0, 90.0, "identity") == 50.0
    ok, bad = NS(valid=True), NS(valid=False)
    mid = theta_h_midpoint(5.0, 90.0, "sqrt")
    assert bisect_failing((0.0, 5.0, 90.0), [ok, bad], "sqrt", 6) == (0.0, 5.0, mid, 90.0)
    assert bisect_failing((0.0, 5.0, 90.0), [bad, bad], "sqrt", 6) == pytest.approx((0.0, 1.25, 5.0, mid, 90.0))
    assert bisect_failing((0.0, 5.0, 90.0), [bad, bad], "sqrt", 3) == pytest.approx((0.0, 1.25, 5.0, 90.0))
    assert bisect_failing((0.0, 5.0, 90.0), [ok, ok], "sqrt", 6) is None
    assert bisect_failing((0.0, 5.0, 90.0), [bad, bad], "sqrt", 2) is None


def test_output_bounded_where_no_cluster_constrains_it(lobe_fit, lobe_file):
    """Q > 0 rules out poles; the upper clamp (twice the largest cluster) bounds the rest, also
    in the theta_h + theta_d > 90 deg corner that has no data."""
    from fit.formats import load_measured

    m = lobe_fit.model
    th, td = np.meshgrid(np.linspace(0, np.pi / 2, 91), np.linspace(0, np.pi / 2, 91), indexing="ij")
    v = m.evaluate_brdf(th, td)
    assert np.all(np.isfinite(v)) and np.all(v >= 0) and np.all(v <= m.value_max)
    p = project_for_fit(load_measured(lobe_file))
    fitted = p.value[:, p.theta_d <= np.deg2rad(THETA_D_MAX_DEG) + 1e-12]
    assert m.value_max == pytest.approx(2 * np.nanmax(fitted), rel=1e-12)


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
