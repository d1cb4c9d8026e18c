"""A fitted material never shows values its fit does not vouch for (issue 20, item 4).

A synthetic measurement (a glossy lobe whose blue channel jumps 25x for theta_d > 68 deg,
theta_h > 20 deg), written as a MERL file and fitted at 5 % with small degrees, gives a fit
whose core (theta_d <= 60 deg) is guaranteed and whose grazing band is flagged in blue only:
the fitter's own record (``valid`` per piece and channel). The renderer must show the projected
table of that file there (clamped to the band's measured range), the fit everywhere else (bit
for bit), refuse on ``unvouched = "refuse"``, log what it did, and an unflagged fit must be
exactly what it was.
"""
from __future__ import annotations

import copy
import json
import shutil

import numpy as np
import pytest

from lab.analytic import glossy_lobe
from fit.formats.angles import (
    directions_to_half_diff,
    half_diff_to_directions,
    spherical_to_direction,
)
from fit.formats.grid import (
    theta_d_centres,
    theta_d_index,
    theta_h_centres,
    theta_h_index,
)
from fit.formats.measured import MeasuredBRDF
from fit.formats.merl import read_merl, write_merl
from fit.rational.brdf_fit import fit_brdf, project_for_fit
from fit.rational.coefficient_file import load as load_coefficients
from fit.rational.coefficient_file import save as save_coefficients
from fit.rational.coefficient_file import to_dict
from fit.rational.flagged import (
    describe_regions,
    flagged_regions,
    region_measured_range,
)
from warp_rbrdf.errors import SceneError
from warp_rbrdf.materials import rational
from warp_rbrdf.materials.build import build_material_data
from warp_rbrdf.scene import MaterialSpec, Scene, ShapeSpec, parse_scene

BAND_DEG = 60.0
SPIKE = 25.0


def _spiky(wi, wo):
    v = np.array(glossy_lobe(exponent=10.0, kd=(0.3, 0.25, 0.2), ks=(0.3, 0.3, 0.3))(wi, wo), float)
    th, _, td, _ = directions_to_half_diff(wi, wo)
    v[..., 2] *= np.where((td > np.radians(68.0)) & (th > np.radians(20.0)), SPIKE, 1.0)
    return v


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """``(folder, fit)``: spiky.binary and its flagged fit spiky.json side by side."""
    d = tmp_path_factory.mktemp("unvouched")
    write_merl(MeasuredBRDF.from_function(_spiky, name="spiky"), d / "spiky.binary")
    fit = fit_brdf(read_merl(d / "spiky.binary"), tol=0.05, max_degree=4, max_den_degree=2,
                   source_file="spiky.binary")
    fit.save(d / "spiky.json")
    return d, fit


def _vouched_copy(model):
    """The same coefficients with every function's record saying 'within its intervals'."""
    m = copy.deepcopy(model)
    for leaf in [q for p in m.pieces for q in getattr(p, "pieces", [p])]:
        leaf.function_info = [dict(i, valid=True, feasible=True) for i in leaf.function_info]
    return m


def test_the_fit_is_flagged_where_the_fitter_says(fitted):
    _, fit = fitted
    assert fit.valid and not fit.all_valid                    # core guaranteed, band not
    model = load_coefficients(fitted[0] / "spiky.json")
    regions = flagged_regions(model)
    assert [(r["channels"], np.degrees(r["theta_d"]).round(1).tolist()) for r in regions] == \
        [((2,), [BAND_DEG, 78.5])]
    assert describe_regions(model) == "theta_d > 60 deg (blue channel)"
    # the file records each function's measured range (the clusters of its piece)
    p = project_for_fit(read_merl(fitted[0] / "spiky.binary"))
    for leaf in model.pieces:
        for c in range(3):
            lo, hi = leaf.function_info[c]["measured_range"]
            assert (lo, hi) == pytest.approx(region_measured_range(p, leaf, c), rel=1e-12)
    band_hi = model.pieces[1].function_info[2]["measured_range"][1]
    core_hi = model.pieces[0].function_info[2]["measured_range"][1]
    assert band_hi > 5 * core_hi                               # the spike is in the band's range


def test_flagged_fit_never_leaves_its_measured_range_numpy(fitted):
    """fit side (step 7 of the file's recipe): a flagged function is clamped to its piece's
    measured range everywhere, data-free corners and theta_d beyond the box included; the
    vouched functions are untouched."""
    model = load_coefficients(fitted[0] / "spiky.json")
    th, td = np.meshgrid(np.linspace(0, np.pi / 2, 120), np.linspace(np.radians(BAND_DEG) + 1e-6,
                                                                     np.radians(89.0), 80), indexing="ij")
    x = np.stack([th, td], -1)
    lo, hi = model.pieces[1].function_info[2]["measured_range"]
    got = model(x)[..., 2]
    assert got.min() >= lo and got.max() <= hi
    unclamped = _vouched_copy(model)(x)
    np.testing.assert_array_equal(model(x)[..., :2], unclamped[..., :2])
    assert np.any(unclamped[..., 2] != got)                   # the clamp is active somewhere


def test_valid_fit_is_clamped_to_its_vouched_range_and_unchanged_at_its_data(fitted):
    """A valid function records the envelope of its data's intervals (``vouched_range``) and is
    clamped to it: every value at a data point (the piece's projected clusters) is unchanged,
    and nowhere, data-free clusters included, does it leave the envelope."""
    from fit.rational.model import vouched_range

    model = load_coefficients(fitted[0] / "spiky.json")
    core = model.pieces[0]
    assert not any(core.flagged)
    p = project_for_fit(read_merl(fitted[0] / "spiky.binary"))
    th, td = np.meshgrid(theta_h_centres(), theta_d_centres(), indexing="ij")
    data = np.isfinite(p.value[..., 0]) & (td <= np.radians(BAND_DEG))
    free = copy.deepcopy(core)
    for i in free.function_info:
        i.pop("vouched_range")
    x = np.stack([th, td], -1)
    clamped, raw = core(x), free(x)
    np.testing.assert_array_equal(clamped[data], raw[data])
    for c in range(3):
        lo, hi = vouched_range(core.function_info[c])
        assert lo >= 0 and hi >= np.nanmax(p.value[..., c][data]) and hi <= 1.5 * np.nanmax(p.value[..., c][data])
        grid = np.stack(np.meshgrid(np.linspace(0, np.pi / 2, 200), np.linspace(0, np.radians(BAND_DEG), 120),
                                    indexing="ij"), -1)
        assert core(grid)[..., c].max() <= hi and core(grid)[..., c].min() >= lo


@pytest.fixture(scope="module")
def renderer(fitted):
    """One scene, one compile: the flagged fit from its file and the same coefficients vouched
    (cosine MIS: the tests evaluate, no inverse-CDF table is tabulated at load)."""
    from warp_rbrdf.renderer import Renderer
    from lab.testing import top_down_camera

    d, _ = fitted
    specs = {"flagged": MaterialSpec(name="flagged", type="rational", file=d / "spiky.json", sampler="mis"),
             "vouched": MaterialSpec(name="vouched", type="rational", sampler="mis",
                                     data=_vouched_copy(load_coefficients(d / "spiky.json")))}
    sc = Scene(camera=top_down_camera(4), materials=specs,
               shapes=[ShapeSpec(type="sphere", material=n, center=(3.0 * i, -10.0, 0.0), radius=0.5)
                       for i, n in enumerate(specs)])
    return Renderer(sc)


def _pairs(n=20000, seed=3):
    rng = np.random.default_rng(seed)
    wi = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    wo = spherical_to_direction(np.arccos(rng.random(n)), rng.random(n) * 2 * np.pi)
    return wi, wo


def test_warp_uses_the_projected_table_where_flagged_and_the_fit_elsewhere(fitted, renderer):
    d, _ = fitted
    wi, wo = _pairs()
    got = renderer.eval_material("flagged", wi, wo)
    fit = renderer.eval_material("vouched", wi, wo)
    _, _, td, _ = directions_to_half_diff(wi, wo)
    band = td > np.radians(BAND_DEG) + 1e-5
    core = td < np.radians(BAND_DEG) - 1e-5
    # elsewhere: the fit's own code, bit for bit (red and green everywhere, blue in the core)
    np.testing.assert_array_equal(got[:, :2], fit[:, :2])
    np.testing.assert_array_equal(got[core, 2], fit[core, 2])
    assert np.abs(got[band, 2] - fit[band, 2]).max() > 0.1     # the band's blue is replaced ...
    # ... by the fallback table (NumPy reference of the Warp evaluation) ...
    lm = renderer.material_data.loaded[renderer.material_index("flagged")]
    assert lm.fallback_table is not None
    ref = lm.evaluate(wi, wo)
    same = np.isclose(got, ref, rtol=1e-5, atol=1e-7).all(axis=1)
    assert same.mean() > 0.999                                 # nearest-cluster edges in float32
    # ... which is the measurement's median projection: at cluster centres in the band, blue is
    # the projected cluster (every non-empty band cluster: float32 of its value, in its range)
    p = project_for_fit(read_merl(d / "spiky.binary"))
    i, j = np.meshgrid(np.arange(90), np.arange(60, 79), indexing="ij")
    keep = np.isfinite(p.value[i, j, 2])
    i, j = i[keep], j[keep]
    ci, co = half_diff_to_directions(theta_h_centres()[i], 0.0, theta_d_centres()[j], np.full(i.size, 1.3))
    up = (ci[:, 2] > 1e-3) & (co[:, 2] > 1e-3)
    th_c, _, td_c, _ = directions_to_half_diff(ci, co)
    on_grid = up & (theta_h_index(th_c) == i) & (theta_d_index(td_c) == j)
    assert on_grid.sum() > 500
    b = renderer.eval_material("flagged", ci[on_grid], co[on_grid])[:, 2]
    np.testing.assert_array_equal(b, np.float32(np.maximum(p.value[i[on_grid], j[on_grid], 2], 0.0)))


def test_values_never_leave_the_regions_measured_range(fitted, renderer):
    """Grazing, data-free corners, theta_d beyond the box: blue in the band stays within the
    band's measured blue range, where the raw fit reaches far outside it. (The band: the pairs
    whose angles, moved onto the measured domain, are in it; tests/test_rational_domain.py.)"""
    wi, wo = _pairs(40000, seed=7)
    th, _, td, _ = directions_to_half_diff(wi, wo)
    x = rational.onto_measured_domain(np.stack([th, td], -1), 79.0)
    band = x[:, 1] > np.radians(BAND_DEG) + 1e-5
    model = load_coefficients(fitted[0] / "spiky.json")
    lo, hi = model.pieces[1].function_info[2]["measured_range"]
    got = renderer.eval_material("flagged", wi, wo)[band, 2]
    assert got.min() >= np.float32(lo) * (1 - 1e-6) and got.max() <= np.float32(hi) * (1 + 1e-6)
    raw = _vouched_copy(model).evaluate(wi[band], wo[band])[:, 2]
    assert raw.max() > 1.5 * hi or raw.min() < 0.5 * lo         # what the fit alone would show


def test_unflagged_fit_is_unchanged(renderer):
    """A fit without a flagged piece loads as before: its own evaluation (on its measured domain,
    tests/test_rational_domain.py), no table, no log line, and the packed data the renderer had
    before this feature (no table channel)."""
    from warp_rbrdf.paths import PACKAGE_DATA

    model = load_coefficients(PACKAGE_DATA / "paper_white_rgb.json")
    assert flagged_regions(model) == []
    lm = rational.load(MaterialSpec(name="s", type="rational", data=model))
    assert lm.fallback_table is None and lm.notes == () and lm.data is model
    cut = rational.measured_domain(model)
    packed = rational.pack_model(model, cutoff_deg=cut)
    assert all(np.array_equal(a, b) for a, b in zip(packed, rational.pack_model(model, False, cut)))
    assert all(np.array_equal(a, b) for a, b in zip(packed, lm.coefficients))
    leaves = [q for p in model.pieces for q in getattr(p, "pieces", [p])]
    assert not any(t for leaf in leaves for t, _ in rational.channel_modes(leaf, table=True))
    # vouched coefficients: exactly the fit (the scene's 'vouched' material gets no table)
    lm = renderer.material_data.loaded[renderer.material_index("vouched")]
    assert lm.fallback_table is None and renderer.material_data.param[renderer.material_index("vouched")] == 0


def _scene_text(folder, unvouched=None, file="spiky.json"):
    """A scene of the fit ``file`` (cosine MIS: no inverse-CDF table tabulated at load)."""
    extra = f'unvouched = "{unvouched}"\n' if unvouched else ""
    extra += 'sampler = "mis"\n'
    return (f'[materials.satin]\ntype = "rational"\nfile = "{file}"\n{extra}'
            f'[[shapes]]\ntype = "sphere"\nmaterial = "satin"\n')


def test_load_log_says_what_happened(fitted):
    d, _ = fitted
    sc = parse_scene(_scene_text(d), path=d / "scene.toml")
    assert sc.materials["satin"].unvouched == "projected"
    lines = []
    md = build_material_data(sc, log=lines.append)
    assert lines == [("material 'satin': rational fit not within its bound for theta_d > 60 deg (blue "
                      "channel): using the projected table there (median projection of spiky.binary, "
                      "embedded in spiky.json, clamped to each region's measured range)")]
    assert md.tables.shape == (90 * 90, 3) and md.param[0] == 0


def test_refuse_is_one_line_naming_material_file_and_region(fitted):
    d, _ = fitted
    sc = parse_scene(_scene_text(d, "refuse"), path=d / "scene.toml")
    with pytest.raises(SceneError) as e:
        build_material_data(sc, log=lambda s: pytest.fail(f"logged {s!r}"))
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"{d / 'scene.toml'}: materials.satin.unvouched: material 'satin': rational fit "
                          "spiky.json is not within its bound for theta_d > 60 deg (blue channel); refused")


def test_scene_key_is_checked(fitted):
    d, _ = fitted
    with pytest.raises(SceneError, match="unvouched.*expected one of"):
        parse_scene(_scene_text(d, "ignore"), path=d / "scene.toml")
    with pytest.raises(SceneError, match="unvouched"):      # only rational materials read it
        parse_scene('[materials.m]\ntype = "lambert"\nunvouched = "refuse"\n')


def _without_fallback(src, dst):
    """``src`` written to ``dst`` as the fitter wrote flagged fits before it embedded the table."""
    data = json.loads(src.read_text())
    data.pop("fallback")
    dst.write_text(json.dumps(data))


def test_missing_or_different_source_is_an_error_naming_it(fitted, tmp_path, monkeypatch):
    """A flagged file without an embedded table (written before the fitter embedded it) needs
    its source measurement."""
    d, _ = fitted
    monkeypatch.setenv("RBRDF_DATA", str(tmp_path / "data"))
    (tmp_path / "data" / "merl").mkdir(parents=True)
    (tmp_path / "fits").mkdir()
    _without_fallback(d / "spiky.json", tmp_path / "fits" / "spiky.json")
    text = _scene_text(tmp_path, file="fits/spiky.json")
    with pytest.raises(SceneError) as e:
        build_material_data(parse_scene(text, path=tmp_path / "scene.toml"), log=lambda s: None)
    msg = str(e.value)
    assert "\n" not in msg and "materials.satin.file" in msg and "'spiky.binary'" in msg and "not found in" in msg
    # a file of that name that is not the measurement the fit was made from
    write_merl(MeasuredBRDF.from_function(glossy_lobe(exponent=5.0), name="other"),
               tmp_path / "data" / "merl" / "spiky.binary")
    with pytest.raises(SceneError, match="another sha256"):
        build_material_data(parse_scene(text, path=tmp_path / "scene.toml"), log=lambda s: None)
    # the right file in a subfolder of RBRDF_DATA is found
    shutil.copy(d / "spiky.binary", tmp_path / "data" / "merl" / "spiky.binary")
    lines = []
    build_material_data(parse_scene(text, path=tmp_path / "scene.toml"), log=lines.append)
    assert len(lines) == 1 and "using the projected table" in lines[0] and "embedded" not in lines[0]


def test_files_without_recorded_range_get_it_from_the_source(fitted, tmp_path):
    """Files written before ``measured_range`` was recorded: still readable; the renderer
    computes the range from the source measurement (the same numbers the fitter records)."""
    d, _ = fitted
    data = json.loads((d / "spiky.json").read_text())
    data.pop("fallback")             # files written before the table was embedded ...
    for piece in data["pieces"]:
        for f in piece["functions"]:
            f.pop("measured_range")
            f.pop("vouched_range")   # ... or either range was recorded
    (tmp_path / "old.json").write_text(json.dumps(data))
    shutil.copy(d / "spiky.binary", tmp_path / "spiky.binary")
    old = load_coefficients(tmp_path / "old.json")
    assert old.pieces[1].output_clamps() == [None, None, None]   # fit side: no range, no clamp
    lm = rational.load(MaterialSpec(name="m", type="rational", file=tmp_path / "old.json"))
    new = load_coefficients(d / "spiky.json")
    assert lm.data.pieces[1].function_info[2]["measured_range"] == \
        pytest.approx(new.pieces[1].function_info[2]["measured_range"], rel=1e-12)
    assert old.pieces[1].output_clamps() == [None, None, None]   # the caller's model is not changed
    # the same as the new file without the valid functions' vouched ranges (not recomputed)
    data = json.loads((d / "spiky.json").read_text())
    for piece in data["pieces"]:
        for f in piece["functions"]:
            f.pop("vouched_range")
    (tmp_path / "new.json").write_text(json.dumps(data))
    wi, wo = _pairs(3000, seed=11)
    ref = rational.load(MaterialSpec(name="m", type="rational", file=tmp_path / "new.json")).evaluate(wi, wo)
    np.testing.assert_array_equal(lm.evaluate(wi, wo), ref)


def test_round_trip_keeps_the_record(fitted, tmp_path):
    d, _ = fitted
    m = load_coefficients(d / "spiky.json")
    save_coefficients(m, tmp_path / "again.json")
    a = json.loads((d / "spiky.json").read_text())
    b = json.loads((tmp_path / "again.json").read_text())
    assert a["version"] == b["version"] == 2
    assert [f["measured_range"] for p in a["pieces"] for f in p["functions"]] == \
        [f["measured_range"] for p in b["pieces"] for f in p["functions"]]
    assert a["fallback"] == b["fallback"]
    assert (tmp_path / "again.json").read_bytes() == (d / "spiky.json").read_bytes()


@pytest.mark.slow
def test_real_rgl_fit_with_a_tiny_degree_limit(tmp_path, monkeypatch):
    """paper_white at 5 % with degrees <= (2, 1): the core is flagged in every channel; the
    source is found in $RBRDF_DATA/rgl by its name and sha256, the core shows the projected
    table (Warp == NumPy reference), the band (met) the fit."""
    from conftest import DATA, data_file

    from fit.formats import load_measured
    from warp_rbrdf.renderer import Renderer
    from lab.testing import top_down_camera

    src = data_file("rgl/paper_white_rgb.bsdf")
    monkeypatch.setenv("RBRDF_DATA", str(DATA))
    fit = fit_brdf(load_measured(src), tol=0.05, max_degree=2, max_den_degree=1, core_theta_d_deg=60,
                   peak_split_deg=None, source_file=src.name)
    fit.save(tmp_path / "paper.json")
    assert describe_regions(fit.model) == "theta_d <= 60 deg (all channels)"
    lines = []
    sc = Scene(camera=top_down_camera(4),
               materials={"paper": MaterialSpec(name="paper", type="rational", file=tmp_path / "paper.json")},
               shapes=[ShapeSpec(type="sphere", material="paper", center=(0.0, -10.0, 0.0), radius=0.5)])
    md = build_material_data(sc, log=lines.append)
    assert len(lines) == 1 and "theta_d <= 60 deg (all channels)" in lines[0] and src.name in lines[0]
    r = Renderer(sc)
    wi, wo = _pairs(20000, seed=5)
    got = r.eval_material("paper", wi, wo)
    ref = md.loaded[0].evaluate(wi, wo)
    assert np.isclose(got, ref, rtol=1e-5, atol=1e-7).all(axis=1).mean() > 0.999
    th, _, td, _ = directions_to_half_diff(wi, wo)
    band = (td > np.radians(60.0) + 1e-5) & (np.cos(th) * np.cos(td) > np.cos(np.radians(79.0)) * (1 + 1e-4))
    np.testing.assert_allclose(got[band], fit.model.evaluate(wi[band], wo[band]), rtol=2e-4, atol=1e-6)


def _rough_band(wi, wo):
    """A glossy lobe whose grazing band (theta_d > 62 deg) varies by +-40 % over phi_d and
    whose phi_d median jitters by +-15 % from cluster to cluster: the band is inside
    ``tol+spread`` intervals (the spread covers the jitter) but no smooth function is within 5 %
    of its medians."""
    v = np.array(glossy_lobe(exponent=10.0, kd=(0.3, 0.25, 0.2), ks=(0.3, 0.3, 0.3))(wi, wo), float)
    th, _, td, pd = directions_to_half_diff(wi, wo)
    band = td > np.radians(62.0)
    f = 1.0 + 0.4 * np.cos(2.0 * pd) + 0.15 * np.sin(40.0 * th) * np.sin(40.0 * td)
    return v * np.where(band, f, 1.0)[..., None]


def test_default_band_intervals_flag_a_band_vouched_only_by_its_spread(tmp_path):
    """The band's default intervals are the pure tolerance (``band_intervals="tol"``): a band
    that only ``tol+spread`` intervals call valid is flagged (and shown with the projected table
    by the renderer, tested above); with ``tol+spread`` asked for explicitly it is valid, as it
    was by default before (the fidelity study's cc_ibiza_sunset: 130 rim pixels above the
    reference's range with the old default, 12 with the new)."""
    write_merl(MeasuredBRDF.from_function(_rough_band, name="rough"), tmp_path / "rough.binary")
    brdf = read_merl(tmp_path / "rough.binary")
    new = fit_brdf(brdf, tol=0.05, max_degree=4, max_den_degree=2, core_theta_d_deg=60.0)
    old = fit_brdf(brdf, tol=0.05, max_degree=4, max_den_degree=2, core_theta_d_deg=60.0,
                   band_intervals="tol+spread")
    assert new.valid and old.valid                              # the core is guaranteed either way
    assert old.all_valid                                        # the spread vouches for the band ...
    assert not new.all_valid                                    # ... the tolerance does not
    assert new.model.fit_info["band_intervals"] == "tol"
    assert flagged_regions(new.model) and not flagged_regions(old.model)
    # only the flagged fit carries a fallback table; the valid one is written as before
    assert new.model.fallback is not None and old.model.fallback is None
    assert "fallback" in to_dict(new.model) and "fallback" not in to_dict(old.model)
    assert describe_regions(new.model).startswith("theta_d > 60 deg")


# The embedded fallback table (fit.rational.fallback): a flagged fit renders without its source
def test_flagged_fit_embeds_the_table_the_renderer_reads(fitted):
    """The fitter writes the part of the projected table the renderer reads: the flagged band's
    clusters (one more on each side) in blue, float32 of the source-based table bit for bit."""
    from fit.rational.fallback import KIND, fallback_table, region_blocks, table_from_record

    d, fit = fitted
    rec = json.loads((d / "spiky.json").read_text())["fallback"]
    assert rec["kind"] == KIND and rec["shape"] == [90, 90, 3] and rec["dtype"] == "<f4"
    assert rec["grazing_cutoff_deg"] == 79.0 == fit.model.fit_info["grazing_cutoff_deg"]
    assert rec["source"] == fit.model.source
    assert [(b["theta_h_index"], b["theta_d_index"], b["channels"]) for b in rec["blocks"]] == \
        [([0, 89], [59, 79], [2])]
    model = load_coefficients(d / "spiky.json")
    assert model.fallback == rec
    emb = table_from_record(rec, model)
    src = fallback_table(project_for_fit(read_merl(d / "spiky.binary")))
    assert emb.dtype == np.float32 and emb.shape == (90, 90, 3)
    for (i0, i1), (j0, j1), chans in region_blocks(model):
        sl = (slice(i0, i1 + 1), slice(j0, j1 + 1), list(chans))
        np.testing.assert_array_equal(emb[sl], src[sl])
        assert emb[sl].tobytes() == src[sl].tobytes()


def test_embedded_table_renders_without_the_source_as_the_source_does(fitted, tmp_path, monkeypatch):
    """Only the coefficient file, no measurement anywhere ($RBRDF_DATA empty): the fit loads
    from its embedded table, and its NumPy reference, packed data and Warp values equal those of
    the same file without the table next to its source measurement, bit for bit."""
    from warp_rbrdf.renderer import Renderer
    from lab.testing import top_down_camera

    d, _ = fitted
    monkeypatch.setenv("RBRDF_DATA", str(tmp_path / "empty"))
    (tmp_path / "empty").mkdir()
    (tmp_path / "alone").mkdir()
    (tmp_path / "old").mkdir()
    shutil.copy(d / "spiky.json", tmp_path / "alone" / "spiky.json")
    _without_fallback(d / "spiky.json", tmp_path / "old" / "spiky.json")
    shutil.copy(d / "spiky.binary", tmp_path / "old" / "spiky.binary")
    emb = rational.load(MaterialSpec(name="e", type="rational", file=tmp_path / "alone" / "spiky.json"))
    src = rational.load(MaterialSpec(name="s", type="rational", file=tmp_path / "old" / "spiky.json"))
    assert emb.notes == (("rational fit not within its bound for theta_d > 60 deg (blue channel): using the "
                          "projected table there (median projection of spiky.binary, embedded in spiky.json, "
                          "clamped to each region's measured range)"),)
    assert src.notes == (("rational fit not within its bound for theta_d > 60 deg (blue channel): using the "
                          "projected table there (median projection of spiky.binary, clamped to each "
                          "region's measured range)"),)
    wi, wo = _pairs(20000, seed=13)
    np.testing.assert_array_equal(emb.evaluate(wi, wo), src.evaluate(wi, wo))
    assert all(np.array_equal(a, b) for a, b in zip(emb.coefficients, src.coefficients))
    # the in-memory fit (spec.data) carries the same table
    mem = rational.load(MaterialSpec(name="m", type="rational", data=load_coefficients(d / "spiky.json")))
    assert mem.notes[0].endswith("(median projection of spiky.binary, carried by the fit, clamped to each "
                                 "region's measured range)")
    np.testing.assert_array_equal(mem.evaluate(wi, wo), src.evaluate(wi, wo))
    # Warp: one scene, both materials
    specs = {"e": MaterialSpec(name="e", type="rational", file=tmp_path / "alone" / "spiky.json", sampler="mis"),
             "s": MaterialSpec(name="s", type="rational", file=tmp_path / "old" / "spiky.json", sampler="mis")}
    sc = Scene(camera=top_down_camera(4), materials=specs,
               shapes=[ShapeSpec(type="sphere", material=n, center=(3.0 * i, -10.0, 0.0), radius=0.5)
                       for i, n in enumerate(specs)])
    r = Renderer(sc)
    got = r.eval_material("e", wi, wo)
    np.testing.assert_array_equal(got, r.eval_material("s", wi, wo))
    assert np.isclose(got, emb.evaluate(wi, wo), rtol=1e-5, atol=1e-7).all(axis=1).mean() > 0.999


def _corrupt_cases():
    def data(rec, f):
        raw = np.frombuffer(__import__("base64").b64decode(rec["blocks"][0]["data"]), "<f4").copy()
        rec["blocks"][0]["data"] = __import__("base64").b64encode(f(raw).astype("<f4").tobytes()).decode()

    def nan(r):
        r[5] = np.nan
        return r

    return {
        "wrong length": (lambda rec: data(rec, lambda r: r[:-3]), "fallback.blocks[0].data", "bytes, expected"),
        "wrong shape": (lambda rec: rec.update(shape=[90, 90, 4]), "fallback.shape", "expected [90, 90, 3]"),
        "non-finite": (lambda rec: data(rec, nan), "fallback.blocks[0].data", "not finite"),
        "negative": (lambda rec: data(rec, lambda r: -r), "fallback.blocks[0].data", "below 0"),
        "not base64": (lambda rec: rec["blocks"][0].update(data="@@@@"), "fallback.blocks[0].data", "base64"),
        "other cut-off": (lambda rec: rec.update(grazing_cutoff_deg=80.0), "fallback.grazing_cutoff_deg",
                          "not the fit's grazing cut-off 79"),
        "too small": (lambda rec: rec["blocks"][0].update(theta_d_index=[60, 79]), "fallback.blocks[0].data",
                      "bytes, expected"),
        "not covering": (lambda rec: rec["blocks"][0].update(channels=[1]), "fallback.blocks",
                         "do not cover flagged piece 1"),
        "index range": (lambda rec: rec["blocks"][0].update(theta_h_index=[0, 90]),
                        "fallback.blocks[0].theta_h_index", "not a range inside [0, 89]"),
        "not an object": (lambda rec: rec.clear() or rec.update(kind=3), "fallback.kind", "expected a string"),
        "dtype": (lambda rec: rec.update(dtype=">f4"), "fallback.dtype", "little-endian float32"),
    }


@pytest.mark.parametrize("case", list(_corrupt_cases()))
def test_corrupt_embedded_table_is_one_line_naming_file_and_key(fitted, tmp_path, case):
    d, _ = fitted
    change, key, problem = _corrupt_cases()[case]
    data = json.loads((d / "spiky.json").read_text())
    change(data["fallback"])
    (tmp_path / "bad.json").write_text(json.dumps(data))
    text = _scene_text(tmp_path, file="bad.json")
    with pytest.raises(SceneError) as e:
        build_material_data(parse_scene(text, path=tmp_path / "scene.toml"), log=lambda s: None)
    msg = str(e.value)
    assert "\n" not in msg and "materials.satin.file" in msg and "bad.json" in msg
    assert f"key {key}:" in msg and problem in msg, msg


def test_corrupt_table_of_an_in_memory_fit_is_one_line(fitted):
    d, _ = fitted
    model = copy.deepcopy(load_coefficients(d / "spiky.json"))
    model.fallback = dict(model.fallback, shape=[90, 90])
    with pytest.raises(SceneError) as e:
        rational.load(MaterialSpec(name="m", type="rational", data=model))
    msg = str(e.value)
    assert "\n" not in msg and "embedded fallback table unusable (key fallback.shape: expected [90, 90, 3]" in msg


def test_valid_file_is_written_as_before(tmp_path):
    """A fit without a flagged piece has no fallback key: saving the shipped paper_white fit
    (valid) again gives its file byte for byte."""
    from warp_rbrdf.paths import PACKAGE_DATA

    src = PACKAGE_DATA / "paper_white_rgb.json"
    model = load_coefficients(src)
    assert not flagged_regions(model) and model.fallback is None
    save_coefficients(model, tmp_path / "again.json")
    assert "fallback" not in json.loads(src.read_text())
    assert (tmp_path / "again.json").read_bytes() == src.read_bytes()


def test_flagged_fit_without_a_recorded_cutoff_is_not_moved_onto_a_domain(fitted):
    """The measured domain of a flagged fit is the cut-off its file records, as for any fit: a
    flagged fit recording none is evaluated by its recipe (its table still comes from the fitter's
    79 deg projection), so that the domain rule never depends on whether a piece is flagged."""
    from fit.rational.coefficient_file import load as load_coefficients
    from warp_rbrdf.materials.rational import evaluate_at_angles, measured_domain

    d, _ = fitted
    m = load_coefficients(d / "spiky.json")
    assert measured_domain(m) is not None and rational.flagged_regions(m)
    free = copy.deepcopy(m)
    free.fit_info.pop("grazing_cutoff_deg")
    assert free.fallback["grazing_cutoff_deg"] == 79.0   # the default the table is checked against
    a = rational.load(MaterialSpec(name="a", type="rational", data=m))
    b = rational.load(MaterialSpec(name="b", type="rational", data=free))
    wi, wo = _pairs(20000, seed=21)
    th, _, td, _ = directions_to_half_diff(wi, wo)
    beyond = (np.cos(th) * np.cos(td) < np.cos(np.radians(measured_domain(m)))) & (wi[:, 2] > 0) & (wo[:, 2] > 0)
    assert beyond.sum() > 100
    np.testing.assert_array_equal(b.evaluate(wi, wo), evaluate_at_angles(free, b.fallback_table, None)(wi, wo))
    np.testing.assert_array_equal(a.evaluate(wi, wo)[~beyond], b.evaluate(wi, wo)[~beyond])
    assert not np.array_equal(a.evaluate(wi, wo)[beyond], b.evaluate(wi, wo)[beyond])
