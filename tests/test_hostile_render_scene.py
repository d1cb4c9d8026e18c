"""Hostile scene files for ``rbrdf render`` (issue 22): every key of every table given a
non-finite, absurd, negative, mistyped or oversized value, TOML that is not UTF-8, nested too
deeply or too large, and scene files that are not regular files.

Each case runs ``rbrdf render SCENE --out WORK/old.exr`` in-process with an existing EXR and
PNG in WORK and asserts the project principle: exit status 2, exactly one stderr line naming
the key (or the file), no traceback or warning, nothing on stdout, every file of WORK unchanged
and no partial file. Scenes are validated before anything is built or compiled, so each case
takes milliseconds. ``CLASSES``: how the issue's campaign classed the failure the case guards
against (lost output, hang, memory, silent wrong result, traceback, unclear message).
"""
from __future__ import annotations

import os

import pytest
from hostile import (
    CLASSES,
    TINY_SCENE,
    assert_bad_input,
    assert_unchanged,
    render_run,
    render_work_folder,
    snapshot,
)


def sub(old: str, new: str):
    """An edit of the tiny scene: ``old`` (which must occur) replaced by ``new``."""
    def edit(text: str) -> str:
        assert old in text, old
        return text.replace(old, new, 1)
    return edit


def add(extra: str):
    """An edit appending TOML text to the tiny scene."""
    return lambda text: text + extra


SPHERE = 'type = "sphere"\nmaterial = "m"\ncenter = [0, 0.5, 0]\nradius = 0.5\n'
CONST = 'type = "constant"\nradiance = 0.5\n'
SKY = '\n[[lights]]\ntype = "sky"\n'


def cam(k, v):
    return sub("resolution = [8, 8]", f"resolution = [8, 8]\n{k} = {v}")


def integ(k, v):
    return sub("spp = 1", f"spp = 1\n{k} = {v}") if k != "spp" else sub("spp = 1", f"spp = {v}")


def mat(k, v):
    return sub("albedo = 0.5", f"{k} = {v}") if k == "albedo" else sub("albedo = 0.5", f"albedo = 0.5\n{k} = {v}")


def shape(k, v):
    if k == "radius":
        return sub("radius = 0.5", f"radius = {v}")
    return sub("radius = 0.5", f"radius = 0.5\n{k} = {v}")


def light(k, v):
    return sub("radiance = 0.5", f"radiance = {v}") if k == "radiance" else sub(CONST, CONST + f"{k} = {v}\n")


def sky(k, v):
    """The constant environment replaced by a sky with ``k = v``."""
    return sub(CONST, f'type = "sky"\n{k} = {v}\n')


def plane(k, v):
    return add(f'\n[[shapes]]\ntype = "plane"\nmaterial = "m"\n{k} = {v}\n')


def transform(v):
    return sub("radius = 0.5", f"radius = 0.5\ntransform = {v}")


def directional(k, v):
    return add(f'\n[[lights]]\ntype = "directional"\n{k} = {v}\n')


BIG = 2**31
SCENE_CASES = [
    # (id, class, edit, text the error line must hold)
    # camera ----------------------------------------------------------------------------------
    ("fov-nan", "silent", cam("fov", "nan"), "camera.fov"),
    ("fov-inf", "silent", cam("fov", "inf"), "camera.fov"),
    ("fov-0", "silent", cam("fov", "0"), "camera.fov"),
    ("fov-180", "silent", cam("fov", "180"), "camera.fov"),
    ("fov-negative", "silent", cam("fov", "-3"), "camera.fov"),
    ("fov-string", "traceback", cam("fov", '"wide"'), "camera.fov"),
    ("fov-axis-z", "silent", cam("fov_axis", '"z"'), "camera.fov_axis"),
    ("origin-nan", "silent", cam("origin", "[nan, 0, 0]"), "camera.origin"),
    ("origin-huge", "silent", cam("origin", "[1e300, 0, 4]"), "camera.origin"),
    ("origin-short", "traceback", cam("origin", "[0, 0]"), "camera.origin"),
    ("target-is-origin", "silent", cam("target", "[0, 1, 4]"), "camera.target"),
    ("up-zero", "silent", cam("up", "[0, 0, 0]"), "camera.up"),
    ("up-parallel", "silent", cam("up", "[0, -0.5, -4]"), "camera.up"),
    ("up-inf", "silent", cam("up", "[0, inf, 0]"), "camera.up"),
    ("resolution-zero", "silent", sub("[8, 8]", "[0, 8]"), "camera.resolution"),
    ("resolution-negative", "silent", sub("[8, 8]", "[8, -1]"), "camera.resolution"),
    ("resolution-float", "traceback", sub("[8, 8]", "[8.5, 8]"), "camera.resolution"),
    ("resolution-huge-float", "memory", sub("[8, 8]", "[1e9, 8]"), "camera.resolution"),
    ("resolution-side", "memory", sub("[8, 8]", "[16385, 8]"), "camera.resolution"),
    ("resolution-int64", "memory", sub("[8, 8]", "[9223372036854775807, 8]"), "camera.resolution"),
    ("resolution-max-square", "hang", sub("[8, 8]", "[16384, 16384]"), "camera.resolution"),
    ("resolution-pixels", "memory", sub("[8, 8]", "[16384, 2048]"), "camera.resolution"),
    ("resolution-three", "traceback", sub("[8, 8]", "[8, 8, 8]"), "camera.resolution"),
    ("resolution-bool", "silent", sub("[8, 8]", "[true, 8]"), "camera.resolution"),
    ("camera-unknown-key", "silent", cam("zoom", "2"), "camera.zoom"),
    ("camera-not-table", "traceback", lambda t: "camera = 3\n" + t.replace("[camera]\nresolution = [8, 8]\n", ""),
     "camera"),
    # integrator ------------------------------------------------------------------------------
    ("spp-zero", "silent", integ("spp", "0"), "integrator.spp"),
    ("spp-negative", "silent", integ("spp", "-1"), "integrator.spp"),
    ("spp-2^31", "silent", integ("spp", str(BIG)), "integrator.spp"),
    ("spp-int64-max", "silent", integ("spp", "9223372036854775807"), "integrator.spp"),
    ("spp-float", "silent", integ("spp", "1.5"), "integrator.spp"),
    ("spp-nan", "silent", integ("spp", "nan"), "integrator.spp"),
    ("spp-times-pixels", "hang", lambda t: t.replace("[8, 8]", "[4096, 4096]").replace("spp = 1", "spp = 1024"),
     "integrator.spp"),
    ("seed-negative", "silent", integ("seed", "-1"), "integrator.seed"),
    ("seed-2^32", "silent", integ("seed", str(2**32)), "integrator.seed"),
    ("max-depth-zero", "silent", integ("max_depth", "0"), "integrator.max_depth"),
    ("max-depth-huge", "hang", integ("max_depth", "100000"), "integrator.max_depth"),
    ("tile-size-zero", "traceback", integ("tile_size", "0"), "integrator.tile_size"),
    ("tile-size-huge", "silent", integ("tile_size", "1000000"), "integrator.tile_size"),
    ("tile-size-one-large-image", "memory", lambda t: t.replace("[8, 8]", "[4096, 4096]").replace(
        "spp = 1", "spp = 1\ntile_size = 1"), "integrator.tile_size"),
    ("ray-epsilon-negative", "silent", integ("ray_epsilon", "-1"), "integrator.ray_epsilon"),
    ("ray-epsilon-inf", "silent", integ("ray_epsilon", "inf"), "integrator.ray_epsilon"),
    ("ray-epsilon-huge", "silent", integ("ray_epsilon", "1e30"), "integrator.ray_epsilon"),
    ("mis-compensation-above-one", "traceback", integ("mis_compensation", "2"), "integrator.mis_compensation"),
    ("mis-compensation-nan", "traceback", integ("mis_compensation", "nan"), "integrator.mis_compensation"),
    ("sampler-unknown", "silent", integ("sampler", '"bogus"'), "integrator.sampler"),
    ("pattern-unknown", "silent", integ("pattern", '"sobol9"'), "integrator.pattern"),
    ("hide-env-int", "silent", integ("hide_environment", "1"), "integrator.hide_environment"),
    # materials -------------------------------------------------------------------------------
    ("albedo-nan", "silent", mat("albedo", "nan"), "materials.m.albedo"),
    ("albedo-inf", "silent", mat("albedo", "inf"), "materials.m.albedo"),
    ("albedo-negative", "silent", mat("albedo", "-0.1"), "materials.m.albedo"),
    ("albedo-above-one", "silent", mat("albedo", "2.0"), "materials.m.albedo"),
    ("albedo-huge", "silent", mat("albedo", "1e300"), "materials.m.albedo"),
    ("albedo-two-values", "traceback", mat("albedo", "[0.5, 0.5]"), "materials.m.albedo"),
    ("albedo-string", "traceback", mat("albedo", '"red"'), "materials.m.albedo"),
    ("material-type-unknown", "silent", sub('type = "lambert"', 'type = "velvet"'), "materials.m.type"),
    ("material-type-missing", "traceback", sub('type = "lambert"\n', ""), "materials.m.type"),
    ("material-unknown-key", "silent", mat("roughness", "0.3"), "materials.m.roughness"),
    ("material-not-table", "traceback", add("\n[materials]\nx = 3\n"), "materials"),
    ("materials-too-many", "hang",
     add("".join(f'\n[materials.x{i}]\ntype = "lambert"\n' for i in range(70))), "materials"),
    ("material-sampler-unknown", "silent", mat("sampler", '"bogus"'), "materials.m.sampler"),
    ("cdf-missing-file", "traceback", mat("cdf", '"nowhere.json"'), "materials.m.cdf"),
    ("cdf-wrong-suffix", "silent", mat("cdf", '"s.toml"'), "materials.m.cdf"),
    ("cdf-nul-byte", "traceback", mat("cdf", '"a\\u0000b.json"'), "materials.m.cdf"),
    ("cdf-folder", "traceback", mat("cdf", '"."'), "materials.m.cdf"),
    ("rational-file-missing", "traceback",
     sub('type = "lambert"\nalbedo = 0.5', 'type = "rational"\nfile = "nowhere.json"'), "materials.m.file"),
    ("rational-file-suffix", "silent", sub('type = "lambert"\nalbedo = 0.5', 'type = "rational"\nfile = "s.toml"'),
     "materials.m.file"),
    ("measured-scale-huge", "silent",
     sub('type = "lambert"\nalbedo = 0.5', 'type = "rational"\nfile = "pkg:satin_rosaline_rgb.json"\nscale = 1e30'),
     "materials.m.scale"),
    ("measured-scale-negative", "silent",
     sub('type = "lambert"\nalbedo = 0.5', 'type = "rational"\nfile = "pkg:satin_rosaline_rgb.json"\nscale = -1'),
     "materials.m.scale"),
    # shapes ----------------------------------------------------------------------------------
    ("radius-zero", "silent", shape("radius", "0"), "shapes[0].radius"),
    ("radius-negative", "silent", shape("radius", "-1"), "shapes[0].radius"),
    ("radius-nan", "silent", shape("radius", "nan"), "shapes[0].radius"),
    ("radius-huge", "silent", shape("radius", "1e300"), "shapes[0].radius"),
    ("center-nan", "silent", sub("center = [0, 0.5, 0]", "center = [nan, 0, 0]"), "shapes[0].center"),
    ("center-huge", "silent", sub("center = [0, 0.5, 0]", "center = [1e300, 0, 0]"), "shapes[0].center"),
    ("subdivisions-huge", "memory", shape("subdivisions", "20"), "shapes[0].subdivisions"),
    ("shape-type-unknown", "silent", sub('type = "sphere"', 'type = "cube"'), "shapes[0].type"),
    ("shape-material-unknown", "traceback", sub('material = "m"', 'material = "nope"'), "shapes[0].material"),
    ("shape-material-missing", "traceback", sub('material = "m"\n', ""), "shapes[0].material"),
    ("shapes-not-array", "traceback", lambda t: "shapes = 3\n" + t.replace("[[shapes]]\n" + SPHERE, ""), "shapes"),
    ("shapes-too-many", "memory", add("".join(f"\n[[shapes]]\n{SPHERE}" for _ in range(4100))), "shapes"),
    ("plane-size-zero", "silent", plane("size", "[0, 1]"), "shapes[1].size"),
    ("plane-size-inf", "silent", plane("size", "[inf, 1]"), "shapes[1].size"),
    ("plane-size-huge", "silent", plane("size", "1e300"), "shapes[1].size"),
    ("scale-zero", "silent", transform("{ scale = 0 }"), "shapes[0].transform.scale"),
    ("scale-tiny", "silent", transform("{ scale = 1e-30 }"), "shapes[0].transform.scale"),
    ("scale-huge", "silent", transform("{ scale = 1e30 }"), "shapes[0].transform.scale"),
    ("scale-nan", "silent", transform("{ scale = nan }"), "shapes[0].transform.scale"),
    ("matrix-singular", "silent", transform("{ matrix = [[1,0,0,0],[0,0,0,0],[0,0,1,0],[0,0,0,1]] }"),
     "shapes[0].transform.matrix"),
    ("matrix-projective", "silent", transform("{ matrix = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]] }"),
     "shapes[0].transform.matrix"),
    ("matrix-3x3", "traceback", transform("{ matrix = [[1,0,0],[0,1,0],[0,0,1]] }"), "shapes[0].transform.matrix"),
    ("matrix-nan", "silent", transform("{ matrix = [[nan,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]] }"),
     "shapes[0].transform.matrix"),
    ("matrix-huge", "silent", transform("{ matrix = [[1e300,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]] }"),
     "shapes[0].transform.matrix"),
    ("matrix-strings", "traceback", transform('{ matrix = [["1",0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]] }'),
     "shapes[0].transform.matrix"),
    ("matrix-ragged", "traceback", transform("{ matrix = [[1,0,0,0],[0,1,0],[0,0,1,0],[0,0,0,1]] }"),
     "shapes[0].transform.matrix"),
    ("rotate-nan", "silent", transform("{ rotate = [nan, 0, 1, 0] }"), "shapes[0].transform.rotate"),
    ("rotate-zero-axis", "silent", transform("{ rotate = [90, 0, 0, 0] }"), "shapes[0].transform.rotate"),
    ("rotate-huge-angle", "silent", transform("{ rotate = [1e300, 0, 1, 0] }"), "shapes[0].transform.rotate"),
    ("rotate-inf-axis", "silent", transform("{ rotate = [90, inf, 1, 0] }"), "shapes[0].transform.rotate"),
    ("rotate-string", "traceback", transform('{ rotate = "x" }'), "shapes[0].transform.rotate"),
    ("translate-huge", "silent", transform("{ translate = [1e300, 0, 0] }"), "shapes[0].transform.translate"),
    ("transform-unknown-key", "silent", transform("{ shear = 1 }"), "shapes[0].transform.shear"),
    ("mesh-file-missing", "traceback", add('\n[[shapes]]\ntype = "mesh"\nmaterial = "m"\nfile = "none.obj"\n'),
     "shapes[1].file"),
    ("mesh-file-folder", "traceback", add('\n[[shapes]]\ntype = "mesh"\nmaterial = "m"\nfile = "."\n'),
     "shapes[1].file"),
    # lights ----------------------------------------------------------------------------------
    ("radiance-inf", "silent", light("radiance", "inf"), "lights[0].radiance"),
    ("radiance-huge", "silent", light("radiance", "1e300"), "lights[0].radiance"),
    ("radiance-negative", "silent", light("radiance", "-1"), "lights[0].radiance"),
    ("irradiance-huge", "silent", directional("irradiance", "1e300"), "lights[1].irradiance"),
    ("irradiance-nan", "silent", directional("irradiance", "[nan, 1, 1]"), "lights[1].irradiance"),
    ("irradiance-negative", "silent", directional("irradiance", "-1"), "lights[1].irradiance"),
    ("direction-zero", "silent", directional("direction", "[0, 0, 0]"), "lights[1].direction"),
    ("direction-nan", "silent", directional("direction", "[nan, -1, 0]"), "lights[1].direction"),
    ("direction-huge", "silent", directional("direction", "[1e300, -1, 0]"), "lights[1].direction"),
    ("directional-radiance", "unclear", directional("radiance", "1"), "lights[1].radiance"),
    ("lights-too-many", "hang", add("".join('\n[[lights]]\ntype = "directional"\n' for _ in range(70))), "lights"),
    ("two-environments", "silent", add(SKY), "lights[1].type"),
    ("light-type-unknown", "silent", sub('type = "constant"', 'type = "area"'), "lights[0].type"),
    ("sky-scale-negative", "silent", sky("scale", "-1"), "lights[0].scale"),
    ("sky-scale-nan", "silent", sky("scale", "nan"), "lights[0].scale"),
    ("sky-scale-huge", "silent", sky("scale", "1e300"), "lights[0].scale"),
    ("sky-resolution-huge", "memory", sky("resolution", "[1e9, 2]"), "lights[0].resolution"),
    ("sky-resolution-texels", "memory", sky("resolution", "[16384, 16384]"), "lights[0].resolution"),
    ("sky-resolution-float", "silent", sky("resolution", "[64.5, 32]"), "lights[0].resolution"),
    ("sky-resolution-one", "silent", sky("resolution", "[1, 1]"), "lights[0].resolution"),
    ("sky-elevation-range", "silent", sky("sun_elevation", "100"), "lights[0].sun_elevation"),
    ("sky-azimuth-inf", "silent", sky("sun_azimuth", "inf"), "lights[0].sun_azimuth"),
    ("sky-rotate-nan", "silent", sky("rotate", "[nan, 0, 1, 0]"), "lights[0].rotate"),
    ("envmap-missing", "traceback", sub(CONST, 'type = "envmap"\nfile = "none.hdr"\n'), "lights[0].file"),
    ("envmap-suffix", "silent", sub(CONST, 'type = "envmap"\nfile = "s.toml"\n'), "lights[0].file"),
    ("envmap-folder", "traceback", sub(CONST, 'type = "envmap"\nfile = "."\n'), "lights[0].file"),
    ("envmap-pkg-missing", "traceback", sub(CONST, 'type = "envmap"\nfile = "pkg:none.exr"\n'), "lights[0].file"),
    # TOML text -------------------------------------------------------------------------------
    ("toml-invalid", "traceback", add("[camera\n"), "invalid TOML"),
    ("toml-nested-arrays", "traceback", add("x = " + "[" * 5000 + "]" * 5000 + "\n"), "s.toml"),
    ("toml-nested-tables", "traceback", add("y = " + "{a = " * 40 + "1" + "}" * 40 + "\n"), "nested"),
    ("toml-unknown-table", "silent", add("\n[render]\nx = 1\n"), "render"),
    ("toml-control-key", "unclear", add('\n"a\\u001b[2Jb" = 1\n'), "a\\x1b[2Jb"),
    ("toml-newline-key", "unclear", add('\n"line1\\nline2" = 1\n'), "line1\\nline2"),
    ("toml-huge-key", "unclear", add('\n"' + "k" * 200000 + '" = 1\n'), "kkk..."),
]


@pytest.fixture
def work(tmp_path):
    """An output folder holding the EXR and PNG of an earlier render."""
    return render_work_folder(tmp_path)


def _run_scene(capsys, tmp_path, work, data: bytes, name="s.toml"):
    scene = tmp_path / name
    scene.write_bytes(data)
    before = snapshot(work)
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--no-progress"])
    assert_unchanged(before, work)
    return rc, out, err


@pytest.mark.parametrize("name,klass,edit,key", SCENE_CASES, ids=[c[0] for c in SCENE_CASES])
def test_bad_scene_values(capsys, tmp_path, work, name, klass, edit, key):
    assert klass in CLASSES
    rc, out, err = _run_scene(capsys, tmp_path, work, edit(TINY_SCENE).encode())
    assert_bad_input(rc, err, key, "s.toml", out=out)
    assert len(err) < 500, len(err)     # readable: values and keys are shown cut


FILE_CASES = [
    # (id, class, bytes of the scene file, text the error must hold)
    ("not-utf8", "traceback", TINY_SCENE.encode() + b"\n# caf\xe9\n", "not UTF-8"),
    ("utf16", "traceback", TINY_SCENE.encode("utf-16"), "not UTF-8"),
    ("binary-garbage", "traceback", bytes(range(256)) * 8, "s.toml"),
    ("nul-bytes", "traceback", b"\x00" * 100, "s.toml"),
    ("too-large", "memory", b"# " + b"x" * (1 << 20) + b"\n" + TINY_SCENE.encode(), "above the limit"),
]


@pytest.mark.parametrize("name,klass,data,text", FILE_CASES, ids=[c[0] for c in FILE_CASES])
def test_bad_scene_files(capsys, tmp_path, work, name, klass, data, text):
    rc, out, err = _run_scene(capsys, tmp_path, work, data)
    assert_bad_input(rc, err, text, out=out)


def test_scene_is_a_folder(capsys, tmp_path, work):
    (tmp_path / "dir.toml").mkdir()
    rc, out, err = render_run(capsys, ["render", tmp_path / "dir.toml", "--out", work / "old.exr"])
    assert_bad_input(rc, err, "dir.toml", "directory", out=out)


def test_scene_is_a_named_pipe(capsys, tmp_path, work):
    """A named pipe used to block the reader forever; it is refused before it is opened."""
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    before = snapshot(work)
    rc, out, err = render_run(capsys, ["render", fifo, "--out", work / "old.exr"])
    assert_bad_input(rc, err, "pipe.toml", "named pipe", out=out)
    assert_unchanged(before, work)


def test_scene_missing(capsys, tmp_path, work):
    rc, out, err = render_run(capsys, ["render", tmp_path / "none.toml", "--out", work / "old.exr"])
    assert_bad_input(rc, err, "none.toml", "not found", out=out)


def test_scene_sparse_huge(capsys, tmp_path, work):
    """A 2 GB (sparse) scene file is refused from its size, not read."""
    big = tmp_path / "big.toml"
    with open(big, "wb") as f:
        f.truncate(2 << 30)
    rc, out, err = render_run(capsys, ["render", big, "--out", work / "old.exr"])
    assert_bad_input(rc, err, "big.toml", "above the limit", out=out)


def test_non_utf8_scene_name(capsys, tmp_path, work):
    """A scene file name that is not UTF-8 prints escaped, on one line."""
    name = os.fsdecode(b"caf\xe9.toml")
    (tmp_path / name).write_bytes(b"[camera]\nfov = -1\n")
    rc, out, err = render_run(capsys, ["render", tmp_path / name, "--out", work / "old.exr"])
    assert_bad_input(rc, err, "caf\\xe9.toml", "camera.fov", out=out)


def case_counts() -> dict:
    """Named cases of this module per class (the file cases: traceback, hang and memory)."""
    out = dict.fromkeys(CLASSES, 0)
    for c in SCENE_CASES + FILE_CASES:
        out[c[1]] += 1
    for k in ("traceback", "hang", "traceback", "memory", "unclear"):   # folder, pipe, missing, sparse, name
        out[k] += 1
    return out
