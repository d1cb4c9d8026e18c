"""Smoke test of ``benchmarks/bench_fit_accuracy.py`` (issue 25) on a tiny pair count, and its
metric on cases with a known answer; the benchmark's numbers themselves are docs/fit_accuracy.md."""
from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import data_file

from benchmarks import bench_fit_accuracy as B

pytestmark = pytest.mark.lab  # tests lab code only (the `lab` marker of pyproject.toml)


def test_metric_known_answers():
    wi, wo = B.cosine_pairs(4000, 1)
    assert np.allclose(np.linalg.norm(wi, axis=1), 1) and np.all(wi[:, 2] >= 0)
    # cosine-distributed: E[cos theta] = 2/3
    assert abs(wi[:, 2].mean() - 2 / 3) < 0.02
    truth = np.ones((4000, 3)) * [0.1, 0.2, 0.3]
    np.testing.assert_allclose(B.relative_rmse(truth * 1.05, truth, wi, wo), 0.05)
    med, p95 = B.relative_error_stats(truth * 1.05, truth)
    assert np.isclose(med, 0.05) and np.isclose(p95, 0.05)
    # a constant rho against 1.1 times it: the albedo error is 0.1 at every angle (same views)

    def lam(a, b):
        return np.full(b.shape[:-1] + (3,), 0.5 / np.pi)

    np.testing.assert_allclose(B.albedo_errors(lambda a, b: 1.1 * lam(a, b), lam, n=500), [0.1] * 4)
    # a channel darker than 5 % of the brightest is held to 5 % of the brightest (the targets'
    # rule): blue 0.001 against 0.002 is 0.001 / (0.05 x 0.5) = 4 % off, not 100 %
    dark = np.array([0.5, 0.5, 0.001]) / np.pi
    err = B.albedo_errors(lambda a, b: np.broadcast_to(dark * [1, 1, 2], b.shape[:-1] + (3,)).copy(),
                          lambda a, b: np.broadcast_to(dark, b.shape[:-1] + (3,)).copy(), n=500)
    np.testing.assert_allclose(err, [0.04] * 4, rtol=1e-3)


def test_smoke_run_and_bad_input(tmp_path, capsys):
    data = data_file("rgl/paper_white_rgb.bsdf").parents[1]
    out = tmp_path / "out"
    rc = B.main(["--data", str(data), "--materials", "paper_white", "--pairs", "500", "--albedo-samples", "300",
                 "--no-table", "--fits-2d", str(tmp_path), "--out", str(out), "--degrees", "3,1", "--edges", "",
                 "--grid", "8,7,5", "--random", "200", "--verify", "2000"])
    assert rc == 0
    res = json.loads((out / "results.json").read_text())
    f3 = res["rows"][0]["fit3d"]
    assert f3["valid"] and f3["coefficients"] == 3 * (20 + 4) and 0 < f3["rel_rmse"] < 1
    assert len(f3["albedo_err"]) == 4 and (out / "paper_white_rgb_3d.json").is_file()
    assert "| paper_white |" in capsys.readouterr().out
    saved = json.loads((out / "paper_white_rgb_3d.json").read_text())["fit"]["domain"]
    assert f3["proved_over_stated"] == saved["proved_over_stated"] > 0 and f3["proved"] == saved["proved"]
    # the render step on the saved fit: the table and the 2-D fit are absent, the 3-D fit rendered
    assert B.main(["--render-from", str(out / "results.json"), "--render-res", "8", "--render-spp", "4",
                   "--render-maps", "studio"]) == 0
    rr = json.loads((out / "render.json").read_text())
    assert rr["meta"]["spp"] == 4 and [(x["material"], x["map"]) for x in rr["rows"]] == [("paper_white", "studio")]
    assert set(rr["rows"][0]) >= {"fit3d", "floor_mean"} and "table" not in rr["rows"][0]
    assert rr["rows"][0]["fit3d"]["de_mean"] >= 0
    assert "3-D target met on" in capsys.readouterr().out
    for argv, words in ((["--materials", "no_such"], "--materials no_such"), (["--pairs", "5"], "--pairs 5"),
                        (["--degrees", "x"], "--degrees 'x'"),
                        (["--render-from", str(tmp_path / "none.json")], "--render-from"),
                        (["--render", "--render-spp", "3"], "--render-spp")):
        assert B.main(["--data", str(data), "--out", str(tmp_path / "o2")] + argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and words in err
    assert not (tmp_path / "o2" / "results.json").exists()


def test_render_block_counts_the_target_and_the_table():
    """``render_markdown``: a representation without a render is n/a; the 3-D target is mean <= 1
    and p99 <= 3; "3-D <= table" needs both numbers at most the table's; the count line says so."""
    rr = [{"material": "a", "map": "studio", "floor_mean": 0.1, "floor_p99": 0.4,
           "table": {"de_mean": 0.9, "de_p99": 4.0}, "fit3d": {"de_mean": 0.5, "de_p99": 2.0}},
          {"material": "a", "map": "rooitou", "floor_mean": 0.1, "floor_p99": 0.4,
           "table": {"de_mean": 0.4, "de_p99": 4.0}, "fit2d": {"de_mean": 2.0, "de_p99": 9.0},
           "fit3d": {"de_mean": 0.5, "de_p99": 3.5}}]
    text = B.render_markdown(rr, {"resolution": 64, "spp": 16})
    assert "| a | studio | 0.10 / 0.40 | 0.90 / 4.00 | n/a | 0.50 / 2.00 | yes | yes |" in text
    assert "| a | rooitou | 0.10 / 0.40 | 0.40 / 4.00 | 2.00 / 9.00 | 0.50 / 3.50 | no | no |" in text
    assert "3-D target met on 1 of 2 renders; 3-D at most the table's mean and p99 on 1 of 2." in text


def test_merge_keeps_earlier_rows(tmp_path, capsys):
    data = data_file("rgl/paper_white_rgb.bsdf").parents[1]
    data_file("rgl/colodur_napoli_4f_rgb.bsdf")
    small = ["--pairs", "400", "--albedo-samples", "300", "--no-table", "--fits-2d", str(tmp_path), "--degrees", "3,1",
             "--edges", "", "--grid", "8,7,5", "--random", "200", "--verify", "0"]
    a, b = tmp_path / "a", tmp_path / "b"
    assert B.main(["--data", str(data), "--materials", "paper_white", "--out", str(a)] + small) == 0
    assert B.main(["--data", str(data), "--materials", "colodur_napoli_4f", "--out", str(b),
                   "--merge", str(a / "results.json")] + small) == 0
    res = json.loads((b / "results.json").read_text())
    assert [r["material"] for r in res["rows"]] == ["colodur_napoli_4f", "paper_white"]
    assert res["meta"]["merged"]["materials"] == ["paper_white"]
    assert "Rows by run (`--merge`, same pairs and seed): this run: colodur_napoli_4f; the run of" in (
        capsys.readouterr().out)
    # another metric (pairs) cannot be merged: one line, exit status 2, nothing written
    c = tmp_path / "c"
    bad = ["--data", str(data), "--materials", "colodur_napoli_4f", "--out", str(c), "--merge", str(a / "results.json")]
    assert B.main(bad + [v if v != "400" else "500" for v in small]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--merge" in err and "--pairs 400" in err
    assert not (c / "results.json").exists()


def test_load_2d_takes_the_cached_fit_else_the_shipped_one(tmp_path):
    """The 2-D column: the cached ``rbrdf-fit brdf`` file where there is one, else the 5 % fit
    shipped in warp_rbrdf/data (paper_white has one), else nothing."""
    from fit.rational.coefficient_file import load, save
    from warp_rbrdf.paths import PACKAGE_DATA

    shipped = B.load_2d("paper_white_rgb", tmp_path)           # empty cache: the shipped fit
    assert shipped is not None
    assert shipped.fit_info["tolerance"] == 0.05
    m = load(PACKAGE_DATA / "paper_white_rgb.json")
    m.name = "cached copy"
    save(m, tmp_path / "paper_white_rgb_tol0p05_cli.json")
    assert B.load_2d("paper_white_rgb", tmp_path).name == "cached copy"
    assert B.load_2d("no_such_material_rgb", tmp_path) is None


def test_the_2d_column_is_the_fit_as_the_renderer_shows_it():
    """``rendered_2d``: where a piece and channel are flagged, the projected table of the source
    (the renderer's default), elsewhere the fit on its measured domain; the raw recipe would put
    a flagged band's best effort into the 2-D column, which no render shows."""
    import copy

    from fit.formats.angles import directions_to_half_diff
    from fit.rational.coefficient_file import load
    from warp_rbrdf.materials import rational
    from warp_rbrdf.paths import PACKAGE_DATA

    path = data_file("rgl/satin_rosaline_rgb.bsdf")
    flagged = load(PACKAGE_DATA / "satin_rosaline_rgb.json")      # the shipped fit: its band's blue flagged
    band = flagged.pieces[-1]
    assert [r["channels"] for r in rational.flagged_regions(flagged)] == [(2,)]
    m = copy.deepcopy(flagged)                                    # the same coefficients, vouched
    m.fallback = None
    m.pieces[-1].function_info[2] = dict(band.function_info[2], valid=True, feasible=True)
    wi, wo = B.cosine_pairs(20_000, 1)
    plain, shown = B.rendered_2d(m, path)(wi, wo), B.rendered_2d(flagged, path)(wi, wo)
    angles = np.stack(directions_to_half_diff(wi, wo)[::2], -1)          # theta_h, theta_d
    x = rational.onto_measured_domain(angles, 79.0)
    lo = band.variables[1].domain[0]
    in_band = x[:, 1] > lo + 1e-6
    assert in_band.sum() > 300
    np.testing.assert_array_equal(shown[:, :2], plain[:, :2])                 # red, green: the fit
    np.testing.assert_array_equal(shown[~in_band, 2], plain[~in_band, 2])     # blue outside the band
    assert np.abs(shown[in_band, 2] - plain[in_band, 2]).max() > 1e-3         # blue in it: the table
    raw = m.evaluate(wi, wo)
    on = np.all(x == angles, axis=1)                   # on the measured domain: the file's recipe itself
    assert (~on).sum() > 20
    np.testing.assert_allclose(plain[on], raw[on], rtol=1e-12, atol=0)


def _synthetic(n, seed=2):
    rng = np.random.default_rng(seed)
    wi, wo = B.cosine_pairs(n, seed)
    truth = rng.gamma(2.0, 1.0, (n, 3))
    truth[:n // 50] = 0.0                                        # zeros: below every threshold
    fit = truth * (1 + 0.1 * rng.standard_normal((n, 3))) + 0.01 * rng.random((n, 3))
    return fit, truth, wi, wo


def test_bootstrap_is_the_statistic_of_each_resample():
    """Each resample's relative RMSE, median and p95 are exactly those of the resampled pairs
    (each with its three channels, threshold recomputed) that :func:`relative_rmse` and
    :func:`relative_error_stats` give; the weighted percentile is ``np.percentile``'s."""
    rng = np.random.default_rng(0)
    for n in (1, 2, 7, 300):
        v, w = np.sort(rng.random(n)), rng.integers(0, 4, n)
        w[-1] += 1
        for q in (0.0, 2.5, 50.0, 95.0, 100.0):
            assert np.isclose(B._weighted_percentiles(v, w, [q])[0], np.percentile(np.repeat(v, w), q))
    fit, truth, wi, wo = _synthetic(1500)
    counts = B.bootstrap_counts(1500, 6, seed=3)
    assert counts.shape == (6, 1500) and np.all(counts.sum(axis=1) == 1500)
    bs = B.bootstrap_stats(fit, truth, wi, wo, counts)
    for b in range(6):
        i = np.repeat(np.arange(1500), counts[b])
        med, p95 = B.relative_error_stats(fit[i], truth[i])
        assert np.isclose(bs["rel_rmse"][b], B.relative_rmse(fit[i], truth[i], wi[i], wo[i]).mean(), rtol=1e-12)
        assert np.isclose(bs["median_rel"][b], med, rtol=1e-12) and np.isclose(bs["p95_rel"][b], p95, rtol=1e-12)


def _values(v):
    """An evaluator giving the values ``v`` ``(n, 3)`` at the n pairs and their mean elsewhere
    (the albedo quadrature's points, which this test does not look at)."""
    return lambda a, b: v if len(a) == len(v) else np.broadcast_to(v.mean(axis=0), np.shape(a)[:-1] + (3,)).copy()


def test_bootstrap_interval_contains_the_estimate_is_seeded_and_narrows():
    def ci(n, seed=0, resamples=100):
        fit, truth, wi, wo = _synthetic(n)
        x = B.measure(_values(fit), truth, wi, wo, _values(truth), 100,
                      B.bootstrap_counts(n, resamples, seed))
        return x, {k: v for k, v in x["ci"].items() if k != "seconds"}

    x, a = ci(2000)
    for k in ("rel_rmse", "median_rel", "p95_rel"):
        lo, hi = a[k]
        assert lo < x[k] < hi, k
    assert a["resamples"] == 100 and a["level"] == 0.95
    assert ci(2000)[1] == a                                     # deterministic for a seed
    assert ci(2000, seed=1)[1]["median_rel"] != a["median_rel"]
    big = ci(32000)[1]                                          # 16x the pairs: about a quarter the width
    for k in ("rel_rmse", "median_rel", "p95_rel"):
        assert np.diff(big[k])[0] < 0.5 * np.diff(a[k])[0], k
    # 3-D against the table from the same resamples: a fit twice as far off is above, itself is a tie
    row = {"table": x, "fit3d": dict(x)}
    fit, truth, wi, wo = _synthetic(2000)
    counts = B.bootstrap_counts(2000, 100, 0)
    row["table"] = B.measure(_values(truth + 2 * (fit - truth)), truth, wi, wo, _values(truth), 100, counts)
    row["fit3d"] = B.measure(_values(fit), truth, wi, wo, _values(truth), 100, counts)
    row["fit2d"] = B.measure(_values(fit), truth, wi, wo, _values(truth), 100, counts)
    B.paired_differences(row)
    d = row["fit3d"]["ci_diff"]
    assert all(d["table"][k][1] < 0 for k in d["table"]) and all(v[0] == v[1] == 0 for v in d["fit2d"].values())
    assert not any("_boot" in v for v in row.values())
    s = B.comparison_summary([dict(row, material="m")])
    assert "relative RMSE below on 1 of 1" in s and "not told apart on 1 (m)" in s


def test_fits_3d_from_measures_the_saved_fits_again(tmp_path, capsys):
    """``--fits-3d-from``: no fitting; the saved 3-D fit measured again gives the earlier run's
    numbers on the same pairs, its fit records are that run's, the table says where they came from."""
    data = data_file("rgl/paper_white_rgb.bsdf").parents[1]
    small = ["--data", str(data), "--pairs", "400", "--albedo-samples", "300", "--no-table", "--fits-2d",
             str(tmp_path), "--bootstrap", "20"]
    a, b = tmp_path / "a", tmp_path / "b"
    assert B.main(small + ["--materials", "paper_white", "--out", str(a), "--degrees", "3,1", "--edges", "",
                           "--grid", "8,7,5", "--random", "200", "--verify", "0"]) == 0
    capsys.readouterr()
    assert B.main(small + ["--out", str(b), "--fits-3d-from", str(a)]) == 0     # materials: that run's
    old, new = (json.loads((d / "results.json").read_text()) for d in (a, b))
    o3, n3 = old["rows"][0]["fit3d"], new["rows"][0]["fit3d"]
    assert [r["material"] for r in new["rows"]] == ["paper_white"] and n3["loaded"]
    for k in ("rel_rmse", "median_rel", "p95_rel", "albedo_err"):
        assert n3[k] == o3[k], k
    n_ci, o_ci = ({k: v for k, v in x["ci"].items() if k != "seconds"} for x in (n3, o3))
    assert n_ci == o_ci
    for k in ("fit_s", "coefficients", "bound", "valid", "albedo_policy"):
        assert n3[k] == o3[k], k
    assert new["meta"]["fits_3d_from"]["date"] == old["meta"]["date"]
    assert new["meta"]["fit3d_options"] == old["meta"]["fit3d_options"]
    assert not list(b.glob("*_3d.json"))
    assert "3-D fits loaded from `" in capsys.readouterr().out
    for extra, words in ((["--degrees", "3,1"], "--degrees"), (["--fits-3d-from", str(tmp_path)], "results.json"),
                         (["--materials", "colodur_napoli_4f"], "colodur_napoli_4f")):
        argv = small + ["--out", str(tmp_path / "c"), "--fits-3d-from", str(a)] + extra
        if extra[0] == "--materials":
            data_file("rgl/colodur_napoli_4f_rgb.bsdf")
        assert B.main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and words in err, err
    assert not (tmp_path / "c" / "results.json").exists()
