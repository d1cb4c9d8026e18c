"""Smoke test of ``benchmarks/bench_eval.py`` (``--quick``): every material is timed, the table
lists them, the JSON holds the run; its numbers themselves are docs/bench_eval.md."""
from __future__ import annotations

import json

import pytest
from conftest import data_file

from benchmarks import bench_eval as B

pytestmark = pytest.mark.lab  # tests lab code only (the `lab` marker of pyproject.toml)


def test_bench_eval_quick(tmp_path, capsys):
    data_file("rgl/satin_rosaline_rgb.bsdf")
    out = tmp_path / "eval.json"
    res = B.main(["--quick", "--json", str(out)])
    rows = res["eval"]["rows"]
    assert set(rows) == set(B.ROWS) | set(B.GENERIC.values())
    assert all(r["ns"] > 0 and len(r["all_ns"]) == 2 for r in rows.values())
    assert "stand-in" in res["notes"]["rational 3-D"]          # no --fit3d: the stand-in layout
    assert json.loads(out.read_text())["pairs"] == 4096
    text = capsys.readouterr().out
    assert all(f"| {row} |" in text for row in rows)


def test_stand_in_3d_fit_has_the_fitters_layout():
    from fit.rational.fit3d import VARIANTS
    from fit.rational.variables3d import is_3d

    m = B.synthetic_3d()
    assert is_3d(m) and len(m.pieces) == len(VARIANTS[0]["piece_degrees"])
    for piece, (dn, dd) in zip(m.pieces, VARIANTS[0]["piece_degrees"]):
        assert piece.value_transform == "log"
        for f in piece.functions:
            assert f.num_exponents.sum(axis=1).max() == dn and f.den_exponents.sum(axis=1).max() == dd


def test_own_sampler_is_the_renderers_default(tmp_path):
    """The sampler each material renders with by default: a fit carrying its inverse CDFs samples
    with them; a fit without them and the tables with ``mis-tabulated``; ``rgl`` with its own."""
    from warp_rbrdf.paths import PACKAGE_DATA
    from warp_rbrdf.scene import MaterialSpec

    bare = PACKAGE_DATA / "satin_rosaline_rgb.json"            # the shipped fit carries no sampler
    assert "sampler" not in json.loads(bare.read_text())
    carried = tmp_path / "carried.json"
    carried.write_text(json.dumps(dict(json.loads(bare.read_text()), sampler={})))
    assert B.own_sampler(MaterialSpec(name="a", type="rational", file=carried)) == "mis-rational"
    assert B.own_sampler(MaterialSpec(name="a", type="rational", file=bare)) == "mis-tabulated"
    assert B.own_sampler(MaterialSpec(name="a", type="rational", data=B.synthetic_3d())) == "mis-tabulated"
    assert B.own_sampler(MaterialSpec(name="a", type="projected", file=tmp_path / "x.npz")) == "mis-tabulated"
    assert B.own_sampler(MaterialSpec(name="a", type="rgl", file=tmp_path / "x.bsdf")) == "mis-rgl"


def test_all_2d_mode(tmp_path, capsys):
    """``--all-2d``: every 2-D fit found (here the shipped paper_white) against its material's
    table, the fit's size from its file."""
    data_file("rgl/paper_white_rgb.bsdf")
    out = tmp_path / "all2d.json"
    res = B.main(["--all-2d", "paper_white", "--quick", "--json", str(out)])
    (row,) = res["rows"]
    assert row["material"] == "paper_white" and row["fit_ns"] > 0 and row["table_ns"] > 0
    assert row["coefficients"] == 160 and row["classes"] == [(4, 3), (4, 4)]
    assert json.loads(out.read_text())["rows"][0]["ratio"] == pytest.approx(row["ratio"])
    assert "| paper_white | 160 | (4, 3), (4, 4) |" in capsys.readouterr().out
