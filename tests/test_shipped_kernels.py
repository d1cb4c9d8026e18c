"""Shipped ahead-of-time render kernels (warp_rbrdf.shipped_kernels, written by
tools.ship_kernels through Warp's AOT API): the README main job's kernel loads from the shipped
set with an empty kernel cache without a compile (nothing copied into the cache), for the CPU's
ISA level and for a level capped by ``$RBRDF_CPU_ISA``, and renders what a compiled kernel
renders; the set is current; a damaged, mismatched or unsupported binary is never used (a load
failure falls back to compiling)."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tools import ship_kernels as ship
from warp_rbrdf import shipped_kernels as sk

ROOT = Path(__file__).resolve().parents[1]
REGENERATE = ship.COMMAND

# one process = a fresh install: render the default scene at 1 spp, report where the render
# kernel came from and what Warp left in the (empty at start) kernel cache
_CHILD = r"""
import json, os, sys
from pathlib import Path
import numpy as np
from warp_rbrdf import Renderer
from warp_rbrdf.defaults import default_scene
r = Renderer(default_scene(), device="cpu")
img = r.render(spp=1, seed=3, threads=1)
m = r.kernels.render_tile.module
ex = m.execs[(None, 1)]
np.save(sys.argv[1], img)
cache = Path(os.environ["WARP_CACHE_PATH"])
print(json.dumps({"source": r.kernel_source, "binary": ex.binary_path, "flags": m.options.get("cpu_compiler_flags"),
                  "files": sorted(p.name for p in cache.rglob("*") if p.is_file())}))
"""


def _fresh_render(tmp_path, name, shipped_root=None, isa_cap=None):
    env = dict(os.environ, PYTHONPATH=str(ROOT), WARP_CACHE_PATH=str(tmp_path / f"cache_{name}"))
    env.pop(sk.ISA_ENV, None)
    if isa_cap is not None:
        env[sk.ISA_ENV] = isa_cap
    if shipped_root is not None:
        env[sk.ENV] = str(shipped_root)
    else:
        env.pop(sk.ENV, None)
    out = tmp_path / f"{name}.npy"
    p = subprocess.run([sys.executable, "-c", _CHILD, str(out)], env=env, capture_output=True, check=False,
                       text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1]), np.load(out)


@pytest.fixture(scope="module")
def default_module():
    from warp_rbrdf.defaults import default_scene
    from warp_rbrdf.renderer import Renderer

    r = Renderer(default_scene(), device="cpu")   # the shipped set is CPU code
    return r.kernels.render_tile.module, r.device


def _shipped_copy(tmp_path):
    """A copy of the shipped set to damage; returns (root, platform folder, manifest)."""
    import warp as wp

    src = sk.PACKAGE_DATA / "kernels"
    root = tmp_path / "kernels"
    shutil.copytree(src, root)
    pdir = root / wp.config.version / sk.platform_tag()
    return root, pdir, json.loads((pdir / sk.MANIFEST).read_text())


def test_shipped_set_is_current():
    problems = ship.check()
    assert not problems, (f"the shipped AOT kernels do not match the default scene's ({problems}); "
                          f"regenerate them with `{REGENERATE}` and commit warp_rbrdf/data/kernels")


def test_shipped_set_is_the_cpu_kernel_whatever_rbrdf_device_says(monkeypatch):
    """The tool checks and writes the CPU kernel also where ``$RBRDF_DEVICE`` names a GPU (a
    CUDA renderer builds another module: one sample per thread). On a GPU machine the suite ran
    with RBRDF_DEVICE=cuda and the check compared the CUDA module with the shipped CPU set."""
    (cpu_module,) = ship.default_job_modules()
    monkeypatch.setenv("RBRDF_DEVICE", "cuda")
    (module,) = ship.default_job_modules()
    assert module.get_module_identifier() == cpu_module.get_module_identifier()


@pytest.mark.heavy
def test_fresh_cache_loads_shipped_kernel_and_matches_a_compile(tmp_path, monkeypatch):
    if not sk.cpu_supports_isa():
        pytest.skip(f"this CPU lacks {sk.ISA_LEVEL}: the shipped kernels are not used here")
    info, img = _fresh_render(tmp_path, "shipped")
    assert info["source"] == "shipped", info
    assert info["flags"] == sk.portable_cpu_flags(sk.isa_level()), info
    # no code generation happened (Warp writes the module's .cpp source only when it compiles)
    # and nothing was copied: the object loads in place from the shipped set
    assert not any(f.endswith((".cpp", ".o", ".meta")) for f in info["files"]), info["files"]
    assert Path(info["binary"]).is_relative_to(sk.PACKAGE_DATA / "kernels"), info["binary"]

    # capped at the portable level: the shipped x86-64-v3 object, in place
    info3, img3 = _fresh_render(tmp_path, "shipped_v3", isa_cap=sk.ISA_LEVEL)
    assert info3["source"] == "shipped" and info3["flags"] == sk.PORTABLE_CPU_FLAGS, info3
    assert Path(info3["binary"]).is_relative_to(sk.PACKAGE_DATA / "kernels"), info3["binary"]
    assert img3.shape == img.shape and np.isfinite(img3).all()
    assert abs(float(img3.mean()) / float(img.mean()) - 1.0) < 1e-5   # the same estimator, other code

    # the same shipped object, damaged, with a manifest that vouches for it: Warp fails to
    # load it, the copied files are removed and the kernel compiles as without a shipped set
    root, pdir, manifest = _shipped_copy(tmp_path)
    ident = Path(info["binary"]).parent.name
    entry = manifest["modules"][ident]
    obj = next(n for n in entry["files"] if n.endswith(".o"))
    (pdir / ident / obj).write_bytes(b"not an object file" * 100)
    entry["files"][obj] = sk.sha256(pdir / ident / obj)
    (pdir / sk.MANIFEST).write_text(json.dumps(manifest))
    info2, img2 = _fresh_render(tmp_path, "fallback", shipped_root=root)
    assert info2["source"].startswith("compiled (load failed"), info2
    assert any(f.endswith(".cpp") for f in info2["files"]), info2["files"]
    assert img.shape == img2.shape == (256, 256, 3)
    assert np.isfinite(img).all() and img.mean() > 0
    assert np.array_equal(img, img2), float(np.abs(img - img2).max())


def test_damaged_or_mismatched_shipped_set_is_not_used(tmp_path, monkeypatch, default_module):
    module, device = default_module
    if not sk.cpu_supports_isa():
        pytest.skip(f"this CPU lacks {sk.ISA_LEVEL}")
    root, pdir, manifest = _shipped_copy(tmp_path)
    monkeypatch.setenv(sk.ENV, str(root))
    ident = module.get_module_identifier()
    assert sk.find_shipped(module, device) == (pdir / ident, "ok")

    obj = next(n for n in manifest["modules"][ident]["files"] if n.endswith(".o"))
    good = (pdir / ident / obj).read_bytes()
    (pdir / ident / obj).write_bytes(good[:-1] + bytes([good[-1] ^ 1]))
    assert sk.find_shipped(module, device) == (None, "checksum-mismatch")
    (pdir / ident / obj).write_bytes(good)

    bad = json.loads(json.dumps(manifest))
    bad["modules"][ident]["hash"] = "0" * 64
    (pdir / sk.MANIFEST).write_text(json.dumps(bad))
    assert sk.find_shipped(module, device) == (None, "hash-mismatch")

    bad = json.loads(json.dumps(manifest))
    bad["warp"] = "0.0.0"
    (pdir / sk.MANIFEST).write_text(json.dumps(bad))
    assert sk.find_shipped(module, device) == (None, "other-version")

    bad = json.loads(json.dumps(manifest))
    bad["modules"][ident]["files"] = {"../" + obj: manifest["modules"][ident]["files"][obj]}
    (pdir / sk.MANIFEST).write_text(json.dumps(bad))
    assert sk.find_shipped(module, device) == (None, "checksum-mismatch")   # no path outside

    bad = json.loads(json.dumps(manifest))
    bad["modules"] = {ident + "x": bad["modules"][ident]}
    (pdir / sk.MANIFEST).write_text(json.dumps(bad))
    assert sk.find_shipped(module, device) == (None, "not-shipped")

    bad = json.loads(json.dumps(manifest))
    bad["modules"][ident]["isa"] = "x86-64-v9"          # a level the loader does not know
    (pdir / sk.MANIFEST).write_text(json.dumps(bad))
    assert sk.find_shipped(module, device) == (None, "cpu-lacks-isa")

    (pdir / sk.MANIFEST).write_text(json.dumps(manifest))
    level = manifest["modules"][ident]["isa"]
    monkeypatch.setitem(sk.ISA_LEVELS, level, sk.ISA_LEVELS[level] | {"no-such-cpu-feature"})
    assert sk.find_shipped(module, device) == (None, "cpu-lacks-isa")

    monkeypatch.setenv(sk.ENV, "")
    assert sk.find_shipped(module, device) == (None, "disabled")


def test_render_kernels_use_portable_flags(default_module, monkeypatch):
    module, _ = default_module
    level = sk.isa_level()
    expected = sk.portable_cpu_flags(level) if level else None
    assert module.options["cpu_compiler_flags"] == expected
    # the AOT API builds and loads the module default variant: the one a CPU launch uses
    assert module.options["block_dim"] == sk.CPU_BLOCK_DIM == 1
    for lv in sk.ISA_LEVELS:
        flags = sk.portable_cpu_flags(lv).split()
        assert "-march=native" not in flags and flags[:2] == ["-target-cpu", lv]
    # a CPU without the portable ISA level keeps Warp's -march=native (never an x86-64-v3 object)
    monkeypatch.setattr(sk, "cpu_flags", lambda: sk.ISA_FEATURES - {"avx2"})
    assert sk.render_module_options() == {"block_dim": 1}
    monkeypatch.setattr(sk, "cpu_flags", lambda: sk.ISA_LEVELS["x86-64-v4"])
    assert sk.render_module_options()["cpu_compiler_flags"] == sk.portable_cpu_flags("x86-64-v4")


def test_isa_level_cap(monkeypatch):
    """``$RBRDF_CPU_ISA`` caps the level (never above what the CPU has), asks for Warp's
    -march=native, or is a one-line error naming the variable."""
    from warp_rbrdf.errors import RenderError

    monkeypatch.setattr(sk, "cpu_flags", lambda: sk.ISA_LEVELS["x86-64-v4"] | {"sse"})
    for cap, level in (("", "x86-64-v4"), ("x86-64-v4", "x86-64-v4"), (" x86-64-v3 ", "x86-64-v3"), ("native", None)):
        monkeypatch.setenv(sk.ISA_ENV, cap)
        assert sk.isa_level() == level, cap
    monkeypatch.setattr(sk, "cpu_flags", lambda: sk.ISA_FEATURES)
    monkeypatch.setenv(sk.ISA_ENV, "x86-64-v4")
    assert sk.isa_level() == "x86-64-v3"          # a cap above the CPU: the CPU's level
    monkeypatch.setenv(sk.ISA_ENV, "avx512")
    with pytest.raises(RenderError, match=r"^RBRDF_CPU_ISA: expected one of x86-64-v4, x86-64-v3 or native, got 'avx512'$"):
        sk.isa_level()


def test_isa_level_is_read_from_cpuinfo(tmp_path, monkeypatch):
    """The level check reads the CPU's flags (``/proc/cpuinfo``): all of x86-64-v4's, x86-64-v4;
    one AVX-512 flag missing, x86-64-v3; one x86-64-v3 flag missing, or no such file, Warp's
    -march=native and no shipped object."""
    f = tmp_path / "cpuinfo"
    monkeypatch.setattr(sk, "CPUINFO", f)
    monkeypatch.delenv(sk.ISA_ENV, raising=False)
    v4 = sk.ISA_LEVELS["x86-64-v4"]
    try:
        for flags, ok, level in ((sk.ISA_FEATURES - {"avx2"}, False, None), (sk.ISA_FEATURES | {"sse"}, True, "x86-64-v3"),
                                 (v4 - {"avx512vl"}, True, "x86-64-v3"), (v4, True, "x86-64-v4"), (None, False, None)):
            if flags is None:
                f.unlink()
            else:
                f.write_text("processor\t: 0\nflags\t\t: " + " ".join(sorted(flags)) + "\n\nprocessor\t: 1\n")
            sk.cpu_flags.cache_clear()
            assert sk.cpu_supports_isa() is ok, flags
            assert sk.isa_level() == level, flags
    finally:
        sk.cpu_flags.cache_clear()
