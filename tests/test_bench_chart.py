"""The error-against-time chart (``benchmarks/bench_chart.py``): which representation reaches
ΔE2000 mean <= 1 first on synthetic ladders (:mod:`benchmarks.chart_report`), and a ``--quick``
run (``lab``: it renders every representation and Mitsuba 3). Timings are never tested."""
from __future__ import annotations

import json
import math

import pytest

from benchmarks import chart_report as CR

pytestmark = pytest.mark.lab  # tests lab code only (the `lab` marker of pyproject.toml)


def rung(spp, seconds, de):
    return {"spp": spp, "seconds": seconds, "de_mean": de, "de_p99": 3 * de}


def test_reach_interpolates_in_log_log():
    lad = [rung(4, 1.0, 4.0), rung(16, 4.0, 2.0), rung(64, 16.0, 0.5)]
    r = CR.reach(lad, 1.0)
    # log ΔE from log 2 to log 0.5 over log t from log 4 to log 16: ΔE = 1 halfway, t = 8
    assert r["how"] == "interpolated"
    assert r["seconds"] == pytest.approx(8.0)
    assert r["spp"] == pytest.approx(32.0)


def test_reach_first_rung_and_never():
    assert CR.reach([rung(4, 0.5, 0.9), rung(16, 2.0, 0.4)]) == {"seconds": 0.5, "spp": 4, "how": "first rung"}
    r = CR.reach([rung(4, 1.0, 5.0), rung(16, 4.0, 2.5), rung(64, 16.0, 2.4)])
    assert r["how"] == "never" and r["seconds"] is None and r["floor"] == 2.4
    # a rung that is not a positive finite number is skipped, not taken as reached
    r = CR.reach([rung(4, 1.0, float("nan")), rung(16, 0.0, 0.1), rung(64, 8.0, 0.8)])
    assert r == {"seconds": 8.0, "spp": 64, "how": "first rung"}


def test_case_summary_picks_the_soonest_and_lists_the_never():
    ladders = {
        "rgl": [rung(4, 1.0, 3.0), rung(16, 4.0, 0.8)],               # reaches between 1 and 4 s
        "rational-3d": [rung(4, 0.2, 3.0), rung(16, 0.8, 0.8)],       # same errors, 5x faster
        "projected": [rung(4, 0.1, 3.0), rung(16, 0.4, 2.0)],         # fastest, never reaches
    }
    s = CR.case_summary(ladders, 1.0)
    assert s["first"] == "rational-3d"
    assert s["seconds"] == pytest.approx(s["reach"]["rgl"]["seconds"] / 5)
    assert s["never"] == ["projected"]
    # equal times: the earlier representation of ORDER wins
    tie = CR.case_summary({"rational-3d": ladders["rgl"], "rgl": ladders["rgl"]}, 1.0)
    assert tie["first"] == "rgl"
    assert CR.case_summary({"projected": ladders["projected"]})["first"] is None


def test_why_not_names_floor_or_cost():
    base = {"truth": {"floor_mean": 0.1}, "notes": {}}
    slow = dict(base, ladders={"rgl": [rung(4, 1.0, 3.0), rung(16, 4.0, 0.5)],
                               "rational-3d": [rung(4, 2.0, 3.0), rung(16, 8.0, 0.5)]})
    slow["summary"] = CR.case_summary(slow["ladders"])
    why = CR.why_not(slow)
    assert why.startswith("rgl first") and "2.00x rgl's seconds per spp" in why
    flat = dict(base, ladders={"rgl": slow["ladders"]["rgl"],
                               "rational-3d": [rung(4, 0.1, 3.0), rung(16, 0.4, 1.6), rung(64, 1.6, 1.5)]})
    flat["summary"] = CR.case_summary(flat["ladders"])
    assert "lowest ΔE mean is 1.5" in CR.why_not(flat) and "bias" in CR.why_not(flat)
    win = dict(base, ladders={"rational-3d": slow["ladders"]["rgl"]})
    win["summary"] = CR.case_summary(win["ladders"])
    assert CR.why_not(win) == "wins"


@pytest.mark.lab
def test_quick_run(tmp_path):
    from conftest import data_file

    data_file("rgl/paper_white_rgb.bsdf")
    from benchmarks import bench_chart as B

    assert B.main(["--quick", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "chart.json").read_text())
    (case,) = res["cases"]
    assert (case["material"], case["map"]) == ("paper_white", "studio")
    for rep in ("rgl", "measured", "projected", "rational-2d"):   # the quick run makes no 3-D fit
        lad = case["ladders"][rep]
        assert [r["spp"] for r in lad] == [2, 8]
        assert all(math.isfinite(r["de_mean"]) and r["de_mean"] > 0 and r["seconds"] > 0 for r in lad)
        assert lad[1]["de_mean"] < lad[0]["de_mean"]                # more samples, less noise
        assert case["memory"][rep]["device_bytes"] > 0
    assert case["memory"]["measured"]["brdf_bytes"] > case["memory"]["projected"]["brdf_bytes"]
    assert case["samplers"]["rgl"] == "mis-rgl" and case["samplers"]["measured"] == "mis-tabulated"
    assert "rational-3d" in case["notes"] or "rational-3d" in case["ladders"]
    assert (tmp_path / "chart.png").stat().st_size > 0
    assert "## Summary" in (tmp_path / "chart.md").read_text()
