"""Seeded fuzzing of the renderer's readers (issue 22): truncations and bit flips of a TOML
scene, of OBJ and binary PLY meshes and of EXR and Radiance HDR environment maps, plus
fresh-process runs of ``rbrdf`` (what a user sees: no library warning on stderr).

Every mutated input must either load and keep the reader's promises (a scene: every number
finite and within :mod:`warp_rbrdf.limits`; a mesh: at least one triangle, finite vertices,
face indices in range; a map: (H >= 2, W, 3) finite texels in [0, MAX_ENV_TEXEL]) or be refused
with a one-line :class:`~warp_rbrdf.errors.SceneError` naming the file, with nothing printed
on file descriptor 2 by the libraries. Any other exception, a second line or a broken promise
fails the test. 600 mutated inputs, about 3 s (the three fresh processes about 7 s more).
"""
from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest
from hostile import (
    QUAD_F,
    QUAD_V,
    assert_one_line,
    bit_flips,
    obj_text,
    ply_binary,
    truncations,
    write_image_file,
)

from warp_rbrdf import limits
from warp_rbrdf.errors import SceneError

RICH_SCENE = """\
[camera]
origin = [0, 1.5, 4]
target = [0, 0.5, 0]
fov = 35.0
resolution = [16, 12]

[integrator]
spp = 4
seed = 7
max_depth = 2
tile_size = 8

[materials.m]
type = "lambert"
albedo = [0.5, 0.4, 0.3]

[[shapes]]
type = "sphere"
material = "m"
center = [0, 0.5, 0]
radius = 0.5
transform = { scale = [1, 1.5, 1], rotate = [[30, 0, 1, 0], [10, 1, 0, 0]], translate = [0.1, 0, 0] }

[[shapes]]
type = "plane"
material = "m"
size = [4, 4]
transform = { matrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]] }

[[lights]]
type = "directional"
irradiance = [2, 2, 2]
direction = [-1, -1, 0]

[[lights]]
type = "sky"
scale = 0.5
sun_elevation = 30
resolution = [64, 32]
"""


def _finite_within(x, bound) -> bool:
    a = np.asarray(x, float)
    return bool(np.isfinite(a).all() and np.abs(a).max(initial=0.0) <= bound)


def _scene_promises(sc) -> None:
    c = sc.camera
    assert limits.check_render_size(*c.resolution, sc.integrator.spp) is None
    assert limits.check_tiles(*c.resolution, sc.integrator.tile_size) is None
    for v in (c.origin, c.target, c.up):
        assert _finite_within(v, limits.MAX_COORDINATE)
    assert 0 < c.fov < 180
    assert 0 <= sc.integrator.ray_epsilon <= limits.MAX_RAY_EPSILON
    assert 0 <= sc.integrator.mis_compensation <= 1
    for m in sc.materials.values():
        assert _finite_within(m.albedo, limits.MAX_ALBEDO) and min(m.albedo) >= 0
    for s in sc.shapes:
        assert _finite_within(s.transform, limits.MAX_COORDINATE ** 2)
        assert abs(np.linalg.det(s.transform[:3, :3])) > 0
        assert _finite_within(s.center, limits.MAX_COORDINATE)
    for lt in sc.lights:
        assert _finite_within(lt.irradiance, limits.MAX_IRRADIANCE) and min(lt.irradiance) >= 0
        assert math.isfinite(lt.scale) and 0 <= lt.scale <= limits.MAX_ENV_SCALE
        assert _finite_within(lt.rotation, 1.0 + 1e-9)


def _load_scene_or_refuse(tmp_path, data: bytes, i: int) -> bool:
    from warp_rbrdf.scene import load_scene

    p = tmp_path / f"f{i}.toml"
    p.write_bytes(data)
    try:
        sc = load_scene(p)
    except SceneError as e:
        assert_one_line(str(e), p.name)
        return False
    _scene_promises(sc)
    return True


@pytest.mark.parametrize("mutator", ["truncate", "flip"])
def test_fuzz_scene(capfd, tmp_path, mutator):
    base = RICH_SCENE.encode()
    assert _load_scene_or_refuse(tmp_path, base, -1)
    inputs = truncations(base, 80, seed=22) if mutator == "truncate" else bit_flips(base, 80, seed=22, flips=1)
    loaded = sum(_load_scene_or_refuse(tmp_path, d, i) for i, d in enumerate(inputs))
    assert loaded < len(inputs)
    assert loaded > 0 or mutator == "flip"   # truncations at a table's end load: promises checked
    assert capfd.readouterr().err == ""      # nothing printed by the libraries (file descriptor 2)


def _mesh_or_refuse(tmp_path, data: bytes, suffix: str, i: int) -> bool:
    from warp_rbrdf.geometry import load_mesh_file

    p = tmp_path / f"m{i}{suffix}"
    p.write_bytes(data)
    try:
        v, f, n = load_mesh_file(p, "s.toml", "shapes[0].file")
    except SceneError as e:
        assert_one_line(str(e), "shapes[0].file", p.name)
        return False
    assert len(f) >= 1 and f.min() >= 0 and f.max() < len(v)
    assert _finite_within(v, limits.MAX_COORDINATE) and np.isfinite(n).all() or len(n) == len(v)
    return True


def _sphere_obj() -> bytes:
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=1)
    return obj_text(s.vertices, s.faces + 1)


@pytest.mark.parametrize("fmt", ["obj", "ply"])
@pytest.mark.parametrize("mutator", ["truncate", "flip"])
def test_fuzz_mesh(capfd, tmp_path, fmt, mutator):
    base = _sphere_obj() if fmt == "obj" else ply_binary(QUAD_V, [(a - 1, b - 1, c - 1) for a, b, c in QUAD_F])
    assert _mesh_or_refuse(tmp_path, base, f".{fmt}", -1)
    header = 0 if fmt == "obj" else base.index(b"end_header") + 11
    inputs = truncations(base, 60, seed=7, header=header) if mutator == "truncate" else \
        bit_flips(base, 60, seed=7, flips=3)
    results = [_mesh_or_refuse(tmp_path, d, f".{fmt}", i) for i, d in enumerate(inputs)]
    assert not all(results)
    assert capfd.readouterr().err == ""


def _env_or_refuse(tmp_path, data: bytes, suffix: str, i: int) -> bool:
    from warp_rbrdf.lights.env_file import read_latlong

    p = tmp_path / f"e{i}{suffix}"
    p.write_bytes(data)
    try:
        img = read_latlong(p, "s.toml", "lights[0].file")
    except SceneError as e:
        assert_one_line(str(e), "lights[0].file", p.name)
        return False
    assert img.ndim == 3 and img.shape[0] >= 2 and img.shape[2] == 3 and img.dtype == np.float32
    assert np.isfinite(img).all() and img.min() >= 0 and img.max() <= limits.MAX_ENV_TEXEL
    return True


@pytest.mark.parametrize("fmt", ["exr", "hdr"])
@pytest.mark.parametrize("mutator", ["truncate", "flip"])
def test_fuzz_env_map(capfd, tmp_path, fmt, mutator):
    rng = np.random.default_rng(3)
    src = write_image_file(tmp_path / f"base.{fmt}", rng.random((8, 16, 3), np.float32) * 4)
    base = src.read_bytes()
    assert _env_or_refuse(tmp_path, base, f".{fmt}", -1)
    inputs = truncations(base, 50, seed=5, header=min(len(base), 300)) if mutator == "truncate" else \
        bit_flips(base, 50, seed=5, flips=4)
    results = [_env_or_refuse(tmp_path, d, f".{fmt}", i) for i, d in enumerate(inputs)]
    assert not all(results)
    assert capfd.readouterr().err == ""      # e.g. libpng's messages when OIIO guessed a format


# ----------------------------------------------------------------------------------------------
# Fresh processes: what a user sees on the terminal
# ----------------------------------------------------------------------------------------------
def _rbrdf(args, tmp_path, **env):
    e = dict(os.environ, **env)
    e["PYTHONPATH"] = os.pathsep.join([str(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))]
                                      + ([e["PYTHONPATH"]] if e.get("PYTHONPATH") else []))
    return subprocess.run([sys.executable, "-m", "warp_rbrdf", *map(os.fsdecode, args)], cwd=tmp_path, check=False,
                          capture_output=True, timeout=120, env=e)


def test_fresh_process_one_line(tmp_path):
    """A bad mesh in a fresh process: exactly one stderr line (Warp's native "CUDA driver"
    warning on machines without a GPU is silenced), exit 2, nothing on stdout."""
    (tmp_path / "m.obj").write_bytes(obj_text([(0, 0, "nan"), (1, 0, 0), (0, 1, 0)], [(1, 2, 3)]))
    (tmp_path / "s.toml").write_text('[materials.m]\ntype = "lambert"\n[[shapes]]\ntype = "mesh"\n'
                                     'material = "m"\nfile = "m.obj"\n')
    r = _rbrdf(["render", "s.toml", "--out", "o.exr"], tmp_path)
    lines = r.stderr.decode().splitlines()
    assert r.returncode == 2 and r.stdout == b"" and len(lines) == 1, r.stderr
    assert lines[0].startswith("rbrdf: error: s.toml: shapes[0].file") and "not finite" in lines[0]
    assert sorted(os.listdir(tmp_path)) == ["m.obj", "s.toml"]


def test_fresh_process_non_utf8_name(tmp_path):
    """A non-UTF-8 scene file name under a UTF-8 locale prints escaped, one line."""
    name = b"sc\xe8ne.toml"
    (tmp_path / os.fsdecode(name)).write_bytes(b"[camera]\nfov = 500\n")
    r = _rbrdf([os.fsdecode(b"render"), os.fsdecode(name), "--out", "o.exr"], tmp_path, LC_ALL="C.UTF-8")
    lines = r.stderr.decode().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert "sc\\xe8ne.toml: camera.fov" in lines[0]


def case_counts() -> dict:
    """Fuzz tests are not named cases; the three fresh-process cases."""
    return {"lost": 0, "hang": 0, "memory": 0, "silent": 0, "traceback": 2, "unclear": 1}


def test_fresh_process_closed_stdout(tmp_path):
    """``rbrdf scene-format | head -0``: stdout closed before anything is written used to end in
    a BrokenPipeError traceback; now exit 141 (as a tool killed by SIGPIPE), stderr empty."""
    e = dict(os.environ)
    e["PYTHONPATH"] = os.pathsep.join([str(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))]
                                      + ([e["PYTHONPATH"]] if e.get("PYTHONPATH") else []))
    p = subprocess.Popen([sys.executable, "-m", "warp_rbrdf", "scene-format"], cwd=tmp_path, env=e,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()                 # before the interpreter has even started
    _, err = p.communicate(timeout=120)
    assert p.returncode == 141 and err == b"", (p.returncode, err)
