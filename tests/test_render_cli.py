"""The rbrdf CLI writes an EXR and a PNG and returns 0; errors are one line and exit status 2."""
from __future__ import annotations

import numpy as np

from warp_rbrdf.cli import main
from warp_rbrdf.image_io import read_image

SCENE = """
[camera]
resolution = [16, 12]
[integrator]
spp = 2
[materials.m]
type = "lambert"
[[shapes]]
type = "sphere"
material = "m"
center = [0, 0.5, 0]
radius = 0.5
[[lights]]
type = "constant"
radiance = 0.5
"""


def test_cli_render_scene(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    out = tmp_path / "img" / "r.exr"
    assert main(["render", str(scene), "--spp", "2", "--seed", "1", "--out", str(out),
                 "--threads", "2", "--exposure", "1", "--no-progress"]) == 0
    img = read_image(out)
    assert img.shape == (12, 16, 3) and np.isfinite(img).all() and img.max() > 0
    png = tmp_path / "img" / "r_ev+1.0.png"
    assert read_image(png).shape == (12, 16, 3)
    text = capsys.readouterr().out
    assert "compile" in text and "samples/s" in text and "thread" in text


def test_cli_default_scene(tmp_path):
    out = tmp_path / "d.exr"
    assert main(["render", "--resolution", "16", "16", "--spp", "1", "--out", str(out), "--no-progress"]) == 0
    assert out.exists()


def test_cli_errors(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[camera]\nfov = -3\n")
    assert main(["render", str(bad), "--out", str(tmp_path / "x.exr")]) == 2
    err = capsys.readouterr().err
    assert "bad.toml: camera.fov" in err and err.count("\n") == 1
    assert main(["render", "--device", "warp-drive", "--out", str(tmp_path / "x.exr")]) == 2
    assert "unknown device" in capsys.readouterr().err


def test_cli_cuda_unavailable_is_clear(tmp_path, capsys, monkeypatch):
    """--device cuda on a machine without CUDA: one clear line, exit 2 (simulated where a GPU
    is present, so the test runs everywhere)."""
    from warp_rbrdf.runtime import init_warp

    wp = init_warp()
    monkeypatch.setattr(wp, "is_cuda_available", lambda: False)
    assert main(["render", "--device", "cuda", "--spp", "1", "--resolution", "8", "8",
                 "--out", str(tmp_path / "x.exr")]) == 2
    assert "CUDA is not available" in capsys.readouterr().err


def test_help(capsys):
    assert main(["render", "--help"]) == 0
    out = capsys.readouterr().out
    assert "--spp" in out and "RBRDF_DEVICE" in out and "RBRDF_CPU_ISA" in out
