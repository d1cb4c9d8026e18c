"""The benchmarks are modules of the ``benchmarks`` package (``python -m benchmarks.<name>`` from
the checkout root): each imports as such and its ``--help`` works. Their timings are never
tested."""
from __future__ import annotations

import importlib
import json

import numpy as np
import pytest
from conftest import data_file, require_mitsuba

pytestmark = pytest.mark.lab  # tests lab code only (the `lab` marker of pyproject.toml)

BENCHMARKS = ("bench_albedo_pole", "bench_convert", "bench_cuda", "bench_dial", "chart_fits", "bench_env_sample_cost", "bench_env_sampling", "bench_error_sources", "bench_eval", "bench_fit", "bench_fit_accuracy", "bench_fit_time", "bench_lanes", "bench_layouts", "bench_mis_compensation", "bench_numpy_eval", "bench_projection", "bench_proved_bound", "bench_rational_domain", "bench_render", "bench_rgl", "bench_sampler_setup", "bench_samplers",
              "bench_spectral", "bench_startup", "bench_vs_mitsuba", "bench_mesh_vs_mitsuba")


@pytest.mark.parametrize("name", BENCHMARKS)
def test_benchmark_help(name, capsys):
    module = importlib.import_module(f"benchmarks.{name}")
    with pytest.raises(SystemExit) as e:
        module.main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: ") and f"python -m benchmarks.{name}" in out


# --------------------------------------------------------------------------------------------
# bench_cuda: its agreement test, on the CPU device against itself and against a biased image


def test_bench_cuda_agreement_flags_a_bias(tmp_path):
    from benchmarks import bench_cuda

    ref = tmp_path / "ref"
    args = ["--cases", "lambert", "--scenes", "sphere-sky", "--check-resolution", "24", "--check-spp", "16"]
    assert bench_cuda.main(["--write-reference", str(ref), *args]) == 0
    out = tmp_path / "cpu.json"
    assert bench_cuda.main(["--device", "cpu", "--reference", str(ref), "--resolution", "16", "--spp", "4",
                            "--repeats", "1", "--out", str(out), *args]) == 0
    row = json.loads(out.read_text())["cases"]["sphere-sky/lambert"]
    assert row["agreement"]["agrees"] and row["agreement"]["mean_z2"] == 0.0
    assert row["speed"]["samples"] == 16 * 16 * 4
    z = np.load(ref / "sphere-sky__lambert.npz")
    probe = {k: z[k] for k in z.files}
    probe["spp"] = int(probe["spp"])
    biased = dict(probe, image=probe["image"] * 1.05)   # a 5 % bias: far outside the pixels' noise
    assert not bench_cuda.compare(biased, probe)["agrees"]
    rng = np.random.default_rng(0)   # an independent estimate of the same image: agrees
    noisy = dict(probe, image=probe["image"] + rng.standard_normal(probe["image"].shape).astype(np.float32)
                 * np.sqrt(probe["variance"] / probe["spp"]))
    assert bench_cuda.compare(noisy, probe)["agrees"]
    # the 3-D case reads the chart's fit of today's fitter defaults, in --fits-3d
    text = bench_cuda.scene_text("sphere-sky", "rational3d-satin", tmp_path, 16, 4, bench_cuda.chart_fit3d(tmp_path / "f3"))
    assert f'file = "{bench_cuda.chart_fit3d(tmp_path / "f3")}"' in text
    assert bench_cuda.chart_fit3d(tmp_path / "f3").parent == tmp_path / "f3"


# --------------------------------------------------------------------------------------------
# bench_mesh_vs_mitsuba: the mesh both renderers read, and a smoke run
def test_mesh_for_mitsuba_is_ours(tmp_path):
    """The PLY written for Mitsuba holds our loader's triangles and normals after the transform
    that puts the mesh's bounding box at the origin with its largest side MESH_EXTENT."""
    from benchmarks import bench_mesh_vs_mitsuba as B
    from warp_rbrdf.geometry import load_mesh_file

    v, f, n = load_mesh_file(data_file("meshes/teapot.obj"))
    m = B.mesh_to_world(v)
    w = v @ m[:3, :3].T + m[:3, 3]
    assert np.allclose((w.max(0) + w.min(0)) / 2, 0, atol=1e-9)
    assert np.isclose((w.max(0) - w.min(0)).max(), B.MESH_EXTENT)
    B.write_ply(tmp_path / "t.ply", w, f, n)
    raw = (tmp_path / "t.ply").read_bytes()
    body = raw[raw.index(b"end_header\n") + len(b"end_header\n"):]
    verts = np.frombuffer(body[:len(v) * 24], "<f4").reshape(-1, 6)
    faces = np.frombuffer(body[len(v) * 24:], dtype=[("n", "u1"), ("i", "<i4", 3)])
    assert len(faces) == len(f) and np.all(faces["n"] == 3) and np.array_equal(faces["i"], f)
    assert np.allclose(verts[:, :3], w, atol=1e-6) and np.allclose(verts[:, 3:], n, atol=1e-6)


def test_bench_mesh_vs_mitsuba_smoke(tmp_path):
    """A tiny run (Mitsuba's scalar variant): the teapot renders the same in both (means within
    4 standard errors of their difference, which is below 8 %: a mesh left untransformed moves
    it by 66 %), every number is there."""
    MR = require_mitsuba()
    data_file("meshes/teapot.obj")
    data_file("envmaps/studio_small_03_1k.hdr")
    from benchmarks import bench_mesh_vs_mitsuba as B

    out = tmp_path / "m.json"
    assert B.main(["--variant", MR.VARIANT, "--objects", "teapot", "--materials", "lambert",
                   "--resolution", "32", "--spp", "16", "--rounds", "2", "--out", str(out)]) == 0
    (c,) = json.loads(out.read_text())["cases"]
    assert c["pixels_on_object"] > 100 and c["mean_rel_diff_se"] < 0.08
    assert abs(c["mean_rel_diff"]) < 4 * c["mean_rel_diff_se"], c
    for k in ("ours", "mitsuba"):
        assert c[k]["samples_per_s"] > 0 and c[k]["rel_variance_per_sample"] > 0


# --------------------------------------------------------------------------------------------
# bench_vs_mitsuba: its error estimate and time-to-target arithmetic, and a smoke run
def test_seed_pair_rmse_and_time_to_target():
    """The seed-pair estimate recovers a known per-pixel noise, and the time to the target is
    exact for RMSE ~ N^-1/2 with time ~ N (interpolated between bracketing rungs, extrapolated
    past the last, scaled down from a first rung already below it)."""
    from benchmarks.bench_vs_mitsuba import (
        Rung,
        last_slope,
        relative_rmse,
        time_to_target,
        time_to_target_slope,
    )

    rng = np.random.default_rng(5)
    truth = rng.uniform(0.5, 1.5, (64, 64, 3))
    mask = np.zeros((64, 64), bool)
    mask[8:56, 8:56] = True
    sigma = 0.05
    e, mean = relative_rmse(truth + rng.normal(0, sigma, truth.shape), truth + rng.normal(0, sigma, truth.shape), mask)
    assert abs(mean / truth[mask].mean() - 1) < 0.01
    assert abs(e / (sigma / truth[mask].mean()) - 1) < 0.03

    def rungs(spps, c=0.8, rate=1000.0, p=0.5):
        return [Rung(n, n / rate, c * n ** -p, 1.0) for n in spps]

    exact = (0.8 / 0.01) ** 2 / 1000.0          # N at 1 % over the rate
    t, how = time_to_target(rungs([4, 16, 64]), 0.01)
    assert how == "extrapolated" and np.isclose(t, exact)
    t, how = time_to_target(rungs([1024, 4096, 16384]), 0.01)
    assert how == "interpolated" and np.isclose(t, exact)
    t, how = time_to_target(rungs([16384, 65536]), 0.01)
    assert how == "measured" and np.isclose(t, exact)
    assert np.isclose(last_slope(rungs([4, 16, 64])), -0.5)
    # a steeper measured slope: the slope extrapolation follows it, N^-1/2 overstates the time
    steep = rungs([4, 16, 64], p=0.75)
    exact_steep = (0.8 / 0.01) ** (1 / 0.75) / 1000.0
    assert np.isclose(time_to_target_slope(steep, 0.01), exact_steep)
    assert time_to_target(steep, 0.01)[0] > exact_steep


def test_bench_vs_mitsuba_smoke(tmp_path):
    """A tiny run (Mitsuba's scalar variant, no system package): every number is there, and the
    check against a converged Mitsuba reference says the seed-pair estimate is right for both
    renderers and that our rgl render agrees with Mitsuba's (what the benchmark rests on)."""
    MR = require_mitsuba()
    data_file("rgl/paper_white_rgb.bsdf")
    data_file("envmaps/studio_small_03_1k.hdr")
    from benchmarks import bench_vs_mitsuba as B

    out = tmp_path / "b.json"
    assert B.main(["--materials", "paper_white_rgb", "--maps", "studio", "--resolution", "48",
                   "--spp", "4", "16", "--variant", MR.VARIANT, "--check", "1", "--check-spp", "512",
                   "--extend-rmse", "0.05", "--extend-max-spp", "256", "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    (case,) = res["cases"]
    assert case["best"] == "rgl:mis-rgl" and set(case["renderers"]) == {"rgl:mis-rgl", "mitsuba"}
    # --extend-rmse 0.05: the 16-spp rung (relative RMSE ~0.1) is extended once, both renderers;
    # at 64 spp (~0.035) the estimate is trusted
    ext = case["extension"]
    assert [x["spp"] for x in ext["rungs"]] == [64] and ext["top_spp"] == 64
    assert ext["status"] == "trusted" and all("rel. RMSE" in w for w in ext["rungs"][0]["reasons"])
    for r in case["renderers"].values():
        assert [x["spp"] for x in r["rungs"]] == [4, 16, 64]
        assert r["time_to_target_s"] > 0 and r["samples_per_s"] > 0 and r["how"] == "extrapolated"
        assert r["rungs"][2]["rel_rmse"] < r["rungs"][1]["rel_rmse"] < r["rungs"][0]["rel_rmse"]
        assert 0 < r["rungs"][2]["mse_se"] < 0.1
    assert np.isfinite(case["ratio"]) and case["ratio"] > 0
    assert 0 < case["ratio_log_se"] < 0.1
    chk = case["check"]["renderers"]
    for label in ("rgl:mis-rgl", "mitsuba"):
        assert 0.8 < chk[label]["ratio"] < 1.25, (label, chk[label])   # estimate == error vs reference
        assert abs(chk[label]["mean_z"]) < 5, (label, chk[label])       # same converged mean
    assert res["summary"]["cases"] == 1 and np.isfinite(res["summary"]["median_rate_ratio"])


def test_bench_mis_compensation_smoke(tmp_path):
    """A tiny run: the compensated rows are compensated, the reference is not, and the table
    reads the same from the JSON it writes."""
    from benchmarks import bench_mis_compensation as B

    data_file("envmaps/studio_small_03_1k.hdr")
    out = tmp_path / "r.json"
    assert B.main(["--quick", "--materials", "lambert", "--maps", "studio", "--fractions", "0.5",
                   "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    row = res["cases"][0]["spp"]["4"]
    assert row["0.5"]["compensated"] and not row["0.0"]["compensated"]
    assert all(np.isfinite(v["rel_rmse"]) and v["rel_rmse"] > 0 for v in row.values())
    assert "| lambert | studio | 4 |" in B.markdown(res)


def test_bench_env_sample_cost_smoke(tmp_path):
    """A tiny run: every stage has a time, the stages add up (each kernel does the one before
    and more), and the float32 descent reaches the float64 one's block for nearly every sample."""
    from benchmarks import bench_env_sample_cost as B

    data_file("envmaps/studio_small_03_1k.hdr")
    out = tmp_path / "cost.json"
    assert B.main(["--maps", "studio", "--samples", "4096", "--repeats", "1", "--json", str(out)]) == 0
    cases = json.loads(out.read_text())["cases"]
    assert set(cases) == {"studio/random", "studio/sorted"}
    for r in cases.values():
        ns = r["ns_per_sample"]
        assert set(ns) == {"descent", "+ select", "+ invert", "descent, float32"} and min(ns.values()) > 0
        assert r["float32_same_block"] > 0.99
    with pytest.raises(SystemExit) as e:
        B.main(["--samples", "0"])
    assert e.value.code == 2


def test_bench_env_sampling_smoke(capsys):
    """A tiny run: every row is a finite relative RMSE, and the table lists them."""
    from benchmarks import bench_env_sampling as B
    from conftest import data_file

    data_file("envmaps/studio_small_03_1k.hdr")
    r = B.main(["--quick", "--res", "24", "--spp", "1,4", "--maps", "studio", "--no-mitsuba",
                "--schemes", "piecewise-constant,hierarchical", "--no-rate"])
    assert {(x["scheme"], x["spp"]) for x in r["rows"]} == {(s, n) for s in ("piecewise-constant", "hierarchical")
                                                           for n in (1, 4)}
    assert all(0 < x["rel_rmse"] < 10 for x in r["rows"])
    assert "| studio | ours | hierarchical | stratified |" in capsys.readouterr().out


# --------------------------------------------------------------------------------------------
# bench_proved_bound: the 3-D fit it proves is the chart's, of today's fitter defaults


def test_bench_proved_bound_picks_todays_3d_fit(tmp_path, monkeypatch):
    """The chart's cache file when it exists; else the newest file whose recorded layouts and
    settings are today's defaults, never a newer fit of an earlier layout; else none."""
    import os

    from benchmarks import bench_proved_bound as B
    from benchmarks.chart_fits import fit3d_path
    from fit.rational.settings import Fit3DSettings

    data = tmp_path / "rgl"
    data.mkdir()
    (data / "x_rgb.bsdf").write_bytes(b"not a measurement")
    monkeypatch.setattr(B, "data_dir", lambda: data)
    fits = tmp_path / "fits"
    fits.mkdir()
    d = Fit3DSettings()
    recorded = {k: getattr(d, a) for k, a in B._RECORDED.items()}
    today = [{"options": o} for o in B.todays_layouts()]
    today[-1] = {"options": dict(today[-1]["options"], tol=0.01), "skipped": "validation RMSE >= 0.065"}
    old = [{"options": {"theta_h_edges": [0.05, 0.1, 0.2], "piece_degrees": [[4, 2]] * 4}}]
    assert B.chart_fit_3d("x_rgb", fits)[0] is None
    for name, variants, t in (("x_rgb_3d_000000000000.json", today, 1), ("x_rgb_3d_ffffffffffff.json", old, 3),
                              ("x_rgb_3d_111111111111.json", today, 2)):
        (fits / name).write_text(json.dumps({"fit": dict(recorded, variants=variants)}))
        os.utime(fits / name, (t, t))
    p, how = B.chart_fit_3d("x_rgb", fits)
    assert p.name == "x_rgb_3d_111111111111.json" and "today's layouts" in how   # newest of today's
    (fits / "x_rgb_3d_111111111111.json").write_text(json.dumps({"fit": dict(recorded, variants=today,
                                                                             wall_limit=60.0)}))
    assert B.chart_fit_3d("x_rgb", fits)[0].name == "x_rgb_3d_000000000000.json"   # a wall limit: not the default
    chart = fit3d_path(data / "x_rgb.bsdf", fit_dir=fits)
    chart.write_text(json.dumps({"fit": {}}))
    p, how = B.chart_fit_3d("x_rgb", fits)
    assert p == chart and "chart's key" in how


def test_bench_proved_bound_lists_every_run_it_merges(tmp_path, monkeypatch):
    """``--merge`` keeps an earlier run's rows and lists both runs in the docs' run lines, each
    with its own materials and models (the run lines of ``--docs`` read them)."""
    from benchmarks import bench_proved_bound as B

    earlier = {"date": "2026-11-27", "load": [2.0, 2.0, 2.0], "load_end": [3.0, 3.0, 3.0], "tol": 0.05,
               "enclosures": ["joint"], "materials": {"a": {"target": 0.1, "2d": {}}, "b": {"target": 0.1, "2d": {}}}}
    now = dict(earlier, date="2026-11-28", load=[1.0, 1.0, 1.0], load_end=[1.5, 1.5, 1.5],
               materials={"b": {"target": 0.1, "3d": {}}})
    files = []
    for k, r in enumerate((earlier, now)):
        files.append(tmp_path / f"r{k}.json")
        files[-1].write_text(json.dumps(r))
    out = B.merged([str(f) for f in files])
    assert [r["materials"] for r in out["runs"]] == [{"a": ["2d"], "b": ["2d"]}, {"b": ["3d"]}]
    assert set(out["materials"]["b"]) == {"target", "2d", "3d"}
    docs = tmp_path / "doc.md"
    docs.write_text(f"before\n{B.MARK[0]}\nold\n{B.MARK[1]}\nafter\n")
    monkeypatch.setattr(B, "DOCS", docs)
    monkeypatch.setattr(B, "table", lambda out: "TABLE")
    B.write_docs(out)
    text = docs.read_text()
    assert "- 2026-11-27, load average 2.0 at the start and 3.0 at the end: a (2-D), b (2-D)" in text
    assert "- 2026-11-28, load average 1.0 at the start and 1.5 at the end: b (3-D)" in text
    assert "TABLE" in text and "old" not in text and text.startswith("before") and text.endswith("after\n")


def test_bench_dial_default_pick_follows_the_selection_rule():
    """bench_dial's offline copy of the default selection: the image score under
    ``select_by="image"`` (5 % margin), the ``if_rmse_below`` gate on the validation RMSE."""
    from benchmarks.bench_dial import default_pick

    def row(v, rmse, img):
        return {"variant": v, "valid": True, "validation_rmse": rmse, "validation_score": rmse, "image_score": img}

    assert default_pick([row(0, 0.03, 1.5), row(1, 0.05, 1.0)]) == 1        # the image decides, not the RMSE
    assert default_pick([row(0, 0.03, 1.0), row(1, 0.02, 0.97)]) == 0       # within the 5 % margin
    assert default_pick([row(0, 0.09, 1.5), row(1, 0.05, 1.0)]) == 0       # gated: 0.09 >= 0.065
    assert default_pick([row(0, 0.03, 1.5), row(1, 0.05, 1.2), row(2, 0.03, 1.0)]) == 2   # the third layout
    assert default_pick([row(0, 0.03, 1.5), row(1, 0.05, 1.0), row(2, 0.03, 0.97)]) == 1  # within the margin


def test_bench_dial_image_marks():
    """The dial's image mark: the fewest coefficients of the ladder whose renders meet mean <= 1
    and p99 <= 3 under every map (the default's own row never counts as a rung)."""
    from benchmarks.bench_dial import DEFAULT_ROW, image_met, markdown, smallest_image, smallest_meeting

    def row(layout, n, rmse, *des):
        r = {"layout": layout, "coefficients": n, "rel_rmse": rmse, "median_rel": 0.1, "p95_rel": 0.2, "valid": True}
        if des:
            r["render"] = {m: {"de_mean": a, "de_p99": b} for m, (a, b) in zip(("studio", "rooitou"), des)}
        return r

    rows = [row("a", 72, 0.2, (0.9, 2.0), (1.1, 2.0)),     # misses under rooitou
            row("b", 135, 0.06, (0.9, 3.5), (0.5, 1.0)),   # misses p99 under studio
            row("c", 198, 0.04, (0.8, 2.9), (0.9, 3.0)),   # meets both
            row(DEFAULT_ROW, 420, 0.01, (0.3, 1.0), (0.3, 1.0)),
            row("d", 1125, 0.03, (0.5, 2.0), (0.4, 2.0))]
    assert [image_met(r) for r in rows] == [False, False, True, True, True]
    assert image_met(row("x", 1, 0.1)) is None
    assert smallest_image(rows) == 2 and smallest_image(rows[3:4]) is None
    assert smallest_meeting(rows, 0.02) is None and smallest_meeting(rows, 0.05) == 2
    meta = {"tol_rmse": 0.05, "tols": [0.05], "command": "x", "date": "d", "machine": "m", "load": "l", "pairs": 10,
            "seed": 0, "complete": True, "render_maps": ["studio", "rooitou"], "render_res": 8, "render_spp": 4}
    text = markdown({"m": rows}, meta)
    assert "| c | 198 | 0.0400 |" in text and "0.80 / 2.90 | 0.90 / 3.00 | **S** **I** |" in text
    assert f"| {DEFAULT_ROW} | 420 |" in text and "1.00 | **D** |" in text
    assert "The image target is met from 198 coefficients (c); the default (420 coefficients) meets it." in text
    assert "Image target met by some layout of the ladder on 1 of 1 materials; by the default on 1." in text


def test_bench_dial_ladder_flags_fit_the_same_layout():
    """Each layout's ``flags`` (docs/fit_dial.md: the command that fits it alone) give the command
    the layout the benchmark fits: the same settings, the objective included."""
    from benchmarks.bench_dial import LADDER, layout_settings
    from fit.cli import build_parser
    from fit.cli.brdf3d import settings_from_args
    from fit.rational.settings import Fit3DSettings

    parser, default = build_parser(), Fit3DSettings().objective
    flagged = [e for e in LADDER if e.get("flags")]
    assert len(flagged) >= 9
    for e in flagged:
        args = parser.parse_args(["brdf", "x.bsdf", "--out", "y.json", "--model", "3d", *e["flags"].split()])
        settings, (layout,) = settings_from_args(args)
        cli = {"objective": settings.objective, **layout}
        assert cli == {"objective": default, **layout_settings(e, keep_verify=True)}, e["name"]


def test_bench_dial_docs_are_those_of_the_stored_run():
    """docs/fit_dial.md and fit_accuracy.md's dial block are what ``--from-json`` writes from the
    stored run (docs/data/dial_*.json): generated, not edited by hand."""
    from benchmarks import bench_dial as D

    (stored,) = sorted((D.ROOT / "docs" / "data").glob("dial_*.json"))[-1:]
    results, meta = D._load_results([stored])
    text = D.markdown(results, meta)
    page = (D.ROOT / "docs" / "fit_dial.md").read_text(encoding="utf-8")
    assert page == D.DIAL_PAGE_HEAD + D.ladder_markdown() + "\n" + text
    block = (D.ROOT / "docs" / "fit_accuracy.md").read_text(encoding="utf-8").split(D.BEGIN)[1].split(D.END)[0]
    assert D.summary_markdown(results, meta) in block and block.startswith("\n" + text.split("\n\n", 1)[0])


def test_bench_dial_complete_render_smoke(tmp_path, monkeypatch):
    """One rung fitted as the command fits it alone, saved, measured and rendered (tiny renders)
    beside no default row; the table has the render columns."""
    from benchmarks import bench_dial as D

    data_file("rgl/paper_white_rgb.bsdf")
    monkeypatch.setattr(D, "LADDER", D.LADDER[:1])
    out = tmp_path / "dial"
    assert D.main(["--materials", "paper_white", "--complete", "--render", "--render-res", "8", "--render-spp", "4",
                   "--render-maps", "studio", "--pairs", "2000", "--no-default", "--out", str(out)]) == 0
    d = json.loads((out / "results.json").read_text())
    (r,) = d["results"]["paper_white"]
    assert r["coefficients"] == 72 and r["valid"] and r["proved_over_stated"] is not None
    assert (out / "fits" / "paper_white" / "1_piece_3_1.json").is_file() and r["file"].endswith("1_piece_3_1.json")
    assert set(r["render"]) == {"studio"} and r["render"]["studio"]["de_mean"] > 0
    assert d["meta"]["complete"] and d["meta"]["render_maps"] == ["studio"]
    assert D.main(["--render", "--render-spp", "3"]) == 2


def test_bench_lanes_smoke(tmp_path):
    """The lanes benchmark's two kernels render the same image (its agreement columns), on tiny
    renders; no timing is read."""
    from benchmarks import bench_lanes

    data_file("rgl/cc_ibiza_sunset_rgb.bsdf")
    out = tmp_path / "lanes.json"
    assert bench_lanes.main(["--quick", "--cases", "rgl", "lambert", "--maps", "studio", "--json", str(out)]) == 0
    cases = json.loads(out.read_text())["cases"]
    assert set(cases) == {"rgl/studio", "lambert/studio"}
    for r in cases.values():
        assert r["image_mean_rel_diff"] < 1e-5 and r["speedup"] > 0


# --------------------------------------------------------------------------------------------
# bench_albedo_pole: a normal-incidence slice that depends on the light's azimuth is measured as such


def test_bench_albedo_pole_measures_an_anisotropic_normal_slice():
    from benchmarks import bench_albedo_pole as B

    class Slice:
        """rho = 0.3 / pi (1 + 0.5 cos 2 dphi), dphi the light's azimuth less the view's (the
        tensors' incidence; atan2(0, 0) = 0 at the normal, as the RGL evaluation reads it)."""
        incident = "view"

        def __init__(self, amplitude):
            self.amplitude = amplitude

        def evaluate(self, wi, wo):
            d = np.arctan2(wi[..., 1], wi[..., 0]) - np.arctan2(wo[..., 1], wo[..., 0])
            v = 0.3 / np.pi * (1.0 + self.amplitude * np.cos(2.0 * d))
            return np.repeat(v[..., None], 3, axis=-1)

    aniso = B.measure(Slice(0.5), None, n=64 ** 2)
    assert aniso["fixed"] == "view" and aniso["slice_spread"] == pytest.approx(3.0, rel=1e-6)
    # in the plane of incidence cos 2 dphi = 1: 1.5x the whole azimuth's mean of 1
    np.testing.assert_allclose(aniso["truth_in_plane"], 1.5 * np.array(aniso["truth_normal"]), rtol=1e-6)
    assert aniso["in_plane_vs_truth"] == pytest.approx(0.5, rel=1e-6)
    np.testing.assert_allclose(aniso["truth_normal"], 0.3, rtol=1e-3)     # the albedo of 0.3 / pi
    iso = B.measure(Slice(0.0), None, n=64 ** 2)
    assert iso["slice_spread"] == pytest.approx(1.0) and iso["in_plane_vs_truth"] < 1e-9
    text = B.markdown({"aniso": aniso, "iso": iso}, {"fits": "x", "date": "d", "points": 4096})
    assert "| aniso | 3.00 | 50.0 % | n/a | n/a |" in text and "| iso | 1.00 | 0.0 % |" in text
