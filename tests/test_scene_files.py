"""Scene files: parsing, defaults, path resolution, and one-line errors naming file and key."""
from __future__ import annotations

import numpy as np
import pytest

from warp_rbrdf import SceneError, load_scene
from warp_rbrdf.paths import resolve_path

GOOD = """
[camera]
origin = [0, 1, 4]
target = [0, 0, 0]
fov = 30
resolution = [32, 16]

[materials.red]
type = "lambert"
albedo = [0.8, 0.1, 0.1]

[[shapes]]
type = "sphere"
material = "red"
transform = { scale = 2, rotate = [90, 0, 1, 0], translate = [1, 0, 0] }

[[lights]]
type = "directional"
irradiance = 3
colinear_with_view = true
"""


def write(tmp_path, text, name="scene.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_good_scene_and_defaults(tmp_path):
    sc = load_scene(write(tmp_path, GOOD))
    assert sc.camera.resolution == (32, 16) and sc.camera.fov_axis == "x"
    # no sampler named: the integrator names none, the Lambert material gets its kind's default
    assert sc.integrator.spp == 16 and sc.integrator.max_depth == 1 and sc.integrator.sampler is None
    assert sc.materials["red"].sampler == "mis"
    assert sc.lights[0].irradiance == (3.0, 3.0, 3.0) and sc.lights[0].colinear_with_view
    m = sc.shapes[0].transform
    np.testing.assert_allclose(m @ [1, 0, 0, 1], [1, 0, -2, 1], atol=1e-12)  # S, then R(90 about y), then T


def test_data_paths(monkeypatch, tmp_path):
    monkeypatch.setenv("RBRDF_DATA", str(tmp_path))
    assert resolve_path("${RBRDF_DATA}/meshes/a.ply") == tmp_path / "meshes" / "a.ply"
    assert resolve_path("data:meshes/a.ply") == tmp_path / "meshes" / "a.ply"
    assert resolve_path("b.obj", tmp_path / "x") == tmp_path / "x" / "b.obj"


@pytest.mark.parametrize("edit, key, words", [
    (lambda s: s.replace('type = "sphere"\n', ""), "shapes[0].type", "missing required key"),
    (lambda s: s.replace("fov = 30", 'fov = "wide"'), "camera.fov", "expected a number"),
    (lambda s: s.replace('material = "red"', 'material = "blue"'), "shapes[0].material", "unknown material 'blue'"),
    (lambda s: s.replace('type = "sphere"', 'type = "mesh"\nfile = "nowhere/bunny.ply"'), "shapes[0].file", "mesh file not found"),
    (lambda s: s.replace("resolution = [32, 16]", "resolution = [32]"), "camera.resolution", "expected [width, height]"),
    (lambda s: s.replace("irradiance = 3", "radiance = 3"), "lights[0].radiance", "irradiance"),
    (lambda s: s.replace("fov = 30", "fov = 30\nfocal = 2"), "camera.focal", "unknown key"),
    (lambda s: s.replace('type = "lambert"', 'type = "plastic"'), "materials.red.type", "expected one of"),
    (lambda s: s.replace('albedo = [0.8, 0.1, 0.1]', 'interpolation = "nearest"'), "materials.red.interpolation",
     "unknown key"),
    (lambda s: s + '\n[integrator]\nspp = 0\n', "integrator.spp", "expected an integer in [1"),
    (lambda s: s + '\n[[lights]]\ntype = "envmap"\nfile = "${RBRDF_DATA}/none.hdr"\n', "lights[1].file", "not found"),
])
def test_bad_scene_errors(tmp_path, edit, key, words):
    p = write(tmp_path, edit(GOOD), "bad.toml")
    with pytest.raises(SceneError) as e:
        load_scene(p)
    msg = str(e.value)
    assert "\n" not in msg
    assert str(p) in msg and key in msg and words in msg, msg


def test_measured_interpolation_key(tmp_path):
    """``interpolation`` of a measured material: "linear" by default, "nearest" when stated."""
    (tmp_path / "m.binary").write_bytes(b"")   # parsing does not read it
    text = GOOD.replace('type = "lambert"\nalbedo = [0.8, 0.1, 0.1]', 'type = "measured"\nfile = "m.binary"')
    assert load_scene(write(tmp_path, text)).materials["red"].interpolation == "linear"
    text = text.replace('file = "m.binary"', 'file = "m.binary"\ninterpolation = "nearest"')
    assert load_scene(write(tmp_path, text)).materials["red"].interpolation == "nearest"
    p = write(tmp_path, text.replace('"nearest"', '"cubic"'), "bad.toml")
    with pytest.raises(SceneError) as e:
        load_scene(p)
    assert str(e.value).startswith(f"{p}: materials.red.interpolation: ") and "expected one of" in str(e.value)


def test_invalid_toml_and_missing_file(tmp_path):
    with pytest.raises(SceneError, match="invalid TOML"):
        load_scene(write(tmp_path, "[camera\n"))
    with pytest.raises(SceneError, match="cannot read scene file"):
        load_scene(tmp_path / "none.toml")


def test_shipped_scenes_parse(monkeypatch):
    """Every scene in scenes/ parses (needs the shared data: skipped locally without it)."""
    from pathlib import Path

    from conftest import DATA, IN_CI

    if not DATA.exists() and not IN_CI:
        pytest.skip("shared data missing")
    scenes = sorted((Path(__file__).resolve().parents[1] / "scenes").glob("*.toml"))
    assert scenes
    for p in scenes:
        load_scene(p)


def test_default_scene_parses():
    from warp_rbrdf import default_scene

    sc = default_scene()
    assert len(sc.shapes) == 2 and sc.environment.type == "sky"
