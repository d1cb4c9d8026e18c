"""Studies (issue 7): a smoke run of each study, and the failure map's findings pinned so that a
regression (or an improvement that changes the map) is noticed.

The failure-map pins run at a small fixed size ("test" preset: 24x24 px, 32 spp, 2 seeds); the
margins are several times the seed-to-seed spread seen at that size.
"""
from __future__ import annotations

import csv
import json
import math
import re
import shutil

import numpy as np
import pytest

from conftest import data_file

import colour  # noqa: E402,F401  (the studies measure ΔE2000 with colour-science)


@pytest.fixture(scope="module")
def rgl_data():
    for m in ("cc_ibiza_sunset_rgb", "paper_white_rgb"):
        data_file(f"rgl/{m}.bsdf")
    data_file("envmaps/rooitou_park_1k.hdr")
    data_file("envmaps/studio_small_03_1k.hdr")
    data_file("meshes/bun_zipper.ply")


# --------------------------------------------------------------------------------------------
# Metrics
def test_delta_e2000_matches_colour_and_is_zero_for_equal_images():
    from studies import common as C

    rng = np.random.default_rng(0)
    a = rng.random((4, 5, 3))
    b = a * 1.1
    de = C.delta_e2000(b, a)
    assert de.shape == (4, 5)
    assert np.allclose(C.delta_e2000(a, a), 0.0)
    cs = colour.RGB_COLOURSPACES["ITU-R BT.709"]
    lab = lambda x: colour.XYZ_to_Lab(colour.RGB_to_XYZ(x, cs, illuminant=cs.whitepoint,  # noqa: E731
                                                        chromatic_adaptation_transform=None), cs.whitepoint)
    assert np.allclose(de, colour.delta_E(lab(b), lab(a), method="CIE 2000"))
    # white maps to L* = 100
    assert np.allclose(C.rgb_to_lab(np.ones(3)), [100, 0, 0], atol=1e-6)


def test_sampler_discovery_includes_base_samplers():
    from studies import common as C
    from warp_rbrdf import registry

    s = C.all_samplers()
    assert s[:4] == ("uniform", "cosine", "light", "mis")
    assert set(s) == set(registry.STRATEGY_NAMES) and set(s[:4]) == set(registry.BASE_STRATEGIES)


# --------------------------------------------------------------------------------------------
# Smoke runs
def test_convergence_smoke(tmp_path, rgl_data):
    from studies import common as C
    from studies import convergence

    # the base samplers plus the table-based inverse-CDF ones when the renderer has them (the
    # rational ones fit inverse CDFs per material first: too slow for a smoke test)
    want = [s for s in C.all_samplers() if s in C.BASE_SAMPLERS or "tabulated" in s]
    r = convergence.run("smoke", tmp_path, samplers=want, quiet=True)
    rows = list(csv.DictReader(open(tmp_path / "convergence.csv")))
    samplers = {x["sampler"] for x in rows}
    assert samplers == set(want) - {s["sampler"] for s in r["meta"]["skipped"]}
    assert {"uniform", "cosine", "light", "mis"} <= samplers
    assert all(math.isfinite(float(x["rmse"])) and float(x["seconds"]) > 0 for x in rows)
    for f in ("convergence.json", "convergence.md", "convergence_rmse_spp.png", "convergence_rmse_time.png",
              "convergence_efficiency.png"):
        assert (tmp_path / f).stat().st_size > 0
    # more samples, less error (MIS under the sun, 1 -> 8 spp)
    e = {int(x["spp"]): float(x["rel_rmse"]) for x in rows
         if x["sampler"] == "mis" and x["light"] == "rooitou"}
    assert e[8] < e[1]
    # colinear directional light only: every sampler traces the same rays (delta light)
    col = {x["sampler"]: float(x["rmse"]) for x in rows
           if x["light"] == "colinear" and x["spp"] == "8" and x["sampler"] in C.BASE_SAMPLERS}
    assert max(col.values()) == pytest.approx(min(col.values()), rel=1e-6)
    assert "| scene |" in r["markdown"]
    # --docs: the charts it publishes are the ones the run wrote; the README table has one row per
    # scene, the MIS column is the summary's value and samplers not run read "–"
    assert all((tmp_path / f).stat().st_size > 0 for f in convergence.DOCS["charts"])
    t = convergence.readme_table(r).splitlines()
    assert t[0].startswith("| scene | material | cosine | light | mis | tabulated | rational-deriv. |")
    body = [x for x in t[2:] if x.startswith("| ")]
    assert len(body) == len(r["references"]) == 2
    mis = [s for s in r["summary"] if s["sampler"] == "mis" and s["light"] == "rooitou"][0]
    row = [x for x in body if x.startswith("| sphere / rooitou | ibiza |")][0].split(" | ")
    assert row[4] == C._fmt(mis["rel_rmse"])
    assert row[6] == "–"          # rational-derivative was not run
    assert row[7] == C._fmt([s for s in r["summary"] if s["sampler"] == "mis-tabulated"
                             and s["light"] == "rooitou"][0]["rel_rmse"])
    assert "at 8 spp" in t[-1]


def test_comparison_smoke(tmp_path, rgl_data):
    from studies import common as C
    from studies import comparison

    r = comparison.run("smoke", tmp_path, allow_fit=False, quiet=True)
    assert len(r["rows"]) == 2
    for row in r["rows"]:
        assert 0 <= row["de_meas_proj_mean"] < 20 and row["de_meas_proj_p99"] >= row["de_meas_proj_mean"]
    assert (tmp_path / "comparison_colinear.png").stat().st_size > 0
    assert (tmp_path / "comparison_envmap.png").stat().st_size > 0
    data = json.loads((tmp_path / "comparison.json").read_text())
    assert data["meta"]["config"]["materials"] == ["paper"]
    assert all((tmp_path / f).stat().st_size > 0 for f in comparison.DOCS["charts"])
    t = comparison.readme_table(r).splitlines()
    row = r["rows"][0]
    rat = (f"{C._fmt(row['de_meas_rati_mean'])} / {C._fmt(row['de_meas_rati_p99'])}"
           if "de_meas_rati_mean" in row else "–")     # a cached or shipped fit, if any
    assert t[2].startswith(f"| paper | {row['light']} | {C._fmt(row['de_meas_proj_mean'])} / "
                           f"{C._fmt(row['de_meas_proj_p99'])} | {rat} | {C._fmt(row['noise_de_mean'])} |")


def test_view_angle_is_measured_to_each_pixels_ray_not_the_camera_axis():
    """The comparison's theta_o bins: the angle between the shading normal and each pixel's own
    ray, checked against the analytic sphere (ray-sphere intersection with the same rays), and
    reaching ~90° at the silhouette, where the angle to the camera axis (what a colinear
    directional light measures) stops at 90° - 12.5°."""
    from studies import common as C
    from studies.comparison import view_angles
    from warp_rbrdf import Renderer
    from warp_rbrdf.camera import camera_frame, camera_rays_numpy
    from studies.coverage import view_angle

    sc = C.make_scene("sphere", "colinear", C.material_spec("lambert", 1.0, "light"), resolution=48)
    r = Renderer(sc)
    got = view_angle(r, 1)                       # one ray through each pixel centre
    H, W = got.shape
    py, px = np.mgrid[0:H, 0:W] + 0.5
    d = camera_rays_numpy(sc.camera, px, py)
    o = camera_frame(sc.camera)[0]
    b = d @ o
    disc = b * b - (o @ o - 0.8 ** 2)
    hit = disc > 0
    t = -b - np.sqrt(np.where(hit, disc, 0.0))
    p = o + t[..., None] * d
    cos = np.sum(p / 0.8 * -d, axis=-1)
    want = np.degrees(np.arccos(np.clip(cos, 0, 1)))
    inner = hit & (want < 80)                    # away from the tessellated silhouette
    assert np.isnan(got[~hit & (disc < -0.05)]).all()
    assert np.abs(got[inner] - want[inner]).max() < 1.0
    assert np.nanmax(got) > 82.0                 # the camera axis would give at most 77.5°
    axis = np.degrees(np.arccos(np.clip(p[hit] @ -camera_frame(sc.camera)[3], -1, 1)))
    assert axis.max() < 78.0
    # the study's entry point averages 4x4 sub-pixel rays of the same geometry
    avg = view_angles(sc, r)
    both = inner & np.isfinite(avg)
    assert np.abs(avg[both] - want[both]).max() < 3.0


def test_fit_study_smoke(tmp_path, rgl_data):
    """Fit (the project's fitter if present, otherwise the labelled direct stand-in) at a tiny
    size, render it, ΔE and evaluation cost."""
    import fit.rational.fitter  # noqa: F401
    from studies import fit_study

    r = fit_study.run("smoke", tmp_path, allow_direct=True, quiet=True)
    row = r["rows"][0]
    assert row["n_coefficients"] > 0
    assert math.isfinite(row["de_vs_measured_mean"]) and math.isfinite(row["de_vs_projected_mean"])
    assert row["eval_ns"] > 0
    t = r["tables"][0]
    assert t["measured_eval_ns"] > 0 and t["projected_eval_ns"] > 0
    assert (tmp_path / "fit_study.md").read_text().count("|") > 10
    assert all((tmp_path / f).stat().st_size > 0 for f in fit_study.DOCS["charts"])
    t = fit_study.readme_table(r).splitlines()
    assert t[0].startswith("| material | coefficients at 20 % | mean ΔE vs 3-D | ns / eval |")
    assert t[2].startswith(f"| paper | {row['n_coefficients']} | {row['de_vs_measured_mean']:.2f} | ")


def test_fit_study_reports_what_each_fit_guarantees():
    """The fit study's "in tol." column tells a fully met fit (yes) from a guaranteed core with a
    flagged grazing band (core) and from a flagged best effort (no), and a failed fitter run is
    reported by its summary line, not by the tail of its table."""
    from studies import fit_study
    from studies import fits as F

    assert fit_study.guarantee(dict(feasible=True, core_guaranteed=True)) == "yes"
    assert fit_study.guarantee(dict(feasible=False, core_guaranteed=True)) == "core"
    assert fit_study.guarantee(dict(feasible=False, core_guaranteed=False)) == "no"
    out = ("paper_white_rgb: tol 0.02\n0-40 h5-90  tol  B  (12,6)  119  2.08%\n"
           "total 735 coefficients, 21.4 s, NOT guaranteed (best fit found, flagged infeasible); "
           "grazing band met; wrote /tmp/x.json\n")
    assert F._fit_failure(out, "") == ("total 735 coefficients, 21.4 s, NOT guaranteed (best fit found, "
                                       "flagged infeasible); grazing band met")
    assert F._fit_failure("", "error: no such file") == "error: no such file"


def test_model_summary_core_guarantee_follows_the_fitters_record(tmp_path):
    """``core_guaranteed`` comes from the coefficient file's per-channel ``valid`` (the core), so a
    fit whose band alone failed is "core", and one whose core failed is not."""
    import copy

    from fit.rational.coefficient_file import load, save
    from studies import fits as F
    from warp_rbrdf.paths import PACKAGE_DATA

    m = load(sorted(PACKAGE_DATA.glob("paper_white*.json"))[0])
    s = F.model_summary(m)
    assert s["feasible_all"] and s["core_guaranteed"]
    bad = copy.deepcopy(m)
    bad.fit_info["valid"] = [True, False, True]
    assert not F.model_summary(bad)["core_guaranteed"]
    # a flagged file in the cache is refused unless the caller accepts best efforts
    tol = float(m.fit_info["tolerance"])
    save(bad, tmp_path / f"paper_white_rgb_tol{F._tag(tol)}_cli.json")
    none, info = F.rational_model("paper", tol, allow_fit=False, fit_dir=tmp_path)
    assert none is None and "flagged" in info["error"]
    got, info = F.rational_model("paper", tol, allow_fit=False, fit_dir=tmp_path, allow_infeasible=True)
    assert info["source"] == "cli (cached)" and not F.model_summary(got)["core_guaranteed"]


# --------------------------------------------------------------------------------------------
# Failure map (pinned findings)
@pytest.fixture(scope="module")
def failure_map(tmp_path_factory, rgl_data):
    from studies import failure_map as fm

    out = tmp_path_factory.mktemp("failure_map")
    r = fm.run("test", out, samplers=["uniform", "cosine", "light", "mis"], quiet=True)
    r["rows"] = {x["case"]: x for x in r["samplers"]}
    r["out"] = out
    return r


def test_mirror_lobe_file_is_exact_merl_layout(failure_map):
    from fit.formats.merl import MERL_FILE_BYTES, read_merl
    from studies import failure_map as fm

    p = failure_map["out"] / f"mirror_n{fm.MIRROR_EXPONENT}.binary"
    assert p.stat().st_size == MERL_FILE_BYTES
    m = read_merl(p)
    peak = m.values[0, :, :, 1].max()
    assert peak == pytest.approx((fm.MIRROR_EXPONENT + 8) / (8 * np.pi), rel=0.01)


def test_failure_mirror_lobe_all_base_samplers(failure_map):
    """Near-mirror lobe: none of the base samplers samples the lobe, so under both maps every one
    of them (uniform, cosine, environment, MIS with cosine BSDF sampling) stays above 100 %
    relative error at 32 spp (measured 5-8x at this size)."""
    for case in ("mirror lobe / studio", "mirror lobe / sun"):
        r = failure_map["rows"][case]
        assert min(r[f"{s}_rel_err"] for s in ("uniform", "cosine", "light", "mis")) > 1.0, case


def test_failure_tiny_sun_cosine_and_uniform(failure_map):
    """Diffuse paper under the tiny bright sun: cosine sampling is > 5x and uniform sampling
    > 3x noisier than environment (light) sampling and MIS."""
    r = failure_map["rows"]["paper sphere / sun"]
    for s, k in (("cosine", 5), ("uniform", 3)):
        assert r[f"{s}_rel_err"] > k * r["light_rel_err"]
        assert r[f"{s}_rel_err"] > k * r["mis_rel_err"]


def test_failure_grazing_projection_error(failure_map):
    """The 2-D projection's error against the 3-D table (ibiza, ΔE2000) grows at a grazing view:
    > 2x the error seen from above, and > 2x the render noise."""
    g = failure_map["other"]["projection_de_grazing_plane"]
    n = failure_map["other"]["projection_de_normal_plane"]
    assert g["de_mean"] > 2 * n["de_mean"]
    assert g["de_mean"] > 2 * g["noise_de_mean"]


def test_low_albedo_sampler_noise_is_scale_invariant(failure_map):
    """A BRDF scaled by 0.02: the estimators are linear, so the relative noise is unchanged
    (low albedo is not a sampler failure)."""
    lo = failure_map["rows"]["paper×0.02 sphere / studio"]
    hi = failure_map["rows"]["paper sphere / studio"]
    for s in ("uniform", "cosine", "light", "mis"):
        assert lo[f"{s}_rel_err"] == pytest.approx(hi[f"{s}_rel_err"], rel=1e-3)


def test_failure_fits(failure_map):
    """Fits at 5 %: the mirror lobe is infeasible (flagged) at degrees where paper fits; with an
    interval floor relative to the peak it fits but its relative error explodes; a low-albedo
    material (x0.02) with the absolute floor of 1e-3 /sr loses the 5 % relative guarantee."""
    o = failure_map["other"]
    assert o["fit_paper"]["feasible"]
    assert not o["fit_mirror"]["feasible"]
    assert o["fit_mirror"]["n_coefficients"] > o["fit_paper"]["n_coefficients"]
    assert o["fit_mirror_floor_0.1%_of_peak"]["max_rel_err"] > 1.0
    assert o["fit_paper_x0.02"]["max_rel_err"] > 3 * 0.05
    assert o["fit_paper"]["max_rel_err"] < 0.1
    # where the interval is relative (value >= floor / tol) a feasible fit keeps the tolerance;
    # scaling by 0.02 pushes most of paper below that value: the relative guarantee is lost there
    for k, v in o.items():
        if k.startswith("fit_") and v["feasible"] and v["relative_share"] > 0:
            assert v["max_rel_err_relative"] <= 0.05 * 1.01, k
    assert o["fit_paper"]["relative_share"] > 0.9
    assert o["fit_paper_x0.02"]["relative_share"] < 0.5 * o["fit_paper"]["relative_share"]


def test_failure_map_outputs(failure_map):
    out = failure_map["out"]
    assert (out / "failure_map.png").stat().st_size > 0
    md = (out / "failure_map.md").read_text()
    assert "mirror lobe / sun" in md and "| case |" in md


# --------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_convergence_moderate(tmp_path, rgl_data):
    from studies import convergence

    r = convergence.run("moderate", tmp_path, quiet=True)
    assert r["summary"]


def test_model_summary_of_nested_piecewise_model():
    """Coefficient counts per channel of a theta_d-piecewise model whose first piece is split
    again in theta_h (as fitted for cc_iris_purple_gem)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_warp_rational import piecewise_model

    from studies import fits as F

    m = piecewise_model()
    s = F.model_summary(m)
    assert s["n_pieces"] == 4 and s["n_coefficients"] == m.n_coefficients
    assert sum(s["per_channel"]) == m.n_coefficients


def test_failure_mirror_cdf_is_bounded_and_explicit(failure_map):
    """The near-mirror lobe's rational inverse CDFs (pieces layout, the default): built without
    reaching a time limit (the rows layout verified 5/32 rows in 20 s, the global one ran 169 s
    unbounded; the pieces take ~10-25 s, reported in the study, not limited here); every row is
    rational or sent to the table with its reason, and the summary says which (never silently)."""
    m = failure_map["other"]["mirror_cdf"]
    assert m["layout"] == "pieces" and m["n_rows"] == 32 and "time limit" not in m["reason"]
    assert 0 < m["verified_rows"] < m["n_rows"]              # the sharp lobe: some rows on the table
    assert m["fallback"] or (f"{m['verified_rows']}/{m['n_rows']} view rows" in m["reason"]
                             or f"all {m['n_rows']} view rows" in m["reason"])
    assert m["reason"] in failure_map["markdown"]


def test_studies_share_one_cdf_table_per_material(rgl_data):
    from studies import common as C

    spec = C.material_spec("measured", C.measured("paper"))
    scene = C.make_scene("sphere", "studio", spec, resolution=8)
    a = C.with_sampler(scene, "tabulated")
    b = C.with_sampler(scene, "mis-tabulated")
    ma, mb = next(iter(a.materials.values())), next(iter(b.materials.values()))
    assert ma.cdf is not None and ma.cdf is mb.cdf and ma.cdf.table is not None
    assert next(iter(scene.materials.values())).cdf is None      # the base scene is untouched



# --------------------------------------------------------------------------------------------
# Publishing (--docs): docs/images, docs/study_<name>.md and the README block between markers
STUDY_DOCS = {"convergence": "convergence", "comparison": "comparison", "fit": "fit_study",
              "failure_map": "failure_map"}   # README marker name -> module


def _docs_root(tmp_path):
    """A folder holding a copy of the repository's README.md (with the studies' markers), each
    study's block marked with a sentinel line so that its replacement can be checked."""
    from studies import common as C

    root = tmp_path / "root"
    root.mkdir()
    shutil.copyfile(C.ROOT / "README.md", root / "README.md")
    text = (root / "README.md").read_text(encoding="utf-8")
    for name in STUDY_DOCS:
        end = C.readme_markers(name)[1]
        text = text.replace(end, f"OLD-BLOCK-{name}\n{end}")
    (root / "README.md").write_text(text, encoding="utf-8")
    return root


def _split(text, name):
    """(text up to and including the BEGIN marker, the block, text from the END marker on)."""
    from studies import common as C

    begin, end = C.readme_markers(name)
    i, j = text.index(begin) + len(begin), text.index(end)
    return text[:i], text[i:j], text[j:]


def test_readme_has_one_marker_pair_per_study():
    import importlib

    from studies import common as C

    text = (C.ROOT / "README.md").read_text(encoding="utf-8")
    for name, module in STUDY_DOCS.items():
        begin, end = C.readme_markers(name)
        assert text.count(begin) == 1 and text.count(end) == 1 and text.index(begin) < text.index(end)
        docs = importlib.import_module(f"studies.{module}").DOCS
        assert docs["name"] == name
        assert all(d.startswith("study_") and d.endswith(".png") for d in docs["charts"].values())
        for d in docs.get("readme_charts") or docs["charts"].values():   # the README links them
            assert d in docs["charts"].values() and f"docs/images/{d}" in _split(text, name)[1]
    assert "--docs" in text


def test_publish_docs_replaces_only_the_block_and_is_idempotent(tmp_path):
    from studies import common as C

    root = _docs_root(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.png").write_bytes(b"\x89PNG first chart")
    (out / "b.png").write_bytes(b"\x89PNG second chart")
    before = (root / "README.md").read_text(encoding="utf-8")
    meta = {"wall_seconds": 12.3, "machine": {"cpus": 2, "platform": "TestOS-1", "python": "3.x",
                                              "time": "2000-01-02 03:04:05"}}
    kw = dict(name="fit", title="Fit study", out=out, meta=meta,
              summary_md="Full summary.\n\n| a | b |\n| --- | --- |\n| 1 | 2 |\n",
              charts={"a.png": "study_fit.png", "b.png": "study_fit_extra.png"},
              readme_table="| k | v |\n| --- | --- |\n| paper | 42 |\n",
              command="python studies/fit_study.py --smoke --docs", docs_root=root,
              readme_charts=("study_fit.png",))
    pub = C.publish_docs(**kw)
    after = (root / "README.md").read_text(encoding="utf-8")
    b0, _, e0 = _split(before, "fit")
    b1, block, e1 = _split(after, "fit")
    assert (b1, e1) == (b0, e0)                         # everything outside the block unchanged
    assert block == "\n" + pub["block"] + "\n"
    lines = pub["block"].splitlines()
    assert lines[0] == "**Fit study** · `python studies/fit_study.py --smoke --docs` (12 s on 2 CPUs, 2000-01-02)"
    assert "![study_fit](docs/images/study_fit.png)" in lines
    assert "study_fit_extra" not in pub["block"]         # not among readme_charts
    assert "| paper | 42 |" in lines and "[docs/study_fit.md](docs/study_fit.md)" in lines[-1]
    assert "OLD-BLOCK-fit" in before and "OLD-BLOCK-fit" not in after   # the old block is gone
    assert "OLD-BLOCK-comparison" in after
    assert (root / "docs/images/study_fit.png").read_bytes() == b"\x89PNG first chart"
    assert (root / "docs/images/study_fit_extra.png").read_bytes() == b"\x89PNG second chart"
    doc = (root / "docs/study_fit.md").read_text(encoding="utf-8")
    assert doc.startswith("# Fit study\n")
    assert "Command: `python studies/fit_study.py --smoke --docs`" in doc
    assert "Wall time: 12 s" in doc and "2 CPUs, TestOS-1, Python 3.x" in doc
    assert "![study_fit](images/study_fit.png)" in doc and "![study_fit_extra](images/study_fit_extra.png)" in doc
    assert doc.rstrip().endswith("| 1 | 2 |")
    # again: the same bytes (idempotent)
    C.publish_docs(**kw)
    assert (root / "README.md").read_text(encoding="utf-8") == after
    assert (root / "docs/study_fit.md").read_text(encoding="utf-8") == doc
    # another study's block is replaced independently of the first
    C.publish_docs(**dict(kw, name="failure_map", charts={"a.png": "study_failure_map.png"}, readme_charts=None))
    final = (root / "README.md").read_text(encoding="utf-8")
    assert _split(final, "fit")[1] == block and final.count("| paper | 42 |") == 2


def test_publish_docs_without_markers_raises_and_writes_nothing(tmp_path):
    from studies import common as C

    root = _docs_root(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.png").write_bytes(b"png")
    text = (root / "README.md").read_text(encoding="utf-8")
    kw = dict(name="fit", title="t", out=out, summary_md="s", meta={}, charts={"a.png": "study_fit.png"},
              readme_table="| x |", command="python x.py", docs_root=root)
    for marker in C.readme_markers("fit"):
        (root / "README.md").write_text(text.replace(marker, ""), encoding="utf-8")
        with pytest.raises(ValueError, match=re.escape(marker)):
            C.publish_docs(**kw)
    with pytest.raises(ValueError, match=re.escape("<!-- BEGIN study:nosuch -->")):
        C.replace_block(text, "nosuch", "x")
    assert not (root / "docs").exists()                   # checked before anything is written
    (root / "README.md").write_text(text, encoding="utf-8")
    with pytest.raises(FileNotFoundError, match="missing.png"):
        C.publish_docs(**dict(kw, charts={"missing.png": "study_fit.png"}))
    assert not (root / "docs").exists()
    readme = (C.ROOT / "README.md").read_bytes()
    with pytest.raises(ValueError, match="--smoke run would overwrite"):  # the repository's own docs
        C.publish_docs(**dict(kw, meta={"preset": "smoke"}, docs_root=None))
    assert (C.ROOT / "README.md").read_bytes() == readme


def test_command_line_and_docs_option(capsys):
    import importlib

    from studies import common as C

    assert C.command_line(C.ROOT / "studies" / "convergence.py", ["--out", "a b", "--docs"]) \
        == "python studies/convergence.py --out 'a b' --docs"
    for module in STUDY_DOCS.values():
        with pytest.raises(SystemExit):
            importlib.import_module(f"studies.{module}").main(["--help"])
        assert "--docs " in capsys.readouterr().out


def test_failure_map_smoke_publishes_docs(tmp_path, rgl_data):
    """A real smoke run through the CLI with --docs into a copy of the README."""
    from studies import common as C
    from studies import failure_map as fm

    root = _docs_root(tmp_path)
    before = (root / "README.md").read_text(encoding="utf-8")
    out = tmp_path / "out"
    argv = ["--smoke", "--out", str(out), "--samplers", "uniform", "cosine", "light", "mis",
            "--docs", "--docs-root", str(root)]
    r = fm.main(argv)
    cmd = C.command_line(fm.__file__, argv)
    assert cmd.startswith("python studies/failure_map.py --smoke --out ")
    assert (root / "docs/images/study_failure_map.png").read_bytes() == (out / "failure_map.png").read_bytes()
    doc = (root / "docs/study_failure_map.md").read_text(encoding="utf-8")
    assert f"Command: `{cmd}`" in doc
    assert (out / "failure_map.md").read_text(encoding="utf-8").strip() in doc
    after = (root / "README.md").read_text(encoding="utf-8")
    b0, _, e0 = _split(before, "failure_map")
    b1, block, e1 = _split(after, "failure_map")
    assert (b1, e1) == (b0, e0)
    assert f"**Failure map** · `{cmd}` (" in block
    assert "![study_failure_map](docs/images/study_failure_map.png)" in block
    assert "| case | uniform | cosine | light | mis |" in block
    sun = r["samplers"][[x["case"] for x in r["samplers"]].index("paper sphere / sun")]
    assert f"| paper sphere / sun | {C._fmt(sun['uniform_rel_err'])} | {C._fmt(sun['cosine_rel_err'])} |" in block
    assert "Rational inverse CDFs of the mirror lobe" in block and "| mirror_floor" not in block  # fits: docs only
    assert "| mirror_floor" in doc
    assert "OLD-BLOCK-failure_map" in before and "OLD-BLOCK-failure_map" not in after
