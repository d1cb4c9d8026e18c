"""Hostile files named by a scene (issue 22): meshes (.obj, .ply, .stl, .glb), environment maps
(.exr, .hdr) and the fitter's files a material names (``cdf =``, rational ``file =``), corrupt,
truncated, non-finite, out of range, oversized or not regular files.

Each case renders a tiny scene that names the file, in-process, with an earlier EXR and PNG in
place, and asserts the project principle: exit status 2, one stderr line naming the scene key
and the problem, no traceback or warning, nothing on stdout, existing files unchanged. Files
are checked when the scene is built, before any kernel is compiled. Texel policy: NaN,
infinite, negative or absurd (> ``MAX_ENV_TEXEL``) texels are refused, never zeroed or
clamped. ``CLASSES``: tests/hostile.py.
"""
from __future__ import annotations

import os
import struct

import numpy as np
import pytest
from hostile import (
    CLASSES,
    QUAD_F,
    QUAD_V,
    TINY_SCENE,
    assert_bad_input,
    assert_unchanged,
    obj_text,
    ply_binary,
    render_run,
    render_work_folder,
    snapshot,
    write_image_file,
)

MESH_SHAPE = '\n[[shapes]]\ntype = "mesh"\nmaterial = "m"\nfile = "{name}"\n'
ENV_LIGHT = 'type = "envmap"\nfile = "{name}"\n'
CONST = 'type = "constant"\nradiance = 0.5\n'


@pytest.fixture
def work(tmp_path):
    """An output folder holding the EXR and PNG of an earlier render."""
    return render_work_folder(tmp_path)


def _render(capsys, tmp_path, work, scene_text):
    scene = tmp_path / "s.toml"
    scene.write_text(scene_text)
    before = snapshot(work)
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--no-progress"])
    assert_unchanged(before, work)
    return rc, out, err


def _sparse(path, size):
    with open(path, "wb") as f:
        f.truncate(size)


# ----------------------------------------------------------------------------------------------
# Meshes
# ----------------------------------------------------------------------------------------------
_PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\n"
             "property float z\nelement face {nf}\nproperty list uchar int vertex_indices\nend_header\n")
_QUAD0 = [(a - 1, b - 1, c - 1) for a, b, c in QUAD_F]

MESH_CASES = [
    # (id, class, file name, bytes, text the error must hold)
    ("obj-nan-vertex", "silent", "m.obj", obj_text([(0, 0, 0), (1, 0, "nan"), (0, 0, 1)], [(1, 2, 3)]), "not finite"),
    ("obj-inf-vertex", "silent", "m.obj", obj_text([(0, 0, 0), (1, 0, "inf"), (0, 0, 1)], [(1, 2, 3)]), "not finite"),
    ("ply-unused-nan-vertex", "silent", "m.ply", ply_binary([*QUAD_V, (float("nan"), 0, 0)], _QUAD0), "not finite"),
    ("obj-huge-coordinate", "silent", "m.obj", obj_text([(0, 0, 0), (1e300, 0, 0), (0, 0, 1)], [(1, 2, 3)]),
     "MAX_COORDINATE"),
    ("obj-index-too-large", "traceback", "m.obj", obj_text(QUAD_V, [(1, 2, 9)]), "m.obj"),
    ("obj-negative-index-out", "traceback", "m.obj", obj_text(QUAD_V, [(-1, -2, -9)]), "m.obj"),
    ("obj-empty", "silent", "m.obj", b"", "no triangles"),
    ("obj-vertices-only", "silent", "m.obj", obj_text(QUAD_V, []), "no triangles"),
    ("obj-text", "silent", "m.obj", b"hello world\n", "no triangles"),
    ("obj-binary", "traceback", "m.obj", bytes(range(256)) * 16, "m.obj"),
    ("ply-index-too-large", "silent", "m.ply", ply_binary(QUAD_V, [(0, 1, 99)]), "vertex index outside"),
    ("ply-negative-index", "silent", "m.ply", ply_binary(QUAD_V, [(0, 1, -5)]), "vertex index outside"),
    ("ply-nan-vertex", "silent", "m.ply", ply_binary([(0, 0, 0), (1, float("nan"), 0), (0, 0, 1)], [(0, 1, 2)]),
     "not finite"),
    ("ply-inf-vertex", "silent", "m.ply", ply_binary([(0, 0, 0), (1, float("inf"), 0), (0, 0, 1)], [(0, 1, 2)]),
     "not finite"),
    ("ply-huge-vertex-count", "memory", "m.ply", ply_binary(QUAD_V, _QUAD0, n_vertices=10**9), "m.ply"),
    ("ply-huge-face-count", "memory", "m.ply", ply_binary(QUAD_V, _QUAD0, n_faces=10**9), "m.ply"),
    ("ply-ascii-huge-count", "memory", "m.ply",
     _PLY_HEAD.format(nv=10**9, nf=1).encode() + b"0 0 0\n1 0 0\n0 0 1\n3 0 1 2\n", "m.ply"),
    ("ply-truncated", "traceback", "m.ply", ply_binary(QUAD_V, _QUAD0)[:-7], "m.ply"),
    ("ply-header-only", "traceback", "m.ply", b"ply\nformat binary_little_endian 1.0\n", "m.ply"),
    ("stl-huge-count", "memory", "m.stl", b"\0" * 80 + struct.pack("<I", 10**9) + b"\0" * 50, "m.stl"),
    ("stl-empty", "silent", "m.stl", b"", "m.stl"),
    ("glb-garbage", "traceback", "m.glb", b"glTF" + bytes(200), "m.glb"),
]


@pytest.mark.parametrize("name,klass,fname,data,text", MESH_CASES, ids=[c[0] for c in MESH_CASES])
def test_bad_meshes(capsys, tmp_path, work, name, klass, fname, data, text):
    assert klass in CLASSES
    (tmp_path / fname).write_bytes(data)
    rc, out, err = _render(capsys, tmp_path, work, TINY_SCENE + MESH_SHAPE.format(name=fname))
    assert_bad_input(rc, err, "shapes[1].file", text, out=out)


def test_mesh_named_pipe(capsys, tmp_path, work):
    os.mkfifo(tmp_path / "p.obj")
    rc, out, err = _render(capsys, tmp_path, work, TINY_SCENE + MESH_SHAPE.format(name="p.obj"))
    assert_bad_input(rc, err, "shapes[1].file", "named pipe", out=out)


def test_mesh_too_large(capsys, tmp_path, work):
    """A 1 GB (sparse) mesh file is refused from its size before trimesh reads it."""
    _sparse(tmp_path / "big.obj", 1 << 30)
    rc, out, err = _render(capsys, tmp_path, work, TINY_SCENE + MESH_SHAPE.format(name="big.obj"))
    assert_bad_input(rc, err, "shapes[1].file", "above the limit", out=out)


def test_scene_triangle_budget(capsys, monkeypatch, tmp_path, work):
    """Tessellated spheres (a non-similarity transform): the scene's triangle budget stops the
    one that passes it before it is built (the limit lowered to 3000 here; each sphere of
    subdivision 3 has 1280 triangles, so the third is refused)."""
    from warp_rbrdf import limits

    monkeypatch.setattr(limits, "MAX_TRIANGLES", 3000)
    sph = ('\n[[shapes]]\ntype = "sphere"\nmaterial = "m"\nsubdivisions = 3\n'
           "transform = { scale = [1, 2, 1] }\n")
    rc, out, err = _render(capsys, tmp_path, work, TINY_SCENE + sph * 3)
    assert_bad_input(rc, err, "shapes[3]", "3840", "MAX_TRIANGLES", out=out)


def test_mesh_triangle_limit(capsys, monkeypatch, tmp_path, work):
    """A mesh file above the triangle limit is refused after reading, before processing."""
    from warp_rbrdf import limits

    monkeypatch.setattr(limits, "MAX_TRIANGLES", 1)
    (tmp_path / "q.obj").write_bytes(obj_text(QUAD_V, QUAD_F))
    rc, out, err = _render(capsys, tmp_path, work, TINY_SCENE + MESH_SHAPE.format(name="q.obj"))
    assert_bad_input(rc, err, "shapes[1].file", "2 triangles", out=out)


def test_env_texel_limit(capsys, monkeypatch, tmp_path, work):
    """A map with more texels than the limit is refused from its header, before its pixels are
    read (the limit lowered to 16 texels here; a real 8192 x 4096 map takes 400 MB to write)."""
    from warp_rbrdf import limits

    monkeypatch.setattr(limits, "MAX_ENV_PIXELS", 16)
    write_image_file(tmp_path / "e.exr", _map())
    rc, out, err = _render(capsys, tmp_path, work, TINY_SCENE.replace(CONST, ENV_LIGHT.format(name="e.exr")))
    assert_bad_input(rc, err, "lights[0].file", "8 x 4 = 32 texels", "MAX_ENV_PIXELS", out=out)


def test_valid_mesh_loads(tmp_path):
    """Positive control: a valid quad loads (the validation is not a blanket refusal)."""
    from warp_rbrdf.geometry import load_mesh_file

    (tmp_path / "q.obj").write_bytes(obj_text(QUAD_V, QUAD_F))
    v, f, n = load_mesh_file(tmp_path / "q.obj")
    assert v.shape == (4, 3) and f.shape == (2, 3) and np.isfinite(n).all()
    (tmp_path / "q.ply").write_bytes(ply_binary(QUAD_V, _QUAD0))
    v, f, _ = load_mesh_file(tmp_path / "q.ply")
    assert v.shape == (4, 3) and f.max() == 3


# ----------------------------------------------------------------------------------------------
# Environment maps
# ----------------------------------------------------------------------------------------------
def _map(value=None, at=(1, 2), shape=(4, 8, 3)):
    img = np.full(shape, 0.5, np.float32)
    if value is not None:
        img[at[0], at[1], 0] = value
    return img


def _hdr_header(w, h):
    return f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n".encode()


ENV_CASES = [
    # (id, class, file name, writer(path), text the error must hold)
    ("exr-nan-texel", "silent", "e.exr", lambda p: write_image_file(p, _map(np.nan)), "NaN"),
    ("exr-inf-texel", "silent", "e.exr", lambda p: write_image_file(p, _map(np.inf)), "infinite"),
    ("exr-negative-texel", "silent", "e.exr", lambda p: write_image_file(p, _map(-1.0)), "negative"),
    ("exr-huge-texel", "silent", "e.exr", lambda p: write_image_file(p, _map(1e30)), "above 1e+09"),
    ("exr-one-row", "traceback", "e.exr", lambda p: write_image_file(p, _map(shape=(1, 8, 3))), "1 x 2"),
    ("exr-garbage", "traceback", "e.exr", lambda p: p.write_bytes(b"\x76\x2f\x31\x01" + bytes(100)), "e.exr"),
    ("exr-empty", "traceback", "e.exr", lambda p: p.write_bytes(b""), "e.exr"),
    ("exr-truncated", "traceback", "e.exr",
     lambda p: (write_image_file(p, _map(shape=(64, 128, 3)) + np.random.default_rng(1).random((64, 128, 3),
                                                                                               np.float32)),
                p.write_bytes(p.read_bytes()[:400])), "e.exr"),
    ("hdr-huge-header", "memory", "e.hdr", lambda p: p.write_bytes(_hdr_header(60000, 30000) + bytes(64)),
     "e.hdr"),
    ("hdr-texels-budget", "memory", "e.hdr", lambda p: p.write_bytes(_hdr_header(8192, 4096) + bytes(64)),
     "e.hdr"),
    ("hdr-truncated", "silent", "e.hdr", lambda p: p.write_bytes(_hdr_header(64, 32) + bytes(100)), "e.hdr"),
    ("hdr-garbage", "traceback", "e.hdr", lambda p: p.write_bytes(b"#?RADIANCE\n" + bytes(range(256))), "e.hdr"),
    ("hdr-empty", "traceback", "e.hdr", lambda p: p.write_bytes(b""), "e.hdr"),
    ("hdr-is-png", "unclear", "e.hdr", lambda p: p.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(50)), "not a Radiance"),
    ("exr-is-hdr", "unclear", "e.exr", lambda p: p.write_bytes(_hdr_header(4, 2) + bytes(32)), "not an OpenEXR"),
]


@pytest.mark.parametrize("name,klass,fname,writer,text", ENV_CASES, ids=[c[0] for c in ENV_CASES])
def test_bad_environment_maps(capsys, tmp_path, work, name, klass, fname, writer, text):
    assert klass in CLASSES
    writer(tmp_path / fname)
    rc, out, err = _render(capsys, tmp_path, work, TINY_SCENE.replace(CONST, ENV_LIGHT.format(name=fname)))
    assert_bad_input(rc, err, "lights[0].file", text, out=out)


def test_env_named_pipe(capsys, tmp_path, work):
    os.mkfifo(tmp_path / "p.exr")
    rc, out, err = _render(capsys, tmp_path, work, TINY_SCENE.replace(CONST, ENV_LIGHT.format(name="p.exr")))
    assert_bad_input(rc, err, "lights[0].file", "named pipe", out=out)


def test_env_too_large(capsys, tmp_path, work):
    _sparse(tmp_path / "big.hdr", 1 << 30)
    rc, out, err = _render(capsys, tmp_path, work, TINY_SCENE.replace(CONST, ENV_LIGHT.format(name="big.hdr")))
    assert_bad_input(rc, err, "lights[0].file", "above the limit", out=out)


def test_non_utf8_env_map_name(capsys, tmp_path, work):
    """A map whose file name is not UTF-8 (valid in TOML only through the folder: a relative
    name is written in UTF-8) loads: OpenImageIO's binding used to raise TypeError."""
    from warp_rbrdf.lights.env_file import read_latlong

    folder = tmp_path / os.fsdecode(b"r\xe9p")
    folder.mkdir()
    os.replace(write_image_file(tmp_path / "e.exr", _map()), folder / "e.exr")
    assert read_latlong(folder / "e.exr").shape == (4, 8, 3)
    os.replace(write_image_file(tmp_path / "n.exr", _map(np.nan)), folder / "n.exr")
    scene = folder / "s.toml"
    scene.write_text(TINY_SCENE.replace(CONST, ENV_LIGHT.format(name="n.exr")))
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--no-progress"])
    assert_bad_input(rc, err, "r\\xe9p", "lights[0].file", "NaN", out=out)


def test_valid_env_maps_load(tmp_path):
    """Positive control: finite maps load, one channel is grey, a zero texel is fine."""
    from warp_rbrdf.lights.env_file import read_latlong

    img = _map(0.0)
    assert np.array_equal(read_latlong(write_image_file(tmp_path / "a.exr", img)), img)
    grey = read_latlong(write_image_file(tmp_path / "g.exr", np.full((4, 8, 1), 2.0, np.float32)))
    assert grey.shape == (4, 8, 3) and (grey == 2.0).all()


# ----------------------------------------------------------------------------------------------
# The fitter's files named by a material: errors of fit.* become one line of rbrdf
# ----------------------------------------------------------------------------------------------
CDF_MAT = 'type = "lambert"\nalbedo = 0.5\nsampler = "mis-tabulated"\ncdf = "{name}"'
RAT_MAT = 'type = "rational"\nfile = "{name}"'

FIT_CASES = [
    # (id, class, material TOML, file name, bytes, text the error must hold)
    ("cdf-garbage", "traceback", CDF_MAT, "c.json", b"\x00\xff garbage", "c.json"),
    ("cdf-not-json", "traceback", CDF_MAT, "c.json", b"{not json", "c.json"),
    ("cdf-nan-literal", "traceback", CDF_MAT, "c.json", b'{"format": NaN}', "c.json"),
    ("cdf-deep", "traceback", CDF_MAT, "c.json", b"[" * 100000 + b"]" * 100000, "c.json"),
    ("cdf-empty-object", "traceback", CDF_MAT, "c.json", b"{}", "c.json"),
    ("cdf-wrong-format", "traceback", CDF_MAT, "c.json", b'{"format": "rbrdf-rational", "version": 2}', "c.json"),
    ("cdf-not-utf8", "traceback", CDF_MAT, "c.json", b'{"name": "caf\xe9"}', "c.json"),
    ("rational-garbage", "traceback", RAT_MAT, "r.json", b"\x00\xff garbage", "r.json"),
    ("rational-empty-object", "traceback", RAT_MAT, "r.json", b"{}", "r.json"),
    ("rational-deep", "traceback", RAT_MAT, "r.json", b'{"a": ' * 2000 + b"1" + b"}" * 2000, "r.json"),
    ("rational-array", "traceback", RAT_MAT, "r.json", b"[1, 2, 3]", "r.json"),
    ("measured-truncated", "traceback", 'type = "measured"\nfile = "{name}"', "x.binary", b"\x5a\x00\x00\x00" * 3,
     "x.binary"),
    ("rgl-garbage", "traceback", 'type = "rgl"\nfile = "{name}"', "x.bsdf", b"tensor_file\x00" + bytes(40), "x.bsdf"),
    ("projected-npz-garbage", "traceback", 'type = "projected"\nfile = "{name}"', "x.npz", b"PK\x03\x04" + bytes(30),
     "x.npz"),
]


@pytest.mark.parametrize("name,klass,mat,fname,data,text", FIT_CASES, ids=[c[0] for c in FIT_CASES])
def test_bad_fitter_files(capsys, tmp_path, work, name, klass, mat, fname, data, text):
    """Any bad ``cdf =`` or material file raised the fitter's error class, which ``rbrdf`` did
    not catch: a traceback."""
    assert klass in CLASSES
    (tmp_path / fname).write_bytes(data)
    scene = TINY_SCENE.replace('type = "lambert"\nalbedo = 0.5', mat.format(name=fname))
    rc, out, err = _render(capsys, tmp_path, work, scene)
    assert_bad_input(rc, err, text, out=out)


def test_cdf_named_pipe(capsys, tmp_path, work):
    os.mkfifo(tmp_path / "p.json")
    scene = TINY_SCENE.replace('type = "lambert"\nalbedo = 0.5', CDF_MAT.format(name="p.json"))
    rc, out, err = _render(capsys, tmp_path, work, scene)
    assert_bad_input(rc, err, "materials.m.cdf", "named pipe", out=out)


def case_counts() -> dict:
    """Named cases of this module per class."""
    out = dict.fromkeys(CLASSES, 0)
    for cases in (MESH_CASES, ENV_CASES, FIT_CASES):
        for c in cases:
            out[c[1]] += 1
    # mesh pipe, mesh size, triangle budget, mesh triangles, env texels, env pipe, env size, cdf pipe,
    # non-UTF-8 env-map folder
    for k in ("hang", "memory", "memory", "memory", "memory", "hang", "memory", "hang", "traceback"):
        out[k] += 1
    return out
