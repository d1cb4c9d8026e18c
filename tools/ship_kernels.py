"""Regenerate (or check) the ahead-of-time render kernels that ``warp_rbrdf`` ships.

Compiles the README main job's render module (``rbrdf render``, embedded default scene) for
every ISA level of :data:`warp_rbrdf.shipped_kernels.ISA_LEVELS` (x86-64-v4 and x86-64-v3: one
object each; a CPU loads the one of its level) with Warp's public ``wp.compile_aot_module``
into a temporary folder and writes their objects and metadata, with a ``manifest.json`` (Warp
version, platform, per module: its ISA level, Warp's full module hash, the CPU flags and the
SHA-256 of every file), into
``warp_rbrdf/data/kernels/<warp version>/<platform>/`` (replacing that folder).
:mod:`warp_rbrdf.shipped_kernels` loads them.

Run after any change to the integrator, materials, techniques or lights the default scene uses,
or for a new Warp version (about 15 s of CPU; compiling needs no CPU of the level)::

    python -m tools.ship_kernels          # rebuild this Warp version's set
    python -m tools.ship_kernels --check  # exit 1 if the set is not current
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

from warp_rbrdf import shipped_kernels as sk
from warp_rbrdf.paths import PACKAGE_DATA

COMMAND = "python -m tools.ship_kernels"


def default_job_modules(level: str | None = None):
    """The Warp modules the README main job (``rbrdf render``, embedded default scene) loads on the
    CPU, whatever ``$RBRDF_DEVICE`` says (a CUDA renderer builds another kernel: one sample per
    thread, no lanes), compiled for ISA ``level`` (default: this CPU's, :func:`sk.isa_level`)."""
    from warp_rbrdf.defaults import default_scene
    from warp_rbrdf.renderer import Renderer

    if level is None:
        return [Renderer(default_scene(), device="cpu").kernels.render_tile.module]
    # the kernels' flags are those of sk.isa_level(): built as on a CPU of exactly that level,
    # with no cap (compiling for a level needs no CPU that runs it)
    saved_flags, saved_cap = sk.cpu_flags, os.environ.pop(sk.ISA_ENV, None)
    sk.cpu_flags = lambda: sk.ISA_LEVELS[level]
    try:
        modules = [Renderer(default_scene(), device="cpu").kernels.render_tile.module]
    finally:
        sk.cpu_flags = saved_flags
        if saved_cap is not None:
            os.environ[sk.ISA_ENV] = saved_cap
    assert all(m.options.get("cpu_compiler_flags") == sk.portable_cpu_flags(level) for m in modules)
    return modules


def check() -> list[str]:
    """Problems with this Warp version's shipped set for the default job (empty: current)."""
    import warp as wp

    from warp_rbrdf.runtime import init_warp

    init_warp()
    device = wp.get_device("cpu")
    problems = []
    for level in sk.ISA_LEVELS:          # every level ships, best first
        for m in default_job_modules(level):
            src, why = sk.find_shipped(m, device)
            if src is None and why != "cpu-lacks-isa":   # a level this CPU lacks: checked up to running it
                problems.append(f"{level}: {m.get_module_identifier()}: {why}")
    return problems


def regenerate(root: Path | None = None) -> Path:
    """Compile the default job's modules (``wp.compile_aot_module``) into a temporary folder and
    write their object and metadata files, with the manifest, into
    ``<root>/<warp version>/<platform>/`` (replacing that folder); returns that folder."""
    import warp as wp

    from warp_rbrdf.runtime import init_warp

    init_warp()
    device = wp.get_device("cpu")
    root = Path(root) if root is not None else PACKAGE_DATA / "kernels"
    pdir = sk.platform_dir(wp, root)
    with tempfile.TemporaryDirectory(prefix="rbrdf-aot-") as tmp:
        build, staged = Path(tmp) / "build", Path(tmp) / "staged"
        modules = {}
        for level, m in ((lv, m) for lv in sk.ISA_LEVELS for m in default_job_modules(lv)):
            ident = m.get_module_identifier()
            (obj,) = wp.compile_aot_module(m, device=device, module_dir=build / ident)
            # the object and Warp's metadata next to it (not the generated C++ source)
            (staged / ident).mkdir(parents=True)
            files = {}
            for f in (Path(obj), *sorted((build / ident).glob("*.meta"))):
                shutil.copyfile(f, staged / ident / f.name)
                files[f.name] = sk.sha256(staged / ident / f.name)
            modules[ident] = {"hash": sk.module_hash(m), "files": files, "isa": level,
                              "flags": m.options.get("cpu_compiler_flags")}
        manifest = {"warp": wp.config.version, "platform": sk.platform_tag(), "modules": modules,
                    "regenerate": COMMAND}
        (staged / sk.MANIFEST).write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
        if pdir.exists():
            shutil.rmtree(pdir)
        pdir.parent.mkdir(parents=True, exist_ok=True)
        shutil.copytree(staged, pdir)
    return pdir


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog=COMMAND, description="Regenerate (or --check) the shipped AOT render kernels.")
    ap.add_argument("--check", action="store_true", help="exit 1 if the shipped set is not current")
    ap.add_argument("--root", type=Path, default=None, help="folder in place of warp_rbrdf/data/kernels")
    a = ap.parse_args(argv)
    if a.check:
        problems = check()
        for p in problems:
            print(f"shipped kernels not current: {p}; run {COMMAND}")
        return 1 if problems else 0
    pdir = regenerate(a.root)
    size = sum(p.stat().st_size for p in pdir.rglob("*") if p.is_file())
    print(f"wrote {pdir} ({size / 1e3:.0f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
