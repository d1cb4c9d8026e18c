"""Hostile command lines for ``rbrdf`` (issue 22): every flag of ``rbrdf render`` given an
out-of-range, non-finite or malformed value, every output path given a place it cannot be
written to, and runs that fail after they started (a non-finite image, a failing PNG write,
Ctrl-C, out of memory), each with an earlier EXR and PNG in place.

Each case asserts the project principle: exit status 2 (130 for Ctrl-C), exactly one stderr
line naming the flag or the path, no traceback or warning, nothing on stdout, every existing
file unchanged and no partial or temporary file left. Flags and output paths are checked before
the scene is read; the failing-run cases replace the render by a stub (no kernel is compiled),
and one real 8 x 8 render checks that a successful run replaces both files. ``CLASSES`` as in
test_hostile_render_scene.py.
"""
from __future__ import annotations

import os

import numpy as np
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


@pytest.fixture
def scene(tmp_path):
    p = tmp_path / "in" / "tiny.toml"
    p.parent.mkdir()
    p.write_text(TINY_SCENE)
    return p


@pytest.fixture
def work(tmp_path):
    """An output folder holding the EXR and PNG of an earlier render."""
    return render_work_folder(tmp_path)


FLAG_CASES = [
    # (id, class, arguments after the scene, text the error line must hold)
    ("spp-zero", "silent", ["--spp", "0"], "--spp"),
    ("spp-negative", "silent", ["--spp", "-1"], "--spp"),
    ("spp-2^31", "silent", ["--spp", str(2**31)], "--spp"),
    ("spp-2^32", "silent", ["--spp", str(2**32)], "--spp"),
    ("spp-2^64", "silent", ["--spp", str(2**64)], "--spp"),
    ("spp-float", "traceback", ["--spp", "1.5"], "--spp"),
    ("spp-nan", "traceback", ["--spp", "nan"], "--spp"),
    ("spp-text", "traceback", ["--spp", "many"], "--spp"),
    ("spp-empty", "traceback", ["--spp", ""], "--spp"),
    ("spp-times-resolution", "hang", ["--spp", "1048576", "--resolution", "4096", "4096"], "--resolution/--spp"),
    ("seed-negative", "silent", ["--seed", "-1"], "--seed"),
    ("seed-2^32", "silent", ["--seed", str(2**32)], "--seed"),
    ("seed-text", "traceback", ["--seed", "x"], "--seed"),
    ("threads-zero", "silent", ["--threads", "0"], "--threads"),
    ("threads-negative", "silent", ["--threads", "-4"], "--threads"),
    ("threads-huge", "memory", ["--threads", "100000"], "--threads"),
    ("threads-text", "traceback", ["--threads", "all"], "--threads"),
    ("exposure-nan", "silent", ["--exposure", "nan"], "--exposure"),
    ("exposure-inf", "silent", ["--exposure", "inf"], "--exposure"),
    ("exposure-huge", "silent", ["--exposure", "1e308"], "--exposure"),
    ("exposure-very-negative", "silent", ["--exposure", "-100000"], "--exposure"),
    ("exposure-text", "traceback", ["--exposure", "bright"], "--exposure"),
    ("exposure-empty", "traceback", ["--exposure", ""], "--exposure"),
    ("resolution-zero", "silent", ["--resolution", "0", "8"], "--resolution"),
    ("resolution-negative", "silent", ["--resolution", "8", "-8"], "--resolution"),
    ("resolution-float", "traceback", ["--resolution", "8.5", "8"], "--resolution"),
    ("resolution-side", "memory", ["--resolution", "16385", "8"], "--resolution"),
    ("resolution-documented-max", "hang", ["--resolution", "16384", "16384"], "--resolution"),
    ("resolution-pixels", "memory", ["--resolution", "16384", "1025"], "--resolution"),
    ("resolution-one-value", "traceback", ["--resolution", "8"], "--resolution"),
    ("device-unknown", "unclear", ["--device", "warp-drive"], "--device"),
    ("device-bad-ordinal", "traceback", ["--device", "cuda:x"], "--device"),
    ("device-empty", "unclear", ["--device", ""], "--device"),
    ("unknown-flag", "unclear", ["--samples", "4"], "--samples"),
    ("missing-value", "unclear", ["--spp"], "--spp"),
    ("two-scenes", "unclear", ["other.toml"], "other.toml"),
]


@pytest.mark.parametrize("name,klass,extra,flag", FLAG_CASES, ids=[c[0] for c in FLAG_CASES])
def test_bad_flag_values(capsys, scene, work, name, klass, extra, flag):
    assert klass in CLASSES
    before = snapshot(work)
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--no-progress", *extra])
    assert_bad_input(rc, err, flag, out=out)
    assert_unchanged(before, work)


def test_bare_rbrdf_prints_usage_on_stderr(capsys):
    """A bare ``rbrdf`` used to print the whole help on stdout and exit 2 without an error."""
    rc, out, err = render_run(capsys, [])
    assert rc == 2 and out == ""
    assert err.startswith("usage: rbrdf") and "rbrdf: error: a command is required" in err


@pytest.mark.parametrize("argv,text", [(["draw"], "invalid choice"), (["--version"], "--version")],
                         ids=["unknown-command", "unknown-top-flag"])
def test_bad_command(capsys, argv, text):
    rc, out, err = render_run(capsys, argv)
    assert_bad_input(rc, err, text, out=out)


# ----------------------------------------------------------------------------------------------
# Output paths: refused before the scene is read, nothing written
# ----------------------------------------------------------------------------------------------
def _fifo(work, name):
    os.mkfifo(work / name)
    return work / name


def _file(work, name="afile"):
    (work / name).write_bytes(b"a file")
    return work / name


def _devnull(work, name):
    (work / name).symlink_to(os.devnull)
    return work / name


OUT_CASES = [
    # (id, class, --out given the work folder, text the error must hold)
    ("png-suffix", "silent", lambda w: ["--out", w / "x.png"], ".exr"),
    ("no-suffix", "silent", lambda w: ["--out", w / "image"], ".exr"),
    ("folder-as-target", "traceback", lambda w: ["--out", w], "folder"),
    ("existing-folder-named-exr", "traceback", lambda w: (w / "d.exr").mkdir() or ["--out", w / "d.exr"], "folder"),
    ("parent-is-a-file", "traceback", lambda w: ["--out", _file(w) / "x.exr"], "not a folder"),
    ("grandparent-is-a-file", "traceback", lambda w: ["--out", _file(w) / "a" / "x.exr"], "not a folder"),
    ("exr-is-named-pipe", "hang", lambda w: ["--out", _fifo(w, "p.exr")], "named pipe"),
    ("exr-links-to-devnull", "lost", lambda w: ["--out", _devnull(w, "n.exr")], "device"),
    ("png-is-a-folder", "lost", lambda w: (w / "x_ev+0.0.png").mkdir() or ["--out", w / "x.exr"], "x_ev+0.0.png"),
    ("png-is-named-pipe", "lost", lambda w: _fifo(w, "x_ev+0.0.png") and ["--out", w / "x.exr"], "named pipe"),
    ("png-of-exposure-is-folder", "lost",
     lambda w: (w / "old_ev+2.0.png").mkdir() or ["--out", w / "old.exr", "--exposure", "2"], "old_ev+2.0.png"),
    ("png-links-to-devnull", "lost", lambda w: _devnull(w, "x_ev+0.0.png") and ["--out", w / "x.exr"], "device"),
    ("empty-path", "traceback", lambda w: ["--out", ""], "--out"),
    ("name-too-long", "traceback", lambda w: ["--out", w / ("x" * 300 + ".exr")], "longer than"),
    ("dot-exr-folder-name", "traceback", lambda w: ["--out", w / ".."], "--out"),
]


@pytest.mark.parametrize("name,klass,args,text", OUT_CASES, ids=[c[0] for c in OUT_CASES])
def test_bad_outputs(capsys, scene, work, name, klass, args, text):
    argv = args(work)
    before = snapshot(work)
    rc, out, err = render_run(capsys, ["render", scene, "--no-progress", *argv])
    assert_bad_input(rc, err, text, out=out)
    assert_unchanged(before, work)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_folder(capsys, scene, work):
    work.chmod(0o555)
    try:
        before = snapshot(work)
        rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr"])
        assert_bad_input(rc, err, "not writable", out=out)
        assert_unchanged(before, work)
    finally:
        work.chmod(0o755)


def test_outputs_checked_before_the_scene(capsys, tmp_path, work):
    """A bad output path is reported before a bad scene is even read."""
    bad = tmp_path / "bad.toml"
    bad.write_text("[camera]\nfov = -1\n")
    rc, out, err = render_run(capsys, ["render", bad, "--out", work / "x.png"])
    assert_bad_input(rc, err, "x.png", out=out)


# ----------------------------------------------------------------------------------------------
# Runs that fail after they started: existing outputs untouched, no partial file
# ----------------------------------------------------------------------------------------------
def _stub_render(monkeypatch, image_or_error):
    """Replace compile and render of :class:`warp_rbrdf.renderer.Renderer` by a stub returning
    ``image_or_error`` (an array) or raising it (an exception), with the stats a render sets."""
    from warp_rbrdf import renderer

    def render(self, spp=None, seed=None, threads=None, progress=False):
        if isinstance(image_or_error, BaseException):
            raise image_or_error
        W, H = self.scene.camera.resolution
        self.stats = renderer.RenderStats(W, H, spp or 1, 1, "cpu", 0.0, 0.0, 0.001, 1)
        return image_or_error

    monkeypatch.setattr(renderer.Renderer, "compile", lambda self: 0.0)
    monkeypatch.setattr(renderer.Renderer, "render", render)


def _image(value=0.5):
    return np.full((8, 8, 3), 0.5, np.float32) if value is None else np.full((8, 8, 3), value, np.float32)


def _nan_pixel():
    img = _image()
    img[3, 5, 1] = np.nan
    return img


def _inf_pixel():
    img = _image()
    img[0, 7, 0] = np.inf
    return img


FAIL_CASES = [
    # (id, class, stub result, expected status, text the error must hold)
    ("nan-pixel", "silent", _nan_pixel, 2, "1 of 64 pixels"),
    ("inf-pixel", "silent", _inf_pixel, 2, "NaN or infinite"),
    ("all-nan", "silent", lambda: _image(np.nan), 2, "64 of 64 pixels"),
    ("memory-error", "memory", lambda: MemoryError(), 2, "out of memory"),
    ("ctrl-c", "lost", lambda: KeyboardInterrupt(), 130, "interrupted"),
]


@pytest.mark.parametrize("name,klass,result,status,text", FAIL_CASES, ids=[c[0] for c in FAIL_CASES])
def test_failing_runs_lose_nothing(capsys, monkeypatch, scene, work, name, klass, result, status, text):
    _stub_render(monkeypatch, result())
    before = snapshot(work)
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--no-progress"])
    if status == 2:
        assert_bad_input(rc, err, text, out=out)
    else:
        assert rc == status and err.strip().count("\n") == 0 and text in err and out == ""
    assert_unchanged(before, work)


def test_nonfinite_image_names_scene_and_materials(capsys, monkeypatch, scene, work):
    _stub_render(monkeypatch, _nan_pixel())
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--no-progress"])
    assert_bad_input(rc, err, "tiny.toml", "materials: m", "x 5, y 3", "nothing written", out=out)


FLOOR = '\n[materials.floor]\ntype = "lambert"\n[[shapes]]\ntype = "plane"\nmaterial = "floor"\nsize = [20, 20]\n'


@pytest.mark.parametrize("extra,xy,seen", [
    ("", (4, 4), "material 'm'"), ("", (0, 0), "the environment"), (FLOOR, (0, 7), "material 'floor'"),
    (FLOOR, (4, 4), "material 'm'")], ids=["sphere", "sky", "plane", "sphere-over-plane"])
def test_nonfinite_image_names_the_material_seen(capsys, monkeypatch, scene, work, extra, xy, seen):
    """The message names what the camera sees through the first bad pixel (a NumPy cast of the
    primary ray): the analytic sphere in the middle, the environment in a corner, the floor
    plane (triangles) at the bottom."""
    scene.write_text(TINY_SCENE + extra)
    img = _image()
    img[xy[1], xy[0], 2] = np.inf
    _stub_render(monkeypatch, img)
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--no-progress"])
    assert_bad_input(rc, err, f"x {xy[0]}, y {xy[1]}, where the camera sees {seen}", out=out)


@pytest.mark.parametrize("which", ["exr", "png"])
def test_write_failure_keeps_the_pair(capsys, monkeypatch, scene, work, which):
    """The EXR used to be written before the PNG path was even checked: a failing PNG write left
    a new EXR next to an old PNG. Now neither is replaced when either write fails."""
    from warp_rbrdf import image_io
    from warp_rbrdf.errors import RenderError

    _stub_render(monkeypatch, _image())

    def fail(path, *a, **k):
        raise RenderError(f"{path}: cannot write image (disk full)")

    monkeypatch.setattr(image_io, f"write_{which}", fail)
    before = snapshot(work)
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--no-progress"])
    assert_bad_input(rc, err, "disk full", out=out)
    assert_unchanged(before, work)


def test_failing_run_removes_created_folders(capsys, monkeypatch, scene, tmp_path):
    _stub_render(monkeypatch, _nan_pixel())
    target = tmp_path / "new" / "deeper" / "x.exr"
    rc, out, err = render_run(capsys, ["render", scene, "--out", target, "--no-progress"])
    assert_bad_input(rc, err, "NaN", out=out)
    assert not (tmp_path / "new").exists()


def test_stubbed_success_replaces_both(capsys, monkeypatch, scene, work):
    from warp_rbrdf.image_io import read_image

    _stub_render(monkeypatch, _image(0.25))
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--no-progress"])
    assert rc == 0 and err == "" and "wrote" in out, err
    assert sorted(p.name for p in work.iterdir()) == ["old.exr", "old_ev+0.0.png"]
    assert np.allclose(read_image(work / "old.exr"), 0.25)
    assert read_image(work / "old_ev+0.0.png").shape == (8, 8, 3)


def test_real_render_replaces_both(capsys, work):
    """One real render, the default scene at 1 spp (its kernel is shipped with the package:
    nothing compiles): both files are replaced, they agree, no temporary file is left."""
    from warp_rbrdf.image_io import read_image, tonemap

    (work / "old.exr").chmod(0o640)
    rc, out, err = render_run(capsys, ["render", "--spp", "1", "--out", work / "old.exr", "--no-progress",
                                       "--threads", "1"])
    assert rc == 0 and err == "" and "wrote" in out, err
    assert sorted(p.name for p in work.iterdir()) == ["old.exr", "old_ev+0.0.png"]
    exr, png = read_image(work / "old.exr"), read_image(work / "old_ev+0.0.png")
    assert np.isfinite(exr).all() and exr.max() > 0
    assert np.array_equal(np.round(png * 255).astype(np.uint8), tonemap(exr, 0.0))
    assert (work / "old.exr").stat().st_mode & 0o777 == 0o640     # a replaced file keeps its mode


def test_python_api_spp_bound(monkeypatch):
    """``Renderer.render(spp=2**31)`` used to wrap in the kernel (an all-black image): the
    Python API applies the command line's bounds (the kernel compile is stubbed here)."""
    from warp_rbrdf import renderer
    from warp_rbrdf.errors import RenderError
    from warp_rbrdf.limits import MAX_SPP, check_render_size
    from warp_rbrdf.scene import parse_scene

    assert check_render_size(8, 8, MAX_SPP) is None
    monkeypatch.setattr(renderer.Renderer, "compile", lambda self: 0.0)
    r = renderer.Renderer(parse_scene(TINY_SCENE))
    for spp in (0, 2**31, 2**64):
        with pytest.raises(RenderError, match="MAX_SPP"):
            r.render(spp=spp)


def case_counts() -> dict:
    """Named cases of this module per class."""
    out = dict.fromkeys(CLASSES, 0)
    for c in FLAG_CASES + OUT_CASES + FAIL_CASES:
        out[c[1]] += 1
    # bare rbrdf, unknown command/flag, read-only folder, outputs-before-scene, nonfinite naming,
    # write failures (2), created folders, python-api spp
    # empty scene path, non-UTF-8 output name, the material seen at a bad pixel (4), Ctrl-C tiles,
    # tiny tiles
    for k in ("unclear", "unclear", "unclear", "lost", "lost", "unclear", "lost", "lost", "lost", "silent",
              "silent", "traceback", "unclear", "unclear", "unclear", "unclear", "hang", "memory"):
        out[k] += 1
    return out


def test_empty_scene_path(capsys, work):
    """``rbrdf render ""`` used to render the embedded default scene (an empty path is falsy)."""
    before = snapshot(work)
    rc, out, err = render_run(capsys, ["render", "", "--out", work / "old.exr"])
    assert_bad_input(rc, err, "SCENE", "empty path", out=out)
    assert_unchanged(before, work)


def test_case_counts_match_the_docs():
    """The per-class table of docs/robustness.md (renderer's half) states these modules' counts."""
    import re
    from pathlib import Path

    import test_hostile_render_assets
    import test_hostile_render_fuzz
    import test_hostile_render_scene

    total = dict.fromkeys(CLASSES, 0)
    for m in (test_hostile_render_scene, test_hostile_render_assets, test_hostile_render_fuzz):
        for k, v in m.case_counts().items():
            total[k] += v
    for k, v in case_counts().items():
        total[k] += v
    doc = (Path(__file__).resolve().parents[1] / "docs" / "robustness.md").read_text(encoding="utf-8")
    section = doc[doc.index("## The renderer's half"):]
    names = {"lost": "lost or half-written output", "hang": "hang", "memory": "memory",
             "silent": "silent wrong result", "traceback": "traceback", "unclear": "unclear"}
    for k, label in names.items():
        m = re.search(rf"^\| {label} \| (\d+) \|", section, re.MULTILINE)
        assert m and int(m.group(1)) == total[k], (k, total[k], m and m.group(0))
    m = re.search(r"^\| \*\*total\*\* \| \*\*(\d+)\*\* \|", section, re.MULTILINE)
    assert m and int(m.group(1)) == sum(total.values()), sum(total.values())


def test_non_utf8_output_name(capsys, monkeypatch, scene, work):
    """An output name that is not UTF-8: OpenImageIO's binding refused it with a TypeError
    traceback after the whole render; now both files are written (and a bad suffix is one
    escaped line)."""
    from warp_rbrdf.image_io import read_image

    rc, out, err = render_run(capsys, ["render", scene, "--out", work / os.fsdecode(b"caf\xe9.png")])
    assert_bad_input(rc, err, "caf\\xe9.png", out=out)
    _stub_render(monkeypatch, _image(0.25))
    target = work / os.fsdecode(b"caf\xe9.exr")
    rc, out, err = render_run(capsys, ["render", scene, "--out", target, "--no-progress"])
    assert rc == 0 and err == "" and "caf\\xe9.exr" in out, err
    assert np.allclose(read_image(target), 0.25)
    assert read_image(work / os.fsdecode(b"caf\xe9_ev+0.0.png")).shape == (8, 8, 3)
    assert len(os.listdir(work)) == 4


def test_interrupt_drops_queued_tiles():
    """Ctrl-C during a render waited for every queued tile (measured: 17 s after SIGINT on a
    512^2 x 256 spp render, 1 s now): the tile pool drops the queued tiles when the main thread
    is interrupted or a tile fails (warp_rbrdf.integrator.launch_tiles)."""
    import threading
    import time

    from warp_rbrdf.integrator import launch_tiles

    done, lock = [], threading.Lock()

    def one(t):
        if t == 3:
            raise KeyboardInterrupt
        time.sleep(0.002)
        with lock:
            done.append(t)

    with pytest.raises(KeyboardInterrupt):
        launch_tiles(one, list(range(2000)), threads=2)
    time.sleep(0.05)
    assert len(done) < 200, len(done)


def test_resolution_flag_with_tiny_tiles(capsys, scene, work):
    """``--resolution`` over a scene with ``tile_size = 4``: 262144 tiles (each a launch and a
    future: measured ~2 kB and 0.1 ms each) are refused before the scene's files are read."""
    scene.write_text(TINY_SCENE.replace("spp = 1", "spp = 1\ntile_size = 4"))
    before = snapshot(work)
    rc, out, err = render_run(capsys, ["render", scene, "--out", work / "old.exr", "--resolution", "2048", "2048"])
    assert_bad_input(rc, err, "--resolution", "262144 tiles", "MAX_TILES", out=out)
    assert_unchanged(before, work)
