"""Regenerate (or check) the ahead-of-time render kernels that ``warp_rbrdf`` ships.

Compiles the README main job's render module (``rbrdf render``, embedded default scene) with
Warp's public ``wp.compile_aot_module`` into a temporary folder and writes its object and
metadata, with a ``manifest.json`` (Warp version, platform, ISA level, per module: Warp's full
module hash, the CPU flags and the SHA-256 of every file), into
``warp_rbrdf/data/kernels/<warp version>/<platform>/`` (replacing that folder).
:mod:`warp_rbrdf.shipped_kernels` loads them.

Run after any change to the integrator, materials, techniques or lights the default scene uses,
or for a new Warp version (about 7 s of CPU)::

    python -m tools.ship_kernels          # rebuild this Warp version's set
    python -m tools.ship_kernels --check  # exit 1 if the set is not current
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

from warp_rbrdf import shipped_kernels as sk
from warp_rbrdf.paths import PACKAGE_DATA

COMMAND = "python -m tools.ship_kernels"


def default_job_modules():
    """The Warp modules the README main job (``rbrdf render``, embedded default scene) loads on the
    CPU, whatever ``$RBRDF_DEVICE`` says (a CUDA renderer builds another kernel: one sample per
    thread, no lanes)."""
    from warp_rbrdf.defaults import default_scene
    from warp_rbrdf.renderer import Renderer

    return [Renderer(default_scene(), device="cpu").kernels.render_tile.module]


def check() -> list[str]:
    """Problems with this Warp version's shipped set for the default job (empty: current)."""
    import warp as wp

    from warp_rbrdf.runtime import init_warp

    init_warp()
    device = wp.get_device("cpu")
    problems = []
    for m in default_job_modules():
        src, why = sk.find_shipped(m, device)
        if src is None and why != "cpu-lacks-isa":
            problems.append(f"{m.get_module_identifier()}: {why}")
    return problems


def regenerate(root: Path | None = None) -> Path:
    """Compile the default job's modules (``wp.compile_aot_module``) into a temporary folder and
    write their object and metadata files, with the manifest, into
    ``<root>/<warp version>/<platform>/`` (replacing that folder); returns that folder."""
    import warp as wp

    from warp_rbrdf.runtime import init_warp

    init_warp()
    if not sk.cpu_supports_isa():
        raise SystemExit(f"this CPU lacks {sk.ISA_LEVEL}: its render kernels use -march=native and "
                         f"cannot ship; regenerate on an {sk.ISA_LEVEL} machine")
    device = wp.get_device("cpu")
    root = Path(root) if root is not None else PACKAGE_DATA / "kernels"
    pdir = sk.platform_dir(wp, root)
    with tempfile.TemporaryDirectory(prefix="rbrdf-aot-") as tmp:
        build, staged = Path(tmp) / "build", Path(tmp) / "staged"
        modules = {}
        for m in default_job_modules():
            ident = m.get_module_identifier()
            (obj,) = wp.compile_aot_module(m, device=device, module_dir=build / ident)
            # the object and Warp's metadata next to it (not the generated C++ source)
            (staged / ident).mkdir(parents=True)
            files = {}
            for f in (Path(obj), *sorted((build / ident).glob("*.meta"))):
                shutil.copyfile(f, staged / ident / f.name)
                files[f.name] = sk.sha256(staged / ident / f.name)
            modules[ident] = {"hash": sk.module_hash(m), "files": files,
                              "flags": m.options.get("cpu_compiler_flags")}
        manifest = {"warp": wp.config.version, "platform": sk.platform_tag(), "isa": sk.ISA_LEVEL,
                    "modules": modules, "regenerate": COMMAND}
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
