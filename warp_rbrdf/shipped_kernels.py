"""Ahead-of-time compiled render kernels shipped with the package (issue 21: cold start).

A fresh install has an empty Warp kernel cache, and LLVM compiling the default scene's render
kernel costs about 5 s of CPU. For the scenes we ship (the README main job's embedded default
scene), the compiled CPU object and Warp's metadata ship in
``warp_rbrdf/data/kernels/<warp version>/<platform>/<module identifier>/``, with a
``manifest.json`` per platform folder recording, per module, Warp's full module hash and the
SHA-256 of every file.

:func:`load_module` is the renderer's compile step: for a CPU module that the user's kernel cache
lacks, it copies the shipped files into the cache (each file through a temporary name and
``os.replace``, the metadata last, so Warp never sees half a module) and lets Warp load the
module as a cache hit. Anything else compiles as before. Never a wrong binary:

- exactly this Warp version (the folder), platform (``linux-x86_64``, the LLVM target triple and
  LLVM version in the manifest) and module identifier (the folder; Warp's name contains the hash
  prefix), and the manifest's full module hash equals ``module.get_module_hash()``;
- the shipped files' SHA-256 match the manifest (a damaged file is not copied);
- the CPU supports the ISA level the objects were built for (:data:`ISA_LEVEL`; LLVM's host
  feature list, as Warp reports it), else an illegal instruction could kill the process;
- if Warp fails to load the copied object, the copied files are removed and the module compiles.

The render kernels are compiled with :data:`PORTABLE_CPU_FLAGS` (Warp's default flags with
``-target-cpu x86-64-v3`` for ``-march=native``; the samples/s cost is measured in
docs/architecture.md), so the module hash, and thus the shipped object, does not depend on the
build machine's CPU; a CPU without x86-64-v3 keeps Warp's ``-march=native`` (and compiles).

``RBRDF_SHIPPED_KERNELS``: another folder to use in place of ``data/kernels`` (tests), or an
empty string to use no shipped kernels.

Regenerate (after any change to the integrator, materials, techniques or lights the default
scene uses, or a new Warp version)::

    python -m warp_rbrdf.shipped_kernels          # rebuilds this Warp version's set
    python -m warp_rbrdf.shipped_kernels --check  # exit 1 if the set is not current
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import shutil
import sys
import tempfile
from pathlib import Path

from .paths import PACKAGE_DATA

#: The instruction-set level of the shipped objects and of every render kernel's code.
ISA_LEVEL = "x86-64-v3"
#: LLVM feature names (Warp's ``_get_cpu_feature_set``) that x86-64-v3 requires.
ISA_FEATURES = frozenset({
    "cx16", "sahf", "popcnt", "sse3", "sse4.1", "sse4.2", "ssse3",                 # v2
    "avx", "avx2", "bmi", "bmi2", "f16c", "fma", "lzcnt", "movbe", "xsave",        # v3
})
#: Warp 1.19's default CPU flags (``warp.config.cpu_compiler_flags``) with a fixed ISA level in
#: place of ``-march=native`` (the flags go to Clang's ``cc1``, which takes ``-target-cpu``).
PORTABLE_CPU_FLAGS = (f"-target-cpu {ISA_LEVEL} -mllvm=-inline-threshold=9000 "
                      "-mllvm=-inline-cold-callsite-threshold=3000 -mllvm=-slp-recursion-max-depth=4 "
                      "-ffp-contract=fast")
MANIFEST = "manifest.json"
ENV = "RBRDF_SHIPPED_KERNELS"


def render_module_options() -> dict:
    """Module options of every render kernel (``@wp.kernel(module_options=...)``): the portable
    flags on a CPU with every :data:`ISA_LEVEL` feature, else none (Warp's ``-march=native``:
    an x86-64-v3 object would stop such a CPU with an illegal instruction)."""
    return {"cpu_compiler_flags": PORTABLE_CPU_FLAGS} if cpu_supports_isa() else {}


def platform_tag() -> str:
    """``<os>-<machine>``, e.g. ``linux-x86_64``: the folder below the Warp version."""
    return f"{sys.platform}-{platform.machine().lower()}"


def shipped_root() -> Path | None:
    """The folder holding ``<warp version>/<platform>/``; ``None`` when disabled."""
    env = os.environ.get(ENV)
    if env is not None:
        return Path(env) if env else None
    return PACKAGE_DATA / "kernels"


def platform_dir(wp, root: Path | None = None) -> Path | None:
    root = shipped_root() if root is None else root
    return None if root is None else root / wp.config.version / platform_tag()


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _toolchain(wp) -> dict:
    # Warp's own CPU target identity (LLVM version, target triple), as in its object file names
    from warp._src import context as ctx

    return {"llvm": ctx._get_cpu_toolchain_version(), "triple": ctx._get_cpu_target_triple()}


def cpu_supports_isa() -> bool:
    """True when the host CPU has every feature of :data:`ISA_LEVEL` (as LLVM detects them)."""
    try:
        from warp._src import context as ctx

        return ISA_FEATURES <= set(ctx._get_cpu_feature_set())
    except Exception:  # noqa: BLE001 - unknown: do not risk an illegal instruction
        return False


def _block_dim(device) -> int:
    """The block_dim variant Warp loads for a launch without one (1 on the CPU)."""
    from warp._src import context as ctx

    return ctx._resolve_launch_block_dim(device, None)


def _names(module, device) -> tuple[str, str, str]:
    """(module identifier, object file name, meta file name) as Warp names them in its cache,
    for the variant a plain launch on ``device`` loads."""
    bd = _block_dim(device)
    return (module.get_module_identifier(bd), module._get_compile_output_name(device, block_dim=bd),
            module._get_meta_name(block_dim=bd))


def _hash(module, device) -> str:
    return module.get_module_hash(_block_dim(device)).hex()


def find_shipped(module, device) -> tuple[Path | None, str]:
    """The verified shipped folder for ``module`` on ``device`` and a one-word reason if none."""
    import warp as wp

    if not device.is_cpu:
        return None, "not-cpu"
    if not wp.config.cache_kernels:   # Warp would compile over the copy anyway
        return None, "cache-off"
    pdir = platform_dir(wp)
    if pdir is None:
        return None, "disabled"
    ident, obj, meta = _names(module, device)
    src = pdir / ident
    try:
        manifest = json.loads((pdir / MANIFEST).read_text())
    except (OSError, ValueError):
        return None, "no-manifest"
    entry = manifest.get("modules", {}).get(ident)
    if entry is None:
        return None, "not-shipped"
    if manifest.get("toolchain") != _toolchain(wp) or manifest.get("warp") != wp.config.version:
        return None, "other-toolchain"
    if entry.get("hash") != _hash(module, device):
        return None, "hash-mismatch"
    files = entry.get("files", {})
    if set(files) != {obj, meta}:
        return None, "other-target"
    for name, digest in files.items():
        try:
            if _sha256(src / name) != digest:
                return None, "checksum-mismatch"
        except OSError:
            return None, "missing-file"
    if not cpu_supports_isa():
        return None, "cpu-lacks-isa"
    return src, "ok"


def _install(src: Path, dest: Path, names: list[str]) -> list[Path]:
    """Copy ``names`` from ``src`` into ``dest`` atomically per file (meta last); returns the
    paths written."""
    dest.mkdir(parents=True, exist_ok=True)
    written = []
    for name in names:
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", dir=dest)
        os.close(fd)
        try:
            shutil.copyfile(src / name, tmp)
            os.replace(tmp, dest / name)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        written.append(dest / name)
    return written


def load_module(module, device) -> str:
    """Load ``module`` on ``device`` as Warp does, taking a shipped binary when the kernel cache
    lacks one. Returns where it came from: ``"shipped"``, ``"cache"`` or ``"compiled"``
    (``"compiled (<reason>)"`` when a shipped binary exists but was not used or failed to load)."""
    import warp as wp

    written: list[Path] = []
    reason = cached = None
    if device.is_cpu:
        try:
            ident, obj, meta = _names(module, device)
            dest = Path(wp.config.kernel_cache_dir) / ident
            cached = (dest / obj).exists() and (dest / meta).exists()
            src, why = (None, "cached") if cached else find_shipped(module, device)
            if src is not None:
                written = _install(src, dest, [obj, meta])
            elif why not in ("cached", "not-shipped", "disabled", "no-manifest", "cache-off"):
                reason = why
        except Exception as e:  # noqa: BLE001 - Warp internals or a read-only/full cache: compile
            reason = f"shipped lookup failed: {e}"
    if written:
        try:
            wp.load_module(module, device=device)
            return "shipped"
        except Exception as e:  # noqa: BLE001 - Warp raises plain Exception on a bad object
            reason = f"load failed: {e}"
            for p in written:
                p.unlink(missing_ok=True)
            module.unload()
    wp.load_module(module, device=device)
    if cached:
        return "cache"
    return "compiled" if reason is None else f"compiled ({reason})"


# ----------------------------------------------------------------------------------------------
def default_job_modules():
    """The Warp modules the README main job (``rbrdf render``, embedded default scene) loads."""
    from .defaults import default_scene
    from .renderer import Renderer

    return [Renderer(default_scene()).kernels.render_tile.module]


def check() -> list[str]:
    """Problems with this Warp version's shipped set for the default job (empty: current)."""
    import warp as wp

    from .runtime import init_warp

    init_warp()
    device = wp.get_device("cpu")
    problems = []
    for m in default_job_modules():
        src, why = find_shipped(m, device)
        if src is None and why != "cpu-lacks-isa":
            problems.append(f"{_names(m, device)[0]}: {why}")
    return problems


def regenerate(root: Path | None = None) -> Path:
    """Compile the default job's modules into a temporary kernel cache and write them, with the
    manifest, into ``<root>/<warp version>/<platform>/`` (replacing that folder)."""
    import warp as wp

    from .runtime import init_warp

    init_warp()
    device = wp.get_device("cpu")
    root = Path(root) if root is not None else PACKAGE_DATA / "kernels"
    pdir = root / wp.config.version / platform_tag()
    old_cache = wp.config.kernel_cache_dir
    with tempfile.TemporaryDirectory(prefix="rbrdf-aot-") as tmp:
        wp.config.kernel_cache_dir = str(Path(tmp) / "cache")
        try:
            staged = Path(tmp) / "staged"
            modules = {}
            for m in default_job_modules():
                m.unload()
                wp.load_module(m, device=device)
                ident, obj, meta = _names(m, device)
                (staged / ident).mkdir(parents=True)
                files = {}
                for name in (obj, meta):
                    shutil.copyfile(Path(wp.config.kernel_cache_dir) / ident / name, staged / ident / name)
                    files[name] = _sha256(staged / ident / name)
                modules[ident] = {"hash": _hash(m, device), "files": files,
                                  "flags": m.options.get("cpu_compiler_flags")}
            manifest = {"warp": wp.config.version, "platform": platform_tag(), "isa": ISA_LEVEL,
                        "toolchain": _toolchain(wp), "modules": modules,
                        "regenerate": "python -m warp_rbrdf.shipped_kernels"}
            (staged / MANIFEST).write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
            if pdir.exists():
                shutil.rmtree(pdir)
            pdir.parent.mkdir(parents=True, exist_ok=True)
            shutil.copytree(staged, pdir)
        finally:
            wp.config.kernel_cache_dir = old_cache
    return pdir


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m warp_rbrdf.shipped_kernels",
                                 description="Regenerate (or --check) the shipped AOT render kernels.")
    ap.add_argument("--check", action="store_true", help="exit 1 if the shipped set is not current")
    ap.add_argument("--root", type=Path, default=None, help="folder in place of warp_rbrdf/data/kernels")
    a = ap.parse_args(argv)
    if a.check:
        problems = check()
        for p in problems:
            print(f"shipped kernels not current: {p}; run python -m warp_rbrdf.shipped_kernels")
        return 1 if problems else 0
    pdir = regenerate(a.root)
    size = sum(p.stat().st_size for p in pdir.rglob("*") if p.is_file())
    print(f"wrote {pdir} ({size / 1e3:.0f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
