"""Inverse-CDF tables remembered on disk (warp_rbrdf.techniques.table_cache): the key follows
the table's inputs (the file, the spec, the tabulation's parameters and version), not the
tabulation's source bytes; a stored table is the tabulated one bit for bit, and the table
shipped for the embedded default scene (tools.ship_tables) is the one its fit tabulates to
today."""
from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

from fit.sampling import table as table_mod
from fit.sampling.table import tabulate
from tools import ship_tables
from warp_rbrdf.defaults import default_scene
from warp_rbrdf.materials.build import build_material_data
from warp_rbrdf.registry import material
from warp_rbrdf.techniques import table_cache as tc

_ARRAYS = ("theta_v", "cdf_theta", "cdf_phi", "row_fallback", "albedo")


def _same(a, b, atol=0.0):
    """Tables ``a`` and ``b`` equal, bit for bit (``atol`` 0) or to ``atol``."""
    for k in _ARRAYS:
        x, y = getattr(a, k), getattr(b, k)
        assert x.dtype == y.dtype and x.shape == y.shape, k
        assert (np.array_equal(x, y) if atol == 0 else np.allclose(x, y, rtol=0.0, atol=atol)), k
    assert a.eps == b.eps


def _sphere_spec():
    return default_scene().materials["sphere"]


def test_key_follows_file_and_spec(tmp_path):
    spec = _sphere_spec()
    k = tc.key(spec)
    assert k is not None and k == tc.key(dataclasses.replace(spec))
    assert tc.key(dataclasses.replace(spec, scale=(2.0, 1.0, 1.0))) != k
    assert tc.key(dataclasses.replace(spec, unvouched="refuse")) != k
    assert tc.key(dataclasses.replace(spec, data=object())) is None
    copy = tmp_path / "fit.json"
    raw = spec.file.read_bytes()
    copy.write_bytes(raw)
    assert tc.key(dataclasses.replace(spec, file=copy)) == k   # content, not the path
    copy.write_bytes(raw + b" ")
    assert tc.key(dataclasses.replace(spec, file=copy)) != k
    assert tc.key(dataclasses.replace(spec, file=tmp_path / "missing.json")) is None


def test_round_trip_and_user_cache(tmp_path, monkeypatch):
    spec = dataclasses.replace(_sphere_spec(), type="lambert", file=None, albedo=(0.3, 0.5, 0.7))
    lm = material("lambert").impl().load(spec, "<t>", "materials.m")
    t = tabulate(lm.evaluate, n_v=4, n_t=8, n_p=8)
    tc.write(tmp_path / "t.npz", t)
    _same(tc.read(tmp_path / "t.npz"), t)
    assert tc.read(tmp_path / "absent.npz") is None
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    assert tc.read(tmp_path / "bad.npz") is None

    monkeypatch.setattr(tc, "user_dir", lambda: tmp_path / "user")
    calls = []

    def counting(evaluate, progress=None):
        calls.append(1)
        return tabulate(evaluate, n_v=4, n_t=8, n_p=8)

    monkeypatch.setattr(tc, "tabulate", counting)
    first = tc.cached_tabulate(spec, lm.evaluate)
    assert (tmp_path / "user" / f"{tc.key(spec)}.npz").is_file()
    second = tc.cached_tabulate(spec, lm.evaluate)
    assert len(calls) == 1
    _same(first, second)
    tc.cached_tabulate(dataclasses.replace(spec, data=object()), lm.evaluate)   # never cached
    assert len(calls) == 2


def test_shipped_default_table_is_current(monkeypatch):
    """The default scene's table is shipped under today's key and equals a fresh tabulation
    (about 5 s: if this fails, run ``python -m tools.ship_tables``)."""
    spec = _sphere_spec()
    shipped = tc.read(tc.SHIPPED / f"{tc.key(spec)}.npz")
    assert shipped is not None, f"no shipped table for the default fit: {ship_tables.COMMAND}"
    assert ship_tables.shipped_path() == tc.SHIPPED / f"{tc.key(spec)}.npz"   # the tool ships this key
    monkeypatch.setattr(tc, "user_dir", lambda: None)
    sc = default_scene()
    md = build_material_data(sc, ["sphere"], log=lambda *a: None)
    assert md.cdf[0] is not None
    _same(md.cdf[0], shipped)
    lm = md.loaded[0]
    # a fresh tabulation of today's fit: its NumPy evaluation sums through BLAS, whose thread
    # count moves the last bit (2e-15 measured with 2 threads against the table made with one);
    # a table of another fit differs by orders of magnitude more
    _same(tabulate(lm.evaluate), shipped, atol=1e-12)


def test_key_ignores_the_tabulation_source_bytes(tmp_path, monkeypatch):
    """A comment added to fit/sampling/table.py keeps the key (and the shipped table) current."""
    spec = _sphere_spec()
    k = tc.key(spec)
    copy = tmp_path / "table.py"
    copy.write_text(inspect.getsource(table_mod) + "\n# a comment changes no table\n")
    monkeypatch.setattr(table_mod, "__file__", str(copy))
    assert tc.key(spec) == k


def test_key_follows_the_tabulation_version_and_parameters(monkeypatch):
    spec = _sphere_spec()
    k = tc.key(spec)
    monkeypatch.setattr(table_mod, "TABULATION_VERSION", table_mod.TABULATION_VERSION + 1)
    assert tc.key(spec) != k
    monkeypatch.undo()
    assert tc.key(spec) == k
    defaults = inspect.signature(table_mod.tabulate).parameters
    for name, other in (("n_v", 16), ("sub", 4), ("eps", 0.05), ("noise", 1e-5)):
        assert defaults[name].default != other

        def changed(evaluate, _name=name, _other=other, **kw):   # tabulate with another default
            return tabulate(evaluate, **{_name: _other, **kw})

        changed.__signature__ = inspect.signature(tabulate).replace(parameters=[
            p.replace(default=other) if p.name == name else p for p in defaults.values()])
        monkeypatch.setattr(table_mod, "tabulate", changed)
        assert tc.key(spec) != k, name
        monkeypatch.undo()
    # how the same table is computed (chunk_rows) and reported (progress) is not part of the key
    assert set(tc.table_inputs()) == {"version", "n_v", "n_t", "n_p", "sub", "eps", "noise"}


@pytest.mark.parametrize("field", ["statistic", "incident", "interpolation"])
def test_key_spec_fields(field):
    spec = _sphere_spec()
    assert tc.key(dataclasses.replace(spec, **{field: "other"})) != tc.key(spec)


def _five_rational_scene():
    """Five rational materials that each need a table (different scales: different keys; none
    is the shipped default's)."""
    from warp_rbrdf.scene import parse_scene

    mats = "".join(f'[materials.m{i}]\ntype = "rational"\nfile = "pkg:satin_rosaline_rgb.json"\n'
                   f'sampler = "mis-tabulated"\nscale = [{1.25 + i * 0.25}, 1.0, 1.0]\n'
                   for i in range(5))
    shapes = "".join(f'[[shapes]]\ntype = "sphere"\nmaterial = "m{i}"\n' for i in range(5))
    return parse_scene(mats + shapes, path="many.toml")


def test_load_time_builds_are_bounded(tmp_path, monkeypatch):
    """A scene naming more materials than MAX_CDF_BUILDS_AT_LOAD whose tables must be built at
    load is refused at the first build past the limit, naming that material's cdf key; cache
    hits cost nothing (issue 22: a small scene file may not ask for minutes of work)."""
    from warp_rbrdf import limits
    from warp_rbrdf.errors import SceneError

    built = []
    shipped = tc.read(next(tc.SHIPPED.glob("*.npz")))

    def fake_tabulate(evaluate, progress=None):   # the real table of another material: only the count matters
        built.append(1)
        return shipped

    monkeypatch.setattr(tc, "tabulate", fake_tabulate)
    monkeypatch.setattr(tc, "user_dir", lambda: tmp_path / "tables")
    monkeypatch.setattr(limits, "MAX_CDF_BUILDS_AT_LOAD", 2)
    scene = _five_rational_scene()
    with pytest.raises(SceneError, match=r"materials\.m2\.cdf: .*more than 2 .*rbrdf-fit cdf"):
        build_material_data(scene, log=lambda *a: None)
    assert len(built) == 2
    # the two tables built are now cached: a second load builds only what is missing
    with pytest.raises(SceneError, match=r"materials\.m4\.cdf"):
        build_material_data(scene, log=lambda *a: None)
    assert len(built) == 4


def test_load_time_build_limit_is_one_line_exit_2(tmp_path, monkeypatch, capsys):
    from warp_rbrdf import limits
    from warp_rbrdf.cli import main

    monkeypatch.setattr(tc, "user_dir", lambda: tmp_path / "tables")
    monkeypatch.setattr(limits, "MAX_CDF_BUILDS_AT_LOAD", 0)
    scene = tmp_path / "many.toml"
    scene.write_text('[materials.m]\ntype = "rational"\nfile = "pkg:satin_rosaline_rgb.json"\n'
                     'sampler = "mis-tabulated"\nscale = [2.0, 1.0, 1.0]\n[[shapes]]\ntype = "sphere"\nmaterial = "m"\n')
    out = tmp_path / "o.exr"
    assert main(["render", str(scene), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "materials.m.cdf" in err and "MAX_CDF_BUILDS_AT_LOAD" in err
    assert not out.exists()
