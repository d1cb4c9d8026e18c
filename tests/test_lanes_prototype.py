"""The K-lane prototype of the render kernel (``benchmarks/lanes_prototype.py``): its
environment distribution and instruction counting, and a ``--quick`` run whose lane and
wavefront variants render the scalar kernel's image from the same random numbers. Its timings are never tested."""
from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import data_file

from benchmarks import lanes_codegen as C
from benchmarks import lanes_prototype as B

pytestmark = pytest.mark.lab  # tests lab code only (the `lab` marker of pyproject.toml)


def test_help(capsys):
    with pytest.raises(SystemExit) as e:
        B.main(["--help"])
    assert e.value.code == 0
    assert capsys.readouterr().out.startswith("usage: python -m benchmarks.lanes_prototype")


def test_env_distribution_is_the_weights():
    """The CDFs' cell masses are luminance x sin(theta) of the row centre, normalized; a black
    row gets a uniform conditional."""
    rng = np.random.default_rng(3)
    H, W = 6, 8
    img = rng.uniform(0.1, 2.0, (H, W, 3)).astype(np.float32)
    img[2] = 0.0
    marg, cond = B.env_distribution(img)
    cond = cond.reshape(H, W + 1)
    lum = img.astype(np.float64) @ [0.2126, 0.7152, 0.0722]
    w = lum * np.sin(np.pi * (np.arange(H) + 0.5) / H)[:, None]
    assert marg[0] == 0 and marg[-1] == 1 and np.all(np.diff(marg) >= 0)
    assert np.allclose(np.diff(marg), w.sum(1) / w.sum(), atol=1e-6)
    rows = [r for r in range(H) if r != 2]
    assert np.allclose(np.diff(cond[rows], axis=1), w[rows] / w[rows].sum(1, keepdims=True), atol=1e-6)
    assert np.allclose(np.diff(cond[2]), 1 / W)


def test_count_instructions():
    text = """
0000000000000000 <k>:
   0:\tvfmadd231ps %ymm1,%ymm2,%ymm3
   5:\tvmulps %xmm1,%xmm2,%xmm3
   9:\tvaddss %xmm1,%xmm2,%xmm3
   d:\tvgatherdps %ymm4,(%rax,%ymm5,4),%ymm6
  13:\tvmovaps %ymm1,%ymm2
  17:\tvfmadd213ps %zmm1,%zmm2,%zmm3
  1d:\tvgatherdps (%rax,%zmm5,4),%zmm6{%k1}
  25:\tret
"""
    c = C.count_instructions(text)
    assert c == {"instructions": 8, "ymm": 3, "zmm": 2, "packed_ps": 3, "packed_ps_ymm": 1, "packed_ps_zmm": 1,
                 "gathers": 2, "scalar_ss": 1}


def test_quick_run_renders_the_scalar_image(tmp_path):
    """Every variant renders the scalar kernel's image (same random numbers: equal up to float
    rounding), the image is not black, and the rates and instruction counts are there."""
    data_file("rgl/cc_ibiza_sunset_rgb.bsdf")
    data_file("envmaps/studio_small_03_1k.hdr")
    out = tmp_path / "r.json"
    assert B.main(["--quick", "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    rows = {r["variant"]: r for r in res["rows"]}
    assert set(rows) == {"scalar", "loop K=4", "hybrid K=4", "unguided", "guided", "wavefront"}
    assert res["image_mean"] > 0
    assert set(res["wavefront_stage_ns"]) == {"camera", "env", "bsdf", "gather"}
    assert all(v > 0 for v in res["wavefront_stage_ns"].values())
    for r in rows.values():
        assert r["agreement"]["mean_rel"] < 1e-5, r
        assert abs(r["agreement"]["image_mean_ratio"] - 1) < 1e-5, r
        assert r["samples_per_s"]["1"] > 0 and r["cpu_samples_per_s"] > 0
        assert r["counts"] == {} or r["counts"]["instructions"] > 100
